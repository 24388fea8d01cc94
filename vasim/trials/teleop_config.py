"""The configuration of a teleoperation trial (``TeleopTrialConfig``): the needle task of
the MRCP vs standard-teleoperation study on the MRCP slave station (``vasim.trials.teleop``,
18 ms control cycle), in one mode.

A config per trial kind (issue #29): the VF trial's ``vasim.trials.vf_config.VfTrialConfig``
keeps the task, schema, control step and fixture gain; this one keeps the mode and the
mode-specific learning. The shared fields are checked by
``vasim.trials.config_fields.check_shared_fields``.

**Decision** (stored record): a teleoperation trial's config record
(``vasim.trials.vf_run.config_record``) holds this dataclass's fields; the VF fields the old
shared config carried there unused (task, variant, schema, dt, velocity_cutoff_hz,
poi_spacing) are no longer written. The trial row's own columns (task ``"needle"``, schema
``"none"``, dt 18 ms) and the samples are unchanged.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from vasim.core.config import check_choice, check_type, expect
from vasim.core.errors import ConfigError
from vasim.operator.profile import OperatorProfile
from vasim.operator.teleop_profile import TeleopEffects
from vasim.trials.config_fields import check_shared_fields
from vasim.trials.kinds import TELEOPERATION_MODES


@dataclass(frozen=True)
class TeleopTrialConfig:
    """Everything that defines one teleoperation trial (stored with it; same config + seed =
    same trial).

    Attributes:
        mode: the teleoperation mode (``"stdt"``, ``"mrcp"``, ``"mrcp_cam"``; spec/study.md
            §4); it is the trial's kind.
        operator, skill, seed, practice, max_time, subject, profile, scene, label: as in
            ``VfTrialConfig``.
        reach_radius: the rings' pass radius [m] (a protocol parameter); None:
            ``vasim.operator.needle.RING_RADIUS``.
        mode_practice: earlier trials of this teleoperation mode in the session (the
            mode-specific learning of ``vasim.operator.teleop_profile``); None: ``practice``.
        mode_effects: the scripted person's mode penalties
            (``vasim.operator.teleop_profile.TeleopEffects``, from the session's declared
            teleoperation scenario); None: none (``NEUTRAL``, the mechanism alone). A
            stored record's dict becomes the dataclass.
    """

    mode: str
    operator: str = "scripted"
    skill: str = "intermediate"
    seed: int = 0
    practice: int = 0
    max_time: float = 180.0
    subject: str | None = None
    profile: OperatorProfile | None = field(default=None, compare=False)
    reach_radius: float | None = None
    scene: str = "default"
    label: str | None = None
    mode_practice: int | None = None
    mode_effects: TeleopEffects | None = None

    @property
    def kind(self) -> str:
        """The trial kind (``vasim.trials.registry``): the mode."""
        return self.mode

    @property
    def task(self) -> str:
        """The task's name: every teleoperation trial carries the needle through the rings
        (``teleop_run.teleop_meta`` stores it as ``"needle"``)."""
        return "needle"

    def __post_init__(self) -> None:
        check_choice(self.mode, "mode", TELEOPERATION_MODES)
        check_shared_fields(self)
        mp = self.mode_practice
        expect(mp is None or (isinstance(mp, int) and not isinstance(mp, bool) and mp >= 0),
               mp, "an integer >= 0 or none", field="mode_practice")
        me = self.mode_effects
        if isinstance(me, Mapping):
            try:
                object.__setattr__(self, "mode_effects", TeleopEffects(**me))
            except (TypeError, ValueError) as exc:
                raise ConfigError(f"mode_effects: {exc}", field="mode_effects") from None
        elif me is not None:
            check_type(me, "mode_effects", TeleopEffects, "TeleopEffects or none")



__all__ = ["TeleopTrialConfig"]
