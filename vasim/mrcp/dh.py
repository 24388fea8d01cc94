"""Serial arms as data: modified Denavit-Hartenberg tables from ``protocols/robots/*.toml``.

A robot file is parsed once into a frozen, validated :class:`RobotModel`; errors name the
file, the dotted field and the bad value. The pure functions here (:func:`link_frames`,
:func:`fk`, :func:`fk_batch`, :func:`jacobian_batch`) are the batched numpy kinematics used
where many configurations are sampled (indices, proximity tests); ``vasim.mrcp.arm``
checks them against pybullet. The closed-form inverse kinematics of arms with the PUMA
structure (the RX60B's) is :mod:`vasim.mrcp.closed_form_ik`.

Convention (Craig's modified DH): joint ``i`` (1-based) is ``(alpha_{i-1}, a_{i-1}, d_i)`` and
``theta_i = q_i + theta_offset_i``::

    T_{i-1,i} = RotX(alpha_{i-1}) TransX(a_{i-1}) RotZ(theta_i) TransZ(d_i)

Frame 0 is the robot base frame; the TCP is ``tcp`` (a point in the last joint frame, the
axes of that frame). Units: metres, radians (``*_deg`` fields in the file are degrees).

**Decision** (spec §2: "verify the imposed limits against your convention"): the RX60B ships
``theta_offset = 180°`` on joint 3. With it, the seed's imposed joint-3 range
``[1.66, 3.92]`` rad begins 5° past the straight-arm singularity (links 2–3 aligned at
``q3 = π/2``) and allows up to 135° of elbow flexion, as on the real arm; with no offset the
same numbers would fold the forearm back onto the upper arm. The limits are shipped as data
unchanged and a test checks that the documented home configuration lies inside them.

TOML layout::

    name = "rx60b"
    tcp = [0.0, 0.0, 0.065]           # TCP in the last joint frame [m]  [0, 0, 0]
    home = [...]                      # (n,) rad, inside the limits (required)
    [[joints]]                        # one table per joint, base to tip
    alpha_deg = -90.0                 # alpha_{i-1} [deg]
    a = 0.0                           # a_{i-1} [m]
    d = 0.0                           # d_i [m]
    theta_offset_deg = 0.0            # [deg]  [0]
    lower = -3.80                     # joint limits [rad], lower < upper
    upper = 1.65
    max_velocity = 5.0                # [rad/s] > 0
    max_acceleration = 20.0           # [rad/s^2] > 0
    [[links]]                         # n + 1 tables: base (link 0) .. last link (optional)
    radius = 0.07                     # swept-sphere radius of the link's hull [m] > 0
    points = [[0, 0, -0.3]]           # extra key points, link frame [m]  [none]
    chain = true                      # include the DH key points  [true]

Limits checked at load (``ConfigError`` naming the field): ``name`` matches
``[A-Za-z0-9_][A-Za-z0-9_.-]*`` (it becomes a folder, a file and URDF text); a link has at
most 3 distinct key points, the chain's included (the compiled distance model handles
points, segments and triangles: with ``chain = true`` a link already has up to 3, so extra
``points`` usually need ``chain = false``); ``|a|, |d| <= 5`` m and ``|lower|, |upper| <=
4π`` rad (units typos).

Example:
    >>> robot = load_robot("rx60b")
    >>> robot.n_joints, robot.joints[2].a
    (6, 0.29)
    >>> bool(np.all((robot.home >= robot.lower) & (robot.home <= robot.upper)))
    True
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from vasim.core.bounds import (
    DH_ANGLE_DEG,
    JOINT_ACCELERATION_RAD_S2,
    JOINT_LIMIT_RAD,
    JOINT_VELOCITY_RAD_S,
    LINK_LENGTH_M,
    LINK_RADIUS_M,
    Bound,
)
from vasim.core.config import (
    check_array,
    check_bool,
    check_keys,
    check_number,
    check_required,
    check_str,
    check_type,
    expect,
    fail,
    parse_toml,
    rewrap,
)
from vasim.core.errors import ConfigError
from vasim.core.geometry import rot_x, rot_z
from vasim.core.kernel_args import readonly_c, writable_c
from vasim.core.resources import data_file, protocols_dir, read_data_file

FloatArray = NDArray[np.float64]

#: Robot names: they become a folder, a file name and URDF (XML) text.
_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")
#: At most this many distinct key points per link (the DH chain's included): the compiled
#: distance model (``vasim.mrcp._distance_kernels``) handles points, segments, triangles.
MAX_KEY_POINTS = 3
#: Plausibility bounds of a robot file (units typos: millimetres, degrees): DH lengths
#: ``|a|, |d|`` [m] and joint limits [rad].
MAX_LENGTH = 5.0
MAX_JOINT_ANGLE = 4.0 * math.pi


def _distinct_points(pts: FloatArray, tol: float = 1e-9) -> int:
    """How many of the points ``(m, 3)`` are distinct (the dedup of the compiled model)."""
    out: list[FloatArray] = []
    for p in pts:
        if all(np.linalg.norm(p - o) > tol for o in out):
            out.append(p)
    return len(out)


def robots_dir() -> Path:
    """The folder of shipped robot files (``protocols/robots``)."""
    return protocols_dir() / "robots"


@dataclass(frozen=True)
class DHJoint:
    """One revolute joint, modified DH (Craig). Angles in radians, lengths in metres."""

    alpha: float              # alpha_{i-1}
    a: float                  # a_{i-1}
    d: float                  # d_i
    theta_offset: float       # theta_i = q_i + theta_offset
    lower: float              # joint limits [rad]
    upper: float
    max_velocity: float       # [rad/s]
    max_acceleration: float   # [rad/s^2]

    def __post_init__(self) -> None:
        for name in ("alpha", "a", "d", "theta_offset", "lower", "upper"):
            check_number(getattr(self, name), name)
        expect(self.lower < self.upper, self.lower, f"a limit below upper ({self.upper!r})",
                field="lower")
        check_number(self.max_velocity, "max_velocity", gt=0)
        check_number(self.max_acceleration, "max_acceleration", gt=0)


@dataclass(frozen=True)
class LinkGeometry:
    """Collision geometry of one link: the convex hull of spheres at key points."""

    radius: float                                 # [m]
    points: tuple[tuple[float, float, float], ...] = ()   # extra key points, link frame [m]
    chain: bool = True                            # include the DH key points

    def __post_init__(self) -> None:
        check_number(self.radius, "radius", gt=0)


@dataclass(frozen=True, eq=False)
class RobotModel:
    """A serial arm: its DH joints, TCP, home configuration and link geometry (constants)."""

    name: str
    joints: tuple[DHJoint, ...]
    tcp: FloatArray = field(default_factory=lambda: np.zeros(3))
    home: FloatArray = field(default_factory=lambda: np.zeros(0))
    links: tuple[LinkGeometry, ...] = ()
    table: FloatArray = field(init=False, repr=False)  # (4, n) set by __post_init__

    def __post_init__(self) -> None:
        # the name becomes a cache folder, a file name and URDF (XML) text
        expect(isinstance(self.name, str) and _NAME.fullmatch(self.name), self.name,
                f"a name matching {_NAME.pattern} (letters, digits, _ . -; no leading dot)",
                field="name")
        n = len(self.joints)
        expect(n > 0, self.joints, "at least one joint", field="joints")
        tcp = check_array(self.tcp, "tcp", shape=(3,))
        home = check_array(self.home, "home", shape=(n,), what=f"{n} finite angles")
        outside = np.flatnonzero((home < self.lower) | (home > self.upper))
        if outside.size:
            i = int(outside[0])
            raise fail(float(home[i]), f"an angle within the joint limits "
                       f"[{self.lower[i]!r}, {self.upper[i]!r}]", field=f"home[{i}]")
        expect(not self.links or len(self.links) == n + 1, len(self.links),
                f"{n + 1} [[links]] tables (base + one per joint)", field="links")
        for k in range(len(self.links)):    # else the compiled distance model fails later
            distinct = _distinct_points(self.link_key_points(k))
            expect(distinct <= MAX_KEY_POINTS, distinct,
                    f"at most {MAX_KEY_POINTS} distinct key points in link {k} (the DH "
                    "chain's and its points)", field=f"links[{k}].points")
        tcp.setflags(write=False)
        home.setflags(write=False)
        object.__setattr__(self, "tcp", tcp)
        object.__setattr__(self, "home", home)
        # (4, n) alpha, a, d, theta_offset: the kernels' input, computed once
        table = np.array([[j.alpha, j.a, j.d, j.theta_offset] for j in self.joints]).T.copy()
        table.setflags(write=False)
        object.__setattr__(self, "table", table)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, RobotModel):
            return NotImplemented
        return (self.name == other.name and self.joints == other.joints
                and self.links == other.links and np.array_equal(self.tcp, other.tcp)
                and np.array_equal(self.home, other.home))

    __hash__ = None  # type: ignore[assignment]  # unhashable: array fields

    @property
    def n_joints(self) -> int:
        return len(self.joints)

    def _column(self, name: str) -> FloatArray:
        cache = self.__dict__.setdefault("_columns", {})
        if name not in cache:
            out = np.array([getattr(j, name) for j in self.joints], dtype=float)
            out.setflags(write=False)
            cache[name] = out
        return cache[name]

    @property
    def lower(self) -> FloatArray:
        return self._column("lower")

    @property
    def upper(self) -> FloatArray:
        return self._column("upper")

    @property
    def max_velocity(self) -> FloatArray:
        return self._column("max_velocity")

    @property
    def max_acceleration(self) -> FloatArray:
        return self._column("max_acceleration")

    def within_limits(self, q: FloatArray, tol: float = 0.0) -> bool:
        """True if every joint of ``q`` lies within its limits (widened by ``tol``)."""
        q = np.asarray(q, dtype=float)
        return bool(np.all(q >= self.lower - tol) and np.all(q <= self.upper + tol))

    def link_key_points(self, k: int) -> FloatArray:
        """``(m, 3)`` key points of link ``k`` (0 = base) in its own frame [m]: the frame
        origin, the point ``a_k`` along ``x_k``, the origin of frame ``k + 1`` (the TCP for
        the last link), plus the file's extra points."""
        geom = self.links[k] if self.links else LinkGeometry(radius=0.01)
        pts: list[FloatArray] = []
        if geom.chain:
            pts.append(np.zeros(3))
            if k < self.n_joints:
                nxt = self.joints[k]
                pts.append(np.array([nxt.a, 0.0, 0.0]))
                pts.append(joint_origin(nxt)[:3, 3])
            else:
                pts.append(np.array(self.tcp, dtype=float))
        pts.extend(np.array(p, dtype=float) for p in geom.points)
        return np.array(pts, dtype=float).reshape(-1, 3)


