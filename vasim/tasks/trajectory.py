"""Trajectory following: one original 3-D path of POIs and six mirrored/rotated variants.

The original path (spec/study.md §1) is a natural cubic spline (``scipy.interpolate.
CubicSpline``, chord-length parametrised) through twelve hand-placed knots that wind through
the workspace above the liver and stomach, dipping toward the organs and rising toward the
wall, with curvature radii from ~1.4 cm to ~20 cm. The spline is resampled at equal arc
length into 30 POIs 10.3-10.6 mm apart (chord > 2 r_reach, so no point of the 5 mm reach
sphere of one POI lies in the next one's); polyline length ~31 cm.

Variants (**decision**): isometries of the horizontal plane about the path's centroid (the
vertical axis is kept, so the path keeps its distance profile to the organs below and the
wall above). With ``c`` the centroid and ``M`` a 2x2 orthogonal matrix acting on (x, y):
``p' = c + blockdiag(M, 1) (p - c)``:

=======  ===========================================  ============
variant  transform                                     kind
=======  ===========================================  ============
0        identity (the original)                       proper
1        mirror x  (x -> -x)                           improper
2        mirror y  (y -> -y)                           improper
3        rotate +90 deg about z                        proper
4        rotate 180 deg about z                        proper
5        rotate 270 deg about z                        proper
6        mirror x, then rotate +90 deg (x <-> y swap)  improper
=======  ===========================================  ============

These are seven of the eight symmetries of the square workspace footprint centred on the
centroid, so every variant stays inside the workspace, and lengths and curvatures are
identical (same difficulty). The start position is transformed with the path.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.interpolate import CubicSpline

from vasim.core.config import check_int, check_number, expect
from vasim.tasks.base import DEFAULT_REACH_RADIUS, WORKSPACE_CENTRE, FloatArray, Task

TRAJECTORY_VARIANTS = 7
"""Number of trajectory variants: 0 = original, 1..6 = mirrored/rotated."""

POI_SPACING = 0.0105
"""Default arc length between successive POIs [m] (> 2 x reach radius): 30 POIs.

