"""Every trial kind's configuration: ``AnyTrialConfig`` is a ``VfTrialConfig`` (a
virtual-fixture trial, ``vasim.trials.vf_config``) or a ``TeleopTrialConfig`` (a
teleoperation trial, ``vasim.trials.teleop_config``); ``config.kind`` names its kind in
``vasim.trials.registry``."""

from __future__ import annotations

from typing import TypeAlias

from vasim.trials.teleop_config import TeleopTrialConfig
from vasim.trials.vf_config import VfTrialConfig

AnyTrialConfig: TypeAlias = VfTrialConfig | TeleopTrialConfig
"""A trial configuration of any kind."""

__all__ = ["AnyTrialConfig", "TeleopTrialConfig", "VfTrialConfig"]