def joint_origin(joint: DHJoint) -> FloatArray:
    """``(4, 4)`` fixed part of ``T_{i-1,i}`` at ``q_i = 0``: RotX(alpha) TransX(a)
    RotZ(theta_offset) TransZ(d) (the joint then turns about the resulting z axis)."""
    t = np.eye(4)
    rx = rot_x(joint.alpha)
    t[:3, :3] = rx @ rot_z(joint.theta_offset)
    t[:3, 3] = rx @ np.array([joint.a, 0.0, joint.d])
    return t


def _dh_arrays(robot: RobotModel) -> tuple[FloatArray, ...]:
    t = robot.table
    return t[0], t[1], t[2], t[3]


def link_frames(robot: RobotModel, q: FloatArray, base: FloatArray | None = None
                ) -> FloatArray:
    """Frames of every link and the TCP, batched.

    Args:
        robot: the arm.
        q: ``(n,)`` or ``(m, n)`` joint angles [rad].
        base: ``(4, 4)`` world-from-base transform (default identity).

    Returns:
        ``(..., n + 2, 4, 4)`` world-from-frame transforms: index 0 the base (frame 0),
        index ``i`` joint frame ``i`` (1..n), index ``n + 1`` the TCP (axes of frame n).
    """
    q = np.asarray(q, dtype=float)
    lead = q.shape[:-1]
    n = robot.n_joints
    if q.shape[-1] != n:
        raise ValueError(f"q must have {n} joints in its last axis, got shape {q.shape}")
    alpha, a, d, off = _dh_arrays(robot)
    theta = q + off                                   # (..., n)
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(alpha), np.sin(alpha)
    # Craig: [[ct, -st, 0, a], [st ca, ct ca, -sa, -sa d], [st sa, ct sa, ca, ca d]]
    t = np.zeros((*lead, n, 4, 4))
    t[..., 0, 0] = ct
    t[..., 0, 1] = -st
    t[..., 0, 3] = a
    t[..., 1, 0] = st * ca
    t[..., 1, 1] = ct * ca
    t[..., 1, 2] = -sa
    t[..., 1, 3] = -sa * d
    t[..., 2, 0] = st * sa
    t[..., 2, 1] = ct * sa
    t[..., 2, 2] = ca
    t[..., 2, 3] = ca * d
    t[..., 3, 3] = 1.0
    frames = np.empty((*lead, n + 2, 4, 4))
    frames[..., 0, :, :] = np.eye(4) if base is None else np.asarray(base, dtype=float)
    for i in range(n):
        frames[..., i + 1, :, :] = frames[..., i, :, :] @ t[..., i, :, :]
    tcp = np.eye(4)
    tcp[:3, 3] = robot.tcp
    frames[..., n + 1, :, :] = frames[..., n, :, :] @ tcp
    return frames


