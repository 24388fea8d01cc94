"""Tests of the per-point trial metrics (vasim/records/point_metrics.py, spec/study.md §2 eq. 6.5).

The reference trial ``tiny_trial`` is computed by hand in the comments below.
"""

from __future__ import annotations

import doctest
import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import vasim.records.point_metrics as metrics_mod
from vasim.records.point_metrics import (
    POINT_COLUMNS,
    SUMMARY_KEYS,
    evaluate_trial,
    path_lengths,
    point_metrics,
    reach_indices,
    reach_times,
    trial_summary,
)

R = 0.25  # reach radius of the tiny trial [m] (numbers chosen exact in binary)
P = np.array([[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])  # p0, p1, p2


def tiny_trial():
    """10 samples, 3 points, dt = 0.5 s, t_j = 0.5 (j + 1) (the runner's t = (k+1) dt).

    Row j logs x(j) and the goal it was compared with (goal advances *after* the row):

      j   t    x                 gi  ||x - p_gi||_1        |x - p_gi|_2
      0  0.5  (0,   0,   0)      0   1                     1
      1  1.0  (0.5, 0,   0)      0   0.5                   0.5
      2  1.5  (1,   0,   0)      0   0      -> p0 reached  0
      3  2.0  (1,   0.5, 0)      1   0.5                   0.5
      4  2.5  (1.5, 0.5, 0)      1   0.5 + 0.5 = 1         0.707
      5  3.0  (1,   1,   0)      1   0      -> p1 reached  0
      6  3.5  (0.5, 1,   0.5)    2   0.5 + 0.5 = 1         0.707
      7  4.0  (0.5, 1,   0)      2   0.5                   0.5
      8  4.5  (0.5, 1,   0.25)   2   0.5 + 0.25 = 0.75     0.559 > R: not reached
      9  5.0  (0,   1,   0)      2   0      -> p2 reached  0
    """
    t = 0.5 * (np.arange(10) + 1)
    x = np.array([
        [0, 0, 0], [0.5, 0, 0], [1, 0, 0],
        [1, 0.5, 0], [1.5, 0.5, 0], [1, 1, 0],
        [0.5, 1, 0.5], [0.5, 1, 0], [0.5, 1, 0.25], [0, 1, 0],
    ], dtype=float)
    gi = np.array([0, 0, 0, 1, 1, 1, 2, 2, 2, 2])
    return t, x, P[gi], gi


# Hand-computed metrics of tiny_trial:
#   e0 = 1 + 0.5 + 0 = 1.5;  e1 = 0.5 + 1 + 0 = 1.5;  e2 = 1 + 0.5 + 0.75 + 0 = 2.25
#   t_reached = t of the reaching rows 2, 5, 9 = 1.5, 3.0, 5.0
#   latency = 1.5 - 0 (trial start), 3.0 - 1.5, 5.0 - 3.0 = 1.5, 1.5, 2.0
#   steps x(j) - x(j-1), charged to gi[j]:
#     j1 (0.5,0,0) g0: L1 .5  L2 .5     j2 (0.5,0,0) g0: .5 .5        -> path0 = 1.0 | 1.0
#     j3 (0,0.5,0) g1: .5 .5   j4 (0.5,0,0) g1: .5 .5   j5 (-.5,.5,0) g1: 1.0 sqrt(.5)
#                                                                    -> path1 = 2.0 | 1 + sqrt(.5)
#     j6 (-.5,0,.5) g2: 1.0 sqrt(.5)   j7 (0,0,-.5): .5 .5   j8 (0,0,.25): .25 .25
#     j9 (-.5,0,-.25): .75 sqrt(.3125)          -> path2 = 2.5 | sqrt(.5) + .75 + sqrt(.3125)
#   n_samples = 3, 3, 4
EXPECTED = pd.DataFrame({
    "point": [0, 1, 2],
    "reached": [True, True, True],
    "t_reached": [1.5, 3.0, 5.0],
    "error_l1": [1.5, 1.5, 2.25],
    "latency": [1.5, 1.5, 2.0],
    "path_l1": [1.0, 2.0, 2.5],
    "path_l2": [1.0, 1 + math.sqrt(0.5), math.sqrt(0.5) + 0.75 + math.sqrt(0.3125)],
    "n_samples": [3, 3, 4],
    # rate-independent e_i = e_i x dt (0.5 s) [mm s]
    "error_l1_mm_s": [750.0, 750.0, 1125.0],
    # distance to the segment of the goal, start = x(0) = (0,0,0) [mm]:
    #   g0 (0,0,0)-(1,0,0): rows 0-2 on it -> 0, 0, 0
    #   g1 (1,0,0)-(1,1,0): rows 3-5 -> 0, 0.5 (x = 1.5), 0
    #   g2 (1,1,0)-(0,1,0): rows 6-9 -> 0.5 (z), 0, 0.25 (z), 0
    "path_dev_mean_mm": [0.0, 500.0 / 3, 187.5],
    "path_dev_rms_mm": [0.0, 1000 * math.sqrt(0.25 / 3), 1000 * math.sqrt(0.3125 / 4)],
    "path_dev_max_mm": [0.0, 500.0, 500.0],
    "path_dev_out_frac": [0.0, 1 / 3, 0.5],   # outside the 2 mm tube
})


def test_tiny_trial_by_hand():
    t, x, g, gi = tiny_trial()
    df = point_metrics(t, x, g, gi, P, r_reach=R)
    assert tuple(df.columns) == POINT_COLUMNS
    pd.testing.assert_frame_equal(df, EXPECTED.astype(df.dtypes.to_dict()), rtol=1e-12)
    assert df["point"].dtype == np.int64 and df["reached"].dtype == bool
    assert df["n_samples"].dtype == np.int64


def test_tiny_trial_summary_by_hand():
    t, x, g, gi = tiny_trial()
    df, s = evaluate_trial(t, x, g, gi, P, r_reach=R)
    assert tuple(s) == SUMMARY_KEYS
    assert s["n_points"] == 3 and s["points_reached"] == 3 and s["completed"] is True
    assert s["completion_time"] == 5.0
    assert s["total_error_l1"] == 5.25  # 1.5 + 1.5 + 2.25
    assert s["mean_latency"] == pytest.approx(5.0 / 3)  # (1.5 + 1.5 + 2) / 3
    assert s["total_path_l1"] == 5.5  # 1 + 2 + 2.5
    assert s["total_path_l2"] == pytest.approx(EXPECTED["path_l2"].sum())
    assert s["duration"] == 5.0
    # without the whole-trial extras, the path totals are the per-point sums
    assert trial_summary(df)["total_path_l1"] == 5.5 and math.isnan(trial_summary(df)["duration"])


def test_reach_derivation_by_hand():
    t, x, g, gi = tiny_trial()
    assert reach_indices(x, g, gi, P, r_reach=R).tolist() == [2, 5, 9]
    assert reach_times(t, x, g, gi, P, r_reach=R).tolist() == [1.5, 3.0, 5.0]
    # a smaller radius: row 9 is exactly on p2 (distance 0), still reached
    assert reach_indices(x, g, gi, 3, r_reach=0.0).tolist() == [2, 5, 9]
    # a larger radius reaches p2 already at row 7 (|x - p2| = 0.5; row 6 is at 0.707)
    assert reach_indices(x, g, gi, 3, r_reach=0.6).tolist() == [2, 5, 7]


def test_interrupted_trial_marks_unreached_points():
    t, x, g, gi = tiny_trial()
    # killed after row 6: p2 was the goal for one sample only
    df = point_metrics(t[:7], x[:7], g[:7], gi[:7], P, r_reach=R)
    assert df["reached"].tolist() == [True, True, False]
    assert df["t_reached"].tolist()[:2] == [1.5, 3.0] and math.isnan(df.at[2, "t_reached"])
    assert math.isnan(df.at[2, "latency"])
    assert df.at[2, "error_l1"] == 1.0 and df.at[2, "n_samples"] == 1  # partial, flagged
    assert df.at[2, "path_l1"] == 1.0  # the step into row 6
    s = trial_summary(df)
    assert s["completed"] is False and s["points_reached"] == 2
    assert math.isnan(s["completion_time"]) and s["mean_latency"] == 1.5


def test_timed_out_on_last_point_and_untargeted_points():
    t, x, g, gi = tiny_trial()
    # timed out after row 8: the last goal p2 never came within R
    df = point_metrics(t[:9], x[:9], g[:9], gi[:9], P, r_reach=R)
    assert df["reached"].tolist() == [True, True, False]
    assert df.at[2, "error_l1"] == 2.25 and df.at[2, "n_samples"] == 3
    # a 4-point task stopped after p2: p3 was never the goal -> no data (NaN), not zero
    df4 = point_metrics(t, x, g, gi, 4, r_reach=R)
    assert df4["reached"].tolist() == [True, True, True, False]
    # p2 still counts as reached at row 9: the last goal is judged by distance
    assert df4.at[2, "t_reached"] == 5.0
    row = df4.iloc[3]
    assert row["n_samples"] == 0 and math.isnan(row["error_l1"]) and math.isnan(row["path_l1"])
    assert trial_summary(df4)["total_error_l1"] == 5.25  # NaN rows are skipped


def test_rows_logged_after_completion_belong_to_no_point():
    t, x, g, gi = tiny_trial()
    # a runner that keeps logging with goal_index == N after the last point
    t2 = np.append(t, 5.5)
    x2 = np.vstack([x, [[0.0, 2.0, 0.0]]])  # one more step of L1 length 1
    g2 = np.vstack([g, [[np.nan] * 3]])  # g of a "done" row is not used
    gi2 = np.append(gi, 3)
    # with the points' geometry: the "done" row (1 m off the path) enters no path deviation
    df, s = evaluate_trial(t2, x2, g2, gi2, P, r_reach=R)
    pd.testing.assert_frame_equal(df, EXPECTED.astype(df.dtypes.to_dict()), rtol=1e-12)
    assert s["path_dev_max_mm"] == 500.0 and s["error_l1_sum_mm_s"] == 2625.0
    assert s["total_path_l1"] == 6.5 and s["duration"] == 5.5  # whole recording


def test_error_follows_a_moving_goal():
    # one point riding on tissue: g(j) moves, e is measured to where the point was
    t = np.array([1.0, 2.0, 3.0])
    x = np.zeros((3, 3))
    g = np.array([[0.5, 0, 0], [0.25, 0, 0], [0, 0, 0.125]])
    df = point_metrics(t, x, g, [0, 0, 0], 1, r_reach=0.2)
    # e0 = 0.5 + 0.25 + 0.125; reached at row 2 (|x - g| = 0.125 <= 0.2)
    assert df.at[0, "error_l1"] == 0.875 and df.at[0, "t_reached"] == 3.0


def test_several_points_reached_in_one_step():
    # goal jumps 0 -> 2 after row 1: p0 and p1 reached together at t = 0.2
    t = np.array([0.1, 0.2, 0.3])
    x = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1]], dtype=float)
    g = np.array([[1, 0, 0], [1, 0, 0], [1, 0, 1]], dtype=float)
    df = point_metrics(t, x, g, [0, 0, 2], 3, r_reach=0.1)
    assert df["t_reached"].tolist() == [0.2, 0.2, 0.3]
    assert df.at[1, "latency"] == 0.0 and df.at[1, "error_l1"] == 0.0  # zero, not NaN
    assert df.at[1, "path_l1"] == 0.0 and df.at[1, "n_samples"] == 0


