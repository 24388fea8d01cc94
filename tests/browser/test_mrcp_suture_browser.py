"""Smoke test in headless Chromium: the page of ``vasim serve --scene mrcp:suture_combined``
loads, the needle, the tissue and the thread are scene nodes, and the MRCP tab names the
current subtask (guides/viewer.md for the launch flags and readiness waits)."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from tests.browser.conftest import VIEWPORT, wait_ready
from tests.polling import wait_for
from vasim.viewer.mrcp_panel import MrcpPace, MrcpViewerApp


@pytest.fixture(scope="module")
def app(browser: Any) -> Iterator[MrcpViewerApp]:
    a = MrcpViewerApp(port=0, scenario="suture_combined", coarse=True,
                      pace=MrcpPace(view_hz=10.0, plot_hz=1.0)).start()
    try:
        yield a
    finally:
        a.stop()


def test_suture_page_shows_needle_thread_and_subtask(browser: Any, app: MrcpViewerApp) -> None:
    pg = browser.new_page(viewport=VIEWPORT)
    try:
        pg.goto(app.url)
        wait_ready(pg, "/mrcp/robots/R1/link6")

        def node(name: str) -> bool:
            return bool(pg.evaluate("(n) => !!window.__viserMutable.nodeRefFromName[n]", name))

        for name in ("/mrcp/task/body", "/mrcp/obstacles/tissue_left", "/mrcp/suture/thread"):
            assert wait_for(lambda n=name: node(n)), name
        assert wait_for(lambda: "subtask:" in pg.evaluate("() => document.body.innerText"))
    finally:
        pg.close()