@njit(cache=True, nogil=True, fastmath=False)
def _chain_kernel(table: FloatArray, tcp: FloatArray, base: FloatArray, q: FloatArray,
                  frames: FloatArray) -> None:  # pragma: no cover - compiled
    """Fills ``frames`` ``(n + 2, 4, 4)`` for one configuration (same maths as
    :func:`link_frames`)."""
    n = q.shape[0]
    frames[0] = base
    t = np.zeros((4, 4))
    t[3, 3] = 1.0
    for i in range(n):
        al, a, d = table[0, i], table[1, i], table[2, i]
        th = q[i] + table[3, i]
        ct, st, ca, sa = np.cos(th), np.sin(th), np.cos(al), np.sin(al)
        t[0, 0] = ct
        t[0, 1] = -st
        t[0, 2] = 0.0
        t[0, 3] = a
        t[1, 0] = st * ca
        t[1, 1] = ct * ca
        t[1, 2] = -sa
        t[1, 3] = -sa * d
        t[2, 0] = st * sa
        t[2, 1] = ct * sa
        t[2, 2] = ca
        t[2, 3] = ca * d
        frames[i + 1] = frames[i] @ t
    frames[n + 1] = frames[n]
    for r in range(3):
        frames[n + 1, r, 3] = (frames[n, r, 0] * tcp[0] + frames[n, r, 1] * tcp[1]
                               + frames[n, r, 2] * tcp[2] + frames[n, r, 3])


