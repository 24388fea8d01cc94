"""Per-point and per-trial metrics of a trajectory-following trial (spec/study.md §2, eq. 6.5).

Pure functions of the logged samples; nothing here touches the store or the clock.

Conventions (**decisions**, the seed leaves them open; they match ``vasim.trials.vf``):

* **Logged goal.** Row j holds ``x(j)`` and the goal *in force when x(j) was compared with
  it*: ``goal_index[j] = i``, ``g(j) = p_i``. If ``|x(j) - p_i| <= r_reach`` the goal
  advances *after* row j is logged, so the next row has ``goal_index = i + 1``.
  ``goal_index`` is non-decreasing and lies in ``[0, N]`` (a runner may log ``N`` = "all
  reached" after completion; such rows belong to no point).
* **Reach time.** ``t_i`` (``t_reached``) is the time of the first sample with
  ``|x - p_i| <= r_reach``, i.e. the step at which the goal advanced past i. From the log:
  the sample just before the first sample whose ``goal_index > i`` (where the goal index
  changes). The last goal of the log has no later change; it counts as reached if one of its
  samples is within ``r_reach`` of its goal (Euclidean, ``|x(j) - g(j)|``), at the first such
  sample. A point with neither is *unreached*: ``t_reached = NaN``.
* **Latency.** ``l_i = t_i - t_(i-1)`` with ``t_(-1) = t_start`` (the trial start, ``t = 0``
  by default, since ``t`` is time since trial start). An unreached point has
  ``latency = NaN``.
* **Eq. 6.5's e_i** (the seed's "cumulative error"; a distance summed over samples, not an
  error of accuracy). ``e_i = sum over rows j with goal_index[j] == i of ||x(j) - g(j)||_1``
  (the reaching sample included). For a static point ``g(j) == p_i`` and this is eq. 6.5
  verbatim; for POIs riding on moving tissue it is the error to where the point was at step
  j.
* **Path length of point i.** The displacement ``x(j) - x(j-1)`` happens during step j, so it
  is charged to ``goal_index[j]``: point i's path runs from the sample that reached point
  i-1 to the sample that reached point i (the motion before the first sample is not
  logged). ``path_l1`` sums Manhattan, ``path_l2`` Euclidean step lengths [m].
* **No data.** An unreached point with no sample (never targeted) gets ``NaN`` error and
  path; the unreached *current* point of an interrupted trial keeps its partial sums
  (flagged by ``reached = False``).
* NaN in ``x`` or ``g`` (e.g. a device dropout) propagates into the sums of its point.

Example:
    >>> import numpy as np
    >>> t = np.array([0.25, 0.5, 0.75, 1.0])
    >>> x = np.array([[1, 0, 0], [2, 0, 0], [2, 0.5, 0], [2, 1, 0]])
    >>> g = np.array([[2, 0, 0], [2, 0, 0], [2, 1, 0], [2, 1, 0]], dtype=float)
    >>> df = point_metrics(t, x, g, [0, 0, 1, 1], points=2, r_reach=0.25)
    >>> df[["t_reached", "error_l1", "latency", "path_l1"]].to_numpy().tolist()
    [[0.5, 1.0, 0.5, 1.0], [1.0, 0.5, 0.5, 1.0]]
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from vasim.records.path_deviation import (
    DEFAULT_PATH_TOLERANCE,
    PATH_POINT_COLUMNS,
    PATH_TRIAL_KEYS,
    point_path_deviation,
    trial_path_deviation,
)
from vasim.tasks.base import DEFAULT_REACH_RADIUS as DEFAULT_REACH_RADIUS

POINT_COLUMNS: tuple[str, ...] = (
    "point", "reached", "t_reached", "error_l1", "latency", "path_l1", "path_l2", "n_samples",
    *PATH_POINT_COLUMNS,
)
"""Columns of ``point_metrics``, in order:

* ``point`` (int64): trajectory point index i, 0..N-1.
* ``reached`` (bool): the point was reached.
* ``t_reached`` (float64) [s]: reach time t_i since trial start, NaN if unreached.
* ``error_l1`` (float64) [m summed over samples, "m·sample"]: eq. 6.5's e_i exactly, the
  Manhattan distance to the next point of interest summed over samples (a sum over
  samples, so it grows with the logging rate and with
  the time spent on the way to p_i: it is not a length; divide by ``n_samples`` for a mean
  error in m).
* ``latency`` (float64) [s]: l_i = t_i - t_(i-1), NaN if unreached.
* ``path_l1``, ``path_l2`` (float64) [m]: Manhattan / Euclidean path length while the goal
  was point i.