def test_explicit_reach_times_and_t_start():
    t, x, g, gi = tiny_trial()
    df = point_metrics(t, x, g, gi, P, t_reached=[1.5, 3.0, np.nan], t_start=0.5)
    assert df["reached"].tolist() == [True, True, False]
    assert df["latency"].tolist()[:2] == [1.0, 1.5]


def test_empty_trial():
    df, s = evaluate_trial(np.empty(0), np.empty((0, 3)), np.empty((0, 3)), np.empty(0, int), 2)
    assert df["reached"].tolist() == [False, False] and df["n_samples"].tolist() == [0, 0]
    assert s["points_reached"] == 0 and s["total_path_l1"] == 0.0 and s["duration"] == 0.0
    assert math.isnan(s["mean_latency"])


@pytest.mark.parametrize(
    ("gi", "match"),
    [([0, 1, 0], "non-decreasing"), ([0, 4], r"\[0, 3\]"), ([-1, 0], r"\[0, 3\]"),
     ([0.5, 1.0], "integers")],
)
def test_bad_goal_index(gi, match):
    n = len(gi)
    with pytest.raises(ValueError, match=match):
        point_metrics(np.arange(n, dtype=float), np.zeros((n, 3)), np.zeros((n, 3)), gi, 3)


def test_bad_shapes():
    with pytest.raises(ValueError, match="x must have shape"):
        point_metrics([0.0, 1.0], np.zeros((2, 2)), np.zeros((2, 3)), [0, 0], 1)
    with pytest.raises(ValueError, match="goal_index must have shape"):
        point_metrics([0.0, 1.0], np.zeros((2, 3)), np.zeros((2, 3)), [0], 1)
    with pytest.raises(ValueError, match="points"):
        point_metrics([0.0], np.zeros((1, 3)), np.zeros((1, 3)), [0], np.zeros((2, 2)))
    with pytest.raises(ValueError, match="t_reached"):
        point_metrics([0.0], np.zeros((1, 3)), np.zeros((1, 3)), [0], 2, t_reached=[1.0])
    with pytest.raises(ValueError, match="r_reach"):
        reach_indices(np.zeros((1, 3)), np.zeros((1, 3)), [0], 1, r_reach=-1.0)