@njit(cache=True, nogil=True, fastmath=False)
def _jacobian_kernel(frames: FloatArray, jac: FloatArray) -> None:  # pragma: no cover
    """Fills ``jac`` ``(6, n)`` from the frames of :func:`_chain_kernel`."""
    n = jac.shape[1]
    tip = frames[n + 1, :3, 3]
    for i in range(n):
        z = frames[i + 1, :3, 2]
        r = tip - frames[i + 1, :3, 3]
        jac[0, i] = z[1] * r[2] - z[2] * r[1]
        jac[1, i] = z[2] * r[0] - z[0] * r[2]
        jac[2, i] = z[0] * r[1] - z[1] * r[0]
        jac[3, i] = z[0]
        jac[4, i] = z[1]
        jac[5, i] = z[2]


@njit(cache=True, nogil=True, fastmath=False)
def _many_kernel(table: FloatArray, tcp: FloatArray, base: FloatArray, q: FloatArray,
                 frames: FloatArray, jac: FloatArray, with_jacobian: bool
                 ) -> None:  # pragma: no cover - compiled
    """Frames ``(m, n + 2, 4, 4)`` (and Jacobians ``(m, 6, n)``) of ``m`` configurations."""
    for k in range(q.shape[0]):
        _chain_kernel(table, tcp, base, q[k], frames[k])
        if with_jacobian:
            _jacobian_kernel(frames[k], jac[k])


