"""Tests of the timing statistics (vasim/haptics/timing.py) against hand-computed values."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.haptics.timing import OVERRUN_FACTOR, TimingRecorder, timing_stats

MS = 1_000_000  # ns


def test_perfect_loop() -> None:
    starts = np.arange(1001) * MS
    s = timing_stats(starts, starts + MS // 10, 1000.0)
    assert s.n_ticks == 1001 and s.duration_s == 1.0 and s.achieved_hz == 1000.0
    assert s.period_p50_ms == s.period_p99_ms == s.period_max_ms == s.period_mean_ms == 1.0
    assert s.jitter_rms_ms == 0.0 and s.overruns == 0
    assert s.tick_cost_p50_ms == pytest.approx(0.1)


def test_known_periods() -> None:
    # periods [ms]: 1, 1, 1.5 (exactly the threshold: not an overrun), 1.6 (overrun), 0.4, 3
    periods = np.array([1.0, 1.0, 1.5, 1.6, 0.4, 3.0])
    starts = np.concatenate([[0], np.cumsum(periods * MS)]).astype(np.int64)
    s = timing_stats(starts, None, 1000.0, missed_deadlines=2)
    assert s.overruns == 2 and s.missed_deadlines == 2
    assert s.period_max_ms == 3.0
    assert s.period_mean_ms == pytest.approx(periods.mean())
    assert s.period_p50_ms == pytest.approx(np.percentile(periods, 50))
    assert s.jitter_rms_ms == pytest.approx(math.sqrt(np.mean((periods - 1.0) ** 2)))
    assert s.achieved_hz == pytest.approx(6 / (periods.sum() * 1e-3))
    assert math.isnan(s.tick_cost_p50_ms)
    assert OVERRUN_FACTOR == 1.5


def test_to_dict_is_json_and_nan_free() -> None:
    s = timing_stats([0], None, 1000.0)  # one tick: no periods
    d = s.to_dict()
    text = json.dumps(d, allow_nan=False)
    assert json.loads(text)["achieved_hz"] is None and d["overrun_factor"] == 1.5
    assert d["n_ticks"] == 1 and d["mode"] == "realtime"
    assert "ticks" in s.summary()


def test_bad_input() -> None:
    with pytest.raises(ValueError, match="nominal_hz"):
        timing_stats([0, 1], None, 0.0)
    with pytest.raises(ValueError, match="non-decreasing"):
        timing_stats([0, 5, 3], None, 1000.0)
    with pytest.raises(ValueError, match="stamps"):
        timing_stats([0, 5], [1], 1000.0)
    with pytest.raises(ValueError, match="chunk"):
        TimingRecorder(chunk=0)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.integers(1, 5 * MS), min_size=1, max_size=300), st.integers(1, 17))
def test_recorder_equals_the_pure_function(periods: list, chunk: int) -> None:
    starts = np.concatenate([[0], np.cumsum(periods)]).astype(np.int64)
    ends = starts + 1000
    rec = TimingRecorder(chunk=chunk)
    for a, b in zip(starts, ends, strict=True):
        rec.record(int(a), int(b))
    assert len(rec) == starts.size
    np.testing.assert_array_equal(rec.stamps(), np.stack([starts, ends], axis=1))
    assert rec.stats(1000.0) == timing_stats(starts, ends, 1000.0)
    rec.clear()
    assert len(rec) == 0 and rec.stamps().shape == (0, 2)
