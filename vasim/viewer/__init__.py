"""The browser viewer (viser): ``vasim serve`` starts :class:`ViewerApp`.

``views`` holds one class per visual (each owns its viser handles and exposes ``update``);
``app`` wires them to a trial running in real time; ``cli`` registers ``vasim serve``.
"""

from __future__ import annotations

from vasim.viewer.app import Command as Command
from vasim.viewer.app import Snapshot as Snapshot
from vasim.viewer.app import TrialInfo as TrialInfo
from vasim.viewer.app import ViewerApp as ViewerApp
from vasim.viewer.app import endoscope_pose as endoscope_pose
from vasim.viewer.app import is_loopback as is_loopback
from vasim.viewer.views import ArrowView as ArrowView
from vasim.viewer.views import CameraController as CameraController
from vasim.viewer.views import CameraPose as CameraPose
from vasim.viewer.views import GhostView as GhostView
from vasim.viewer.views import HudInfo as HudInfo
from vasim.viewer.views import HudView as HudView
from vasim.viewer.views import OrganView as OrganView
from vasim.viewer.views import ToolView as ToolView
from vasim.viewer.views import TrajectoryView as TrajectoryView

__all__ = [
    "ArrowView",
    "CameraController",
    "CameraPose",
    "Command",
    "GhostView",
    "HudInfo",
    "HudView",
    "OrganView",
    "Snapshot",
    "ToolView",
    "TrajectoryView",
    "TrialInfo",
    "ViewerApp",
    "endoscope_pose",
    "is_loopback",
]
