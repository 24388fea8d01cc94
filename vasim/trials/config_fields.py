"""The fields every trial kind's configuration shares, checked once.

``vasim.trials.vf_config.VfTrialConfig`` (a virtual-fixture trial) and
``vasim.trials.teleop_config.TeleopTrialConfig`` (a teleoperation trial) are separate frozen
dataclasses (issue #29: a config per trial kind); the person, the seed, the limits and the
scene are the same in both and are checked here.
"""

from __future__ import annotations

import math
from typing import Protocol

from vasim.core.errors import ConfigError
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
    if isinstance(cfg.seed, bool) or not isinstance(cfg.seed, int) or not (
            0 <= cfg.seed < 2**63):
        raise ConfigError(f"seed must be an integer in [0, 2**63), got {cfg.seed!r}",
                          field="seed")
    from vasim.records.trial_meta import validate_subject_code

    if cfg.subject is not None:
        validate_subject_code(cfg.subject)
    if cfg.operator != "scripted":
        raise ConfigError(f"unknown operator {cfg.operator!r} (available: 'scripted')",
                          field="operator")
    if cfg.skill not in SKILLS:
        raise ConfigError(f"unknown skill {cfg.skill!r} (novice, intermediate, expert)",
                          field="skill")
    try:
        check_trial_time(cfg.max_time, "max_time")
    except ConfigError as exc:
        raise ConfigError(f"max_time {exc.reason}", field="max_time") from None
    if cfg.practice < 0:
        raise ConfigError(f"practice must be >= 0, got {cfg.practice!r}", field="practice")
    r = cfg.reach_radius
    if r is not None and (isinstance(r, bool) or not isinstance(r, int | float)
                          or not math.isfinite(r) or not r > 0):
        raise ConfigError(f"reach_radius must be > 0 m, got {r!r}", field="reach_radius")
    if not isinstance(cfg.scene, str) or not cfg.scene.strip():
        raise ConfigError(f"scene must be a scene name, a TOML path or 'none', got "
                          f"{cfg.scene!r}", field="scene")
    if cfg.profile is not None and not isinstance(cfg.profile, OperatorProfile):
        raise ConfigError(f"profile must be an OperatorProfile, got {cfg.profile!r}",
                          field="profile")


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
