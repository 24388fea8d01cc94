"""The operator's hands and the endoscope of a teleoperation trial (``vasim.trials.teleop``).

* :class:`Hand`: one scripted hand (``vasim.operator.scripted``) on one master, following
  a path of goals; the master increment per step [m, world frame].
* :class:`ScriptedHands`: the trial's default ``HandFactory`` (``vasim.operator.port``):
  a scripted :class:`Hand` per path, with the mode's carry or handover profile.
* :class:`Camera`: the endoscope, fixed on the rings' centroid (``stdt``, ``mrcp``) or
  driven by the camera hand of ``mrcp_cam`` (its decisions are in ``vasim.trials.teleop``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vasim.mrcp.toolstation import CameraRobot
from vasim.operator.needle import NeedleTask
from vasim.operator.port import HandRequest
from vasim.operator.scripted import OperatorProfile, ScriptedOperator
from vasim.operator.teleop_profile import TeleopAdjustment
from vasim.trials.endoscope import DEFAULT_ENDOSCOPE, in_view_cone

CAMERA_FOV_DEG = 70.0
"""Full field of view of the camera robot of ``mrcp_cam`` [deg]."""

CAMERA_ZOOM = math.tan(math.radians(DEFAULT_ENDOSCOPE.fov_deg / 2)) / math.tan(
    math.radians(CAMERA_FOV_DEG / 2))
"""Magnification of the following camera relative to the fixed endoscope (1.70)."""

CAMERA_TIME_CONSTANT = 0.4
"""The camera hand's pursuit time constant [s]."""

class Hand:
    """One scripted hand on one master, following a path of goals."""

    def __init__(self, profile: OperatorProfile, task: NeedleTask, points: np.ndarray,
                 start: np.ndarray, seed: int, practice: int,
                 reach: float | tuple[float, ...]) -> None:
        self.points = np.asarray(points, dtype=float).reshape(-1, 3)
        self.reach = np.broadcast_to(np.asarray(reach, dtype=float), (len(self.points),))
        self.op = ScriptedOperator(profile, task.operator_task(
            self.points, start, float(self.reach.min())), seed=seed, practice=practice)
        self.op.reset(start)
        self.j = 0

    @property
    def done(self) -> bool:
        return self.j >= len(self.points)

    def move(self, dt: float, seen: np.ndarray, goal: np.ndarray, zoom: float) -> np.ndarray:
        """One hand step: the master increment [m] toward ``goal`` (current position)."""
        dx = self.op.step_floats(dt, tuple(seen.tolist()), tuple(goal.tolist()),
                                 min(self.j, len(self.points) - 1), False, 0.0, zoom,
                                 (1.0, 1.0, 1.0), (0.0, 0.0, 0.0))
        d = np.asarray(dx, dtype=float)
        return np.where(np.isfinite(d), d, 0.0)

    def check(self, position: np.ndarray, goal: np.ndarray) -> bool:
        """Advances the goal when ``position`` is within reach of it; True if it did."""
        if float(np.linalg.norm(position - goal)) <= self.reach[min(self.j,
                                                                     len(self.reach) - 1)]:
            self.j += 1
            return True
        return False


@dataclass(frozen=True)
class ScriptedHands:
    """The scripted person's hands (the default ``HandFactory`` of ``TeleopTrial``).

    Attributes:
        adjustment: the hands' profiles of this mode and mode practice (``carry`` for a
            carry to a ring, ``handover`` for every other movement).
        task: the needle task. practice: the operator's practice (trials done).
    """

    adjustment: TeleopAdjustment
    task: NeedleTask
    practice: int

    def __call__(self, request: HandRequest) -> Hand:
        prof = self.adjustment.carry if request.carry else self.adjustment.handover
        return Hand(prof, self.task, request.points, request.start, request.seed,
                    self.practice, request.reach)


@dataclass
class Camera:
    """The endoscope: fixed on the rings' centroid, or (``follows``) driven by a hand."""

    robot: CameraRobot
    aim: np.ndarray
    follows: bool
    path: float = 0.0

    @property
    def zoom(self) -> float:
        return CAMERA_ZOOM if self.follows else 1.0

    def view(self) -> tuple[np.ndarray, np.ndarray, float]:
        return self.robot.lens(self.aim), self.aim, math.radians(self.robot.fov_deg)

    def contains(self, p: np.ndarray) -> bool:
        pos, look, fov = self.view()
        return bool(in_view_cone(p[None, :], pos, look, fov)[0])

    def follow(self, p: np.ndarray, dt: float) -> None:
        """The camera hand: re-aim when ``p`` leaves the central third of the view."""
        if not self.follows:
            return
        pos, look, fov = self.view()
        if bool(in_view_cone(p[None, :], pos, look, fov / 3.0)[0]):
            return
        step = (p - self.aim) * (1.0 - math.exp(-dt / CAMERA_TIME_CONSTANT))
        self.aim = self.aim + step
        self.path += float(np.linalg.norm(step))


__all__ = ["CAMERA_FOV_DEG", "CAMERA_TIME_CONSTANT", "CAMERA_ZOOM", "Camera", "Hand",
           "ScriptedHands"]