**Decision** (the seed gives neither the spacing nor r_reach; issue #15): 10.5 mm with
r_reach = 5 mm, chosen so that eq. 6.5's e_i rises with the deviation from the path over the
deviations operators show. Reason, the geometry of the reach rule: a tip moving at speed v
with a lateral offset d (< r) heads for p_i from a + s before it to a before it, a =
sqrt(r^2 - d^2) (where the rule fires), so e_i = (s / v)(a + s/2 + d) in L1 (offset along
an axis; tested
analytically in ``tests/study/test_metrics_path_deviation.py``). It grows with d only while
d < r / sqrt(2): beyond, the goal advances earlier and e_i *falls* with the deviation, and
at d >= r the goal does not advance at all (the operator must stop and correct). The
VF-free simulated operator deviates 3-4 mm on average (path_dev_mean_mm), so r = 5 mm keeps
e_i increasing up to 3.5 mm; s > 2 r keeps the reach spheres apart, and the smallest such
spacing (10.5 mm) maximises the share of the deviation term d / (a + s/2 + d). A smaller
radius (the seed's df2 = 98131 over 46 x 38 trials suggests ~56 rows per trial, ~5.6 mm
spacing, r < 2.8 mm) makes e_i fall above 1.8-2 mm of deviation and turns each POI into a
targeting task: measured (2 simulated subjects per fixture, 5.6 / 2.5 mm), VF-free trials
took 55 s instead of 17 s and e_i / duration stayed 7.8-8.2 mm for every fixture. Even so,
the travel term a + s/2 is more than half of e_i / duration for every d < r when s > 2 r
(75 % at d = 3 mm with the default), so e_i ranks the fastest condition first in any
reach-rule task; ``vasim.records.path_deviation`` gives the
accuracy measure that does not depend on speed. ``poi_spacing_m`` and ``reach_radius_m``
set other values per protocol."""

POI_SPACING_RANGE = (0.002, 0.05)
"""Accepted POI spacings [m]: 2 mm (the tool's own size) to 5 cm (6 POIs on the path)."""

START_OFFSET = 0.012
"""Distance of the tool's start position before the first POI, against the path tangent [m]."""

TRAJECTORY_SCALE = 0.03
"""D [m]: error normalisation of the trajectory task for the fixtures."""

_KNOTS_CM = np.array([
    (-3.0, -3.9, -0.5), (-0.6, -3.9, 1.2), (2.0, -3.2, 2.0), (3.6, -1.2, 0.8),
    (2.8, 1.0, -1.2), (0.2, 0.6, -2.0), (-2.2, 1.4, -0.6), (-3.4, 3.0, 1.0),
    (-1.6, 4.0, 2.2), (1.2, 3.6, 1.0), (3.4, 3.8, -0.8), (3.8, 2.4, -1.8),
])
"""Hand-placed spline knots [cm], relative to the workspace centre (before re-centring)."""

_M2 = {
    0: ((1.0, 0.0), (0.0, 1.0)),
    1: ((-1.0, 0.0), (0.0, 1.0)),
    2: ((1.0, 0.0), (0.0, -1.0)),
    3: ((0.0, -1.0), (1.0, 0.0)),
    4: ((-1.0, 0.0), (0.0, -1.0)),
    5: ((0.0, 1.0), (-1.0, 0.0)),
    6: ((0.0, 1.0), (1.0, 0.0)),  # rot90 @ mirror_x = [[0,-1],[1,0]] @ [[-1,0],[0,1]]
}
VARIANT_NAMES = ("original", "mirror_x", "mirror_y", "rot90", "rot180", "rot270",
                 "mirror_x_rot90")
"""Names of the variant transforms, indexed by variant."""


def variant_matrix(variant: int) -> FloatArray:
    """The (3, 3) orthogonal matrix of a variant (acting about the path centroid).

    Raises:
        ConfigError: if ``variant`` is not an int in [0, 6].
    """
    check_int(variant, "variant", lo=0, hi=TRAJECTORY_VARIANTS - 1)
    m = np.eye(3)
    m[:2, :2] = np.array(_M2[int(variant)])
    return m


@lru_cache(maxsize=8)
def _original(spacing: float = POI_SPACING) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(points (N,3), start (3,), centroid (3,)) of the original path with POIs ``spacing``
    [m] apart along it; arrays read-only."""
    knots = _KNOTS_CM * 0.01
    chord = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(knots, axis=0), axis=1))]
    spline = CubicSpline(chord, knots, bc_type="natural")
    u = np.linspace(0.0, chord[-1], 20001)
    dense = spline(u)
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(dense, axis=0), axis=1))]
    n_seg = round(s[-1] / spacing)
    u_poi = np.interp(np.linspace(0.0, s[-1], n_seg + 1), s, u)
    pts = spline(u_poi)
    tangent = spline(u_poi[0], 1)
    tangent = tangent / np.linalg.norm(tangent)
    start = pts[0] - START_OFFSET * tangent
    shift = WORKSPACE_CENTRE.copy()
    shift[:2] -= pts[:, :2].mean(axis=0)
    pts = pts + shift
    start = start + shift
    centroid = np.array([WORKSPACE_CENTRE[0], WORKSPACE_CENTRE[1], 0.0])
    for a in (pts, start, centroid):
        a.setflags(write=False)
    return pts, start, centroid


def trajectory_task(variant: int = 0, *, reach_radius: float = DEFAULT_REACH_RADIUS,
                    scale: float = TRAJECTORY_SCALE, poi_spacing: float = POI_SPACING) -> Task:
    """The trajectory-following task, original (0) or one of its six variants (1..6).

    Args:
        variant: 0 = original; 1..6 = mirrored/rotated (see the module docstring).
        reach_radius: r_reach [m], the goal advances when ``|x - p_i| <= r_reach``.
        scale: D [m], error normalisation for the fixtures.
        poi_spacing: target arc length between POIs [m] (``POI_SPACING``: 30 POIs), in
            ``POI_SPACING_RANGE`` and > 2 ``reach_radius`` (so no reach sphere of one POI
            overlaps the next one's).

    Returns:
        A :class:`Task` with the POIs [m] (30 at the default spacing), world frame, no
        normals.

    Raises:
        ConfigError: (a ``ValueError``) for a variant outside [0, 6] or a bad spacing.

    Example:
        >>> a, b = trajectory_task(0), trajectory_task(3)
        >>> abs(a.length() - b.length()) < 1e-12, a.n_points
        (True, 30)
    """
    m = variant_matrix(variant)
    lo, hi = POI_SPACING_RANGE
    check_number(poi_spacing, "poi_spacing", ge=lo, le=hi)
    expect(not isinstance(reach_radius, int | float) or poi_spacing > 2.0 * reach_radius,
           poi_spacing, f"a POI spacing [m] more than twice the reach radius "
           f"({reach_radius!r} m)", field="poi_spacing")
    pts, start, c = _original(float(poi_spacing))
    vpts = (pts - c) @ m.T + c
    vstart = (start - c) @ m.T + c
    return Task(
        name=f"trajectory/v{int(variant)}", kind="trajectory", variant=int(variant),
        points=vpts, normals=None, reach_radius=reach_radius, scale=scale, start=vstart,
    )


__all__ = [
    "POI_SPACING",
    "POI_SPACING_RANGE",
    "TRAJECTORY_SCALE",
    "TRAJECTORY_VARIANTS",
    "VARIANT_NAMES",
    "trajectory_task",
    "variant_matrix",
]
