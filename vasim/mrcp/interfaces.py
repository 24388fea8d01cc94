"""The seams of the MRCP slave station: what the control kernel needs from the robot world.

The kernel (prediction, indices, time transformation, selection, actions; spec/mrcp.md
§§3-8) never imports pybullet: it sees robots through :class:`ArmKinematics` and the world
through :class:`ProximityWorld`. ``vasim.mrcp.arm`` and ``vasim.mrcp.world`` implement them
over pybullet; tests may implement them analytically (e.g. a planar arm) to check the kernel
independently.

Conventions (every implementation follows them):

* SI units: metres, radians, seconds. Positions are ``(3,)`` float64 arrays in the world
  frame; orientations are ``(3, 3)`` rotation matrices (world-from-tool), never quaternions,
  so no ordering ambiguity crosses a seam.
* Joint vectors are ``(n,)`` float64 arrays; ``q`` is never modified in place by a callee.
* ``jacobian(q)`` is the ``(6, n)`` geometric Jacobian of the TCP in the world frame:
  rows 0-2 linear velocity [m/s per rad/s], rows 3-5 angular velocity.
* ``ik`` returns ``None`` when no configuration within the joint limits reaches the pose
  within tolerance (it never raises for an unreachable pose).
* A distance query returns the signed minimum distance (negative = penetration) and the
  two witness points (on ``a`` and on ``b``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


@runtime_checkable
class ArmKinematics(Protocol):
    """One serial arm: limits, forward/inverse kinematics and the Jacobian."""

    name: str

    @property
    def n_joints(self) -> int: ...

    @property
    def joint_lower(self) -> FloatArray: ...

    @property
    def joint_upper(self) -> FloatArray: ...

    @property
    def max_velocity(self) -> FloatArray:
        """Per-joint speed limit [rad/s]."""
        ...

    @property
    def max_acceleration(self) -> FloatArray:
        """Per-joint acceleration limit [rad/s^2]."""
        ...

    def tcp_pose(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """TCP position ``(3,)`` and rotation ``(3, 3)`` at configuration ``q``."""
        ...

    def jacobian(self, q: FloatArray) -> FloatArray:
        """``(6, n)`` geometric Jacobian of the TCP (world frame, linear rows first)."""
        ...

    def ik(self, position: FloatArray, rotation: FloatArray | None = None,
           q_seed: FloatArray | None = None) -> FloatArray | None:
        """A configuration reaching the pose (closest to ``q_seed``), or None."""
        ...


@dataclass(frozen=True)
class Proximity:
    """Result of a distance query between two bodies (or a robot and anything)."""

    distance: float          # signed minimum distance [m], < 0 = penetration
    point_a: FloatArray      # witness point on the first body (world frame)
    point_b: FloatArray      # witness point on the second body (world frame)
    link_a: int = -1         # link index on the first body (-1 = base / not a robot)
    link_b: int = -1


@runtime_checkable
class ProximityWorld(Protocol):
    """The robots and obstacles of a station, posed by name, queried for distances."""

    def robot_names(self) -> list[str]: ...

    def obstacle_names(self) -> list[str]: ...

    def set_configuration(self, robot: str, q: FloatArray) -> None: ...

    def configuration(self, robot: str) -> FloatArray: ...

    def min_distance(self, a: str, b: str, max_distance: float = 1.0) -> Proximity:
        """Closest approach between two named bodies (robots or obstacles), up to
        ``max_distance`` (beyond it: ``distance = max_distance``, witness points NaN)."""
        ...

    def in_collision(self, robot: str) -> bool:
        """True if the robot touches anything (other robots, obstacles, itself beyond its
        adjacent links)."""
        ...
