"""Issue #30 item 3 in a real headless Chromium: on the experimenter's page, Start for a
subject who completed the protocol shows the refusal (no second session), and the reason
typed in "Again, because" is stored with the new session it then starts."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.browser.conftest import VIEWPORT, WAIT_MS, wait_ready
from tests.polling import wait_for
from tests.study.tiny_protocols import TINY, install
from tests.study.tiny_protocols import session_rows as sessions
from vasim.cli import main
from vasim.viewer import TrialOptions, ViewerApp, ViewerPace
from vasim.viewer.history import AGAIN_FIELD


@pytest.fixture
def app(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, browser: Any,
        capsys: pytest.CaptureFixture[str]) -> Iterator[ViewerApp]:
    """A viewer whose store holds D9's completed session of the tiny protocol (run with
    ``vasim study run``), the tiny protocol offered beside the shipped ones."""
    install(monkeypatch, tmp_path / "studies", tiny=TINY)
    db = tmp_path / "s.sqlite"
    assert main(["study", "run", "--protocol", "tiny", "--db", str(db), "--subject", "D9",
                 "--no-progress"]) == 0
    capsys.readouterr()
    a = ViewerApp(port=0, db=str(db), scene="none", trials=TrialOptions(pause_s=0.3),
                  pace=ViewerPace(speed=3.0, view_hz=10.0)).start()
    try:
        yield a
    finally:
        a.stop()


def field(page: Any, label: str) -> Any:
    """The input of the GUI control labelled ``label``."""
    return page.locator(f"xpath=//label[normalize-space()='{label}']"
                        "/ancestor::div[.//input][1]//input")


def body_has(page: Any, text: str) -> None:
    try:
        page.wait_for_function("(t) => document.body.innerText.includes(t)", arg=text,
                               timeout=120_000)
    except Exception as exc:
        raise AssertionError(f"{text!r} not on the page: {page.inner_text('body')!r}"
                             ) from exc


def test_the_page_refuses_a_second_session_and_stores_the_reason(
        app: ViewerApp, browser: Any) -> None:
    db = Path(str(app.controller.db))
    page = browser.new_page(viewport=VIEWPORT)
    try:
        page.goto(app.experimenter_url)
        wait_ready(page)
        # protocol mode, subject and protocol (the menus are tested elsewhere)
        for kind, value in (("mode", "protocol"), ("protocol", "tiny")):
            app.request(kind, value)
        assert wait_for(lambda: app.panel.protocol == "tiny"), app.errors[-3:]
        field(page, "Subject code").fill("D9", force=True)
        # the typed code reaches the server before the click (viser sends a text field
        # on change; a click sent first set the subject to "")
        assert wait_for(lambda: app.panel_view.subject.value == "D9"), app.errors[-3:]
        page.get_by_role("button", name="Set subject").click(force=True)
        assert wait_for(lambda: app.panel.subject == "D9"), app.errors[-3:]
        body_has(page, "already completed tiny (session 1): Start is refused")
        # Start: refused on the page; no session, no trial
        n = app.snapshot.info.number
        page.get_by_role("button", name="Start trial").click(force=True)
        body_has(page, "already completed protocol 'tiny'")
        assert wait_for(lambda: "already completed protocol" in app.panel.status)
        assert app.snapshot.info.number == n and len(sessions(db)) == 1
        # the reason, then Start: a new session with the reason stored
        field(page, AGAIN_FIELD).fill("the device failed in session 1", force=True)
        assert wait_for(lambda: app.panel_view.again.value == "the device failed in session 1")
        page.get_by_role("button", name="Set reason").click(force=True)
        assert wait_for(lambda: app.panel.again == "the device failed in session 1"), \
            app.errors[-3:]
        # the page shows the new status line before Start is clicked: a click during that
        # re-layout was lost once at load 3 (the trial never started)
        body_has(page, "reason for a new session: the device failed in session 1")
        page.get_by_role("button", name="Start trial").click(force=True)
        assert wait_for(lambda: len(sessions(db)) == 2), app.panel.status
        assert sessions(db)[1] == (2, "D9", "running", "again after completed session 1: "
                                   "the device failed in session 1")
        assert wait_for(lambda: app.snapshot.info.schedule_index == 0
                        and app.panel.session_id == 2), app.panel.status
        # the used reason is cleared: the panel's state, the field viser synchronises and
        # the page's input (a make-test run found the view missing the short-lived state)
        assert wait_for(lambda: app.panel.again is None), app.panel.again
        assert wait_for(lambda: app.panel_view.again.value == ""), app.panel_view.again.value
        page.wait_for_function(
            "(l) => { const x = document.evaluate(`//label[normalize-space()='${l}']"
            "/ancestor::div[.//input][1]//input`, document, null, "
            "XPathResult.FIRST_ORDERED_NODE_TYPE, null).singleNodeValue; "
            "return x && x.value === ''; }", arg=AGAIN_FIELD, timeout=WAIT_MS)
    finally:
        page.close()
