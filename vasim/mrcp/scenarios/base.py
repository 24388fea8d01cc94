"""What a scripted MRCP scenario is: a station, a task and an operator's scripted input.

A scenario module builds a :class:`Setup` — the robots (the kernel's
:class:`~vasim.mrcp.interfaces.ArmKinematics`), their
:class:`~vasim.mrcp.interfaces.ProximityWorld`, the task's grasp points, who holds the task
at start, the kernel parameters — and an *operator*: the task pose commanded at time ``t``
(the seed's experiments map the master's increments onto the manipulated object, so a
scripted task trajectory *is* the operator's input). :mod:`vasim.mrcp.scenarios.runner`
runs it through :class:`~vasim.mrcp.kernel.MRCPKernel`.

Helpers shared by the scenarios: gripper frames on a cube's faces (:func:`cube_points`),
RX60B stations (:func:`rx60b_model`, :func:`base_pose`); rotations come from
``vasim.core.geometry``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from vasim.core.geometry import frame_z_x, rot_z
from vasim.mrcp.interfaces import ArmKinematics, FloatArray, ProximityWorld
from vasim.mrcp.kernel import KernelConfig, TaskPoint

#: The operator: time [s] -> commanded task position ``(3,)`` and rotation ``(3, 3)`` (or None).
Operator = Callable[[float], tuple[FloatArray, FloatArray | None]]


@dataclass(frozen=True)
class ScenarioOptions:
    """How to run a scenario.

    Attributes:
        seed: seed of the kernel's random planner force (and of any scenario randomness).
        duration: run length [s] (None: the scenario's own).
        coarse: a cheaper run for tests: a longer evaluation period (and proportionally
            larger per-cycle steps), same task trajectory and the same qualitative outcome.
    """

    seed: int = 0
    duration: float | None = None
    coarse: bool = False

    def __post_init__(self) -> None:
        if self.duration is not None and self.duration <= 0.0:
            raise ValueError(f"ScenarioOptions.duration must be > 0, got {self.duration!r}")


@dataclass
class Setup:
    """A built scenario, ready to run.

    Attributes:
        arms: robot name -> kinematics (the kernel's robots; the world may hold more, e.g.
            a camera robot).
        world: the station.
        task_points: the task's grasp points (task frame).
        rsel, cutp: the robot holding the task at start and its point.
        operator: the scripted operator input.
        config: kernel parameters.
        duration: run length [s].
        on_cycle: called before each cycle with the time and the world (a moving obstacle).
        extras: time -> scenario data for task-oriented indices (passed to the kernel).
        close: releases the world's resources.
        notes: scenario facts copied into the run's summary (e.g. the turning rate).
        custom_run: a scenario that is more than the kernel following a script (the
            suture's state graph switches the pairing mode) runs its own loop:
            ``custom_run(name, duration, progress) -> RunResult``; the runner calls it
            instead of its own (None: the runner's loop).
    """

    arms: dict[str, ArmKinematics]
    world: ProximityWorld
    task_points: list[TaskPoint]
    rsel: str
    cutp: int
    operator: Operator
    config: KernelConfig
    duration: float
    on_cycle: Callable[[float, ProximityWorld], None] | None = None
    extras: Callable[[float], Mapping[str, Any]] | None = None
    close: Callable[[], None] = lambda: None
    notes: dict[str, Any] = field(default_factory=dict)
    custom_run: Callable[..., Any] | None = None


class Scenario(Protocol):
    """A registered scenario: ``build(options)`` -> :class:`Setup`."""

    name: str
    summary: str
    duration: float

    def build(self, options: ScenarioOptions) -> Setup: ...


# ---------------------------------------------------------------------------- geometry


def gripper_frame(approach: FloatArray, x_hint: FloatArray) -> FloatArray:
    """Gripper rotation whose z axis (the approach direction, flange -> fingers) is
    ``approach`` and whose x axis is ``x_hint`` made orthogonal to it."""
    z = np.asarray(approach, dtype=float)
    return frame_z_x(z / np.linalg.norm(z), x_hint, what="gripper_frame: x_hint")


def cube_points(half: float, palm: float, standoff: float,
                side_hint: tuple[float, float, float] = (0.0, 0.0, 1.0)) -> list[TaskPoint]:
    """Six grasp points, one per face of a cube of half side ``half`` (task frame, order
    +x, -x, +y, -y, +z, -z); the gripper approaches along the inward normal, its TCP (the
    palm) ``palm`` off the face's centre (**decision**: the RX60B's flange link is a 30 mm
    ball beyond the TCP and no gripper is modelled, so the fingers are the unmodelled
    ``palm`` between the TCP and the face), and waits ``standoff`` further out (the
    pre-grasp pose). The gripper's x axis is ``side_hint`` on the side faces (a parallel
    gripper may roll by 180°: choose the roll that keeps the wrist's last joint mid-range)
    and the task's x axis on the top and bottom faces."""
    out = []
    for axis in range(3):
        for sign in (1.0, -1.0):
            n = np.zeros(3)
            n[axis] = sign
            hint = np.array(side_hint, dtype=float) if axis != 2 else np.array([1.0, 0.0, 0.0])
            out.append(TaskPoint((half + palm) * n, gripper_frame(-n, hint),
                             approach=standoff * n))
    return out


def base_pose(position: FloatArray, yaw: float) -> FloatArray:
    """``(4, 4)`` world-from-base transform: the base at ``position`` turned by ``yaw``."""
    out = np.eye(4)
    out[:3, :3] = rot_z(yaw)
    out[:3, 3] = position
    return out


def rx60b_model() -> Any:
    """The shipped Stäubli RX60B model (imported lazily: pybullet is loaded on demand)."""
    from vasim.mrcp.dh import load_robot

    return load_robot("rx60b")


def grasp_configuration(arm: ArmKinematics, position: FloatArray, rotation: FloatArray | None,
                        seed: FloatArray, what: str) -> FloatArray:
    """IK of a start pose; a scenario whose start is unreachable is a programming error."""
    q = arm.ik(position, rotation, seed)
    if q is None:
        raise RuntimeError(f"scenario: {what} is unreachable for {arm.name}")
    return q
