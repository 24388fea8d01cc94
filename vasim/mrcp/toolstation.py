"""The laparoscopic slave station of the MRCP study: tool robots through trocars, a camera.

Two tool robots hold straight laparoscopic instruments through the working trocars of the
virtual abdomen (``vasim.abdomen.anatomy.trocar_points``); each is a
:class:`~vasim.mrcp.fulcrum.LaparoscopicArm` (its TCP is the tool tip, the fulcrum
constraint built in) over a :class:`ToolPositioner`. A third robot holds the endoscope
through the camera trocar (:class:`CameraRobot`). :class:`ShaftWorld` is the station's
:class:`~vasim.mrcp.interfaces.ProximityWorld`: every instrument is a capsule from its
mount to its tip.

**Decisions**:

* The tool holder is an analytic 6-DoF positioner (three prismatic axes along the world
  axes, then an X-Y-Z wrist whose zero pose points the tool straight down): closed-form
  forward and inverse kinematics, so one kernel cycle costs well under a millisecond and
  a whole study trial runs in seconds. The RX60B arms of ``vasim.mrcp.backend`` plug into
  the same ``LaparoscopicArm`` (``build_station(holder=...)``), at ~10-20 ms of IK per
  kernel cycle (measured on the 2-core development machine), too slow for simulated
  cohorts. The wrist's singularity (tool horizontal, ``v = ±π/2``) lies outside its joint
  limits (``|v| <= 1.3``). Speed limits 1.5 m/s (prismatic) and 4 rad/s (wrist): with
  the tip ~10 cm past the trocar the tip may move at ~0.4 m/s, above a person's hand
  speeds, so the MRCP kernel's "joint speed limit" holds stay rare (at 2 rad/s the
  scripted operator's faster movements were refused, it pushed harder, and trials stalled).
* Collision geometry: instruments are capsules of radius ``SHAFT_RADIUS`` (2.5 mm, a 5 mm
  needle driver) from mount to tip; the organs are not in the proximity world (tissue
  contact is the abdomen physics' business, ``vasim.abdomen``).
* Tool-orientation cones (``vasim.mrcp.indices.cone``) at each working trocar: axis the
  inward wall normal (-z), a circular base of polar limit ``CONE_HALF_ANGLE`` (50 deg,
  ``tan`` = 1.19). The seed's example semi-axes (0.8 / 0.6, section 5.2) belong to its
  own phantom; in this abdomen the needle works 8-11 cm under trocars 15 cm apart, and
  50 deg lets either instrument work on its own side (< 25 deg) and across the midline
  (|x| < ~3 cm, the hand-over zone, ~43 deg) but not on the far side (> 54 deg): a needle
  carried across the abdomen must change hands.

Frames and units: world frame of the scene (z up toward the wall, x the patient's left),
metres, radians.

Example:
    >>> st = build_station()
    >>> sorted(st.arms), round(st.arms["right"].tool.length, 2)
    (['left', 'right'], 0.3)
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

import numpy as np

from vasim.core.config import check_choice
from vasim.core.errors import ConfigError
from vasim.core.geometry import rot_x, rot_y, rot_z, vector_norm
from vasim.mrcp.fulcrum import Fulcrum, LaparoscopicArm, LaparoscopicTool
from vasim.mrcp.indices.cone import ConeSector, ToolCone
from vasim.mrcp.interfaces import ArmKinematics, FloatArray, Proximity

SHAFT_RADIUS = 0.0025
"""Radius of an instrument's collision capsule [m] (a 5 mm needle driver)."""

TOOL_LENGTH = 0.30
"""Length of the laparoscopic instruments [m] (mount to tip)."""

CONE_HALF_ANGLE = math.radians(50.0)
"""Polar limit of the instruments' orientation cones [rad] (module docstring)."""

MOUNT_HEIGHT = 0.20
"""Height of the tool mount above its trocar at the robot's start [m]."""

_R0 = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
"""Rx(pi): the positioner's wrist frame at zero, tool z axis pointing down."""

_ROTATION_CACHE = 32
"""Wrist rotations a ``ToolPositioner`` keeps (most MRCP-cycle repeats are within ~16)."""


