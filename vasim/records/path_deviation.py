"""Accuracy measures that do not move with speed: distance of the tool tip to the planned path.

The seed's e_i (eq. 6.5, called "cumulative error" there) sums ``||x(j) - p_i||_1`` over
every sample logged while p_i was the goal, so it grows with the time spent on the way to
p_i and with the logging rate (at 1 kHz it is a sum of ~1,000 distances per second). With
POIs ~1 cm apart it is dominated by the distance still to travel, i.e. it measures speed.
The measures here answer "how far from the planned path was the tool", whatever its speed.

Conventions (**decisions**, the seed has no path-deviation measure):

* **Planned path.** The polyline ``start -> p_0 -> p_1 -> ... -> p_(N-1)`` through the POIs
  [m, world frame]. ``start`` is the task's tool start position; **Decision**: when it is not
  given the first logged sample ``x(0)`` stands for it, because the runner logs the first
  sample one control step after the start, so the two differ by one step of motion (< 0.1 mm
  at 1 kHz) and callers that do not know the start (the needle task) still get a path.
* **Segment of a sample.** **Decision**: a sample logged with goal i is compared with the
  segment of its goal, ``[p_(i-1), p_i]`` (``p_(-1)`` = start), and the segment before it,
  ``[p_(i-2), p_(i-1)]`` (the nearer of the two), not with the nearest part of the whole
  polyline, because the trajectory crosses over itself in plan view and a tool wandering
  onto another part of the path is off *its* path. The previous segment is needed because
  the goal advances as soon as the tip is within r_reach of p_(i-1), up to r_reach *before*
  it: a tip exactly on the path would otherwise read as up to r_reach off it. Rows with
  goal N ("all reached") belong to no segment and are left out.
* **Time weighting.** Sample j stands for the interval (t_(j-1), t_j] (``t_(-1) = t_start``),
  as in ``trial_metrics``; means, RMS and the fraction outside the tube weight samples by that
  duration w_j. With the runner's uniform log this is the plain sample mean.
* **Tolerance tube.** ``out_frac`` is the fraction of time with distance > ``tolerance``
  (protocol parameter ``path_tolerance_m``, default 2 mm).
* **Rate-independent e.** ``error_l1_mm_s`` = sum_j ||x(j) - g(j)||_1 w_j [mm s]: eq. 6.5
  times the sample period; the same number whatever the logging rate.
* **Progress along the path** (issue #26 §6; :func:`path_progress`). A sample's progress
  is the arc length of the planned path up to its projection onto the segment of its goal,
  ``[p_(i-1), p_i]`` (clamped to it); a row with goal N has covered the whole path.
  ``path_covered_frac`` is the largest progress over the trial divided by the path's
  length. **Decision**: the progress of a sample counts however far off the path it is
  (the deviation measures say how far); the goal index only advances by reaching points in
  order, so the progress cannot jump ahead of the points reached.
* **Deviation over the part attempted** (``path_dev_attempted_mm``). The time mean of the
  distance rewards waiting: a tool that never leaves the start sits on the path (0 mm).
  **Decision**: this measure averages the distance *along the path*, over the attempted
  part ``[0, s_max]`` only: ``[0, s_max]`` is cut into bins of ``ATTEMPT_BIN_M`` (or 200
  bins, whichever is coarser), a bin's value is the mean distance of the samples whose
  progress falls in it, an empty bin (the tool passed it between two samples) takes the
  value interpolated from its neighbours, and the measure is the mean over the bins. Time
  spent anywhere does not weigh, and a trial that attempted nothing (``s_max = 0``) has no
  value (NaN): it is never scored as accurate.
* **Point targeting.** ``final_error`` is ``|x(n-1) - p_(N-1)|`` [m] (Euclidean, last
  sample); ``overshoot`` is how far the tip went past the last POI along the approach
  direction u = (p_(N-1) - p_(N-2)) / |...| (the start for N = 1):
  ``max(0, max_j (x(j) - p) . u)`` [m].

Example:
    >>> import numpy as np
    >>> x = np.array([[0.001, 0.003, 0.0], [0.002, 0.003, 0.0]])
    >>> segment_distances(x, np.zeros((2, 3)), np.array([[0.01, 0.0, 0.0]] * 2)).tolist()
    [0.003, 0.003]
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

ATTEMPT_BIN_M = 0.0005
"""Arc-length bin of ``path_dev_attempted_mm`` [m] (0.5 mm; coarser for paths over 10 cm:
at most 200 bins)."""

DEFAULT_PATH_TOLERANCE = 0.002
"""Radius of the tolerance tube around the planned path [m] (protocol ``path_tolerance_m``)."""

PATH_POINT_COLUMNS: tuple[str, ...] = (
    "error_l1_mm_s", "path_dev_mean_mm", "path_dev_rms_mm", "path_dev_max_mm",
    "path_dev_out_frac",
)
"""Per-point columns added by :func:`point_path_deviation` (units in the names)."""

PATH_TRIAL_KEYS: tuple[str, ...] = (
    "path_dev_mean_mm", "path_dev_rms_mm", "path_dev_max_mm", "path_dev_out_frac",
    "error_l1_sum_mm_s", "final_error_mm", "overshoot_mm", "path_covered_frac",
    "path_dev_attempted_mm",
)
"""Per-trial keys of :func:`trial_path_deviation` (units in the names)."""


def segment_distances(x: ArrayLike, a: ArrayLike, b: ArrayLike) -> FloatArray:
    """Euclidean distance of each point x_j to the segment [a_j, b_j] [m].

    Args:
        x, a, b: (n, 3) positions [m], any common frame. A degenerate segment (a_j = b_j)
            gives the distance to that point.

    Returns:
        (n,) distances [m]; NaN where an input is NaN.

    Example:
        >>> segment_distances([[2.0, 1.0, 0.0]], [[0.0, 0.0, 0.0]], [[1.0, 0.0, 0.0]]).tolist()
        [1.4142135623730951]
    """
    xx, aa, bb = (np.asarray(v, dtype=np.float64).reshape(-1, 3) for v in (x, a, b))
    if not (xx.shape == aa.shape == bb.shape):
        raise ValueError(f"x, a, b must share a shape (n, 3), got {xx.shape}, {aa.shape}, "
                         f"{bb.shape}")
    ab = bb - aa
    den = (ab * ab).sum(axis=1)
    num = ((xx - aa) * ab).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)
    s = np.clip(s, 0.0, 1.0)
    d = xx - (aa + s[:, None] * ab)
    return np.sqrt((d * d).sum(axis=1))


def path_distances(x: ArrayLike, goal_index: ArrayLike, points: ArrayLike,
                   start: ArrayLike | None = None) -> FloatArray:
    """Distance [m] of each sample to the segment of its goal (module conventions).

    Args:
        x: (n, 3) tool-tip positions [m]. goal_index: (n,) logged goal index in [0, N].
        points: (N, 3) POIs [m]. start: (3,) tool start [m]; None: ``x(0)``.

    Returns:
        (n,) distances [m]; NaN for rows with goal N (no segment).

    Example:
        >>> pts = [[0.01, 0.0, 0.0], [0.02, 0.0, 0.0]]
        >>> path_distances([[0.005, 0.001, 0], [0.015, -0.002, 0]], [0, 1], pts,
        ...                start=[0, 0, 0]).round(6).tolist()
        [0.001, 0.002]
    """
    xx = np.asarray(x, dtype=np.float64).reshape(-1, 3)
    gi = np.asarray(goal_index, dtype=np.int64).reshape(-1)
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if gi.shape[0] != xx.shape[0]:
        raise ValueError(f"goal_index must have shape ({xx.shape[0]},), got {gi.shape}")
    n_pts = p.shape[0]
    if xx.shape[0] == 0 or n_pts == 0:
        return np.full(xx.shape[0], np.nan)
    s0 = xx[0] if start is None else np.asarray(start, dtype=np.float64).reshape(3)
    nodes = np.vstack([s0[None, :], p])           # nodes[i] = p_(i-1), nodes[i+1] = p_i
    active = gi < n_pts
    out = np.full(xx.shape[0], np.nan)
    g = gi[active]
    xa = xx[active]
    own = segment_distances(xa, nodes[g], nodes[g + 1])
    before = segment_distances(xa, nodes[np.maximum(g - 1, 0)], nodes[g])
    out[active] = np.minimum(own, before)
    return out


def _nodes(x: FloatArray, points: ArrayLike, start: ArrayLike | None) -> FloatArray:
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    s0 = x[0] if start is None else np.asarray(start, dtype=np.float64).reshape(3)
    return np.vstack([s0[None, :], p])


def path_progress(x: ArrayLike, goal_index: ArrayLike, points: ArrayLike,
                  start: ArrayLike | None = None) -> tuple[FloatArray, float]:
    """Each sample's progress along the planned path [m] and the path's length [m]
    (module conventions).

    Args: as :func:`path_distances`.

    Returns:
        ``(s, length)``: ``s`` (n,) arc length [m] of the sample's projection onto the
        segment of its goal (``length`` for rows with goal N); ``length`` the polyline's
        length ``start -> p_0 -> ... -> p_(N-1)``.

    Example:
        >>> pts = [[0.01, 0.0, 0.0], [0.01, 0.01, 0.0]]
        >>> s, L = path_progress([[0.004, 0.003, 0], [0.02, 0.002, 0], [0, 0, 0]], [0, 1, 2],
        ...                      pts, start=[0, 0, 0])
        >>> s.round(6).tolist(), round(L, 6)
        ([0.004, 0.012, 0.02], 0.02)
    """
    xx = np.asarray(x, dtype=np.float64).reshape(-1, 3)
    gi = np.asarray(goal_index, dtype=np.int64).reshape(-1)
    if gi.shape[0] != xx.shape[0]:
        raise ValueError(f"goal_index must have shape ({xx.shape[0]},), got {gi.shape}")
    n_pts = np.asarray(points, dtype=np.float64).reshape(-1, 3).shape[0]
    if xx.shape[0] == 0 or n_pts == 0:
        return np.zeros(xx.shape[0]), 0.0
    nodes = _nodes(xx, points, start)
    seg = np.linalg.norm(np.diff(nodes, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    length = float(cum[-1])
    g = np.clip(gi, 0, n_pts)
    out = np.full(xx.shape[0], length)
    active = g < n_pts
    ga = g[active]
    a, b = nodes[ga], nodes[ga + 1]
    ab = b - a
    den = (ab * ab).sum(axis=1)
    num = ((xx[active] - a) * ab).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.where(den > 0, num / np.where(den > 0, den, 1.0), 1.0)
    out[active] = cum[ga] + np.clip(np.nan_to_num(u, nan=0.0), 0.0, 1.0) * seg[ga]
    return out, length


def attempted_deviation(progress: ArrayLike, distance: ArrayLike,
                        bin_m: float = ATTEMPT_BIN_M, max_bins: int = 200) -> float:
    """Mean distance from the path along the attempted part ``[0, max(progress)]`` [same
    unit as ``distance``] (module conventions: arc-length bins, empty bins interpolated;
    NaN when nothing was attempted or no sample has a distance).

    Example:
        >>> round(attempted_deviation([0.0, 0.0, 0.0, 0.01], [0.0, 0.0, 0.0, 2.0]), 6)
        1.0
        >>> attempted_deviation([0.0, 0.0], [0.0, 0.0])
        nan
    """
    s = np.asarray(progress, dtype=np.float64).reshape(-1)
    d = np.asarray(distance, dtype=np.float64).reshape(-1)
    ok = np.isfinite(s) & np.isfinite(d)
    s, d = s[ok], d[ok]
    if s.size == 0 or not float(s.max()) > 0.0:
        return math.nan
    s_max = float(s.max())
    n_bins = max(1, min(max_bins, math.ceil(s_max / bin_m)))
    k = np.minimum((s / s_max * n_bins).astype(np.int64), n_bins - 1)
    sums = np.bincount(k, weights=d, minlength=n_bins)
    counts = np.bincount(k, minlength=n_bins)
    filled = counts > 0
    centres = (np.arange(n_bins) + 0.5) / n_bins
    values = np.interp(centres, centres[filled], sums[filled] / counts[filled])
    return float(values.mean())


def _weighted(d: FloatArray, w: FloatArray, tolerance: float) -> tuple[float, float, float,
                                                                      float]:
    """(mean, RMS, max [same unit as d], fraction of weight with d > tolerance)."""
    if d.size == 0:
        return math.nan, math.nan, math.nan, math.nan
    tot = float(w.sum())
    if not tot > 0:
        w = np.ones_like(d)
        tot = float(d.size)
    mean = float((d * w).sum() / tot)
    rms = math.sqrt(float((d * d * w).sum() / tot))
    return mean, rms, float(d.max()), float(w[d > tolerance].sum() / tot)


def _durations(t: ArrayLike, n: int, t_start: float) -> FloatArray:
    tt = np.asarray(t, dtype=np.float64).reshape(-1)
    if tt.shape[0] != n:
        raise ValueError(f"t must have shape ({n},), got {tt.shape}")
    if n == 0:
        return np.zeros(0)
    return np.diff(tt, prepend=float(t_start))


def _prepared(t: ArrayLike, x: ArrayLike, g: ArrayLike, goal_index: ArrayLike,
              points: ArrayLike, start: ArrayLike | None, t_start: float, tolerance: float,
              ) -> tuple[FloatArray, FloatArray, NDArray[np.int64], int, FloatArray, FloatArray]:
    """The samples as arrays — x, g (n, 3), goal index (n,), the number of POIs, each
    sample's duration w and its distance d to the path — after checking ``tolerance``."""
    if not tolerance >= 0:
        raise ValueError(f"tolerance must be >= 0 m, got {tolerance!r}")
    xx = np.asarray(x, dtype=np.float64).reshape(-1, 3)
    gg = np.asarray(g, dtype=np.float64).reshape(-1, 3)
    gi = np.asarray(goal_index, dtype=np.int64).reshape(-1)
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    w = _durations(t, xx.shape[0], t_start)
    return xx, gg, gi, p.shape[0], w, path_distances(xx, gi, p, start)


