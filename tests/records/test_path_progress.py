"""Progress along the planned path and the deviation over the part attempted (issue #26 §6):
analytic cases on straight and bent paths, and the invariants (coverage in [0, 1], the
attempted deviation between the smallest and largest distance, NaN only when nothing was
attempted)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.records.path_deviation import (
    attempted_deviation,
    path_distances,
    path_progress,
    trial_path_deviation,
)
from vasim.records.point_metrics import evaluate_trial

START = np.zeros(3)
POINTS = np.array([[0.01, 0.0, 0.0], [0.02, 0.0, 0.0], [0.03, 0.0, 0.0], [0.04, 0.0, 0.0]])


def _along(x_end: float, n: int, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """Tool moving along +x from 0 to x_end at a constant lateral offset [m]; goal index
    as the runner advances it (a point within 0 mm is reached: the goal is the next point
    ahead)."""
    xs = np.linspace(0.0, x_end, n)
    x = np.column_stack([xs, np.full(n, offset), np.zeros(n)])
    gi = np.minimum(np.floor(xs / 0.01 + 1e-9).astype(int), len(POINTS))
    return x, gi


def test_a_tool_that_never_moves_covers_nothing_and_has_no_attempted_deviation() -> None:
    n = 1000
    x = np.zeros((n, 3))
    t = np.arange(1, n + 1) * 0.18
    m = trial_path_deviation(t, x, np.tile(POINTS[0], (n, 1)), np.zeros(n, int), POINTS,
                             start=START)
    assert m["path_covered_frac"] == 0.0
    assert math.isnan(m["path_dev_attempted_mm"])
    # The time mean of the old measure calls this perfect: the reason for the new one.
    assert m["path_dev_mean_mm"] == 0.0


def test_half_the_path_at_a_constant_offset() -> None:
    x, gi = _along(0.02, 401, 0.001)
    t = np.arange(1, len(x) + 1) * 0.01
    m = trial_path_deviation(t, x, POINTS[np.minimum(gi, 3)], gi, POINTS, start=START)
    assert m["path_covered_frac"] == pytest.approx(0.5)
    assert m["path_dev_attempted_mm"] == pytest.approx(1.0)


def test_waiting_on_the_path_does_not_dilute_the_attempted_deviation() -> None:
    # 90 s still at the start (on the path), then 2 cm at 2 mm off the path in 10 s.
    still = np.zeros((900, 3))
    xs = np.linspace(0.0005, 0.02, 100)
    moving = np.column_stack([xs, np.full(100, 0.002), np.zeros(100)])
    x = np.vstack([still, moving])
    gi = np.minimum(np.floor(x[:, 0] / 0.01 + 1e-9).astype(int), 4)
    t = np.arange(1, len(x) + 1) * 0.1
    m = trial_path_deviation(t, x, POINTS[np.minimum(gi, 3)], gi, POINTS, start=START)
    assert m["path_dev_mean_mm"] < 0.3                      # the time mean: mostly waiting
    assert m["path_dev_attempted_mm"] == pytest.approx(2.0, abs=0.05)   # along the path


def test_progress_on_a_bent_path_counts_arc_length() -> None:
    pts = np.array([[0.03, 0.0, 0.0], [0.03, 0.04, 0.0]])          # L = 3 + 4 cm
    s, length = path_progress([[0.015, 0.005, 0.0], [0.04, 0.01, 0.0]], [0, 1], pts,
                              start=START)
    assert length == pytest.approx(0.07)
    assert s.tolist() == pytest.approx([0.015, 0.04])


def test_the_whole_path_reached_is_covered() -> None:
    # The tool stops 3 mm short of the last point, which counts as reached (r_reach 5 mm):
    # every point reached is the whole path covered.
    x, gi = _along(0.037, 75, 0.0)
    t = np.arange(1, len(x) + 1) * 0.05
    _, s = evaluate_trial(t, x, POINTS[np.minimum(gi, 3)], gi, POINTS, start=START,
                          r_reach=0.005)
    assert s["completed"]
    assert s["path_covered_frac"] == pytest.approx(1.0)
    assert s["path_dev_attempted_mm"] == pytest.approx(0.0, abs=1e-9)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(-0.01, 0.05), st.floats(-0.01, 0.01),
                          st.integers(0, 4)), min_size=1, max_size=40))
def test_coverage_and_attempted_deviation_invariants(rows: list[tuple[float, float, int]]
                                                     ) -> None:
    x = np.array([[a, b, 0.0] for a, b, _ in rows])
    gi = np.maximum.accumulate(np.array([g for *_, g in rows]))   # goals only advance
    s, length = path_progress(x, gi, POINTS, START)
    assert np.all(s >= 0.0) and np.all(s <= length + 1e-12)
    m = trial_path_deviation(np.arange(1, len(x) + 1) * 0.1, x, POINTS[np.minimum(gi, 3)],
                             gi, POINTS, start=START)
    assert 0.0 <= m["path_covered_frac"] <= 1.0
    active = gi < len(POINTS)
    d = path_distances(x, gi, POINTS, START)[active] * 1000.0
    dev = m["path_dev_attempted_mm"]
    if math.isnan(dev):
        assert not np.any(s[active] > 0.0)                  # NaN: nothing attempted
    else:
        assert d.min() - 1e-9 <= dev <= d.max() + 1e-9


def test_attempted_deviation_interpolates_bins_the_tool_skipped() -> None:
    # Two samples, at the start (0 mm) and at 1 cm (4 mm): the bins between are a ramp.
    assert attempted_deviation([0.0, 0.01], [0.0, 4.0]) == pytest.approx(2.0)
