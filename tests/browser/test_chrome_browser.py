"""The trainee's page carries none of viser's own controls (issue #26.1): no settings /
diagnostics button, scene tree with eye or pencil toggles, server address, Dev Settings,
Share or command button; the experimenter's page (a control: another scene) keeps its
configuration panel but no Share button. Headless Chromium at 1280x800."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from tests.browser.conftest import WAIT_MS, wait_ready
from vasim.viewer import TrialOptions, ViewerApp, ViewerPace
from vasim.viewer.chrome import HIDDEN_ICONS

LAPTOP = {"width": 1280, "height": 800}
CONFIG_ICONS = ("home-move", "eye", "eye-off", "pencil", "photo")
"""Icons inside viser's configuration panel (its buttons and the scene tree's toggles)."""


@pytest.fixture(scope="module")
def app(browser: Any) -> Iterator[ViewerApp]:
    a = ViewerApp(port=0, scene="none", trials=TrialOptions(schema="vg"),
                  pace=ViewerPace(view_hz=10.0)).start()
    try:
        yield a
    finally:
        a.stop()


def _visible_icons(page: Any, names: tuple[str, ...]) -> list[str]:
    return [n for n in names
            if any(loc.is_visible() for loc in page.locator(f"svg.tabler-icon-{n}").all())]


def test_the_trainee_page_has_none_of_viser_s_controls(browser: Any, app: ViewerApp) -> None:
    page = browser.new_page(viewport=LAPTOP)
    try:
        page.goto(app.url)
        wait_ready(page)
        page.wait_for_function("() => document.body.innerText.includes('Points reached')",
                               timeout=WAIT_MS)
        # viser did render its settings toggle (it is in the page), but it is not shown.
        assert page.locator("svg.tabler-icon-adjustments").count() >= 1
        assert _visible_icons(page, HIDDEN_ICONS + CONFIG_ICONS) == []
        assert not any(i.is_visible() for i in page.locator("input[value^='ws://']").all())
        assert not page.get_by_text("Dev Settings").is_visible()
        assert not any(b.is_visible() for b in page.get_by_role("button", name="Share").all())
        # (display: none also takes them out of the keyboard's Tab order.)
        assert page.evaluate("() => [...document.querySelectorAll('svg.tabler-icon-adjustments')]"
                             ".every(s => getComputedStyle(s.closest('button')).display"
                             " === 'none')")
        # The scene is still all there and visible to the trainee.
        assert page.evaluate("() => window.__viserMutable.nodeRefFromName['/trajectory/path']"
                             ".visible")
    finally:
        page.close()


def test_the_experimenter_page_keeps_its_own_panel_without_share(browser: Any,
                                                                  app: ViewerApp) -> None:
    page = browser.new_page(viewport=LAPTOP)
    try:
        page.goto(app.experimenter_url)
        wait_ready(page)
        assert _visible_icons(page, ("adjustments",)) == ["adjustments"]   # the control
        assert _visible_icons(page, ("share",)) == []
    finally:
        page.close()
