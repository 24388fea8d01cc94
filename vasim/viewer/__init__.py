"""The browser viewer (viser): ``vasim serve`` starts :class:`ViewerApp`.

``views`` holds one class per visual (each owns its viser handles and exposes ``update``);
``controller`` owns the training state (modes, sessions, the live trial, the store); ``live``
runs a trial in real time (``teleop_live`` a teleoperation trial a person drives, issue
#28); ``panel`` is the experimenter's panel (``questionnaire_form`` its questionnaires),
``audio`` the page's AG synth; ``app`` wires them together; ``cli`` registers ``vasim
serve``.
"""

from __future__ import annotations

from vasim.viewer.access import is_loopback as is_loopback
from vasim.viewer.app import Command as Command
from vasim.viewer.app import DragInput as DragInput
from vasim.viewer.app import Snapshot as Snapshot
from vasim.viewer.app import TrialInfo as TrialInfo
from vasim.viewer.app import ViewerApp as ViewerApp
from vasim.viewer.app import endoscope_pose as endoscope_pose
from vasim.viewer.app_options import PageAccess as PageAccess
from vasim.viewer.app_options import TrialOptions as TrialOptions
from vasim.viewer.app_options import ViewerPace as ViewerPace
from vasim.viewer.audio import AudioStream as AudioStream
from vasim.viewer.controller import PanelState as PanelState
from vasim.viewer.controller import TrainingController as TrainingController
from vasim.viewer.panel import ExperimenterPanel as ExperimenterPanel
from vasim.viewer.trainee import HudInfo as HudInfo
from vasim.viewer.trainee import HudView as HudView
from vasim.viewer.views import ArrowView as ArrowView
from vasim.viewer.views import CameraController as CameraController
from vasim.viewer.views import CameraPose as CameraPose
from vasim.viewer.views import GhostView as GhostView
from vasim.viewer.views import OrganView as OrganView
from vasim.viewer.views import ToolView as ToolView
from vasim.viewer.views import TrajectoryView as TrajectoryView

__all__ = [
    "ArrowView",
    "AudioStream",
    "CameraController",
    "CameraPose",
    "Command",
    "DragInput",
    "ExperimenterPanel",
    "GhostView",
    "HudInfo",
    "HudView",
    "OrganView",
    "PageAccess",
    "PanelState",
    "Snapshot",
    "ToolView",
    "TrainingController",
    "TrajectoryView",
    "TrialInfo",
    "TrialOptions",
    "ViewerApp",
    "ViewerPace",
    "endoscope_pose",
    "is_loopback",
]
