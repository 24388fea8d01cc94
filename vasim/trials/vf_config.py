"""The configuration of a virtual-fixture trial (``TrialConfig``) and what it names: the
task (``make_task``) and the simulated person's profile (``make_profile``).

Moved out of ``vasim.trials.vf`` (which re-exports them) so that the engine's model
(``vasim.trials.vf_model``) and the engine (``vasim.trials.vf``) each stay small.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

from vasim.core.errors import ConfigError
from vasim.fixtures.gain import GainRule, rule_from_record
from vasim.operator.scripted import OperatorProfile
from vasim.operator.teleop_profile import TeleopEffects
from vasim.tasks import Task, point_task, trajectory_task
from vasim.trials.kinds import TELEOPERATION_MODES, check_trial_time

TaskName = Literal["trajectory", "point"]

SkillName = Literal["novice", "intermediate", "expert"]


@dataclass(frozen=True)
class TrialConfig:
    """Everything that defines one trial (stored with it; same config + seed = same trial).

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
        mode: None for a trial of ``task`` under ``schema`` (this module's runner), or a
            teleoperation mode of the MRCP study (``"stdt"``, ``"mrcp"``, ``"mrcp_cam"``):
            the needle task on the MRCP slave station (``vasim.trials.teleop``, 18 ms
            control cycle), where ``task``, ``variant``, ``schema``, ``dt`` and
            ``velocity_cutoff_hz`` are not used.
        gain: the fixture gain (``vasim.fixtures.gain``): a constant in [0, 1] (1: the
            schema as written) or an ``AdaptiveRule``; logged per sample (``gain``).
        mode_practice: earlier trials of this teleoperation mode in the session (the
            mode-specific learning of ``vasim.operator.teleop_profile``); None: ``practice``.
        mode_effects: the scripted person's mode penalties in a teleoperation trial
            (``vasim.operator.teleop_profile.TeleopEffects``, from the session's declared
            teleoperation scenario); None: none (``NEUTRAL``, the mechanism alone). A
            stored record's dict becomes the dataclass.
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
    mode: str | None = None
    label: str | None = None
    gain: GainRule = 1.0
    mode_practice: int | None = None
    mode_effects: TeleopEffects | None = None

    def __post_init__(self) -> None:
        # the fixture gain (vasim.fixtures.gain): a constant, or the adaptive rule (a stored
        # record's table becomes the rule)
        object.__setattr__(self, "gain", rule_from_record(self.gain, "gain"))
        if self.mode is not None and self.mode not in TELEOPERATION_MODES:
            raise ConfigError(f"unknown teleoperation mode {self.mode!r} (expected one of "
                              f"{', '.join(TELEOPERATION_MODES)} or None)", field="mode")
        if self.task not in ("trajectory", "point"):
            raise ConfigError(f"unknown task {self.task!r} (expected 'trajectory' or 'point')",
                              field="task")
        if self.task == "point" and self.variant != 0:
            raise ConfigError(f"the point task has no variants, got variant {self.variant!r}",
                              field="variant")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or not (
                0 <= self.seed < 2**63):
            raise ConfigError(f"seed must be an integer in [0, 2**63), got {self.seed!r}",
                              field="seed")
        from vasim.records.trial_meta import validate_subject_code

        if self.subject is not None:
            validate_subject_code(self.subject)
        if self.operator != "scripted":
            raise ConfigError(f"unknown operator {self.operator!r} (available: 'scripted')",
                              field="operator")
        if self.skill not in ("novice", "intermediate", "expert"):
            raise ConfigError(f"unknown skill {self.skill!r} (novice, intermediate, expert)",
                              field="skill")
        if not (math.isfinite(self.dt) and 0 < self.dt <= 0.02):
            raise ConfigError(f"dt must be in (0, 0.02] s, got {self.dt!r}", field="dt")
        try:
            check_trial_time(self.max_time, "max_time")
        except ConfigError as exc:
            raise ConfigError(f"max_time {exc.reason}", field="max_time") from None
        if self.practice < 0:
            raise ConfigError(f"practice must be >= 0, got {self.practice!r}", field="practice")
        if not (math.isfinite(self.velocity_cutoff_hz) and self.velocity_cutoff_hz > 0):
            raise ConfigError(f"velocity_cutoff_hz must be > 0, got {self.velocity_cutoff_hz!r}",
                              field="velocity_cutoff_hz")
        r = self.reach_radius
        if r is not None and (isinstance(r, bool) or not isinstance(r, int | float)
                              or not math.isfinite(r) or not r > 0):
            raise ConfigError(f"reach_radius must be > 0 m, got {r!r}", field="reach_radius")
        if not isinstance(self.scene, str) or not self.scene.strip():
            raise ConfigError(f"scene must be a scene name, a TOML path or 'none', got "
                              f"{self.scene!r}", field="scene")
        if self.profile is not None and not isinstance(self.profile, OperatorProfile):
            raise ConfigError(f"profile must be an OperatorProfile, got {self.profile!r}",
                              field="profile")
        mp = self.mode_practice
        if mp is not None and (isinstance(mp, bool) or not isinstance(mp, int) or mp < 0):
            raise ConfigError(f"mode_practice must be an integer >= 0 or None, got {mp!r}",
                              field="mode_practice")
        me = self.mode_effects
        if isinstance(me, Mapping):
            try:
                object.__setattr__(self, "mode_effects", TeleopEffects(**me))
            except (TypeError, ValueError) as exc:
                raise ConfigError(f"mode_effects: {exc}", field="mode_effects") from None
        elif me is not None and not isinstance(me, TeleopEffects):
            raise ConfigError(f"mode_effects must be TeleopEffects or None, got {me!r}",
                              field="mode_effects")



def make_task(config: TrialConfig) -> Task:
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


def make_profile(config: TrialConfig) -> OperatorProfile:
    if config.profile is not None:
        return config.profile
    if config.skill == "novice":
        return OperatorProfile.novice()
    if config.skill == "expert":
        return OperatorProfile.expert()
    return OperatorProfile.intermediate()


__all__ = ["SkillName", "TaskName", "TrialConfig", "make_profile", "make_task"]
