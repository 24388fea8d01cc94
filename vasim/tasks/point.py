"""Point targeting: reach one POI on an organ surface, approaching along its normal.

The default POI lies on the upper (diaphragmatic) surface of the procedural liver
(``vasim.abdomen.anatomy.liver`` with its default parameters): the vertex nearest to
(x, y) = (-0.058, 0.085) m at the top of the organ, with that vertex's outward normal
(tilted ~12 deg from +z toward the patient's left and caudal). The values are stored here
rather than computed from the mesh so tasks do not depend on the mesher; pass ``poi`` and
``normal`` for another organ or a user mesh.
"""

from __future__ import annotations

import math

import numpy as np

from vasim.core.config import check_array, check_number, expect
from vasim.tasks.base import DEFAULT_REACH_RADIUS, Task

LIVER_POI = (-0.058, 0.0851, 0.0704)
"""Default POI [m], world frame: top surface of the default liver."""
LIVER_NORMAL = (0.1849, -0.1022, 0.9774)
"""Outward surface normal at :data:`LIVER_POI` (normalised when the task is built)."""


def point_task(poi: object = LIVER_POI, normal: object = LIVER_NORMAL, *,
               start_distance: float = 0.07, reach_radius: float = DEFAULT_REACH_RADIUS,
               scale: float | None = None, name: str = "point/liver") -> Task:
    """The point-targeting task: one POI with its unit surface normal.

    Args:
        poi: (3,) POI on an organ surface [m], world frame.
        normal: (3,) outward surface normal at the POI (any length > 0; normalised).
        start_distance: distance of the tool start from the POI along the normal [m].
        reach_radius: r_reach [m].
        scale: D [m] for the fixtures' error normalisation; default ``start_distance``.
        name: task name.

    Returns:
        A :class:`Task` with N = 1, ``normals`` (1, 3) unit, ``start = poi + d * n``.

    Raises:
        ConfigError: on a non-finite or zero normal, or ``start_distance <= 0``.

    Example:
        >>> t = point_task()
        >>> round(float(np.linalg.norm(t.start - t.points[0])), 6)
        0.07
    """
    p = np.array(poi, dtype=np.float64).reshape(-1)
    n = np.array(normal, dtype=np.float64).reshape(-1)
    check_array(p, "poi", shape=(3,), what="a finite 3-vector")
    ln = float(np.linalg.norm(n)) if n.shape == (3,) else float("nan")
    expect(math.isfinite(ln) and ln > 1e-12, normal, "a finite non-zero 3-vector",
           field="normal")
    n = n / ln
    check_number(start_distance, "start_distance", gt=0)
    return Task(
        name=name, kind="point", variant=0, points=p[None, :], normals=n[None, :],
        reach_radius=reach_radius, scale=start_distance if scale is None else scale,
        start=p + start_distance * n,
    )


__all__ = ["LIVER_NORMAL", "LIVER_POI", "point_task"]
