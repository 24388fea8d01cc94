"""In a real browser: the trainee drives the laparoscopic instrument with the keyboard and
the mouse through a trial the experimenter's page starts and stops (issue #19 §2, §5)."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from tests.browser.conftest import VIEWPORT, wait_for, wait_ready
from vasim.haptics.laparoscopic import InputMapping
from vasim.viewer.app import ViewerApp
from vasim.viewer.controller import Command


@pytest.fixture(scope="module")
def app(browser: Any, tmp_path_factory: pytest.TempPathFactory) -> Iterator[ViewerApp]:
    db = str(tmp_path_factory.mktemp("instrument") / "study.sqlite")
    a = ViewerApp(port=0, schema="vg", db=db, scene="none", view_hz=15.0).start()
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
        presses = [(k, min(d, 0.6)) for k, d in presses if d > 0.01]
        t0 = time.monotonic()
        for key, _ in presses:
            page.keyboard.down(key)
        for key, d in sorted(presses, key=lambda kd: kd[1]):
            time.sleep(max(0.0, t0 + d - time.monotonic()))
            page.keyboard.up(key)
        time.sleep(0.25)  # the page sends, the device smooths, the view updates
    return int(app.snapshot.frame.goal_index)


def test_a_trainee_reaches_five_points_with_keyboard_and_mouse(app: ViewerApp,
                                                               browser: Any) -> None:
    exp = browser.new_page(viewport=VIEWPORT)
    trainee = browser.new_page(viewport=VIEWPORT)
    try:
        exp.goto(app.experimenter_url)
        wait_ready(exp)
        trainee.goto(app.url)
        wait_ready(trainee)
        trainee.wait_for_function("() => window.__vasimInput !== undefined", timeout=20_000)
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
        dev = app.controller.instrument
        assert dev is not None and dev.mapping.sensitivity == 0.5
        # The mouse: the wheel advances the instrument once the view has the pointer.
        trainee.mouse.click(VIEWPORT["width"] * 0.3, VIEWPORT["height"] * 0.5)
        locked = trainee.evaluate("() => window.__vasimInput.locked")
        depth0 = dev.target.insertion
        if locked:
            trainee.mouse.wheel(0, -300)         # 3 lines forward: +6 mm at sensitivity 0.5
            assert wait_for(lambda: dev.target.insertion > depth0 + 0.004), dev.target
            trainee.mouse.move(VIEWPORT["width"] * 0.3 + 40, VIEWPORT["height"] * 0.5)
            trainee.keyboard.press("Escape")
        else:                                    # no pointer lock: keys only (said below)
            trainee.keyboard.down("KeyW")
            time.sleep(0.3)
            trainee.keyboard.up("KeyW")
            assert wait_for(lambda: dev.target.insertion > depth0 + 0.003), dev.target
        # The keyboard: five points of the trajectory.
        reached = _steer(app, trainee, 5, timeout=90.0)
        print("DBG", reached, app.instrument_input.batches, app.instrument_input.refused,
              trainee.evaluate("() => window.__vasimInput"), app.controller.instrument is dev)
        assert reached >= 5, (reached, app.snapshot.frame.t, app.errors[-3:])
        assert app.instrument_input.batches > 20
        sent = trainee.evaluate("() => window.__vasimInput.sent")
        assert sent >= app.instrument_input.batches
        # The experimenter stops it; the trial is stored with the input that drove it.
        tid = app.snapshot.info.trial_id
        exp.get_by_role("button", name="Stop trial").click(force=True)
        assert wait_for(lambda: not app.panel.running), app.panel.status
        row = app.controller.store().trial(tid)
        assert row["operator"] == "laparoscopic"
        print(f"pointer lock in headless Chromium: {locked}")
    finally:
        trainee.close()
        exp.close()