def test_path_lengths():
    assert path_lengths(np.zeros((1, 3))) == (0.0, 0.0)
    assert path_lengths([[0, 0, 0], [1, 2, 2], [1, 2, 2]]) == (5.0, 3.0)


# --------------------------------------------------------------------- properties
def naive_point_metrics(t, x, g, gi, n_points, r_reach):
    """Loop-by-loop reading of the documented conventions (the vectorised code's oracle)."""
    rows = []
    n = len(t)
    for i in range(n_points):
        rows_i = [j for j in range(n) if gi[j] == i]
        later = [j for j in range(n) if gi[j] > i]
        reach = None
        if later:
            reach = later[0] - 1
        elif n and gi[-1] == i:
            inside = [j for j in rows_i if np.linalg.norm(x[j] - g[j]) <= r_reach]
            reach = inside[0] if inside else None
        err = sum(float(np.abs(x[j] - g[j]).sum()) for j in rows_i)
        p1 = sum(float(np.abs(x[j] - x[j - 1]).sum()) for j in range(1, n) if gi[j] == i)
        p2 = sum(float(np.linalg.norm(x[j] - x[j - 1])) for j in range(1, n) if gi[j] == i)
        rows.append((reach, err, p1, p2, len(rows_i)))
    return rows


@st.composite
def random_trials(draw):
    n_points = draw(st.integers(1, 5))
    n = draw(st.integers(0, 30))
    steps = draw(st.lists(st.integers(0, 2), min_size=n, max_size=n))
    gi = np.minimum(np.cumsum(steps) - (steps[0] if n else 0), n_points).astype(int)
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    x = rng.normal(scale=0.01, size=(n, 3))
    pts = rng.normal(scale=0.01, size=(n_points + 1, 3))
    g = pts[gi]
    r = draw(st.sampled_from([0.0, 0.005, 0.02]))
    return np.arange(1, n + 1) * 1e-3, x, g, gi, n_points, r


