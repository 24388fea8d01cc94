"""An analytic robot world for testing the MRCP kernel without pybullet.

:class:`PlanarArm` is a two-link planar arm (shoulder and elbow about the vertical axis)
on a vertical lift: ``q = (θ1, θ2, z)``. Its TCP is

    x = bx + l1 cos θ1 + l2 cos(θ1 + θ2),  y = by + l1 sin θ1 + l2 sin(θ1 + θ2),  z = bz + z

so its translational Jacobian is full rank except where the links align (``sin θ2 = 0``):
there ``det(J_xy) = l1 l2 sin θ2`` vanishes — the planar analogue of the RX60B's joint-3/5
alignment and workspace boundary. IK is closed form (both elbow branches, the one closest
to the seed wins).

:class:`PlanarWorld` implements :class:`~vasim.mrcp.interfaces.ProximityWorld` with capsule
links (segment + radius) and spherical obstacles; distances are exact segment-segment and
point-segment distances (Ericson, *Real-Time Collision Detection*, 5.1.9). Obstacles with
``solid=False`` (a view cone stand-in) are queried but never count as collisions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from vasim.mrcp.interfaces import Proximity

FloatArray = NDArray[np.float64]


@dataclass
class PlanarArm:
    """Two-link planar arm on a lift (see module docstring); ``yaw`` turns its base."""

    name: str
    base: FloatArray = field(default_factory=lambda: np.zeros(3))
    yaw: float = 0.0
    l1: float = 0.3
    l2: float = 0.25
    lower: FloatArray = field(default_factory=lambda: np.array([-2.8, -2.8, -0.2]))
    upper: FloatArray = field(default_factory=lambda: np.array([2.8, 2.8, 0.2]))
    vmax: FloatArray = field(default_factory=lambda: np.array([2.0, 2.0, 0.5]))
    amax: FloatArray = field(default_factory=lambda: np.array([10.0, 10.0, 2.0]))
    radius: float = 0.03

    @property
    def n_joints(self) -> int:
        return 3

    @property
    def joint_lower(self) -> FloatArray:
        return self.lower

    @property
    def joint_upper(self) -> FloatArray:
        return self.upper

    @property
    def max_velocity(self) -> FloatArray:
        return self.vmax

    @property
    def max_acceleration(self) -> FloatArray:
        return self.amax

    def points(self, q: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Shoulder, elbow and TCP positions."""
        t1, t2, z = q
        t1 = t1 + self.yaw
        s = self.base + np.array([0.0, 0.0, z])
        e = s + self.l1 * np.array([np.cos(t1), np.sin(t1), 0.0])
        tcp = e + self.l2 * np.array([np.cos(t1 + t2), np.sin(t1 + t2), 0.0])
        return s, e, tcp

    def tcp_pose(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        c, s = np.cos(self.yaw + q[0] + q[1]), np.sin(self.yaw + q[0] + q[1])
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return self.points(q)[2], rot

    def jacobians(self, qs: FloatArray) -> FloatArray:
        """``(N, 6, 3)`` Jacobians (batched, analytic)."""
        qs = np.atleast_2d(qs)
        t1 = qs[:, 0] + self.yaw
        t12 = t1 + qs[:, 1]
        out = np.zeros((qs.shape[0], 6, 3))
        out[:, 0, 0] = -self.l1 * np.sin(t1) - self.l2 * np.sin(t12)
        out[:, 0, 1] = -self.l2 * np.sin(t12)
        out[:, 1, 0] = self.l1 * np.cos(t1) + self.l2 * np.cos(t12)
        out[:, 1, 1] = self.l2 * np.cos(t12)
        out[:, 2, 2] = 1.0
        out[:, 5, 0] = 1.0
        out[:, 5, 1] = 1.0
        return out

    def jacobian(self, q: FloatArray) -> FloatArray:
        return self.jacobians(np.asarray(q)[None, :])[0]

    def ik(self, position: FloatArray, rotation: FloatArray | None = None,
           q_seed: FloatArray | None = None) -> FloatArray | None:
        dx = float(position[0]) - float(self.base[0])
        dy = float(position[1]) - float(self.base[1])
        z = float(position[2]) - float(self.base[2])
        lo = [float(v) for v in self.lower]
        hi = [float(v) for v in self.upper]
        if not lo[2] - 1e-12 <= z <= hi[2] + 1e-12:
            return None
        c2 = (dx * dx + dy * dy - self.l1 ** 2 - self.l2 ** 2) / (2 * self.l1 * self.l2)
        if abs(c2) > 1.0 + 1e-9:
            return None
        c2 = min(1.0, max(-1.0, c2))
        seed = [0.0, 0.0, 0.0] if q_seed is None else [float(v) for v in q_seed]
        best: tuple[float, float, float] | None = None
        best_d = math.inf
        a2 = math.acos(c2)
        for t2 in ((a2, -a2) if a2 > 0.0 else (a2,)):
            t1 = (math.atan2(dy, dx) - self.yaw
                  - math.atan2(self.l2 * math.sin(t2), self.l1 + self.l2 * math.cos(t2)))
            for w1 in (t1 - 2 * math.pi, t1, t1 + 2 * math.pi):
                if not (lo[0] - 1e-12 <= w1 <= hi[0] + 1e-12 and lo[1] - 1e-12 <= t2 <= hi[1]
                        + 1e-12):
                    continue
                if rotation is not None:
                    yaw = self.yaw + w1 + t2
                    r = np.asarray(rotation)
                    if abs(r[0, 0] - math.cos(yaw)) + abs(r[1, 0] - math.sin(yaw)) > 1e-6:
                        continue
                d = (w1 - seed[0]) ** 2 + (t2 - seed[1]) ** 2 + (z - seed[2]) ** 2
                if d < best_d:
                    best, best_d = (w1, t2, z), d
        return None if best is None else np.array(best)


def closest_segment_segment(p1: FloatArray, q1: FloatArray, p2: FloatArray, q2: FloatArray
                            ) -> tuple[FloatArray, FloatArray]:
    """Closest points of segments ``p1q1`` and ``p2q2`` (Ericson 5.1.9)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, f = d1 @ d1, d2 @ d2, d2 @ r
    eps = 1e-15
    if a <= eps and e <= eps:
        return p1.copy(), p2.copy()
    if a <= eps:
        s, t = 0.0, float(np.clip(f / e, 0.0, 1.0))
    else:
        c = d1 @ r
        if e <= eps:
            s, t = float(np.clip(-c / a, 0.0, 1.0)), 0.0
        else:
            b = d1 @ d2
            den = a * e - b * b
            s = float(np.clip((b * f - c * e) / den, 0.0, 1.0)) if den > eps else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                t, s = 0.0, float(np.clip(-c / a, 0.0, 1.0))
            elif t > 1.0:
                t, s = 1.0, float(np.clip((b - c) / a, 0.0, 1.0))
    return p1 + d1 * s, p2 + d2 * t


def closest_point_segment(p: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    ab = b - a
    den = ab @ ab
    s = 0.0 if den <= 1e-15 else float(np.clip((p - a) @ ab / den, 0.0, 1.0))
    return a + s * ab


def segment_distances(p1: FloatArray, q1: FloatArray, p2: FloatArray, q2: FloatArray
                      ) -> FloatArray:
    """Vectorised segment-segment distances (arrays ``(..., 3)``, broadcast); same clamping
    as :func:`closest_segment_segment`."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a = np.sum(d1 * d1, -1)
    e = np.sum(d2 * d2, -1)
    f = np.sum(d2 * r, -1)
    c = np.sum(d1 * r, -1)
    b = np.sum(d1 * d2, -1)
    den = a * e - b * b
    a_s = np.maximum(a, 1e-15)
    e_s = np.maximum(e, 1e-15)
    s = np.where(den > 1e-15, np.clip((b * f - c * e) / np.maximum(den, 1e-15), 0.0, 1.0), 0.0)
    t = (b * s + f) / e_s
    s = np.where(t < 0.0, np.clip(-c / a_s, 0.0, 1.0), np.where(t > 1.0,
                                                                  np.clip((b - c) / a_s, 0, 1), s))
    t = np.clip(t, 0.0, 1.0)
    point2 = e <= 1e-15                      # second segment degenerate: point-segment
    s = np.where(point2, np.clip(-c / a_s, 0.0, 1.0), s)
    t = np.where(point2, 0.0, t)
    point1 = a <= 1e-15
    s = np.where(point1, 0.0, s)
    t = np.where(point1, np.clip(f / e_s, 0.0, 1.0), t)
    diff = (p1 + d1 * s[..., None]) - (p2 + d2 * t[..., None])
    return np.linalg.norm(diff, axis=-1)


@dataclass
class Sphere:
    center: FloatArray
    radius: float
    solid: bool = True


class PlanarWorld:
    """Capsule-link robots and spherical obstacles (a ProximityWorld)."""

    def __init__(self, arms: dict[str, PlanarArm], configs: dict[str, FloatArray],
                 obstacles: dict[str, Sphere] | None = None) -> None:
        self.arms = arms
        self.q = {k: np.asarray(v, dtype=np.float64).copy() for k, v in configs.items()}
        self.obstacles = dict(obstacles or {})
        self.queries = 0
        self._seg_cache: dict[str, tuple[bytes, FloatArray, FloatArray]] = {}

    def robot_names(self) -> list[str]:
        return list(self.arms)

    def obstacle_names(self) -> list[str]:
        return list(self.obstacles)

    def set_configuration(self, robot: str, q: FloatArray) -> None:
        self.q[robot] = np.asarray(q, dtype=np.float64).copy()

    def configuration(self, robot: str) -> FloatArray:
        return self.q[robot].copy()

    def _segments(self, robot: str) -> list[tuple[FloatArray, FloatArray]]:
        s, e, t = self.arms[robot].points(self.q[robot])
        return [(s, e), (e, t)]

    def min_distance(self, a: str, b: str, max_distance: float = 1.0) -> Proximity:
        self.queries += 1
        best = (np.inf, np.full(3, np.nan), np.full(3, np.nan), -1, -1)
        ra = self.arms[a].radius
        for i, (p1, q1) in enumerate(self._segments(a)):
            if b in self.arms:
                rb = self.arms[b].radius
                for j, (p2, q2) in enumerate(self._segments(b)):
                    ca, cb = closest_segment_segment(p1, q1, p2, q2)
                    d = float(np.linalg.norm(cb - ca))
                    if d - ra - rb < best[0]:
                        u = (cb - ca) / d if d > 1e-12 else np.array([1.0, 0.0, 0.0])
                        best = (d - ra - rb, ca + ra * u, cb - rb * u, i, j)
            else:
                sph = self.obstacles[b]
                ca = closest_point_segment(sph.center, p1, q1)
                d = float(np.linalg.norm(sph.center - ca))
                if d - ra - sph.radius < best[0]:
                    u = (sph.center - ca) / d if d > 1e-12 else np.array([1.0, 0.0, 0.0])
                    best = (d - ra - sph.radius, ca + ra * u, sph.center - sph.radius * u, i, -1)
        if best[0] >= max_distance:
            nan = np.full(3, np.nan)
            return Proximity(max_distance, nan, nan.copy(), -1, -1)
        return Proximity(best[0], best[1], best[2], best[3], best[4])

    def _posed_segments(self, robot: str) -> tuple[FloatArray, FloatArray]:
        """Link segments ``(2, 3)`` at the robot's current configuration (cached)."""
        key = self.q[robot].tobytes()
        hit = self._seg_cache.get(robot)
        if hit is None or hit[0] != key:
            s0, s1 = self._segments_batch(robot, self.q[robot][None, :])
            hit = (key, s0[0], s1[0])
            self._seg_cache[robot] = hit
        return hit[1], hit[2]

    def _segments_batch(self, robot: str, qs: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Link segment start and end points ``(N, 2, 3)`` at ``(N, 3)`` configurations."""
        arm = self.arms[robot]
        qs = np.atleast_2d(qs)
        t1 = qs[:, 0] + arm.yaw
        t12 = t1 + qs[:, 1]
        s = np.repeat(arm.base[None, :], qs.shape[0], axis=0)
        s[:, 2] += qs[:, 2]
        e = s.copy()
        e[:, 0] += arm.l1 * np.cos(t1)
        e[:, 1] += arm.l1 * np.sin(t1)
        tcp = e.copy()
        tcp[:, 0] += arm.l2 * np.cos(t12)
        tcp[:, 1] += arm.l2 * np.sin(t12)
        return np.stack([s, e], axis=1), np.stack([e, tcp], axis=1)

    def min_distances(self, robot: str, qs: FloatArray, bodies: list[str],
                      max_distance: float = 1.0) -> FloatArray:
        """``(N, B)`` minimum distances of ``robot`` at ``(N, n)`` configurations to
        ``bodies`` (posed as they are), capped at ``max_distance`` (batched)."""
        self.queries += 1
        a0, a1 = self._segments_batch(robot, qs)                  # (N, 2, 3)
        ra = self.arms[robot].radius
        out = np.empty((a0.shape[0], len(bodies)))
        b0 = np.empty((len(bodies), 2, 3))
        b1 = np.empty((len(bodies), 2, 3))
        radii = np.empty(len(bodies))
        for j, body in enumerate(bodies):
            if body in self.arms:
                b0[j], b1[j] = self._posed_segments(body)
                radii[j] = self.arms[body].radius
            else:                       # a sphere: a degenerate segment, twice
                sph = self.obstacles[body]
                b0[j] = b1[j] = sph.center
                radii[j] = sph.radius
        d = segment_distances(a0[:, :, None, None, :], a1[:, :, None, None, :],
                              b0[None, None], b1[None, None])       # (N, 2, B, 2)
        out = d.min(axis=(1, 3)) - ra - radii[None, :]
        return np.minimum(out, max_distance)

    def in_collision(self, robot: str) -> bool:
        solid = [b for b in self.arms if b != robot] + [
            name for name, sph in self.obstacles.items() if sph.solid]
        if not solid:
            return False
        return bool(np.any(self.min_distances(robot, self.q[robot][None, :], solid) < 0.0))

def make_context(arm: PlanarArm, world: PlanarWorld, positions: FloatArray,
                 std: FloatArray | None = None, dt: float = 0.05,
                 seed: FloatArray | None = None, past: list[FloatArray] | None = None):
    """An :class:`~vasim.mrcp.indices.EvalContext` for ``arm`` holding a task point moving
    through ``positions`` ``(K+1, 3)`` (IK seeded along the way), points ``dt`` apart."""
    from vasim.mrcp.indices import EvalContext

    pos = np.asarray(positions, dtype=np.float64)
    n_pts = pos.shape[0]
    configs = np.full((n_pts, 3), np.nan)
    reach = np.zeros(n_pts, dtype=bool)
    s = world.configuration(arm.name) if seed is None else seed
    for k in range(n_pts):
        sol = arm.ik(pos[k], None, s)
        if sol is not None:
            configs[k], reach[k], s = sol, True, sol
    vel = np.zeros_like(configs)
    vel[:-1] = np.nan_to_num(np.diff(configs, axis=0) / dt)
    vel[-1] = vel[-2] if n_pts > 1 else 0.0
    return EvalContext(robot=arm.name, arm=arm, point=0, selected=True,
                       times=dt * np.arange(n_pts), positions=pos,
                       std=np.zeros_like(pos) if std is None else np.asarray(std, float),
                       rotations=None, configs=configs, reachable=reach, joint_velocity=vel,
                       past_configs=past or [], world=world)
