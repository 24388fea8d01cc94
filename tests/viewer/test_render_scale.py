"""Fewer pixels when a page cannot keep up (vasim/viewer/render_scale.py, issue #26.2):
the step rule (pure), the per-page shell, and what a page is told."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vasim.viewer.render_scale import (
    DOWN_AFTER_S,
    HIGH_FRACTION,
    LOW_FRACTION,
    SCALES,
    UP_AFTER_S,
    PageScales,
    ScaleState,
    next_state,
    scale_notice,
    set_scale_js,
)

rates = st.one_of(st.none(), st.just(math.nan),
                  st.floats(min_value=0.0, max_value=200.0, allow_nan=False))


@given(level=st.integers(0, len(SCALES) - 1),
       samples=st.lists(st.tuples(rates, rates, st.floats(0.0, 5.0)), max_size=60))
def test_the_step_stays_on_the_ladder_and_moves_one_level_at_a_time(
        level: int, samples: list[tuple[float | None, float | None, float]]) -> None:
    state, now = ScaleState(level), 0.0
    for page_hz, produced_hz, dt in samples:
        now += dt
        new = next_state(state, page_hz, produced_hz, now)
        assert 0 <= new.level < len(SCALES)
        assert abs(new.level - state.level) <= 1
        if new.level > state.level:      # coarser only for a page too slow
            assert page_hz is not None and produced_hz
            assert page_hz / produced_hz < LOW_FRACTION
        if new.level < state.level:      # finer only for a page keeping up
            assert page_hz is not None and produced_hz
            assert page_hz / produced_hz >= HIGH_FRACTION
        state = new


def test_a_slow_page_goes_coarser_after_its_wait_and_a_fast_one_finer_after_its_own() -> None:
    s = ScaleState()
    t = 0.0
    while s.level == 0:                  # 5 of 40 frames/s: too slow
        s = next_state(s, 5.0, 40.0, t)
        t += 0.5
    assert s.level == 1 and t - 0.5 == pytest.approx(DOWN_AFTER_S)
    while s.level < len(SCALES) - 1:
        s = next_state(s, 5.0, 40.0, t)
        t += 0.5
    assert s.scale == SCALES[-1]
    assert next_state(s, 5.0, 40.0, t + 100).level == len(SCALES) - 1   # the floor holds
    t0 = t
    while s.level == len(SCALES) - 1:    # 39 of 40: keeps up
        s = next_state(s, 39.0, 40.0, t)
        t += 0.5
    assert t - 0.5 - t0 == pytest.approx(UP_AFTER_S)
    # in between the thresholds, or without a figure, nothing changes and both waits restart
    mid = next_state(ScaleState(1, slow_since=0.0), 0.7 * 40, 40.0, 100.0)
    assert mid == ScaleState(1)
    assert next_state(ScaleState(2, slow_since=0.0), None, 40.0, 50.0) == ScaleState(2)
    assert next_state(ScaleState(2, slow_since=0.0), 3.0, 0.0, 50.0) == ScaleState(2)


def test_the_shell_tells_a_page_only_when_its_step_changes_and_keeps_the_coarsest() -> None:
    sent: list[tuple[tuple[int, int], float]] = []
    scales = PageScales(lambda key, s: sent.append((key, s)), window_s=3.0)
    assert scales.produced(0.0, 0) is None
    assert scales.produced(2.0, 80) == pytest.approx(40.0)
    scales.add((1, 7))
    scales.add((2, 8))
    for i in range(10):
        scales.update((1, 7), 5.0, 40.0, 0.5 * i)      # slow trainee page
        scales.update((2, 8), 40.0, 40.0, 0.5 * i)     # the experimenter's keeps up
    assert sent == [((1, 7), SCALES[1]), ((1, 7), SCALES[2])]
    assert scales.coarsest == {1: SCALES[2], 2: 1.0}
    scales.drop((1, 7))
    scales.restart(1)
    assert scales.coarsest[1] == 1.0


def test_what_the_page_reads_and_runs() -> None:
    assert scale_notice(1.0) == ""
    assert scale_notice(0.35).startswith("Drawn at 35 % resolution")
    assert set_scale_js(0.5) == "window.__vasimScale && window.__vasimScale.set(0.500);"
    for bad in (0.0, -1.0, 1.5, math.nan, math.inf):
        with pytest.raises(ValueError, match="render scale"):
            set_scale_js(bad)
