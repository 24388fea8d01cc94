"""Less per frame (issue #26.2): the unsteered scene is paced (``flow.ScenePacer``), the AG
parameter stream is latest-wins per page, and what a frame queues is counted by node."""

from __future__ import annotations

import asyncio
import collections
import itertools
import math
import time
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from viser.infra._async_message_buffer import AsyncMessageBuffer

from vasim.viewer.app import TrialOptions, ViewerApp
from vasim.viewer.audio import run_js
from vasim.viewer.flow import FRAMES_PER_SCENE, MIN_SCENE_HZ, SCENE_HZ, ScenePacer

# -- the pacer ----------------------------------------------------------------------------


@given(page_hz=st.one_of(st.none(), st.just(math.nan),
                         st.floats(min_value=0.0, max_value=1000.0)),
       more=st.floats(min_value=0.0, max_value=100.0))
def test_the_scene_rate_is_bounded_and_grows_with_the_page(page_hz: float | None,
                                                           more: float) -> None:
    p = ScenePacer()
    r = p.rate(page_hz)
    assert MIN_SCENE_HZ <= r <= SCENE_HZ
    if page_hz is None or page_hz != page_hz:
        assert r == SCENE_HZ          # no page that acknowledges: the base rate
    else:
        assert p.rate(page_hz + more) >= r     # a faster page never gets it less often
        # at most one of FRAMES_PER_SCENE of the page's frames, unless at the floor
        assert r <= max(MIN_SCENE_HZ, page_hz / FRAMES_PER_SCENE) + 1e-12


@settings(max_examples=60)
@given(view_hz=st.floats(min_value=5.0, max_value=120.0),
       page_hz=st.one_of(st.none(), st.floats(min_value=0.0, max_value=200.0)),
       seconds=st.floats(min_value=1.0, max_value=20.0))
def test_frames_carry_the_scene_at_its_rate(view_hz: float, page_hz: float | None,
                                            seconds: float) -> None:
    """Frames at ``view_hz`` for ``seconds``: the scene goes with the first frame, then
    never twice within its period (1 ms of slack), and never waits a frame period longer."""
    p = ScenePacer()
    rate = p.rate(page_hz)
    times = [k / view_hz for k in range(int(seconds * view_hz))]
    due = [t for t in times if p.due(t, page_hz)]
    assert due[0] == times[0]
    gaps = [b - a for a, b in itertools.pairwise(due)]
    assert all(g >= 1.0 / rate - 1e-3 - 1e-9 for g in gaps)
    assert all(g <= 1.0 / rate + 1.0 / view_hz + 1e-9 for g in gaps)
    assert p.sent == len(due)


def test_a_new_trial_resets_the_pacer_and_bad_rates_are_refused() -> None:
    p = ScenePacer()
    assert p.due(0.0, None) and not p.due(0.01, None)
    p.reset()
    assert p.due(0.02, None)
    for bad in ((0.0, 0.0, 3), (5.0, 10.0, 3), (10.0, 1.0, 0)):
        with pytest.raises(ValueError, match="min_hz"):
            ScenePacer(*bad)


# -- the AG stream: latest wins per page ----------------------------------------------------


def test_keyed_page_scripts_keep_only_the_newest_waiting_one() -> None:
    loop = asyncio.new_event_loop()
    try:
        buf = AsyncMessageBuffer(loop, persistent_messages=False)

        class Connection:
            def queue_message(self, m: Any) -> None:
                buf.push(m)

        class Client:
            _websock_connection = Connection()

        client: Any = Client()
        run_js(client, "setup()")
        for i in range(50):
            run_js(client, f"set({i})", key="audio_params")
        run_js(client, "other()")
        run_js(client, "other()")
        waiting = [m.source for m in buf.message_from_id.values()]
        assert waiting == ["setup()", "set(49)", "other()", "other()"]
        wire = next(iter(buf.message_from_id.values())).as_serializable_dict()
        assert wire == {"source": "setup()", "type": "RunJavascriptMessage"}
        keyed = next(m for m in buf.message_from_id.values() if m.source == "set(49)")
        assert keyed.as_serializable_dict() == {"source": "set(49)",
                                                "type": "RunJavascriptMessage"}
    finally:
        loop.close()


# -- what a frame queues ------------------------------------------------------------------


def _count(app: ViewerApp, seconds: float) -> tuple[collections.Counter[str], int, float]:
    """Messages the trainee's server queues per node name over ``seconds``, in whole view
    frames only, the number of those frames and the wall time.

    Each message is tagged with the frame that queued it (``_view_updates`` counts frames
    when one ends); the first and last frames seen may be cut by the window's edges, so
    they are dropped: a frame's messages are counted all or not at all."""
    assert app.server is not None
    ws = app.server._websock_server
    tagged: list[tuple[int, str]] = []
    original = ws.queue_message

    def counted(msg: Any) -> None:
        tagged.append((app._view_updates,
                       str(getattr(msg, "name", None) or type(msg).__name__)))
        original(msg)

    ws.queue_message = counted  # type: ignore[method-assign,assignment]
    t0 = time.monotonic()
    try:
        time.sleep(seconds)
    finally:
        ws.queue_message = original  # type: ignore[method-assign]
    wall = time.monotonic() - t0
    seen = [f for f, _ in tagged]
    if not seen:
        return collections.Counter(), 0, wall
    first, last = min(seen), max(seen)
    counts = collections.Counter(name for f, name in tagged if first < f < last)
    return counts, max(0, last - first - 1), wall


def test_frames_carry_the_organs_at_the_scene_rate_and_the_tool_with_every_frame() -> None:
    app = ViewerApp(port=0, scene="default",
                    trials=TrialOptions(schema="trajectory_following")).start()
    try:
        t_end = time.monotonic() + 60
        while app.scene_pacer.sent < 2 and time.monotonic() < t_end:
            time.sleep(0.1)
        counts, frames, wall = _count(app, 3.0)
    finally:
        app.stop()
    liver, tip = counts["/organs/liver"], counts["/tool/tip"]
    assert frames > 0 and tip > 0, (frames, counts)
    assert 1 <= liver <= wall * SCENE_HZ + 1, (liver, wall)   # breathing, at most 10 Hz
    # (the tool tip moves with the scripted hand every frame; frames beyond the organs'
    # rate carry it alone)
    if frames > wall * SCENE_HZ + 2:
        assert tip > liver, (tip, liver, frames)
    # the tones of an organ move with it, in the same frames
    assert counts["/organs/liver/tone1"] == liver
