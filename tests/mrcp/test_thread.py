"""The suture thread's chain (vasim.mrcp.thread): lengths kept, FABRIK attachment,
tightening draws slack before reserve, an overstretched thread reports its gap."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.mrcp.thread import LOOP_SLACK, SutureThread

coord = st.floats(-0.05, 0.05, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(coord, coord, coord), min_size=1, max_size=6))
def test_length_kept_and_end_attached_within_reach(tails: list[tuple[float, float, float]]
                                                   ) -> None:
    th = SutureThread(np.zeros(3), np.array([0.02, 0.0, 0.0]), 0.4, 0.1, 12)
    for t in tails:
        s = th.update(np.array(t))
        seg = np.linalg.norm(np.diff(s.nodes, axis=0), axis=1)
        assert np.allclose(seg, s.free_length / 12, atol=1e-12)
        assert s.total_length == pytest.approx(0.4, abs=1e-12)
        assert s.attach_gap < 1e-4         # every tail is within 0.087 m < the free chain


def test_pull_takes_up_slack_before_reserve_and_overstretch_shows_a_gap() -> None:
    th = SutureThread(np.zeros(3), np.array([0.01, 0.0, 0.0]), 0.2, 0.05, 8)
    th.update(np.array([0.02, 0.0, -0.01]))
    th.pin(np.array([0.02, 0.0, 0.0]), np.array([0.03, 0.0, 0.0]), np.array([0.035, 0, 0.0]))
    assert th.slack >= LOOP_SLACK
    slack, reserve = th.slack, th.reserve
    s = th.update(np.array([0.03 + th.free_length + 0.5 * slack, 0.0, 0.0]))
    assert s.slack == pytest.approx(0.5 * slack) and s.reserve == pytest.approx(reserve)
    assert th.taut()
    s = th.update(np.array([0.03 + s.free_length + slack, 0.0, 0.0]))
    assert s.slack == 0.0 and s.reserve < reserve
    assert s.total_length == pytest.approx(0.2, abs=1e-12)
    s = th.update(np.array([1.0, 0.0, 0.0]))        # beyond the whole thread
    assert s.reserve == 0.0 and s.attach_gap == pytest.approx(1.0 - 0.03 - s.free_length)


def test_bad_threads_are_refused() -> None:
    with pytest.raises(ValueError, match="free chain"):
        SutureThread(np.zeros(3), np.array([0.1, 0.0, 0.0]), 0.3, 0.05)
    with pytest.raises(ValueError, match="segments"):
        SutureThread(np.zeros(3), np.array([0.01, 0.0, 0.0]), 0.3, 0.05, 1)
