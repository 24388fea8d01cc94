"""Real-browser tests of the viewer: Debian's headless Chromium driven by playwright.

Every test here carries the ``browser`` marker (given in tests/conftest.py; ``pytest -m "not
browser"`` leaves them out).
They skip, with the reason, only when ``/usr/bin/chromium`` (or ``$VASIM_CHROMIUM``) or the
playwright package is missing (``make test`` installs both; never ``playwright install``,
which downloads).
Launch flags and readiness waits follow guides/viewer.md.
"""

from __future__ import annotations

import importlib.util
import os
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from tests.polling import WAIT_S, wait_for

CHROMIUM = os.environ.get("VASIM_CHROMIUM", "/usr/bin/chromium")   # as .ci/ensure-chromium
LAUNCH_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
               "--disable-component-update", "--disable-sync", "--no-first-run"]
VIEWPORT = {"width": 820, "height": 520}
WAIT_MS = int(WAIT_S * 1000)
"""The same, for Playwright's waits (ms)."""

READY_TIMEOUT_MS = WAIT_MS  # page-to-first-frame stalls of 5-11 s at load 1-3, > 45 s at 30-40
ACTION_TIMEOUT_MS = 180_000  # clicks, navigations (Playwright: 30 s; > 90 s seen at load 40)


def missing_browser() -> str | None:
    """Why the browser tests cannot run here, or None."""
    if not os.path.exists(CHROMIUM):
        return f"{CHROMIUM} is missing (apt-get install chromium; make test does it)"
    if importlib.util.find_spec("playwright") is None:
        return "the playwright package is missing (pip install playwright; never playwright " \
               "install)"
    return None


@pytest.fixture(scope="session")
def browser() -> Iterator[Any]:
    reason = missing_browser()
    if reason:
        pytest.skip(reason)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=LAUNCH_ARGS)
        try:
            yield _Browser(b)
        finally:
            b.close()


class _Browser:
    """The browser, whose pages wait :data:`ACTION_TIMEOUT_MS` for an action (a click, a
    navigation) instead of Playwright's 30 s: a page rendering software WebGL on a loaded
    2-core machine has taken longer to take a click (issue #31)."""

    def __init__(self, browser: Any) -> None:
        self._browser = browser

    def new_page(self, **kwargs: Any) -> Any:
        page = self._browser.new_page(**kwargs)
        page.set_default_timeout(ACTION_TIMEOUT_MS)
        page.set_default_navigation_timeout(ACTION_TIMEOUT_MS)
        return page

    def __getattr__(self, name: str) -> Any:
        return getattr(self._browser, name)


def click_until(locator: Any, done: Callable[[], object], *, what: str, tries: int = 3,
                wait_s: float = 60.0) -> None:
    """Clicks ``locator`` until the server shows the click's effect (``done``), at most
    ``tries`` times, waiting ``wait_s`` after each click. A click on a page re-laid out under
    it (a notice line appearing on a busy host) can land beside its button and be lost; a
    click is repeated only while ``done`` -- read on the server, where the click acts first --
    is false, so a toggle is never clicked twice. A repeat dispatches the click event on the
    element itself: in a clean-clone ``make test`` (load 3-5) three pointer clicks 60 s apart
    all missed the Enable-audio button (a covering or moved element takes a forced click)."""
    for i in range(tries):
        if i == 0:
            locator.click(force=True)
        else:
            locator.dispatch_event("click")
        if wait_for(done, timeout=wait_s):
            return
    raise AssertionError(f"{what}: {tries} clicks, no effect on the server")


def wait_ready(page: Any, node: str = "/tool/tip") -> None:
    """Waits until the page is connected, the scene node exists and two frames were drawn."""
    page.wait_for_function("() => !document.body.innerText.includes('Connecting')",
                           timeout=READY_TIMEOUT_MS)
    page.wait_for_function(
        "(n) => window.__viserMutable && window.__viserMutable.nodeRefFromName[n]", arg=node,
        timeout=READY_TIMEOUT_MS)
    page.evaluate("() => new Promise(r => requestAnimationFrame(() => "
                  "requestAnimationFrame(() => r(true))))")