@njit(cache=True, nogil=True, fastmath=False)
def _wrap_clip(q: FloatArray, lower: FloatArray, upper: FloatArray
               ) -> FloatArray:  # pragma: no cover - compiled
    """Each joint outside its limits moved by a multiple of 2π (-1, 1, -2, 2) into them
    when one fits, then clamped (the projection of the numeric IK)."""
    out = q.copy()
    for i in range(q.shape[0]):
        if not lower[i] <= out[i] <= upper[i]:
            for k in (-1.0, 1.0, -2.0, 2.0):
                cand = q[i] + k * 2.0 * np.pi
                if lower[i] <= cand <= upper[i]:
                    out[i] = cand
                    break
        out[i] = min(max(out[i], lower[i]), upper[i])
    return out


@njit(cache=True, nogil=True, fastmath=False)
def _position_dls_kernel(table: FloatArray, tcp: FloatArray, base: FloatArray,
                         q0: FloatArray, target: FloatArray, lower: FloatArray,
                         upper: FloatArray, tol: float, iterations: int, damping: float
                         ) -> tuple[FloatArray, bool]:  # pragma: no cover - compiled
    n = q0.shape[0]
    q = np.minimum(np.maximum(q0, lower), upper)
    frames = np.empty((n + 2, 4, 4))
    jac = np.empty((6, n))
    history = np.empty(iterations)
    jj = np.empty((3, 3))
    dq = np.empty(n)
    for it in range(iterations):
        _chain_kernel(table, tcp, base, q, frames)
        _jacobian_kernel(frames, jac)
        ep = target - frames[n + 1, :3, 3]
        norm = np.sqrt(ep @ ep)
        if norm <= tol:
            return q, True
        history[it] = norm
        if it >= 8 and norm > 0.7 * history[it - 5]:     # stagnating: give this start up
            return q, False
        for a in range(3):
            for b in range(3):
                acc = 0.0
                for c in range(n):
                    acc += jac[a, c] * jac[b, c]
                jj[a, b] = acc + (damping if a == b else 0.0)
        # (J Jᵀ + λ I) x = e by Cholesky (symmetric positive definite: λ > 0)
        l00 = np.sqrt(jj[0, 0])
        l10 = jj[1, 0] / l00
        l20 = jj[2, 0] / l00
        l11 = np.sqrt(jj[1, 1] - l10 * l10)
        l21 = (jj[2, 1] - l20 * l10) / l11
        l22 = np.sqrt(jj[2, 2] - l20 * l20 - l21 * l21)
        y0 = ep[0] / l00
        y1 = (ep[1] - l10 * y0) / l11
        y2 = (ep[2] - l20 * y0 - l21 * y1) / l22
        x2 = y2 / l22
        x1 = (y1 - l21 * x2) / l11
        x0 = (y0 - l10 * x1 - l20 * x2) / l00
        step = 0.0
        for c in range(n):
            dq[c] = jac[0, c] * x0 + jac[1, c] * x1 + jac[2, c] * x2
            step = max(step, abs(dq[c]))
        scale = 0.5 / step if step > 0.5 else 1.0
        for c in range(n):
            dq[c] = q[c] + dq[c] * scale
        q = _wrap_clip(dq, lower, upper)
    return q, False


