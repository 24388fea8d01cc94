"""The task value shared by trajectory following and point targeting.

A :class:`Task` is a frozen value: the points of interest (POIs) the tool tip must visit in
order, optional surface normals, the reach radius that advances the goal, the error scale
``D`` the fixtures normalise with, and the tool's start position. The helpers are pure
functions of the points (length, curvature, look-ahead point for the Mag camera).

Frame: world frame of the scene, metres (``z`` up toward the abdominal wall, ``y`` cranial,
``x`` toward the patient's left).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from vasim.core.config import check_array, check_choice, check_int, check_number, expect
from vasim.fixtures.types import TaskState, Vec3

FloatArray = NDArray[np.float64]
TaskKind = Literal["trajectory", "point"]

DEFAULT_REACH_RADIUS = 0.005
"""r_reach [m]: the goal advances when ``|x - p_i| <= r_reach`` (spec/study.md §2 decision)."""

WORKSPACE_MIN = np.array([-0.05, -0.03, 0.075])
"""(3,) lower corner of the trajectory workspace [m], world frame (above liver and stomach)."""
WORKSPACE_MAX = np.array([0.05, 0.07, 0.135])
"""(3,) upper corner of the trajectory workspace [m], world frame (below the wall)."""
WORKSPACE_CENTRE = 0.5 * (WORKSPACE_MIN + WORKSPACE_MAX)
"""(3,) centre of the trajectory workspace [m]: (0.0, 0.02, 0.105)."""
for _a in (WORKSPACE_MIN, WORKSPACE_MAX, WORKSPACE_CENTRE):
    _a.setflags(write=False)


def polyline_lookahead(points: FloatArray, i: int, distance: float = 0.02) -> FloatArray:
    """A point ``distance`` [m] further along the polyline ``points`` (n, 3) from p_i.

    Walks p_i -> p_(i+1) -> ... by arc length; returns the last point when the path ends
    first. ``i`` is clamped to [0, n - 1]. Pure: :meth:`Task.lookahead` on any points (e.g.
    POIs that move with the tissue).

    Raises:
        ValueError: for a negative or non-finite distance.
    """
    if distance < 0 or not math.isfinite(distance):
        raise ValueError(f"lookahead distance must be finite and >= 0, got {distance!r}")
    p = np.asarray(points, dtype=np.float64)
    n = len(p)
    i = min(max(int(i), 0), n - 1)
    remaining = float(distance)
    while i < n - 1:
        seg = p[i + 1] - p[i]
        ln = float(np.linalg.norm(seg))
        if ln >= remaining and ln > 0:
            return p[i] + seg * (remaining / ln)
        remaining -= ln
        i += 1
    return p[-1].copy()


@dataclass(frozen=True, eq=False)
class Task:
    """A task: POIs to visit in order (trajectory following) or one POI (point targeting).

    Attributes:
        name: human-readable name, e.g. ``"trajectory/v3"``.
        kind: ``"trajectory"`` or ``"point"``.
        variant: trajectory variant (0 = original, 1..6 mirrored/rotated); 0 for point tasks.
        points: (N, 3) POIs in visiting order [m], world frame (N = 1 for point targeting).
            Read-only.
        normals: (N, 3) unit surface normals at the POIs, or None (trajectory following).
        reach_radius: r_reach [m]; the goal advances when ``|x - p_i| <= r_reach``.
        scale: D [m], the distance that normalises errors for the fixtures (d_norm = |e|/D).
        start: (3,) tool-tip start position [m].

    Raises:
        ConfigError: on a bad shape, a non-finite value, a non-positive radius/scale or a
            non-unit normal (the message names the field and the value).

    Example:
        >>> t = Task("demo", "trajectory", 0, np.array([[0, 0, 0.1], [0.01, 0, 0.1]]),
        ...          None, start=np.array([-0.01, 0, 0.1]))
        >>> round(t.length(), 6), t.n_points
        (0.01, 2)
    """

    name: str
    kind: TaskKind
    variant: int
    points: FloatArray
    normals: FloatArray | None
    reach_radius: float = DEFAULT_REACH_RADIUS
    scale: float = 0.03
    start: FloatArray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        check_choice(self.kind, "kind", ("trajectory", "point"))
        # copies (np.array): the task's arrays are made read-only, never the caller's
        pts = np.array(check_array(self.points, "points", shape=(None, 3)))
        expect(len(pts) >= 1 and (self.kind != "point" or len(pts) == 1), pts.shape,
               "at least one POI (exactly one in a point task)", field="points")
        pts.setflags(write=False)
        object.__setattr__(self, "points", pts)
        if self.normals is not None:
            nrm = np.array(check_array(self.normals, "normals", shape=pts.shape))
            lens = np.linalg.norm(nrm, axis=1)
            expect(not np.any(np.abs(lens - 1.0) > 1e-9), lens.tolist(),
                   "unit vectors (normals' lengths)", field="normals")
            nrm.setflags(write=False)
            object.__setattr__(self, "normals", nrm)
        start = check_array(np.array(self.start, dtype=np.float64).reshape(-1), "start",
                            shape=(3,))
        start.setflags(write=False)
        object.__setattr__(self, "start", start)
        for name in ("reach_radius", "scale"):
            check_number(getattr(self, name), name, gt=0)
        check_int(self.variant, "variant", lo=0)

    # -- queries --------------------------------------------------------------------------
    @property
    def n_points(self) -> int:
        """Number of POIs N."""
        return int(self.points.shape[0])

    def _check_index(self, i: int) -> int:
        if not -self.n_points <= i < self.n_points:
            raise IndexError(f"POI index {i!r} out of range for {self.n_points} points")
        return i % self.n_points

    def goal(self, i: int) -> Vec3:
        """Returns the POI p_i, a read-only (3,) array [m].

        Raises:
            IndexError: if ``i`` is not a valid POI index.
        """
        return self.points[self._check_index(i)]

    def normal(self, i: int) -> Vec3 | None:
        """Returns the unit surface normal at POI i (3,), or None when the task has none."""
        if self.normals is None:
            return None
        return self.normals[self._check_index(i)]

    def lookahead(self, i: int, distance: float = 0.02) -> Vec3:
        """A point ``distance`` [m] further along the path from p_i (Mag aims at it).

        Walks the polyline p_i -> p_(i+1) -> ... by arc length; returns the last POI when
        the path ends first; for a point task (N = 1) returns the POI itself.

        Args:
            i: index of the current goal (``n_points`` or more is clamped to the last POI).
            distance: arc length ahead [m], >= 0.

        Returns:
            (3,) new array [m], world frame.
        """
        return polyline_lookahead(self.points, i, distance)

    def segment_lengths(self) -> FloatArray:
        """(N-1,) distances between successive POIs [m]."""
        return np.linalg.norm(np.diff(self.points, axis=0), axis=1)

    def length(self) -> float:
        """Polyline length of the POI sequence [m] (0 for a point task)."""
        return float(self.segment_lengths().sum())

    def curvature_profile(self) -> FloatArray:
        """(N-2,) discrete curvature at the interior POIs [1/m].

        kappa_i = turning angle at p_i / mean(|p_i - p_(i-1)|, |p_(i+1) - p_i|), where the
        turning angle is the angle between the incoming and outgoing segments [rad]. It is
        invariant under rotations and reflections (so all trajectory variants share it).
        Empty for N < 3.
        """
        p = self.points
        if p.shape[0] < 3:
            return np.zeros(0)
        a = p[1:-1] - p[:-2]
        b = p[2:] - p[1:-1]
        la = np.linalg.norm(a, axis=1)
        lb = np.linalg.norm(b, axis=1)
        cos = np.einsum("ij,ij->i", a, b) / (la * lb)
        ang = np.arccos(np.clip(cos, -1.0, 1.0))
        return ang / (0.5 * (la + lb))

    def advance(self, i: int, tcp: Vec3) -> int:
        """The goal index after the tool tip is at ``tcp`` while the goal is p_i.

        Returns ``i + 1`` when ``|tcp - p_i| <= reach_radius`` (one POI per step), else ``i``;
        ``n_points`` means the task is complete.
        """
        if i >= self.n_points:
            return i
        d = np.asarray(tcp, dtype=np.float64) - self.points[i]
        return i + 1 if float(d @ d) <= self.reach_radius**2 else i

    def state(self, i: int, tcp: Vec3, **kwargs: object) -> TaskState:
        """Builds the fixtures' :class:`TaskState` for goal index ``i`` (clamped to N-1).

        Fills goal, scale, kind, look-ahead and normal from the task; other TaskState fields
        (``tcp_velocity``, ``dx_master``, ``t``, ...) come from ``kwargs``.
        """
        j = min(max(int(i), 0), self.n_points - 1)
        return TaskState(
            tcp=np.asarray(tcp, dtype=np.float64), goal=self.points[j], scale=self.scale,
            kind=self.kind, lookahead=self.lookahead(j), normal=self.normal(j),
            **kwargs,  # type: ignore[arg-type]  # kwargs: TaskState's optional fields
        )


__all__ = [
    "DEFAULT_REACH_RADIUS",
    "WORKSPACE_CENTRE",
    "WORKSPACE_MAX",
    "WORKSPACE_MIN",
    "Task",
    "TaskKind",
]
