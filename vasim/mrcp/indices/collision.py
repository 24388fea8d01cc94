"""CR — collision risk from the estimated impact time (spec/mrcp.md §4, seed eq. 3.27).

Along the predicted trajectory the robot is posed at each predicted configuration and its
minimum distance ``d_k`` to every other body (robots at their measured configurations,
obstacles) is queried. Between consecutive points the closing speed is
``v = -(d_{k+1} - d_k) / Δt``; when ``v > 0`` the impact is expected at
``t_k + d_k / v`` (``t_k`` from now); a predicted penetration ``d_k <= 0`` is an impact at
``t_k``. ``timp = min`` over bodies and segments, capped at the window ``t_max``.
``CR_r = timp_r / max_r' timp_r'`` over every (robot, point) evaluated in the cycle
(:meth:`CollisionRiskIndex.combine`).

**Decision**: the per-link minimum of the seed is the minimum returned by the world's
robot-level distance query (it is the minimum over the robot's links); distances come from
:class:`~vasim.mrcp.interfaces.ProximityWorld` only. A world may add the batched query
``min_distances(robot, configs (N, n), bodies, max_distance) -> (N, B)`` (same values as
posing the robot and calling ``min_distance`` per body); the queries are made once per
context (:meth:`~vasim.mrcp.indices.EvalContext.body_distances`) and shared with the
visibility index. CR reads only the nearest body (:class:`~vasim.mrcp.indices.base.NearestQuery`,
every body but the ignored ones): the kernel answers that minimum for every context of a
cycle in one batched call (one branch and bound over all the bodies at once), the values of
the per-body queries' row minimum.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

import numpy as np
from numpy.typing import NDArray

from vasim.mrcp.indices.base import INDICES, EvalContext, Key, NearestQuery
from vasim.mrcp.interfaces import ProximityWorld

FloatArray = NDArray[np.float64]


def impact_time(times: FloatArray, distances: FloatArray, t_max: float) -> float:
    """Estimated time to impact [s] from distances sampled along a trajectory.

    Args:
        times: ``(K+1,)`` times [s] (``[0]`` = now).
        distances: ``(K+1,)`` minimum distances [m]; NaN = point skipped; ``-inf`` (a
            penetration too deep to estimate) is an impact like any distance ``<= 0``.
        t_max: the window; no impact expected -> ``t_max``.

    Example:
        >>> import numpy as np
        >>> round(impact_time(np.array([0.0, 0.1]), np.array([0.3, 0.2]), 5.0), 9)  # 1 m/s
        0.3
        >>> nan = float("nan")  # only the ends measured: the closing speed spans the gap
        >>> round(impact_time(np.array([0.0, 0.1, 0.2]), np.array([0.3, nan, 0.1]), 5.0), 9)
        0.3
    """
    t = (np.asarray(times, dtype=np.float64) - float(times[0])).tolist()
    d = np.asarray(distances, dtype=np.float64).tolist()    # Python floats: same IEEE maths
    best = float(t_max)
    for k in range(len(d)):
        if d[k] <= 0.0:         # before the finiteness skip: -inf, the deepest, is an impact
            return float(min(best, t[k]))
        if not math.isfinite(d[k]):
            continue
        # the next *measured* distance (NaN = skipped point, e.g. distance_points="ends"):
        # with every point measured this is k + 1
        j = k + 1
        while j < len(d) and math.isnan(d[j]):
            j += 1
        if j < len(d) and math.isfinite(d[j]):     # a -inf next is the impact at t[j]
            v = -(d[j] - d[k]) / (t[j] - t[k])
            if v > 0.0:
                best = min(best, t[k] + d[k] / v)
    return float(max(0.0, best))


@INDICES.add("cr")
class CollisionRiskIndex:
    """Collision risk: raw value ``timp`` [s], combined to ``timp / max timp``.

    Args:
        t_max: the impact-time window [s] (no impact foreseen within it -> ``t_max``).
        max_distance: distance queries beyond it return it [m].
        ignore: body names never considered (e.g. a visibility cone, a held object).
    """

    name = "cr"

    def __init__(self, t_max: float = 2.0, max_distance: float = 1.0,
                 ignore: Iterable[str] = ()) -> None:
        if t_max <= 0.0 or max_distance <= 0.0:
            raise ValueError(f"cr: t_max and max_distance must be > 0, got {t_max!r}, "
                             f"{max_distance!r}")
        self.t_max = float(t_max)
        self.max_distance = float(max_distance)
        self.ignore = frozenset(ignore)
        self._query = NearestQuery(self.max_distance, exclude=self.ignore)

    def distance_range(self, world: ProximityWorld) -> float | None:
        """The range of the body distances this index reads [m], for the kernel's one
        batched query per robot."""
        return self.max_distance

    def nearest_queries(self, world: ProximityWorld) -> tuple[NearestQuery, ...]:
        """CR reads only the nearest body (every body but the ignored ones), for the
        kernel's one batched nearest-body query per cycle."""
        return (self._query,)

    def distances(self, ctx: EvalContext) -> FloatArray:
        """``(K+1,)`` minimum distance to any other body at each reachable point (NaN else)."""
        if not self._query.bodies(ctx.world, ctx.robot):
            out = np.full(ctx.configs.shape[0], np.nan)
            out[ctx.reachable] = self.max_distance
            return out
        return ctx.nearest_distances(self._query).copy()

    def evaluate(self, ctx: EvalContext) -> float:
        if not ctx.reachable[0]:
            return 0.0
        return impact_time(ctx.times, self.distances(ctx), self.t_max)

    def combine(self, raw: Mapping[Key, float]) -> dict[Key, float]:
        top = max(raw.values(), default=0.0)
        if top <= 0.0:
            return {k: 0.0 for k in raw}
        return {k: v / top for k, v in raw.items()}
