"""viser's uPlot draws nothing when a series holds a NaN (issue #26 §5: the f5PL editor's
curve was blank); ``panel.plot_data`` sends none: finite values as they are, inside the
fixed y range, and every missing value outside it."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from vasim.viewer.panel import plot_data

values = st.floats(min_value=-1e6, max_value=1e6) | st.just(math.nan)


@given(st.integers(1, 30).flatmap(
    lambda n: st.lists(arrays(np.float64, n, elements=values), min_size=1, max_size=4)))
def test_no_nan_reaches_the_chart_and_finite_values_stay_in_range(series: list) -> None:
    x = np.arange(len(series[0]), dtype=np.float64)
    data, scales = plot_data((x, *series))
    lo, hi = scales["y"]["range"]
    assert scales["y"]["auto"] is False and lo < hi
    np.testing.assert_array_equal(data[0], x)
    for given_y, sent in zip(series, data[1:], strict=True):
        assert np.isfinite(sent).all()
        ok = np.isfinite(given_y)
        np.testing.assert_array_equal(sent[ok], given_y[ok])
        assert ((sent[ok] >= lo) & (sent[ok] <= hi)).all()
        assert (sent[~ok] > hi).all()


def test_the_editor_series_keep_their_values() -> None:
    from vasim.fixtures.ms import MS_TRAJECTORY_F5PL
    from vasim.viewer.f5pl_view import FixtureAxes, editor_data

    raw = editor_data(MS_TRAJECTORY_F5PL, None, FixtureAxes("ms", 0.03, "x", "y"), 0.015)
    data, scales = plot_data(raw)
    _lo, hi = scales["y"]["range"]
    np.testing.assert_array_equal(data[1], raw[1])          # the edited curve as is
    assert (data[2] > hi).all()                              # no reference: out of sight
    shown = np.flatnonzero(data[3] <= hi)                    # the one operating point
    assert len(shown) == 1 and data[0][shown[0]] == 15.0
