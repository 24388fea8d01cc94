"""The fields every trial kind's configuration shares, checked once.

``vasim.trials.vf_config.VfTrialConfig`` (a virtual-fixture trial) and
``vasim.trials.teleop_config.TeleopTrialConfig`` (a teleoperation trial) are separate frozen
dataclasses (issue #29: a config per trial kind); the person, the seed, the limits and the
scene are the same in both and are checked here.
"""

from __future__ import annotations

from typing import Protocol

from vasim.core.config import check_choice, check_number, check_type, expect
from vasim.operator.profile import OperatorProfile
from vasim.trials.kinds import check_trial_time

SKILLS = ("novice", "intermediate", "expert")
"""The scripted operator's presets."""


class SharedFields(Protocol):
    """What :func:`check_shared_fields` reads."""

    @property
    def operator(self) -> str: ...
    @property
    def skill(self) -> str: ...
    @property
    def seed(self) -> int: ...
    @property
    def practice(self) -> int: ...
    @property
    def max_time(self) -> float: ...
    @property
    def subject(self) -> str | None: ...
    @property
    def profile(self) -> OperatorProfile | None: ...
    @property
    def reach_radius(self) -> float | None: ...
    @property
    def scene(self) -> str: ...


def check_shared_fields(cfg: SharedFields) -> None:
    """Checks the shared fields of a trial configuration.

    Raises:
        ConfigError: naming the first bad field and its value.
    """
    seed = cfg.seed
    expect(isinstance(seed, int) and not isinstance(seed, bool) and 0 <= seed < 2**63, seed,
           "an integer in [0, 2**63)", field="seed")
    from vasim.records.trial_meta import validate_subject_code

    if cfg.subject is not None:
        validate_subject_code(cfg.subject)
    check_choice(cfg.operator, "operator", ("scripted",))
    check_choice(cfg.skill, "skill", SKILLS)
    check_trial_time(cfg.max_time, "max_time")
    expect(cfg.practice >= 0, cfg.practice, "a practice count >= 0", field="practice")
    if cfg.reach_radius is not None:
        check_number(cfg.reach_radius, "reach_radius", gt=0)
    expect(isinstance(cfg.scene, str) and cfg.scene.strip(), cfg.scene,
           "a scene name, a TOML path or 'none'", field="scene")
    if cfg.profile is not None:
        check_type(cfg.profile, "profile", OperatorProfile, "an OperatorProfile")


def preset_profile(profile: OperatorProfile | None, skill: str) -> OperatorProfile:
    """``profile`` if given, else the ``skill`` preset (intermediate for an unknown name)."""
    if profile is not None:
        return profile
    if skill == "novice":
        return OperatorProfile.novice()
    if skill == "expert":
        return OperatorProfile.expert()
    return OperatorProfile.intermediate()


__all__ = ["SKILLS", "SharedFields", "check_shared_fields", "preset_profile"]
