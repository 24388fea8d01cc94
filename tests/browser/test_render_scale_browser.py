"""Fewer pixels when a page cannot keep up (vasim/viewer/render_scale.py), in a real
browser: the page's renderer draws at the scale it is told (its canvas's backing store
shrinks, its CSS size does not), back to full when told so, and the page's notice line says
so when the step rule sends it coarser."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from tests.browser.conftest import READY_TIMEOUT_MS, wait_ready
from vasim.viewer.app import TrialOptions, ViewerApp
from vasim.viewer.render_scale import SCALES

RATIO_JS = """() => { const c = window.__viserMutable && window.__viserMutable.canvas;
  return c && c.clientWidth ? c.width / (c.clientWidth * (window.devicePixelRatio || 1))
                            : null; }"""


@pytest.fixture(scope="module")
def app() -> Iterator[ViewerApp]:
    a = ViewerApp(port=0, scene="none", trials=TrialOptions(schema="none", countdown_s=0.0)).start()
    try:
        yield a
    finally:
        a.stop()


def _wait_ratio(page: Any, scale: float) -> None:
    page.wait_for_function(f"() => Math.abs(({RATIO_JS})() - {scale}) < 0.02",
                           timeout=READY_TIMEOUT_MS)


def test_a_page_draws_at_the_scale_it_is_told(app: ViewerApp, browser: Any,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    # The rule's own input (this page's update rate on a loaded host) is left out: the view
    # thread's notice round is stopped, and the test drives the steps.
    monkeypatch.setattr(app.notices, "show", lambda *a, **k: None)
    page = browser.new_page()
    try:
        page.goto(app.url)
        wait_ready(page)
        _wait_ratio(page, 1.0)
        key = next(k for k in app.notices.handles if k[0] == app.acks.port)
        app.notices._send_scale(key, 0.5)
        _wait_ratio(page, 0.5)
        app.notices._send_scale(key, 1.0)
        _wait_ratio(page, 1.0)
        # The step rule: a page applying 2 of 40 frames/s goes one step coarser after its
        # wait, and the page shows the line (the rule's own timing is tested in
        # tests/viewer/test_render_scale.py; here its effect on a real page).
        for t in (0.0, 1.0, 2.0, 3.0):
            app.notices.scales.update(key, 2.0, 40.0, 1000.0 + t)
        _wait_ratio(page, SCALES[1])
        assert app.notices.scales.coarsest[app.acks.port] == SCALES[1]
    finally:
        page.close()