def point_path_deviation(
    t: ArrayLike, x: ArrayLike, g: ArrayLike, goal_index: ArrayLike, points: ArrayLike, *,
    start: ArrayLike | None = None, tolerance: float = DEFAULT_PATH_TOLERANCE,
    t_start: float = 0.0,
) -> dict[str, FloatArray]:
    """Per-point path deviation and rate-independent e_i (module conventions).

    Args:
        t: (n,) sample times since trial start [s]. x: (n, 3) tool tip [m].
        g: (n, 3) logged goals [m]. goal_index: (n,) in [0, N]. points: (N, 3) POIs [m].
        start: (3,) tool start [m] (None: ``x(0)``). tolerance: tube radius [m].
        t_start: trial start [s].

    Returns:
        dict column -> (N,) array for ``PATH_POINT_COLUMNS`` [mm, mm s, fraction]; NaN for a
        point without samples.

    Raises:
        ValueError: on a negative tolerance or inconsistent shapes.
    """
    xx, gg, gi, n_pts, w, d = _prepared(t, x, g, goal_index, points, start, t_start,
                                        tolerance)
    err = np.abs(xx - gg).sum(axis=1)
    out = {c: np.full(n_pts, np.nan) for c in PATH_POINT_COLUMNS}
    for i in range(n_pts):
        rows = gi == i
        if not rows.any():
            continue
        mean, rms, mx, frac = _weighted(d[rows], w[rows], tolerance)
        out["error_l1_mm_s"][i] = 1000.0 * float((err[rows] * w[rows]).sum())
        out["path_dev_mean_mm"][i] = 1000.0 * mean
        out["path_dev_rms_mm"][i] = 1000.0 * rms
        out["path_dev_max_mm"][i] = 1000.0 * mx
        out["path_dev_out_frac"][i] = frac
    return out