class ToolPositioner:
    """An analytic 6-DoF tool holder: ``q = (x, y, z, u, v, c)``.

    The mount is at ``origin + (x, y, z)`` (prismatic joints along the world axes); its
    rotation is ``Rx(pi) Rx(u) Ry(v) Rz(c)`` (tool z axis down at ``u = v = 0``, ``c`` the
    roll about the tool). Implements :class:`~vasim.mrcp.interfaces.ArmKinematics`.

    Args:
        name: robot name. origin: ``(3,)`` world position of the prismatic zero [m].
        travel: half range of each prismatic joint [m].
        tilt: limit of ``|u|`` and ``|v|`` [rad].
        linear_speed: prismatic speed limit [m/s]. angular_speed: wrist limit [rad/s].
    """

    def __init__(self, name: str, origin: FloatArray, *, travel: float = 0.30,
                 tilt: float = 1.3, linear_speed: float = 1.5,
                 angular_speed: float = 4.0) -> None:
        self.name = name
        self.origin = np.asarray(origin, dtype=float).reshape(3)
        self._lower = np.array([-travel] * 3 + [-tilt, -tilt, -2 * math.pi])
        self._upper = np.array([travel] * 3 + [tilt, tilt, 2 * math.pi])
        self._vmax = np.array([linear_speed] * 3 + [angular_speed] * 3)
        self.home = np.zeros(6)
        self._rotations: dict[bytes, FloatArray] = {}   # rotation()'s recent results

    @property
    def n_joints(self) -> int:
        return 6

    @property
    def joint_lower(self) -> FloatArray:
        return self._lower

    @property
    def joint_upper(self) -> FloatArray:
        return self._upper

    @property
    def max_velocity(self) -> FloatArray:
        return self._vmax

    @property
    def max_acceleration(self) -> FloatArray:
        return 4.0 * self._vmax

    def rotation(self, q: FloatArray) -> FloatArray:
        """``(3, 3)`` mount rotation at ``q``."""
        # Speed: the MRCP cycle asks for the same wrist angles again and again (an IK's
        # solution is the next IK's seed, whose x axis sets the roll; the fulcrum check
        # poses the solution), so the last results are kept, keyed by the angles' exact
        # bits (-0.0 is not 0.0), and a copy returned. The product is kept as is: a closed
        # form sums in another order than the matrix products (BLAS, with FMA) and differs
        # in the last bit.
        qa = np.asarray(q, dtype=float)
        key = qa[3:6].tobytes()
        rot = self._rotations.get(key)
        if rot is None:
            rot = _R0 @ rot_x(float(qa[3])) @ rot_y(float(qa[4])) @ rot_z(float(qa[5]))
            if len(self._rotations) >= _ROTATION_CACHE:
                self._rotations.clear()     # (clear: one atomic step, no eviction order)
            self._rotations[key] = rot
        return rot.copy()

    def tcp_pose(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        q = np.asarray(q, dtype=float)
        return self.origin + q[:3], self.rotation(q)

    def jacobian(self, q: FloatArray) -> FloatArray:
        q = np.asarray(q, dtype=float)
        jac = np.zeros((6, 6))
        jac[:3, :3] = np.eye(3)
        r1 = _R0 @ rot_x(float(q[3]))
        jac[3:, 3] = _R0[:, 0]
        jac[3:, 4] = r1[:, 1]
        jac[3:, 5] = (r1 @ rot_y(float(q[4])))[:, 2]
        return jac

    def ik(self, position: FloatArray, rotation: FloatArray | None = None,
           q_seed: FloatArray | None = None) -> FloatArray | None:
        """Closed form; ``rotation`` None keeps the seed's wrist. None outside the limits."""
        seed = self.home if q_seed is None else np.asarray(q_seed, dtype=float)
        q = seed.copy()
        q[:3] = np.asarray(position, dtype=float) - self.origin
        if rotation is not None:
            # (as Python floats, and np.clip's value (NaN passes) by comparisons: the same
            # numbers without numpy's per-call dispatch, ~10 us per IK)
            m = (_R0.T @ np.asarray(rotation, dtype=float)).tolist()
            sv = m[0][2]
            sv = -1.0 if sv < -1.0 else 1.0 if sv > 1.0 else sv
            q[4] = math.asin(sv)
            q[3] = math.atan2(-m[1][2], m[2][2])
            c = math.atan2(-m[0][1], m[0][0])
            # nearest to the seed (float(): the same arithmetic and int as on numpy's float)
            c += 2 * math.pi * round((float(seed[5]) - c) / (2 * math.pi))
            q[5] = c
        if (q < self._lower - 1e-12).any() or (q > self._upper + 1e-12).any():
            return None
        return q


# ---------------------------------------------------------------------- proximity
def segment_closest_points(p1: FloatArray, q1: FloatArray, p2: FloatArray,
                           q2: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Closest points of segments ``[p1, q1]`` and ``[p2, q2]`` (Ericson 2005, §5.1.9).

    Example:
        >>> a, b = segment_closest_points(np.zeros(3), np.array([1.0, 0, 0]),
        ...                               np.array([0.5, 1, -1]), np.array([0.5, 1, 1]))
        >>> a.tolist(), b.tolist()
        ([0.5, 0.0, 0.0], [0.5, 1.0, 0.0])
    """
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, f = float(d1 @ d1), float(d2 @ d2), float(d2 @ r)
    point = 1e-30   # squared length of a segment that is a point (below any rounding)
    if a <= point and e <= point:
        return p1.copy(), p2.copy()
    if a <= point:
        s, t = 0.0, min(max(f / e, 0.0), 1.0)
    else:
        c = float(d1 @ r)
        if e <= point:
            s, t = min(max(-c / a, 0.0), 1.0), 0.0
        else:
            b = float(d1 @ d2)
            den = a * e - b * b   # |d1|² |d2|² sin²θ, to a rounding of ~1e-16 a e
            if den <= 1e-12 * a * e:
                # (nearly) parallel: the closest pair has an endpoint of one segment, so
                # the best of the four endpoint projections (exact for parallel segments)
                cands = [(0.0, min(max(f / e, 0.0), 1.0)),
                         (1.0, min(max((b + f) / e, 0.0), 1.0)),
                         (min(max(-c / a, 0.0), 1.0), 0.0),
                         (min(max((b - c) / a, 0.0), 1.0), 1.0)]
                s, t = min(cands, key=lambda st: float(np.sum(
                    (p1 + d1 * st[0] - p2 - d2 * st[1]) ** 2)))
            else:
                s = min(max((b * f - c * e) / den, 0.0), 1.0)
                t = (b * s + f) / e
                if t < 0.0:
                    t, s = 0.0, min(max(-c / a, 0.0), 1.0)
                elif t > 1.0:
                    t, s = 1.0, min(max((b - c) / a, 0.0), 1.0)
    return p1 + d1 * s, p2 + d2 * t


@dataclass
class _Shaft:
    arm: ArmKinematics
    q: FloatArray
    radius: float


@dataclass
class ShaftWorld:
    """The station's proximity world: instrument capsules (mount -> tip) and spheres.

    Implements :class:`~vasim.mrcp.interfaces.ProximityWorld`; robots are added with
    :meth:`add_robot` (an arm whose TCP is the tool tip, e.g. a ``LaparoscopicArm``).
    """

    shafts: dict[str, _Shaft] = field(default_factory=dict)
    spheres: dict[str, tuple[FloatArray, float]] = field(default_factory=dict)

    def add_robot(self, name: str, arm: LaparoscopicArm, q: FloatArray,
                  radius: float = SHAFT_RADIUS) -> None:
        if name in self.shafts or name in self.spheres:
            raise ConfigError(f"a body named {name!r} already exists", field="name")
        self.shafts[name] = _Shaft(arm, np.asarray(q, dtype=float).copy(), radius)

    def add_sphere(self, name: str, centre: FloatArray, radius: float) -> None:
        if name in self.shafts or name in self.spheres:
            raise ConfigError(f"a body named {name!r} already exists", field="name")
        self.spheres[name] = (np.asarray(centre, dtype=float).reshape(3), float(radius))

    def robot_names(self) -> list[str]:
        return list(self.shafts)

    def obstacle_names(self) -> list[str]:
        return list(self.spheres)

    def set_configuration(self, robot: str, q: FloatArray) -> None:
        self.shafts[robot].q = np.asarray(q, dtype=float).copy()

    def configuration(self, robot: str) -> FloatArray:
        return self.shafts[robot].q.copy()

    def segment(self, robot: str) -> tuple[FloatArray, FloatArray]:
        """(mount, tip) of a robot's instrument [m]."""
        s = self.shafts[robot]
        tip, rot = s.arm.tcp_pose(s.q)
        length = getattr(getattr(s.arm, "tool", None), "length", 0.0)
        return tip - length * rot[:, 2], tip

    def min_distance(self, a: str, b: str, max_distance: float = 1.0) -> Proximity:
        pa0, pa1 = self.segment(a)
        ra = self.shafts[a].radius
        if b in self.shafts:
            pb0, pb1 = self.segment(b)
            ca, cb = segment_closest_points(pa0, pa1, pb0, pb1)
            rb = self.shafts[b].radius
        else:
            centre, rb = self.spheres[b]
            ca, cb = segment_closest_points(pa0, pa1, centre, centre)
        gap = cb - ca
        n = vector_norm(gap)
        d = n - ra - rb
        if d >= max_distance:
            nan = np.full(3, np.nan)
            return Proximity(max_distance, nan, nan)
        u = gap / n if n > 1e-12 else np.array([0.0, 0.0, 1.0])
        return Proximity(d, ca + ra * u, cb - rb * u)

    def in_collision(self, robot: str) -> bool:
        return any(self.min_distance(robot, b, 0.1).distance < 0.0
                   for b in (*self.shafts, *self.spheres) if b != robot)


# ------------------------------------------------------------------------ the station
@dataclass(frozen=True)
class CameraRobot:
    """The endoscope through the camera trocar: lens inside the body, aimed at a point.

    Attributes:
        fulcrum: ``(3,)`` camera trocar [m]. insertion: lens depth past the trocar [m].
        fov_deg: full field of view [deg].
    """

    fulcrum: FloatArray
    insertion: float = 0.03
    fov_deg: float = 70.0

    def lens(self, aim: FloatArray) -> FloatArray:
        """Lens position when the scope points at ``aim`` (on the trocar-aim line)."""
        d = np.asarray(aim, dtype=float) - self.fulcrum
        return self.fulcrum + self.insertion * d / max(vector_norm(d), 1e-12)


@dataclass(frozen=True, eq=False)
class Station:
    """The tool robots, their world, cones and the camera robot.

    Attributes:
        arms: robot name -> ``LaparoscopicArm`` (tip = TCP). world: their proximity world.
        cones: robot name -> orientation cone at its trocar. camera: the endoscope robot.
    """

    arms: Mapping[str, LaparoscopicArm]
    world: ShaftWorld
    cones: Mapping[str, ToolCone]
    camera: CameraRobot

    def tip(self, robot: str) -> FloatArray:
        """Tool tip of ``robot`` at its current configuration [m]."""
        return self.arms[robot].tcp_pose(self.world.configuration(robot))[0]

    def close(self) -> None:
        """Releases the holders' resources (the pybullet clients of RX60B holders)."""
        _close_holders(self.arms.values())


def _close_holders(arms: Iterable[LaparoscopicArm]) -> None:
    for arm in arms:
        close = getattr(arm.arm, "close", None)
        if close is not None:
            close()


def tool_cone(port: FloatArray, half_angle: float = CONE_HALF_ANGLE) -> ToolCone:
    """The orientation cone of a working trocar (module docstring, decision)."""
    r = math.tan(half_angle)
    return ToolCone(np.asarray(port, dtype=float), np.array([0.0, 0.0, -1.0]),
                    np.array([1.0, 0.0, 0.0]), (ConeSector(0.0, 2 * math.pi, r, r),))


def build_station(start_tips: Mapping[str, FloatArray] | None = None, *,
                  holder: str = "positioner") -> Station:
    """The study station: robots ``"right"`` / ``"left"`` at the working trocars.

    Args:
        start_tips: robot -> start tool-tip position [m] (default 6 cm below its trocar).
        holder: ``"positioner"`` (:class:`ToolPositioner`) or ``"rx60b"`` (the pybullet
            RX60B arm facing the trocar, slow).

    Raises:
        ConfigError: an unknown holder or an unreachable start tip.
    """
    from vasim.abdomen.anatomy import TROCAR_NAMES, trocar_points

    check_choice(holder, "holder", ("positioner", "rx60b"))
    ports = trocar_points()
    tool = LaparoscopicTool(TOOL_LENGTH)
    world = ShaftWorld()
    arms: dict[str, LaparoscopicArm] = {}
    cones: dict[str, ToolCone] = {}
    for name, trocar, yaw in (("right", "working_right", 0.0),
                              ("left", "working_left", math.pi)):
        port = ports[TROCAR_NAMES.index(trocar)]
        fulcrum = Fulcrum(point=port, normal=np.array([0.0, 0.0, 1.0]))
        base: ArmKinematics
        if holder == "positioner":
            base = ToolPositioner(name, port + np.array([0.0, 0.0, MOUNT_HEIGHT]))
        else:   # "rx60b" (checked above)
            from vasim.mrcp.backend import PybulletArm, pose_matrix
            from vasim.mrcp.dh import load_robot

            rot = rot_z(yaw)
            base = PybulletArm(load_robot("rx60b"),
                               pose_matrix(port - rot @ np.array([0.31, 0.049, 0.2]), rot),
                               name=name)
        arm = LaparoscopicArm(base, tool, fulcrum)
        tip = (np.asarray(start_tips[name], dtype=float) if start_tips and name in start_tips
               else port + np.array([0.0, 0.0, -0.06]))
        q = arm.ik(tip, None, getattr(base, "home", None))
        if q is None:
            _close_holders([*arms.values(), arm])
            raise ConfigError(f"robot {name!r} cannot reach its start tip {tip.tolist()!r}",
                              field="start_tips")
        world.add_robot(name, arm, q)
        arms[name] = arm
        cones[name] = tool_cone(port)
    camera = CameraRobot(ports[TROCAR_NAMES.index("camera")].copy())
    return Station(arms, world, cones, camera)


__all__ = [
    "CONE_HALF_ANGLE",
    "MOUNT_HEIGHT",
    "SHAFT_RADIUS",
    "TOOL_LENGTH",
    "CameraRobot",
    "ShaftWorld",
    "Station",
    "ToolPositioner",
    "build_station",
    "segment_closest_points",
    "tool_cone",
]
