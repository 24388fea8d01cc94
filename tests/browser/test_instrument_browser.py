"""In a real browser: the trainee drives the laparoscopic instrument with the keyboard and
the mouse through a trial the experimenter's page starts and stops (issue #19 §2, §5).

Reliability on a 2-core machine (**decisions**): the pages render with software WebGL, and
Playwright's key events wait for a renderer busy with it. So the test keeps the renderer
light — small viewports (the trainee's 3-D view is ~1/8 of the usual pixels; the
experimenter's page is opened only to start and to stop the trial), no abdomen scene, 10
view updates per second — and steers in a closed loop over real key events with pulses
long enough (>= 40 ms, <= 0.8 s) that event delivery jitter is small beside them. It never
reaches into the device: every motion comes from the page's key and wheel events."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import closing
from typing import Any

import numpy as np
import pytest

from tests.browser.conftest import WAIT_MS, wait_ready
from tests.polling import wait_for
from vasim.haptics.laparoscopic import InputMapping
from vasim.study.store import TrialStore
from vasim.viewer.app import TrialOptions, ViewerApp, ViewerPace
from vasim.viewer.controller import Command


@pytest.fixture(scope="module")
def app(browser: Any, tmp_path_factory: pytest.TempPathFactory) -> Iterator[ViewerApp]:
    db = str(tmp_path_factory.mktemp("instrument") / "study.sqlite")
    a = ViewerApp(port=0, db=db, scene="none", trials=TrialOptions(schema="vg", countdown_s=1.0),
                  pace=ViewerPace(view_hz=10.0)).start()
    try:
        yield a
    finally:
        a.stop()


def _choose(page: Any, label: str, option: str) -> None:
    page.get_by_role("combobox", name=label).click(force=True)
    page.get_by_role("option", name=option, exact=True).click(force=True)


def _steer(app: ViewerApp, page: Any, points: int, timeout: float) -> int:
    """Drives the instrument as a person would with the keys: look where the goal is, press
    the arrow keys (mirrored by the fulcrum effect) and W/S for as long as the gap needs,
    let go, look again. Returns the points reached."""
    right, up = app.controller.screen
    dev = app.controller.instrument
    assert dev is not None
    rate = dev.mapping.stick_rad_per_s * dev.mapping.sensitivity      # shaft turn [rad/s]
    speed = dev.mapping.insert_m_per_s * dev.mapping.sensitivity      # insertion [m/s]
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        frame = app.snapshot.frame
        if frame.goal_index >= points or frame.done:
            break
        tip, goal = np.asarray(frame.tcp), np.asarray(frame.goal)
        shaft = tip - dev.port.fulcrum
        depth = float(np.linalg.norm(shaft))
        shaft /= depth
        # The tip moves by J @ (right angle, up angle, insertion): turning the shaft moves
        # it across the shaft (mirrored by the fulcrum effect), inserting moves it along.

        jac = np.column_stack([-(v - float(v @ shaft) * shaft) * depth for v in (right, up)]
                              + [shaft])
        a_r, a_u, ins = np.linalg.lstsq(jac, goal - tip, rcond=None)[0]
        # ArrowRight asks a positive right angle, ArrowUp a positive up angle.
        presses = [("ArrowRight" if a_r > 0 else "ArrowLeft", abs(a_r) / rate),
                   ("ArrowUp" if a_u > 0 else "ArrowDown", abs(a_u) / rate),
                   ("KeyW" if ins > 0 else "KeyS", abs(ins) / speed)]
        presses = [(k, min(max(d, 0.04), 0.8)) for k, d in presses if d > 0.01]
        t0 = time.monotonic()
        for key, _ in presses:
            page.keyboard.down(key)
        for key, d in sorted(presses, key=lambda kd: kd[1]):
            time.sleep(max(0.0, t0 + d - time.monotonic()))
            page.keyboard.up(key)
        time.sleep(0.3)  # the page sends, the device smooths, the trial steps
    return int(app.snapshot.frame.goal_index)


TRAINEE_VIEW = {"width": 420, "height": 300}      # a light page for software WebGL
EXPERIMENTER_VIEW = {"width": 560, "height": 520}
EXPERIMENTER_ONLY = (("button", "Start trial"), ("button", "Stop trial"),
                     ("combobox", "Mode"), ("combobox", "Input"), ("combobox", "Schema"),
                     ("button", "Apply f5PL"), ("button", "Set subject"))


def test_a_trainee_reaches_five_points_with_keyboard_and_mouse(app: ViewerApp, browser: Any,
                                                               tmp_path: Any) -> None:
    exp = browser.new_page(viewport=EXPERIMENTER_VIEW)
    trainee = browser.new_page(viewport=TRAINEE_VIEW)
    try:
        trainee.goto(app.url)
        wait_ready(trainee)
        trainee.wait_for_function("() => window.__vasimInput !== undefined", timeout=WAIT_MS)
        # The trainee page shows no experimenter control.
        for role, name in EXPERIMENTER_ONLY:
            assert trainee.get_by_role(role, name=name).count() == 0, name  # type: ignore[arg-type]
        exp.goto(app.experimenter_url)
        wait_ready(exp)
        # The experimenter: free training, the trainee's instrument, a gentle sensitivity.
        _choose(exp, "Mode", "free")
        assert wait_for(lambda: app.panel.mode == "free"), app.errors[-3:]
        _choose(exp, "Input", "laparoscopic")
        assert wait_for(lambda: app.panel.input == "laparoscopic"), app.errors[-3:]
        app.submit(Command("input_mapping", InputMapping(sensitivity=0.5)))
        n0 = app.snapshot.info.number
        exp.get_by_role("button", name="Start trial").click(force=True)
        assert wait_for(lambda: app.snapshot.info.number > n0
                        and app.controller.instrument is not None), app.errors[-3:]
        exp.close()   # the experimenter's 3-D view would compete with the trainee's for the CPU
        dev = app.controller.instrument
        info = app.snapshot.info
        assert dev is not None and dev.mapping.sensitivity == 0.5 and info.trial_id is not None
        # The trainee's page names the trial as the store does and tells what to do.
        trainee.wait_for_function("(t) => document.body.innerText.includes(t)",
                                  arg=f"{info.title} — running", timeout=WAIT_MS)
        assert "points along the path" in trainee.inner_text("body")
        # The trainee's camera is the endoscope: dragging over the view does not orbit it.
        client = next(iter(app.server.get_clients().values()))   # type: ignore[union-attr]
        cam0 = np.array(client.camera.position)
        trainee.mouse.move(TRAINEE_VIEW["width"] * 0.2, TRAINEE_VIEW["height"] * 0.5)
        trainee.mouse.down()
        trainee.mouse.move(TRAINEE_VIEW["width"] * 0.45, TRAINEE_VIEW["height"] * 0.3,
                           steps=8)
        trainee.mouse.up()
        time.sleep(1.0)
        assert np.abs(np.array(client.camera.position) - cam0).max() < 1e-3
        # The mouse: the wheel over the view advances the instrument (3 lines: +6 mm at
        # sensitivity 0.5); a click takes the pointer where the browser allows it.
        view = (TRAINEE_VIEW["width"] * 0.25, TRAINEE_VIEW["height"] * 0.6)
        trainee.mouse.click(*view)
        locked = trainee.evaluate("() => window.__vasimInput.locked")
        trainee.mouse.move(*view)
        depth0 = dev.target.insertion
        trainee.mouse.wheel(0, -300)
        assert wait_for(lambda: dev.target.insertion > depth0 + 0.004), dev.target
        if locked:
            trainee.keyboard.press("Escape")
        # The keyboard: five points of the trajectory, in a closed loop. What is asserted is
        # the behaviour (the points were reached; the page's key input was applied), not how
        # many input batches a page on a loaded machine happens to send (issue #31).
        batches0 = app.instrument_input.batches
        reached = _steer(app, trainee, 5, timeout=400.0)   # a closed loop: slow under load
        assert reached >= 5, (reached, app.snapshot.frame.t, app.instrument_input.batches,
                              app.errors[-3:])
        assert app.instrument_input.batches > batches0   # the keys' batches were applied
        sent = trainee.evaluate("() => window.__vasimInput.sent")
        assert sent >= app.instrument_input.batches      # every applied batch came from the page
        # The endoscope's view is drawn (not blank) while the trainee works.
        shot = tmp_path / "endoscope.png"
        trainee.screenshot(path=str(shot))
        assert _lit_fraction(shot) > 0.05
        # The experimenter's page (opened again) stops it; the trainee sees how it ended
        # and a score card; the trial is stored with the input and condition that drove it.
        exp = browser.new_page(viewport=EXPERIMENTER_VIEW)
        exp.goto(app.experimenter_url)
        wait_ready(exp)
        exp.get_by_role("button", name="Stop trial").click(force=True)
        assert wait_for(lambda: not app.panel.running), app.panel.status
        trainee.wait_for_function(
            "(t) => document.body.innerText.includes(t)",
            arg=f"{info.title} — ended: stopped by the experimenter", timeout=WAIT_MS)
        trainee.wait_for_function("(t) => document.body.innerText.includes(t)",
                                  arg=f"Score card — {info.title}", timeout=WAIT_MS)
        body = trainee.inner_text("body")
        assert "running" not in body.split("Score card")[0].split(info.title)[1][:20]
        assert "Points reached" in body and "Path length" in body
        with closing(TrialStore(app.controller.db, readonly=True)) as st:
            row = st.trial(info.trial_id)
        assert row["operator"] == "laparoscopic" and row["outcome"] == "stopped"
        assert row["config"]["viewer"]["input_mapping"]["sensitivity"] == 0.5
        print(f"pointer lock in headless Chromium: {locked}; points reached: {reached}")
    finally:
        trainee.close()
        exp.close()


def _lit_fraction(path: Any) -> float:
    """Fraction of the 3-D view's pixels (left half, below the WebGL notice) that are lit."""
    import matplotlib.image as mpimg

    img = mpimg.imread(str(path))[..., :3]
    h, w = img.shape[:2]
    region = img[h // 2:, : w // 2]
    return float((region.max(axis=2) > 0.2).mean())


PRESS_JS = """() => {
  const S = window.__vasimInput, before = S.sent, seq0 = S.seq;
  const wait = (ms) => { const t = performance.now(); while (performance.now() - t < ms) {} };
  const down = new KeyboardEvent("keydown", {code: "KeyQ", bubbles: true});
  wait(5);                        // the page handles the press 5 ms late (held time > 0)
  window.dispatchEvent(down);
  const onDown = S.sent - before;
  const up = new KeyboardEvent("keyup", {code: "KeyQ", bubbles: true});
  wait(5);
  window.dispatchEvent(up);
  return [onDown, S.sent - before - onDown, seq0, S.seq];
}"""


def test_a_key_press_and_its_release_leave_the_page_from_their_handlers(
        app: ViewerApp, browser: Any) -> None:
    """Issue #26.2: the batch of a new press (and of a release) is sent in the key event's
    own turn of the page's script, before any timer can run (the page's 33 ms timer used to
    send it: on a throttled page, up to 230 ms later); the server records each batch's
    arrival (``InstrumentInput.arrivals``, which bench/viewer.py splits latency with)."""
    page = browser.new_page(viewport=TRAINEE_VIEW)
    try:
        page.goto(app.url)
        wait_ready(page)
        page.wait_for_function("() => window.__vasimInput !== undefined", timeout=WAIT_MS)
        on_down, on_up, seq0, seq1 = page.evaluate(PRESS_JS)
        assert (on_down, on_up) == (1, 1)
        assert seq1 == seq0 + 2
        sent = {seq0 + 1, seq0 + 2}
        assert wait_for(lambda: sent <= {s for s, _ in app.instrument_input.arrivals},
                        timeout=WAIT_MS / 1000)
    finally:
        page.close()
