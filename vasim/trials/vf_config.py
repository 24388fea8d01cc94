"""The configuration of a virtual-fixture trial (``VfTrialConfig``, also named
``TrialConfig``) and what it names: the task (``make_task``) and the simulated person's
profile (``make_profile``).

Moved out of ``vasim.trials.vf`` (which re-exports them) so that the engine's model
(``vasim.trials.vf_model``) and the engine (``vasim.trials.vf``) each stay small.

**Decision** (issue #29, a config per trial kind): a teleoperation trial has its own
``vasim.trials.teleop_config.TeleopTrialConfig``; the VF config lost ``mode``,
``mode_practice`` and ``mode_effects`` (a VF trial never used them) and the teleoperation
config has no ``task``, ``variant``, ``schema``, ``dt``, ``velocity_cutoff_hz``,
``poi_spacing`` or ``gain`` (documented as unused there). A VF trial's stored config record
is unchanged (the three teleoperation fields were left out of it when None).
``TrialConfig`` stays the VF config's name for its many callers.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from vasim.core.config import check_choice, check_number, expect
from vasim.fixtures.gain import GainRule, rule_from_record
from vasim.operator.scripted import OperatorProfile
from vasim.tasks import Task, point_task, trajectory_task
from vasim.trials.config_fields import SharedFields, check_shared_fields, preset_profile

TaskName = Literal["trajectory", "point"]

SkillName = Literal["novice", "intermediate", "expert"]


@dataclass(frozen=True)
class VfTrialConfig:
    """Everything that defines one virtual-fixture trial (stored with it; same config +
    seed = same trial).

    Attributes:
        task: ``"trajectory"`` (trajectory following) or ``"point"`` (point targeting).
        variant: trajectory variant, 0 = original, 1..6 mirrored/rotated.
        schema: fixture schema name (``protocols/schemas/NAME.toml``) or path to a TOML file.
        operator: input device; ``"scripted"`` is the only one in this release.
        skill: scripted operator preset.
        seed: random seed of the operator (noise, tremor).
        practice: number of earlier trials of this subject (learning).
        dt: control step [s] (1 ms: the haptic rate).
        max_time: simulated time limit [s]; the trial ends there even if points remain.
        subject: subject code (never a name), or None for a trial without a subject.
        label: a free-practice label (``TrialMeta.label``), or None.
        velocity_cutoff_hz: low-pass cutoff of the TCP velocity FF's damping uses [Hz].
        reach_radius: r_reach [m] (a protocol parameter); None: the task's default (5 mm).
        poi_spacing: arc length between the trajectory's POIs [m] (a protocol parameter);
            None: the task's default (10.5 mm, 30 POIs).
        profile: the operator profile; None: the ``skill`` preset.
        scene: the virtual abdomen the task lives in: a scene name
            (``protocols/scenes/NAME.toml``) or TOML path, or ``"none"`` for a static task
            with no tissue (no breathing, no contact).
        gain: the fixture gain (``vasim.fixtures.gain``): a constant in [0, 1] (1: the
            schema as written) or an ``AdaptiveRule``; logged per sample (``gain``).
    """

    task: TaskName = "trajectory"
    variant: int = 0
    schema: str = "none"
    operator: str = "scripted"
    skill: SkillName = "intermediate"
    seed: int = 0
    practice: int = 0
    dt: float = 1e-3
    max_time: float = 180.0
    subject: str | None = None
    velocity_cutoff_hz: float = 30.0
    profile: OperatorProfile | None = field(default=None, compare=False)
    reach_radius: float | None = None
    scene: str = "default"
    poi_spacing: float | None = None
    label: str | None = None
    gain: GainRule = 1.0

    @property
    def kind(self) -> str:
        """The trial kind (``vasim.trials.registry``): ``"vf"``."""
        return "vf"

    def __post_init__(self) -> None:
        # the fixture gain (vasim.fixtures.gain): a constant, or the adaptive rule (a stored
        # record's table becomes the rule)
        object.__setattr__(self, "gain", rule_from_record(self.gain, "gain"))
        check_choice(self.task, "task", ("trajectory", "point"))
        expect(self.task != "point" or self.variant == 0, self.variant,
               "variant 0 (the point task has no variants)", field="variant")
        check_number(self.dt, "dt", gt=0, le=0.02)
        check_number(self.velocity_cutoff_hz, "velocity_cutoff_hz", gt=0)
        check_shared_fields(self)


TrialConfig = VfTrialConfig
"""The VF trial's configuration under its historical name."""


def make_task(config: VfTrialConfig) -> Task:
    """Builds the task a config names (with its reach radius and POI spacing, if the config
    sets them)."""
    kw: dict[str, float] = {}
    if config.reach_radius is not None:
        kw["reach_radius"] = float(config.reach_radius)
    if config.task == "trajectory":
        if config.poi_spacing is not None:
            kw["poi_spacing"] = float(config.poi_spacing)
        return trajectory_task(config.variant, **kw)
    if config.reach_radius is not None:
        return point_task(reach_radius=float(config.reach_radius))
    return point_task()


def make_profile(config: SharedFields) -> OperatorProfile:
    """The config's operator profile, else its skill's preset (any trial kind)."""
    return preset_profile(config.profile, config.skill)


__all__ = ["SkillName", "TaskName", "TrialConfig", "VfTrialConfig", "make_profile", "make_task"]