def trial_path_deviation(
    t: ArrayLike, x: ArrayLike, g: ArrayLike, goal_index: ArrayLike, points: ArrayLike, *,
    start: ArrayLike | None = None, tolerance: float = DEFAULT_PATH_TOLERANCE,
    t_start: float = 0.0,
) -> dict[str, float]:
    """Per-trial path deviation, rate-independent e sum and point-targeting errors.

    Args: as :func:`point_path_deviation`.

    Returns:
        dict with ``PATH_TRIAL_KEYS``: ``path_dev_mean_mm``, ``path_dev_rms_mm``,
        ``path_dev_max_mm`` [mm] and ``path_dev_out_frac`` [0..1] over every sample with a
        goal; ``error_l1_sum_mm_s`` [mm s] (sum over points of ``error_l1_mm_s``);
        ``final_error_mm``, ``overshoot_mm`` [mm] for a single-POI (point-targeting) task,
        NaN otherwise; ``path_covered_frac`` [0..1] (largest progress over the path's
        length) and ``path_dev_attempted_mm`` [mm] (mean distance along the attempted part;
        NaN when nothing was attempted).

    Example:
        >>> import numpy as np
        >>> t = np.arange(1, 11) * 0.1
        >>> x = np.column_stack([np.linspace(0, 0.009, 10), np.full(10, 0.001), 0 * t])
        >>> m = trial_path_deviation(t, x, [[0.01, 0, 0]] * 10, [0] * 10, [[0.01, 0, 0]],
        ...                          start=[0, 0, 0])
        >>> round(m["path_dev_mean_mm"], 9), round(m["path_dev_max_mm"], 9)
        (1.0, 1.0)
    """
    xx, gg, gi, n_pts, w, d = _prepared(t, x, g, goal_index, points, start, t_start,
                                        tolerance)
    active = gi < n_pts
    mean, rms, mx, frac = _weighted(d[active], w[active], tolerance)
    err = np.abs(xx - gg).sum(axis=1)
    out = {
        "path_dev_mean_mm": 1000.0 * mean, "path_dev_rms_mm": 1000.0 * rms,
        "path_dev_max_mm": 1000.0 * mx, "path_dev_out_frac": frac,
        "error_l1_sum_mm_s": 1000.0 * float((err[active] * w[active]).sum())
        if active.any() else math.nan,
        "final_error_mm": math.nan, "overshoot_mm": math.nan,
        "path_covered_frac": math.nan, "path_dev_attempted_mm": math.nan,
    }
    progress, length = path_progress(xx, gi, points, start)
    if progress.size and length > 0:
        out["path_covered_frac"] = float(progress.max()) / length
        out["path_dev_attempted_mm"] = 1000.0 * attempted_deviation(progress[active],
                                                                    d[active])
    if n_pts == 1 and xx.shape[0]:
        target = np.asarray(points, dtype=np.float64).reshape(-1, 3)[-1]
        s0 = xx[0] if start is None else np.asarray(start, dtype=np.float64).reshape(3)
        u = target - s0
        nu = float(np.linalg.norm(u))
        out["final_error_mm"] = 1000.0 * float(np.linalg.norm(xx[-1] - target))
        if nu > 0:
            along = (xx - target) @ (u / nu)
            out["overshoot_mm"] = 1000.0 * max(0.0, float(np.nanmax(along)))
    return out


__all__ = [
    "ATTEMPT_BIN_M",
    "DEFAULT_PATH_TOLERANCE",
    "PATH_POINT_COLUMNS",
    "PATH_TRIAL_KEYS",
    "attempted_deviation",
    "path_distances",
    "path_progress",
    "point_path_deviation",
    "segment_distances",
    "trial_path_deviation",
]