def wrap_clip(q: FloatArray, lower: FloatArray, upper: FloatArray) -> FloatArray:
    """Each joint of ``q`` ``(n,)`` outside its limits moved by a multiple of 2π (-1, 1,
    -2, 2) into them when one fits, then clamped (compiled; the numeric IK's projection)."""
    return _wrap_clip(writable_c(q), readonly_c(lower), readonly_c(upper))


def position_dls(robot: RobotModel, q0: FloatArray, target: FloatArray,
                 base: FloatArray | None = None, tol: float = 1e-6, iterations: int = 60,
                 damping: float = 1e-6) -> FloatArray | None:
    """Position-only damped least squares from ``q0`` (compiled): each step
    ``dq = Jᵀ (J Jᵀ + λ I)⁻¹ e`` on the TCP's linear Jacobian, scaled to at most 0.5 rad,
    joints wrapped by 2π into their limits then clamped; None when the error stagnates
    (above 0.7 x its value 5 steps earlier, from step 8 on) or after ``iterations``. The
    3 x 3 system is solved by an explicit Cholesky factorisation (no LAPACK call)."""
    q, ok = _position_dls_kernel(
        robot.table, robot.tcp, _EYE4 if base is None else writable_c(base),
        writable_c(q0), writable_c(target), readonly_c(robot.lower), readonly_c(robot.upper),
        float(tol), int(iterations), float(damping))
    return q if ok else None


def frames_many(robot: RobotModel, q: FloatArray, base: FloatArray | None = None
                ) -> FloatArray:
    """``(m, n + 2, 4, 4)`` frames of configurations ``(m, n)`` (compiled; the maths of
    :func:`frames_one` per configuration)."""
    q = writable_c(np.atleast_2d(q))
    if q.ndim != 2 or q.shape[1] != robot.n_joints:
        raise ValueError(f"q must have shape (m, {robot.n_joints}), got {q.shape}")
    frames = np.empty((q.shape[0], robot.n_joints + 2, 4, 4))
    _many_kernel(robot.table, robot.tcp, _EYE4 if base is None else writable_c(base), q,
                 frames, np.empty((1, 6, robot.n_joints)), False)
    return frames


_EYE4 = np.eye(4)


def frames_one(robot: RobotModel, q: FloatArray, base: FloatArray | None = None
               ) -> FloatArray:
    """``(n + 2, 4, 4)`` frames of one configuration ``(n,)`` (compiled; a few µs)."""
    q = writable_c(q)
    if q.shape != (robot.n_joints,):
        raise ValueError(f"q must have shape ({robot.n_joints},), got {q.shape}")
    frames = np.empty((robot.n_joints + 2, 4, 4))
    _chain_kernel(robot.table, robot.tcp, _EYE4 if base is None else writable_c(base), q,
                  frames)
    return frames


def fk(robot: RobotModel, q: FloatArray, base: FloatArray | None = None
       ) -> tuple[FloatArray, FloatArray]:
    """TCP position ``(3,)`` and rotation ``(3, 3)`` (world frame) at ``q`` ``(n,)``."""
    f = frames_one(robot, q, base)[-1]
    return f[:3, 3].copy(), f[:3, :3].copy()


def jacobian(robot: RobotModel, q: FloatArray, base: FloatArray | None = None) -> FloatArray:
    """``(6, n)`` geometric TCP Jacobian (world frame, linear rows first) at ``q`` ``(n,)``."""
    frames = frames_one(robot, q, base)
    jac = np.empty((6, robot.n_joints))
    _jacobian_kernel(frames, jac)
    return jac


