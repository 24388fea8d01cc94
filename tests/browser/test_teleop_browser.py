"""In a real browser: a teleoperation trial of a protocol session (issue #28). The
experimenter's page picks protocol mode, the trainee's instrument, the subject code and a
one-trial MRCP protocol, and starts it; the trainee's keys move the needle (the task) through
the station's master; the experimenter stops it; the stored row is the teleoperation
trial's (task ``needle``, the mode in its config, its trial metrics with what was moved).

The page is kept light as in test_instrument_browser.py (no abdomen scene, small
viewports, 10 view updates per second); every motion comes from the page's key events.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import closing
from typing import Any

import numpy as np
import pytest

from tests.browser.conftest import WAIT_MS, wait_ready
from tests.polling import wait_for
from tests.study.tiny_protocols import install
from tests.viewer.test_teleop_session import teleop_protocol
from vasim.study.store import TrialStore
from vasim.viewer.app import TrialOptions, ViewerApp, ViewerPace

TELEOP_BROWSER = teleop_protocol("teleop_browser", 300.0, ("mrcp",), question=False)

TRAINEE_VIEW = {"width": 420, "height": 300}
EXPERIMENTER_VIEW = {"width": 560, "height": 620}


@pytest.fixture
def app(browser: Any, tmp_path: Any, monkeypatch: pytest.MonkeyPatch) -> Iterator[ViewerApp]:
    install(monkeypatch, tmp_path / "protocols", teleop_browser=TELEOP_BROWSER)
    with ViewerApp(port=0, db=str(tmp_path / "study.sqlite"), scene="none",
                   trials=TrialOptions(countdown_s=1.0), pace=ViewerPace(view_hz=10.0)) as a:
        yield a


def test_a_person_moves_the_needle_of_an_mrcp_trial_and_it_is_stored(
        app: ViewerApp, browser: Any) -> None:
    exp = browser.new_page(viewport=EXPERIMENTER_VIEW)
    trainee = None
    try:
        exp.goto(app.experimenter_url)
        wait_ready(exp)
        app.request("mode", "protocol")
        assert wait_for(lambda: app.panel.mode == "protocol"), app.errors[-3:]
        exp.get_by_role("combobox", name="Input").click(force=True)
        exp.get_by_role("option", name="laparoscopic", exact=True).click(force=True)
        assert wait_for(lambda: app.panel.input == "laparoscopic"), app.errors[-3:]
        exp.locator("xpath=//label[normalize-space()='Subject code']"
                    "/ancestor::div[.//input][1]//input").fill("T01", force=True)
        # the typed code reaches the server before the click (viser sends a text field on
        # change; a click sent first set the subject to "")
        assert wait_for(lambda: app.panel_view.subject.value == "T01"), app.errors[-3:]
        exp.get_by_role("button", name="Set subject").click(force=True)
        assert wait_for(lambda: app.panel.subject == "T01"), app.errors[-3:]
        app.request("protocol", "teleop_browser")   # the menus are tested elsewhere
        assert wait_for(lambda: app.panel.protocol == "teleop_browser"), app.errors[-3:]
        # the status line has its final length: the buttons below it stay where they are
        exp.wait_for_function("(t) => document.body.innerText.includes(t)",
                              arg="new session of teleop_browser for T01", timeout=WAIT_MS)
        trainee = browser.new_page(viewport=TRAINEE_VIEW)   # the trainee's page, keys ready
        trainee.goto(app.url)
        wait_ready(trainee)
        trainee.wait_for_function("() => window.__vasimInput !== undefined", timeout=WAIT_MS)
        exp.get_by_role("button", name="Start trial").click(force=True)
        assert wait_for(lambda: app.snapshot.info.trial_id is not None
                        and app.controller.instrument is not None
                        and app.snapshot.frame.k >= 0), (app.panel.status, app.errors[-3:])
        info = app.snapshot.info
        assert info.condition == "mrcp" and info.task_name == "needle"
        exp.close()   # its 3-D view would compete with the trainee's for the CPU
        trainee.wait_for_function("(t) => document.body.innerText.includes(t)",
                                  arg="Carry the needle through the 6 rings",
                                  timeout=WAIT_MS)
        # The keys: advance the instrument (W) and turn it (ArrowRight); the master's
        # increments move the needle (the kernel holds it with the right robot).
        x0 = np.array(app.snapshot.frame.tcp)
        batches0 = app.instrument_input.batches
        t_end = time.monotonic() + 120.0
        while time.monotonic() < t_end:
            for key in ("KeyW", "ArrowRight"):
                trainee.keyboard.down(key)
                time.sleep(0.4)
                trainee.keyboard.up(key)
            time.sleep(0.3)
            if np.linalg.norm(np.array(app.snapshot.frame.tcp) - x0) > 3e-3:
                break
        moved = float(np.linalg.norm(np.array(app.snapshot.frame.tcp) - x0))
        assert moved > 3e-3, (moved, app.instrument_input.batches, app.errors[-3:])
        assert app.instrument_input.batches > batches0
        # The experimenter's page stops it; the row is the teleoperation trial's.
        exp = browser.new_page(viewport=EXPERIMENTER_VIEW)
        exp.goto(app.experimenter_url)
        wait_ready(exp)
        exp.get_by_role("button", name="Stop trial").click(force=True)
        assert wait_for(lambda: not app.panel.running), app.panel.status
        assert "stays pending" in app.panel.status
        with closing(TrialStore(app.controller.db, readonly=True)) as st:
            row = st.trial(info.trial_id)
            metrics = st.trial_metrics(info.trial_id).set_index("metric")["value"]
        assert (row["task"], row["operator"], row["status"], row["outcome"]) == (
            "needle", "laparoscopic", "interrupted", "stopped")
        assert row["config"]["mode"] == "mrcp" and row["schedule_index"] == 0
        assert metrics["path_l2"] >= moved - 1e-9 and metrics["master_path_l2"] > 0
        print(f"needle moved {1e3 * moved:.1f} mm by the page's keys; "
              f"path {1e3 * metrics['path_l2']:.1f} mm stored")
    finally:
        if trainee is not None:
            trainee.close()
        exp.close()