@settings(max_examples=60, deadline=None)
@given(random_trials())
def test_vectorised_metrics_match_the_naive_loop(trial):
    t, x, g, gi, n_points, r = trial
    df = point_metrics(t, x, g, gi, n_points, r_reach=r)
    for i, (reach, err, p1, p2, ns) in enumerate(naive_point_metrics(t, x, g, gi, n_points, r)):
        row = df.iloc[i]
        assert row["reached"] == (reach is not None)
        assert row["n_samples"] == ns
        if reach is not None:
            assert row["t_reached"] == t[reach]
        if reach is None and ns == 0:
            assert math.isnan(row["error_l1"]) and math.isnan(row["path_l1"])
        else:
            assert row["error_l1"] == pytest.approx(err, abs=1e-15)
            assert row["path_l1"] == pytest.approx(p1, abs=1e-15)
            assert row["path_l2"] == pytest.approx(p2, abs=1e-15)
    # invariants: reach times never decrease; reached points form a prefix
    tr = df["t_reached"].to_numpy()
    reached = df["reached"].to_numpy()
    assert np.all(np.diff(tr[reached]) >= 0)
    assert not np.any(reached[1:] & ~reached[:-1])
    # all logged motion towards real goals is charged to some point
    if len(t) >= 2 and np.all(gi < n_points):
        assert np.nansum(df["path_l1"]) == pytest.approx(path_lengths(x)[0], abs=1e-12)


def test_docstring_examples_run():
    result = doctest.testmod(metrics_mod)
    assert result.failed == 0 and result.attempted > 0