def fk_and_jacobian(robot: RobotModel, q: FloatArray, base: FloatArray | None = None
                    ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """TCP position, rotation and Jacobian from one pass over the chain."""
    frames = frames_one(robot, q, base)
    jac = np.empty((6, robot.n_joints))
    _jacobian_kernel(frames, jac)
    return frames[-1, :3, 3].copy(), frames[-1, :3, :3].copy(), jac


def fk_batch(robot: RobotModel, q: FloatArray, base: FloatArray | None = None
             ) -> tuple[FloatArray, FloatArray]:
    """TCP positions ``(m, 3)`` and rotations ``(m, 3, 3)`` for configurations ``(m, n)``."""
    f = link_frames(robot, np.atleast_2d(q), base)[..., -1, :, :]
    return f[..., :3, 3].copy(), f[..., :3, :3].copy()


def jacobian_batch(robot: RobotModel, q: FloatArray, base: FloatArray | None = None
                   ) -> FloatArray:
    """Geometric TCP Jacobians ``(..., 6, n)`` (world frame, linear rows first).

    Column ``i`` of a revolute joint is ``[z_i x (p_tcp - p_i); z_i]`` with ``z_i``, ``p_i``
    the axis and origin of joint frame ``i``. A ``(m, n)`` batch is computed by the
    compiled chain (one pass per configuration, no numpy temporaries).
    """
    q = np.asarray(q, dtype=float)
    if q.ndim == 2 and q.shape[1] == robot.n_joints:
        qc = writable_c(q)
        jac = np.empty((q.shape[0], 6, robot.n_joints))
        _many_kernel(robot.table, robot.tcp, _EYE4 if base is None else writable_c(base), qc,
                     np.empty((q.shape[0], robot.n_joints + 2, 4, 4)), jac, True)
        return jac
    frames = link_frames(robot, q, base)
    n = robot.n_joints
    z = frames[..., 1:n + 1, :3, 2]                   # (..., n, 3)
    p = frames[..., 1:n + 1, :3, 3]
    tip = frames[..., n + 1, None, :3, 3]
    lin = np.cross(z, tip - p)
    return np.concatenate([np.swapaxes(lin, -1, -2), np.swapaxes(z, -1, -2)], axis=-2)


# ---------------------------------------------------------------------------- loading

def _num(value: Any, path: str, file: str | Path | None, bound: Bound | None = None,
         ) -> float:
    return check_number(value, path, bound=bound, file=file)


def _vec(value: Any, n: int, path: str, file: str | Path | None,
         bound: Bound | None = None) -> FloatArray:
    if not isinstance(value, list) or len(value) != n:
        raise fail(value, f"a list of {n} numbers", field=path, file=file)
    return np.array([_num(v, f"{path}[{i}]", file, bound) for i, v in enumerate(value)])


def _check_keys(table: dict[str, Any], allowed: set[str], path: str,
                file: str | Path | None) -> None:
    check_keys(table, sorted(allowed), path, file=file)


_JOINT_BOUNDS = {"alpha_deg": DH_ANGLE_DEG, "theta_offset_deg": DH_ANGLE_DEG,
                 "a": LINK_LENGTH_M, "d": LINK_LENGTH_M, "lower": JOINT_LIMIT_RAD,
                 "upper": JOINT_LIMIT_RAD, "max_velocity": JOINT_VELOCITY_RAD_S,
                 "max_acceleration": JOINT_ACCELERATION_RAD_S2}
_JOINT_KEYS = {"alpha_deg", "a", "d", "theta_offset_deg", "lower", "upper", "max_velocity",
               "max_acceleration"}
_REQUIRED_JOINT_KEYS = _JOINT_KEYS - {"theta_offset_deg"}


def parse_robot(text: str, file: str | Path | None = None) -> RobotModel:
    """Parses a robot TOML document (see the module docstring) into a :class:`RobotModel`.

    Raises:
        ConfigError: naming the file, the dotted field and the bad value.
    """
    data = parse_toml(text, file=file, kind="robot")
    _check_keys(data, {"name", "tcp", "home", "joints", "links"}, "", file)
    name = check_str(data.get("name"), "name", file=file)
    # the name becomes a path and XML text (see RobotModel)
    expect(_NAME.fullmatch(name), name, f"a name matching {_NAME.pattern}", file=file,
            field="name")
    raw_joints = data.get("joints")
    if not isinstance(raw_joints, list) or not raw_joints:
        raise fail(raw_joints, "at least one [[joints]] table", file=file, field="joints")
    joints = []
    for i, jt in enumerate(raw_joints):
        path = f"joints[{i}]"
        _check_keys(jt, _JOINT_KEYS, path, file)
        check_keys(jt, sorted(_JOINT_KEYS), path, file=file,
                   required=sorted(_REQUIRED_JOINT_KEYS))
        vals = {k: _num(jt[k], f"{path}.{k}", file, _JOINT_BOUNDS[k]) for k in jt}
        if not vals["lower"] < vals["upper"]:
            raise fail(vals["lower"], f"a limit below upper = {vals['upper']!r} rad",
                       field=f"{path}.lower", file=file)
        # plausibility: catches millimetres for metres, degrees for radians
        for key, bound, unit in (("a", MAX_LENGTH, "m"), ("d", MAX_LENGTH, "m"),
                                 ("lower", MAX_JOINT_ANGLE, "rad"),
                                 ("upper", MAX_JOINT_ANGLE, "rad")):
            expect(abs(vals[key]) <= bound, vals[key], f"|{key}| <= {bound:g} {unit} (units?)",
                    file=file, field=f"{path}.{key}")
        try:
            joints.append(DHJoint(
                alpha=math.radians(vals["alpha_deg"]), a=vals["a"], d=vals["d"],
                theta_offset=math.radians(vals.get("theta_offset_deg", 0.0)),
                lower=vals["lower"], upper=vals["upper"], max_velocity=vals["max_velocity"],
                max_acceleration=vals["max_acceleration"]))
        except ConfigError as exc:
            raise rewrap(exc, path, file) from None
    n = len(joints)
    tcp = _vec(data.get("tcp", [0.0, 0.0, 0.0]), 3, "tcp", file, LINK_LENGTH_M)
    check_required(data, ["home"], file=file)
    home = _vec(data["home"], n, "home", file, JOINT_LIMIT_RAD)
    for i, (h, jt) in enumerate(zip(home, joints, strict=True)):
        if not jt.lower <= h <= jt.upper:
            raise fail(float(h), f"an angle within joints[{i}]'s limits [{jt.lower!r}, "
                       f"{jt.upper!r}] rad", field=f"home[{i}]", file=file)
    links = []
    raw_links = data.get("links", [])
    check_type(raw_links, "links", list, "[[links]] tables", file=file)  # links = 5: was a
    for k, lt in enumerate(raw_links):                                    # TypeError
        path = f"links[{k}]"
        check_keys(lt, ["chain", "points", "radius"], path, file=file, required=["radius"])
        pts_raw = check_type(lt.get("points", []), f"{path}.points", list, "a list of points",
                             file=file)
        pts = tuple(tuple(float(x) for x in _vec(p, 3, f"{path}.points[{j}]", file,
                                                   LINK_LENGTH_M))
                    for j, p in enumerate(pts_raw))
        chain = check_bool(lt.get("chain", True), f"{path}.chain", file=file)
        expect(chain or pts, pts_raw, "points (a link with chain = false needs them)",
                file=file, field=f"{path}.points")
        try:
            links.append(LinkGeometry(radius=_num(lt["radius"], f"{path}.radius", file,
                                                   LINK_RADIUS_M),
                                      points=pts,  # type: ignore[arg-type]  # checked (k, 3) floats
                                      chain=chain))
        except ConfigError as exc:
            raise rewrap(exc, path, file) from None
    try:
        return RobotModel(name=name, joints=tuple(joints), tcp=tcp, home=home,
                          links=tuple(links))
    except ConfigError as exc:
        raise rewrap(exc, None, file) from None


def load_robot(ref: str | Path) -> RobotModel:
    """Loads a robot by shipped name (``"rx60b"``) or path to a TOML file."""
    path = data_file(ref, robots_dir(), "robot")
    return parse_robot(read_data_file(path, "robot"), file=path)
