"""Visibility — keep the robots out of the camera's view cone (spec/mrcp.md §4, seed 3.6.1).

The camera's field of view on the object is a solid cone from the camera to the minimum
enclosing circle of the object's image; the station models it as a (non-colliding) body of
the proximity world, kept in place by the scenario as the object moves. The index is the
robot's minimum distance to that body, normalised by ``d_ref`` and clamped to [0, 1]
(0 = occluding), averaged along the predicted trajectory with ``w_k = 1/(k+1)``.

**Decision**: the view cone is a world body (named ``cone_body``) rather than geometry
inside the index, so link shapes stay in one place (the world) and the index needs only
:class:`~vasim.mrcp.interfaces.ProximityWorld` distance queries.
"""

from __future__ import annotations

import numpy as np

from vasim.mrcp.indices.base import INDICES, EvalContext, NearestQuery, prediction_weights
from vasim.mrcp.interfaces import ProximityWorld


def view_cone_half_angle(camera: np.ndarray, center: np.ndarray, radius: float) -> float:
    """Half-angle [rad] of the cone from ``camera`` tangent to a sphere (``center``,
    ``radius``): the enclosing circle of the object's image for a spherical bound.

    Example:
        >>> import numpy as np
        >>> round(view_cone_half_angle(np.zeros(3), np.array([0.0, 0.0, 2.0]), 1.0), 6)
        0.523599
    """
    dist = float(np.linalg.norm(np.asarray(center) - np.asarray(camera)))
    if dist <= radius:
        return float(np.pi / 2)
    return float(np.arcsin(radius / dist))


@INDICES.add("visibility")
class VisibilityIndex:
    """Normalised clearance between a robot and the camera's view cone.

    Args:
        cone_body: name of the view-cone body in the proximity world.
        d_ref: clearance that scores 1 [m].
    """

    name = "visibility"

    def __init__(self, cone_body: str = "view_cone", d_ref: float = 0.05) -> None:
        if d_ref <= 0.0:
            raise ValueError(f"visibility: d_ref must be > 0, got {d_ref!r}")
        self.cone_body = cone_body
        self.d_ref = float(d_ref)
        self._query = NearestQuery(self.d_ref, only=frozenset({cone_body}))

    def distance_range(self, world: ProximityWorld) -> float | None:
        """The range of the body distances this index reads [m] (None: it reads none in
        ``world``), for the kernel's one batched query per robot."""
        return self.d_ref if self.cone_body in world.obstacle_names() else None

    def nearest_queries(self, world: ProximityWorld) -> tuple[NearestQuery, ...]:
        """The view cone's distance (a set of one body), for the kernel's one batched
        nearest-body query per cycle."""
        return (self._query,) if self.cone_body in world.obstacle_names() else ()

    def evaluate(self, ctx: EvalContext) -> float:
        world = ctx.world
        if not ctx.reachable[0]:
            return 0.0
        if self.cone_body not in world.obstacle_names():
            return 1.0
        col = ctx.nearest_distances(self._query)
        # An unreachable point scores 0; a reachable point whose distance was not queried
        # (``distance_points="ends"``) is left out of the average, as in CR.
        measured = np.isfinite(col)
        vals = np.where(ctx.reachable & measured,
                        np.clip(np.where(measured, col, 0.0) / self.d_ref, 0.0, 1.0), 0.0)
        w = np.where(ctx.reachable & ~measured, 0.0, prediction_weights(vals.shape[0]))
        return float((w * vals).sum() / w.sum())