* ``n_samples`` (int64): samples logged with goal_index == i.
* ``error_l1_mm_s`` (float64) [mm s]: the rate-independent e_i, ``sum_j ||x(j) - g(j)||_1
  w_j`` (eq. 6.5 times the sample period; ``vasim.records.path_deviation``).
* ``path_dev_mean_mm``, ``path_dev_rms_mm``, ``path_dev_max_mm`` (float64) [mm]: time mean,
  RMS and maximum distance of the tool tip to the planned path segment [p_(i-1), p_i]
  while p_i was the goal (independent of speed).
* ``path_dev_out_frac`` (float64) [0..1]: fraction of that time outside the tolerance tube.

The path-deviation columns are NaN when ``points`` is given as a count (no geometry); every
path column is NaN for a point without samples.
"""

SUMMARY_KEYS: tuple[str, ...] = (
    "n_points", "points_reached", "completed", "completion_time", "total_error_l1",
    "mean_latency", "total_path_l1", "total_path_l2", "duration", *PATH_TRIAL_KEYS,
)
"""Keys of ``trial_summary``; see its docstring."""


def _n_points(points: ArrayLike | int) -> int:
    if isinstance(points, (int, np.integer)) and not isinstance(points, bool):
        if points < 0:
            raise ValueError(f"n_points must be >= 0, got {points!r}")
        return int(points)
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points must be an int N or an (N, 3) array, got shape {p.shape}")
    return int(p.shape[0])


def _goal_index(goal_index: ArrayLike, n_points: int, n: int | None = None) -> NDArray[np.int64]:
    gi = np.asarray(goal_index)
    if gi.ndim != 1 or (n is not None and gi.shape[0] != n):
        raise ValueError(f"goal_index must have shape ({n if n is not None else 'n'},), "
                         f"got {gi.shape}")
    if gi.size and not np.issubdtype(gi.dtype, np.integer):
        if not np.all(np.isfinite(gi)) or np.any(gi != np.round(gi)):
            raise ValueError("goal_index must hold integers")
    gi = gi.astype(np.int64, copy=False)
    if gi.size:
        lo, hi = int(gi.min()), int(gi.max())
        if lo < 0 or hi > n_points:
            raise ValueError(f"goal_index must lie in [0, {n_points}], got values in [{lo}, {hi}]")
        steps = np.diff(gi)
        if np.any(steps < 0):
            j = int(np.argmax(steps < 0)) + 1
            raise ValueError(
                f"goal_index must be non-decreasing; it goes from {int(gi[j - 1])} to "
                f"{int(gi[j])} at sample {j}"
            )
    return gi


def _vec_track(name: str, a: ArrayLike, n: int) -> NDArray[np.float64]:
    arr = np.asarray(a, dtype=np.float64)
    if arr.shape != (n, 3):
        raise ValueError(f"{name} must have shape ({n}, 3), got {arr.shape}")
    return arr


def reach_indices(
    x: ArrayLike,
    g: ArrayLike,
    goal_index: ArrayLike,
    points: ArrayLike | int,
    *,
    r_reach: float = DEFAULT_REACH_RADIUS,
) -> NDArray[np.int64]:
    """Returns, per point, the index of the sample that reached it (see the conventions).

    Point i's reaching sample is the one just before the first sample with
    ``goal_index > i`` (where the logged goal index changes); for the last goal of the log,
    the first of its samples with ``|x - g| <= r_reach``.

    Args:
        x: (n, 3) TCP positions [m]. g: (n, 3) logged goal points [m].
        goal_index: (n,) logged goal index, non-decreasing, in [0, N].
        points: (N, 3) trajectory points [m], or just N.
        r_reach: reach radius [m] (the protocol's; used for the last goal only).

    Returns:
        (N,) int64 sample indices, -1 for an unreached point.

    Raises:
        ValueError: on inconsistent shapes or an invalid goal_index.

    Example:
        >>> x = [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0.1]]
        >>> g = [[0, 0, 0], [0, 0, 0.1], [0, 0, 0.1], [0, 0, 0.1]]
        >>> reach_indices(x, g, [0, 1, 1, 1], points=3, r_reach=0.01).tolist()
        [0, 3, -1]
    """
    N = _n_points(points)
    gi = _goal_index(goal_index, N)
    n = gi.shape[0]
    xx = _vec_track("x", x, n)
    gg = _vec_track("g", g, n)
    if not r_reach >= 0:
        raise ValueError(f"r_reach must be >= 0 [m], got {r_reach!r}")
    first_after = np.searchsorted(gi, np.arange(N), side="right")  # first j with gi[j] > i
    idx = (first_after - 1).astype(np.int64)
    idx[first_after >= n] = -1
    if n and gi[-1] < N:
        last = int(gi[-1])
        rows = np.flatnonzero(gi == last)
        d = xx[rows] - gg[rows]
        inside = np.flatnonzero((d * d).sum(axis=1) <= r_reach * r_reach)
        if inside.size:
            idx[last] = rows[inside[0]]
    return idx


def reach_times(
    t: ArrayLike,
    x: ArrayLike,
    g: ArrayLike,
    goal_index: ArrayLike,
    points: ArrayLike | int,
    *,
    r_reach: float = DEFAULT_REACH_RADIUS,
) -> NDArray[np.float64]:
    """Returns the reach time t_i [s] of each point, NaN where unreached.

    Args:
        t: (n,) sample times since trial start [s]; the rest as ``reach_indices``.

    Returns:
        (N,) float64 reach times.

    Example:
        >>> x = [[0, 0, 0], [0, 0, 0], [0, 0, 0.05]]
        >>> g = [[0, 0, 0], [0, 0, 0.1], [0, 0, 0.1]]
        >>> reach_times([0.5, 1.0, 1.5], x, g, [0, 1, 1], points=2, r_reach=0.01).tolist()
        [0.5, nan]
    """
    idx = reach_indices(x, g, goal_index, points, r_reach=r_reach)
    tt = np.asarray(t, dtype=np.float64)
    if tt.shape != (np.asarray(goal_index).shape[0],):
        raise ValueError(f"t must have the shape of goal_index, got {tt.shape}")
    out = np.full(idx.shape[0], np.nan)
    ok = idx >= 0
    out[ok] = tt[idx[ok]]
    return out


def path_lengths(x: ArrayLike) -> tuple[float, float]:
    """Returns the total (Manhattan, Euclidean) path length [m] of a (n, 3) TCP track.

    Example:
        >>> path_lengths([[0, 0, 0], [3, 4, 0]])
        (7.0, 5.0)
    """
    xx = np.asarray(x, dtype=np.float64)
    if xx.ndim != 2 or xx.shape[1] != 3:
        raise ValueError(f"x must have shape (n, 3), got {xx.shape}")
    if xx.shape[0] < 2:
        return 0.0, 0.0
    d = np.diff(xx, axis=0)
    return float(np.abs(d).sum()), float(np.sqrt((d * d).sum(axis=1)).sum())


def _point_path_lengths(xx: NDArray[Any], gi: NDArray[Any], N: int,
                        ) -> tuple[NDArray[Any], NDArray[Any]]:
    """Each point's (Manhattan, Euclidean) path length [m]: the motion of every step whose
    goal (the goal index of the step's end sample) is that point."""
    path_l1: NDArray[Any] = np.zeros(N)  # float64 (np.bincount with weights)
    path_l2: NDArray[Any] = np.zeros(N)
    if xx.shape[0] >= 2:
        d = np.diff(xx, axis=0)  # d[j-1] = x(j) - x(j-1), the motion of step j
        seg_goal = gi[1:]
        seg = seg_goal < N
        path_l1 = np.bincount(seg_goal[seg], weights=np.abs(d[seg]).sum(axis=1), minlength=N)[:N]
        path_l2 = np.bincount(
            seg_goal[seg], weights=np.sqrt((d[seg] * d[seg]).sum(axis=1)), minlength=N
        )[:N]
    return path_l1, path_l2


def point_metrics(
    t: ArrayLike,
    x: ArrayLike,
    g: ArrayLike,
    goal_index: ArrayLike,
    points: ArrayLike | int,
    *,
    r_reach: float = DEFAULT_REACH_RADIUS,
    t_reached: ArrayLike | None = None,
    t_start: float = 0.0,
    start: ArrayLike | None = None,
    tolerance: float = DEFAULT_PATH_TOLERANCE,
) -> pd.DataFrame:
    """Per-point metrics of one trial (eq. 6.5), as a tidy DataFrame.

    Args:
        t: (n,) sample times since trial start [s].
        x: (n, 3) TCP positions x(j) [m].
        g: (n, 3) logged goal points g(j) [m] (see the module conventions).
        goal_index: (n,) logged goal index, non-decreasing, in [0, N].
        points: (N, 3) trajectory points p_i [m], or just N (only the count is used: errors
            are taken against the logged ``g``).
        r_reach: reach radius [m]; pass the task's (``Task.reach_radius``). Only decides
            whether the last goal of the log was reached.
        t_reached: (N,) reach times [s] recorded by the runner (NaN = unreached); derived
            with ``reach_times`` when omitted.
        t_start: trial start [s], the reference of the first latency (t_(-1)).
        start: (3,) the tool's start position [m], first node of the planned path (None:
            the first sample); used only when ``points`` is an array.
        tolerance: radius of the tolerance tube of ``path_dev_out_frac`` [m].

    Returns:
        DataFrame with one row per point and the columns ``POINT_COLUMNS``.

    Raises:
        ValueError: on inconsistent shapes or an invalid goal_index.
    """
    tt = np.asarray(t, dtype=np.float64)
    if tt.ndim != 1:
        raise ValueError(f"t must have shape (n,), got {tt.shape}")
    n = tt.shape[0]
    xx = _vec_track("x", x, n)
    gg = _vec_track("g", g, n)
    N = _n_points(points)
    gi = _goal_index(goal_index, N, n)

    if t_reached is None:
        tr = reach_times(tt, xx, gg, gi, N, r_reach=r_reach)
    else:
        tr = np.asarray(t_reached, dtype=np.float64)
        if tr.shape != (N,):
            raise ValueError(f"t_reached must have shape ({N},), got {tr.shape}")
    reached = ~np.isnan(tr)

    active = gi < N  # rows whose goal is a real point (not "all reached")
    err = np.abs(xx - gg).sum(axis=1)
    error_l1 = np.bincount(gi[active], weights=err[active], minlength=N)[:N]
    n_samples = np.bincount(gi[active], minlength=N)[:N].astype(np.int64)

    path_l1, path_l2 = _point_path_lengths(xx, gi, N)

    prev = np.concatenate(([float(t_start)], tr[:-1])) if N else np.empty(0)
    latency = tr - prev  # NaN wherever this (hence also the next) point is unreached

    no_data = ~reached & (n_samples == 0)
    error_l1 = np.where(no_data, np.nan, error_l1)
    path_l1 = np.where(no_data, np.nan, path_l1)
    path_l2 = np.where(no_data, np.nan, path_l2)

    if isinstance(points, (int, np.integer)):  # no planned path: only e_i [mm s]
        path = {c: np.full(N, np.nan) for c in PATH_POINT_COLUMNS}
        w = np.diff(tt, prepend=float(t_start)) if n else np.zeros(0)
        path["error_l1_mm_s"] = 1000.0 * np.bincount(
            gi[active], weights=(err * w)[active], minlength=N)[:N]
    else:
        path = point_path_deviation(tt, xx, gg, gi, points, start=start, tolerance=tolerance,
                                    t_start=t_start)
    path["error_l1_mm_s"] = np.where(no_data, np.nan, path["error_l1_mm_s"])
    return pd.DataFrame(
        {
            "point": np.arange(N, dtype=np.int64),
            "reached": reached.astype(bool),
            "t_reached": tr,
            "error_l1": error_l1.astype(np.float64),
            "latency": latency.astype(np.float64),
            "path_l1": path_l1.astype(np.float64),
            "path_l2": path_l2.astype(np.float64),
            "n_samples": n_samples,
            **path,
        },
        columns=list(POINT_COLUMNS),
    )


def trial_summary(
    points: pd.DataFrame,
    *,
    duration: float | None = None,
    path_l1: float | None = None,
    path_l2: float | None = None,
    path_deviation: dict[str, float] | None = None,
) -> dict[str, Any]:
    """Per-trial summary of a ``point_metrics`` frame.

    Args:
        points: the output of ``point_metrics``.
        duration: the trial's logged duration [s] (e.g. the last sample time); NaN if None.
        path_l1, path_l2: whole-trial path lengths [m] (``path_lengths(x)``); when None, the
            sums of the per-point paths.
        path_deviation: ``path_deviation.trial_path_deviation`` of the trial; its keys
            (``PATH_TRIAL_KEYS``) are NaN when None.

    Returns:
        dict with keys ``SUMMARY_KEYS``, plain Python numbers:
        ``n_points`` (int), ``points_reached`` (int), ``completed`` (bool: every point
        reached), ``completion_time`` [s] (reach time of the last point, NaN unless
        completed), ``total_error_l1`` [m·sample] (sum of e_i over points with data; a sum
        of per-sample distances, not a length),
        ``mean_latency`` [s] (mean l_i over reached points, NaN if none),
        ``total_path_l1``, ``total_path_l2`` [m], ``duration`` [s], then
        ``PATH_TRIAL_KEYS`` (path deviation [mm], ``error_l1_sum_mm_s`` [mm s], final error
        and overshoot of point targeting [mm]).

    Example:
        >>> import pandas as pd
        >>> df = point_metrics([1.0, 2.0], [[0, 0, 0], [1, 0, 0]], [[1, 0, 0]] * 2,
        ...                    [0, 0], points=1, r_reach=0.1)
        >>> s = trial_summary(df)
        >>> s["completed"], s["completion_time"], s["total_error_l1"], s["mean_latency"]
        (True, 2.0, 1.0, 2.0)
    """
    missing = [c for c in POINT_COLUMNS if c not in points.columns]
    if missing:
        raise ValueError(f"points lacks the point_metrics columns {missing}")
    n_points = len(points)
    reached = points["reached"].to_numpy(dtype=bool)
    n_reached = int(reached.sum())
    completed = n_points > 0 and n_reached == n_points
    t_reached = points["t_reached"].to_numpy(dtype=np.float64)
    latency = points["latency"].to_numpy(dtype=np.float64)

    def _nansum(col: str) -> float:
        v = points[col].to_numpy(dtype=np.float64)
        return float(np.nansum(v)) if n_points else 0.0

    lat = latency[reached]
    dev = None if path_deviation is None else dict(path_deviation)
    if dev is not None and completed:
        # Every point reached is the whole path covered: the last point counts as reached
        # within r_reach of it, before the tool's projection gets to the path's end.
        dev["path_covered_frac"] = 1.0
    return {
        "n_points": n_points,
        "points_reached": n_reached,
        "completed": bool(completed),
        "completion_time": float(t_reached[-1]) if completed else math.nan,
        "total_error_l1": _nansum("error_l1"),
        "mean_latency": float(lat.mean()) if lat.size else math.nan,
        "total_path_l1": _nansum("path_l1") if path_l1 is None else float(path_l1),
        "total_path_l2": _nansum("path_l2") if path_l2 is None else float(path_l2),
        "duration": math.nan if duration is None else float(duration),
        **{k: math.nan if dev is None else float(dev[k]) for k in PATH_TRIAL_KEYS},
        "error_l1_sum_mm_s": _nansum("error_l1_mm_s"),   # needs no geometry
    }


def evaluate_trial(
    t: ArrayLike,
    x: ArrayLike,
    g: ArrayLike,
    goal_index: ArrayLike,
    points: ArrayLike | int,
    *,
    r_reach: float = DEFAULT_REACH_RADIUS,
    t_reached: ArrayLike | None = None,
    t_start: float = 0.0,
    start: ArrayLike | None = None,
    tolerance: float = DEFAULT_PATH_TOLERANCE,
) -> tuple[pd.DataFrame, dict[str, Any]]:
    """``point_metrics`` plus ``trial_summary`` with whole-trial path and duration.

    ``duration`` is the last sample time minus ``t_start`` (0 for an empty trial); the total
    paths cover the whole recording (``path_lengths(x)``), including any motion logged after
    the last point was reached. With ``points`` an array, the path-deviation measures of
    ``vasim.records.path_deviation`` (planned path from ``start``, tube radius ``tolerance``
    [m]) fill the path columns and summary keys.

    Example:
        >>> df, s = evaluate_trial([0.5, 1.0], [[0, 0, 0], [0, 0, 1]], [[0, 0, 1]] * 2,
        ...                        [0, 0], points=1, r_reach=0.1)
        >>> s["completed"], s["completion_time"], s["duration"], s["total_path_l1"]
        (True, 1.0, 1.0, 1.0)
    """
    df = point_metrics(t, x, g, goal_index, points, r_reach=r_reach, t_reached=t_reached,
                       t_start=t_start, start=start, tolerance=tolerance)
    tt = np.asarray(t, dtype=np.float64)
    xx = np.asarray(x, dtype=np.float64).reshape(-1, 3)
    l1, l2 = path_lengths(xx)
    duration = float(tt[-1] - t_start) if tt.size else 0.0
    dev = None
    if not isinstance(points, (int, np.integer)):
        dev = trial_path_deviation(tt, xx, g, goal_index, points, start=start,
                                   tolerance=tolerance, t_start=t_start)
    return df, trial_summary(df, duration=duration, path_l1=l1, path_l2=l2,
                             path_deviation=dev)
