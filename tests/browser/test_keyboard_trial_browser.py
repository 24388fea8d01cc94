"""A whole trajectory trial by keyboard on a laptop-sized, CPU-throttled page (issue #26.3).

The trainee's page at 1280x800 with the deforming abdomen, Chromium's CPU throttled 4x
(DevTools ``Emulation.setCPUThrottlingRate``), the trainee steering the instrument with the
arrow keys and W/S in a closed loop: look where the goal is (the trial's state), press the
keys for as long as the gap needs, let go, wait until the page's input has reached the
instrument (its target stops moving: a condition, not a count of batches), look again. The
test asserts the trial ends with every point reached within its time limit and prints the
points reached and the times for the record.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from tests.browser.conftest import wait_ready
from vasim.haptics.laparoscopic import InputMapping
from vasim.viewer.app import ViewerApp
from vasim.viewer.controller import Command

LAPTOP = {"width": 1280, "height": 800}
THROTTLE = 4.0


@pytest.fixture(scope="module")
def app(browser: Any, tmp_path_factory: pytest.TempPathFactory) -> Iterator[ViewerApp]:
    db = str(tmp_path_factory.mktemp("keyboard") / "study.sqlite")
    a = ViewerApp(port=0, schema="vg", db=db, scene="default", countdown_s=1.0).start()
    try:
        yield a
    finally:
        a.stop()


def _settled(dev: Any, quiet_s: float = 0.4, timeout: float = 20.0) -> None:
    """Waits until the instrument's target has not moved for ``quiet_s`` (the page's
    batches for the last key presses have all arrived), at most ``timeout``."""
    last, since = repr(dev.target), time.monotonic()
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        time.sleep(0.05)
        now = repr(dev.target)
        if now != last:
            last, since = now, time.monotonic()
        elif time.monotonic() - since >= quiet_s:
            return


def _steer_all(app: ViewerApp, page: Any, timeout: float) -> int:
    right, up = app.controller.screen  # type: ignore[misc]
    dev = app.controller.instrument
    assert dev is not None
    rate = dev.mapping.stick_rad_per_s * dev.mapping.sensitivity
    speed = dev.mapping.insert_m_per_s * dev.mapping.sensitivity
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        frame = app.snapshot.frame
        if frame.done or frame.goal_index >= frame.n_points:
            break
        tip, goal = np.asarray(frame.tcp), np.asarray(frame.goal)
        shaft = tip - dev.port.fulcrum
        depth = float(np.linalg.norm(shaft))
        shaft /= depth
        jac = np.column_stack([-(v - float(v @ shaft) * shaft) * depth for v in (right, up)]
                              + [shaft])
        a_r, a_u, ins = np.linalg.lstsq(jac, goal - tip, rcond=None)[0]
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
        _settled(dev)
    return int(app.snapshot.frame.goal_index)


@pytest.mark.timeout(900)  # a 180 s trial (3x its limit in wall time on a loaded host)
def test_a_whole_trial_by_keyboard_on_a_throttled_laptop_page(app: ViewerApp,
                                                              browser: Any) -> None:
    page = browser.new_page(viewport=LAPTOP)
    try:
        page.goto(app.url)
        wait_ready(page, "/organs/liver")
        page.wait_for_function("() => window.__vasimInput !== undefined", timeout=60_000)
        page.context.new_cdp_session(page).send("Emulation.setCPUThrottlingRate",
                                                {"rate": THROTTLE})
        app.submit(Command("mode", "free"))
        app.submit(Command("input", "laparoscopic"))
        app.submit(Command("input_mapping", InputMapping(sensitivity=0.5)))
        n0 = app.snapshot.info.number
        app.submit(Command("start"))
        t_end = time.monotonic() + 60
        while time.monotonic() < t_end and not (
                app.snapshot.info.number > n0 and app.controller.instrument is not None
                and app.controller.countdown_until is None):
            time.sleep(0.05)
        info = app.snapshot.info
        assert app.controller.instrument is not None, app.errors[-3:]
        limit = float(info.config.max_time)
        wall0 = time.monotonic()
        reached = _steer_all(app, page, timeout=3.0 * limit)
        frame = app.snapshot.frame
        wall = time.monotonic() - wall0
        flow = app.flow_stats()
        print(f"\nkeyboard trial at 1280x800, CPU {THROTTLE:g}x throttled, abdomen on: "
              f"{reached} of {frame.n_points} points, trial time {frame.t:.1f} s of "
              f"{limit:.0f} s, wall {wall:.1f} s; page updates "
              f"{flow['trainee_page_update_hz_min']:.1f}/s, windows in flight peak "
              f"{flow['trainee_windows_ahead_peak']:.0f}, loop "
              f"{flow['realtime_factor_recent']:.2f}x real time")
        assert reached == frame.n_points, (reached, frame.n_points, frame.t)
        assert frame.t <= limit
    finally:
        page.close()
