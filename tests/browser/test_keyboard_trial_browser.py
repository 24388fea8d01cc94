"""A whole trajectory trial by keyboard on a laptop-sized, CPU-throttled page (issue #26.3).

The trainee's page at 1280x800 with the deforming abdomen, Chromium's CPU throttled 4x
(DevTools ``Emulation.setCPUThrottlingRate``), a scripted trainee steering the instrument
with the arrow keys and W/S in a closed loop *on what the page shows*:

1. look: the page's drawn tool tip (``/tool/tip``), the highlighted next point
   (``/trajectory/goal``) and the HUD's "Points reached" (its text content: no layout
   forced), read from the page as it was last drawn, never from the server;
2. plan: how long to hold each key so the tip moves from where it is drawn to the point,
   from the instrument's known behaviour, as a trainee who knows the controls would: the
   holds are solved on the instrument's own mapping (it pivots about its port; the arrows
   turn it along the view's right/up axes with the fulcrum effect, W/S advance/withdraw it),
   fed in the page's 33 ms batches;
3. act: hold those keys for those durations (key-down/key-up events through DevTools'
   ``Input.dispatchKeyEvent``, all pressed at once, each stamped with the time it
   happens at, as a real keyboard's events are);
4. wait for the page to show the result: another point reached (the HUD counts it; the
   next move is planned from where the holds take the tip, which the page has not drawn
   yet), or the drawn tip where the holds were to take it, or blocked; look again.

A page that updates twice a second draws the tip still for half a second mid-move, so "at
rest for a moment" is not a result: the first version of this driver looked then, planned
from a stale tip and overshot (112 looks on a quiet host, 409 at load 8-10).

The test asserts that the trainee reaches every point of the trajectory by keyboard on this
page, and prints the trial time against the viewer's 180 s limit for free trials. The trial's
own limit here is :data:`TEST_LIMIT_S`: how fast a look comes is the host's figure, not the
code's (issue #31: a suite that fails by the machine's load blocks every landing). On a quiet
2-core host: 30 of 30 points in 117 s of trial time in 45 looks (the page at 2.3 updates/s).
It prints whether the page said it was behind.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from tests.browser.conftest import wait_ready
from vasim.haptics.laparoscopic import Increment, InputMapping, InstrumentPose, tip_position
from vasim.viewer.app import ViewerApp
from vasim.viewer.app_options import TrialOptions
from vasim.viewer.controller import Command

LAPTOP = {"width": 1280, "height": 800}
THROTTLE = 4.0
LONGEST_PRESS_S = 1.5
"""Longest single key hold: a longer move is done in several looks."""
BATCH_S = 0.033
"""The page sends the keys' held times every 33 ms (:mod:`vasim.viewer.instrument_input`)."""
TRAINING_LIMIT_S = 180.0
"""The viewer's time limit of a free trial (``TrialOptions().max_time``), reported against."""
TEST_LIMIT_S = 900.0
"""This trial's limit: long enough for a loaded host (module doc)."""
STUCK_S = 2.0
"""The drawn tip has not moved for this long (several page updates): it is blocked."""
ARRIVED_M = 1e-3
"""The drawn tip is this close to where the holds were to take it: the page shows their
result (what is left of the motion is under the point's 5 mm reach radius)."""
"""The drawn tip has not moved for this long: the page shows the result of the presses."""

KEYS = {"ArrowLeft": ("ArrowLeft", 37), "ArrowUp": ("ArrowUp", 38),
        "ArrowRight": ("ArrowRight", 39), "ArrowDown": ("ArrowDown", 40),
        "KeyW": ("w", 87), "KeyS": ("s", 83)}
"""DOM ``code`` -> (``key``, virtual key code) of the keys the driver uses."""

SHOWN_JS = r"""() => {
  const n = window.__viserMutable && window.__viserMutable.nodeRefFromName;
  const tip = n && n['/tool/tip'], goal = n && n['/trajectory/goal'];
  if (!tip || !goal) { return null; }
  const text = document.body.textContent;
  const hud = /Points reached\s*(\d+) of (\d+)/.exec(text);
  return {tip: tip.position.toArray(), goal: goal.position.toArray(),
          goalShown: goal.visible, reached: hud ? Number(hud[1]) : null,
          behind: /Running behind|This page is behind/.test(text)};
}"""


@pytest.fixture(scope="module")
def app(browser: Any, tmp_path_factory: pytest.TempPathFactory) -> Iterator[ViewerApp]:
    db = str(tmp_path_factory.mktemp("keyboard") / "study.sqlite")
    a = ViewerApp(port=0, scene="default", db=db,
                  trials=TrialOptions(schema="vg", countdown_s=1.0,
                                      max_time=TEST_LIMIT_S)).start()
    try:
        yield a
    finally:
        a.stop()


class PageTrainee:
    """Steers by what the page draws (module doc)."""

    def __init__(self, app: ViewerApp, page: Any, cdp: Any):
        dev = app.controller.instrument
        assert dev is not None and app.controller.screen is not None
        self.page, self.cdp = page, cdp
        self.port, self.mapping = dev.port, dev.mapping
        self.fulcrum = np.asarray(dev.port.fulcrum, dtype=float)
        self.right, self.up = (np.asarray(v, dtype=float) for v in app.controller.screen)
        self.looks = 0
        self.presses = 0
        self.told_behind = False
        """The page showed a "running behind" line at some look."""

    def shown(self) -> dict[str, Any] | None:
        s = self.page.evaluate(SHOWN_JS)
        if s is None:
            return None
        self.told_behind = self.told_behind or bool(s["behind"])
        return {"tip": np.asarray(s["tip"], dtype=float),
                "goal": np.asarray(s["goal"], dtype=float), "goal_shown": s["goalShown"],
                "reached": s["reached"]}

    def plan(self, tip: np.ndarray,
             goal: np.ndarray) -> tuple[list[tuple[str, float]], np.ndarray]:
        """Key holds [s] that move the tip from ``tip`` to ``goal`` (one look's worth: all
        of the way, or :data:`LONGEST_PRESS_S` of it) and where they should take it.

        The trainee knows the controls: the holds are solved (Newton's method) on the
        instrument's own mapping (:meth:`InputMapping.apply`), fed the page's 33 ms batches
        of those holds, from the pose the drawn tip implies (the shaft passes the port)."""
        aim = goal
        t = self._solve(tip, aim)
        longest = float(np.max(np.abs(t)))
        if longest > LONGEST_PRESS_S:           # part of the way: re-solved for that part
            aim = tip + (LONGEST_PRESS_S / longest) * (goal - tip)
            t = self._solve(tip, aim)
            t *= min(1.0, LONGEST_PRESS_S / float(np.max(np.abs(t))))
        holds = [("ArrowRight" if t[0] > 0 else "ArrowLeft", abs(t[0])),
                 ("ArrowUp" if t[1] > 0 else "ArrowDown", abs(t[1])),
                 ("KeyW" if t[2] > 0 else "KeyS", abs(t[2]))]
        # A hold under 10 ms is left out (the instrument moves under 0.5 mm in it).
        return [(k, d) for k, d in holds if d >= 0.01], aim

    def _pose(self, tip: np.ndarray) -> InstrumentPose:
        shaft = tip - self.fulcrum
        local = self.port.frame.T @ (shaft / np.linalg.norm(shaft))
        return InstrumentPose(yaw=math.atan2(local[0], local[2]),
                              pitch=-math.asin(float(np.clip(local[1], -1.0, 1.0))),
                              insertion=float(np.linalg.norm(shaft)))

    def predict(self, tip: np.ndarray, t: np.ndarray) -> np.ndarray:
        """The tip after holding right/up/advance for ``t`` [s] (signed: left/down/withdraw
        negative), as the page sends it: a batch every 33 ms of the time each key was held
        in it."""
        pose = self._pose(tip)
        span = float(np.max(np.abs(t)))
        for j in range(max(1, math.ceil(span / BATCH_S))):
            lo, hi = j * BATCH_S, (j + 1) * BATCH_S
            part = np.sign(t) * np.clip(np.minimum(np.abs(t), hi) - lo, 0.0, None)
            pose = self.mapping.apply(self.port, pose, Increment(
                stick_x_s=float(part[0]), stick_y_s=float(-part[1]),
                insert_s=float(part[2])), screen=(self.right, self.up))
        return tip_position(self.port, pose)

    def _solve(self, tip: np.ndarray, aim: np.ndarray) -> np.ndarray:
        """Signed holds that take ``tip`` to ``aim``, or as near as the port's cone allows
        (Gauss-Newton with step halving: at the cone's rim the model stops moving)."""
        t = np.zeros(3)
        miss = aim - self.predict(tip, t)
        for _ in range(10):
            if np.linalg.norm(miss) < 2e-4:
                break
            now = aim - miss
            jac = np.column_stack([(self.predict(tip, t + h) - now) / 1e-3
                                   for h in np.eye(3) * 1e-3])
            step = np.linalg.lstsq(jac, miss, rcond=1e-3)[0]
            for _ in range(6):
                trial = np.clip(t + step, -3.0, 3.0)
                trial_miss = aim - self.predict(tip, trial)
                if np.linalg.norm(trial_miss) < np.linalg.norm(miss):
                    t, miss = trial, trial_miss
                    break
                step = step / 2
            else:
                break
        return t

    def act(self, holds: list[tuple[str, float]]) -> None:
        """Holds the keys, all pressed at once, each released after its time. Each key
        event carries the time it happens at, as a real keyboard's do (the page measures
        holds by event time stamps): on a throttled page a key event waits for its main
        thread, and the wait must not lengthen the hold."""
        t0, w0 = time.monotonic(), time.time()
        for key, _ in holds:
            self._key("keyDown", key, w0)
        for key, d in sorted(holds, key=lambda kd: kd[1]):
            time.sleep(max(0.0, t0 + d - time.monotonic()))
            self._key("keyUp", key, w0 + d)
        self.presses += len(holds)

    def _key(self, kind: str, code: str, stamp: float) -> None:
        key, vk = KEYS[code]
        self.cdp.send("Input.dispatchKeyEvent", {
            "type": kind, "key": key, "code": code, "windowsVirtualKeyCode": vk,
            "nativeVirtualKeyCode": vk, "timestamp": stamp})

    def wait_shown(self, before: dict[str, Any], aim: np.ndarray,
                   timeout: float = 10.0) -> bool:
        """Until the page shows another point reached (True), or draws the tip where the
        holds were to take it (:data:`ARRIVED_M`), or not moving for :data:`STUCK_S`
        (blocked, e.g. by tissue), or ``timeout`` [s] (False). A page that has not drawn
        the presses yet shows the tip at rest where it was, for as long as it takes to
        draw the next update: waiting for the drawn tip to *arrive* never looks then."""
        last, since = None, time.monotonic()
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            s = self.shown()
            if s is None:
                return False
            if not s["goal_shown"] or s["reached"] != before["reached"]:
                return True                    # reached: the HUD counts it
            if np.linalg.norm(s["tip"] - aim) <= ARRIVED_M:
                return False                   # drawn where the holds were to take it
            if last is None or np.linalg.norm(s["tip"] - last) > 1e-5:
                last, since = s["tip"], time.monotonic()
            elif time.monotonic() - since >= STUCK_S:
                return False
            time.sleep(0.1)  # each look costs the throttled page a little
        return False

    def steer(self, app: ViewerApp, timeout: float) -> None:
        t_end = time.monotonic() + timeout
        resting: np.ndarray | None = None
        while time.monotonic() < t_end:
            frame = app.snapshot.frame   # only to know when the trial is over
            if frame.done or frame.goal_index >= frame.n_points:
                return
            s = self.shown()
            if s is None or not s["goal_shown"]:
                time.sleep(0.1)
                continue
            self.looks += 1
            # Right after a point is reached the drawn tip is still on its way to where the
            # last holds take it: the trainee plans the next move from there.
            start = s["tip"] if resting is None else resting
            holds, aim = self.plan(start, s["goal"])
            if holds:
                self.act(holds)
            resting = aim if self.wait_shown(s, aim) else None


@pytest.mark.timeout(1500)  # 120 s on a quiet host; a loaded one runs the loop slower
def test_a_whole_trial_by_keyboard_on_a_throttled_laptop_page(app: ViewerApp,
                                                              browser: Any) -> None:
    page = browser.new_page(viewport=LAPTOP)
    try:
        page.goto(app.url)
        wait_ready(page, "/organs/liver")
        page.wait_for_function("() => window.__vasimInput !== undefined", timeout=60_000)
        cdp = page.context.new_cdp_session(page)
        cdp.send("Emulation.setCPUThrottlingRate", {"rate": THROTTLE})
        app.submit(Command("mode", "free"))
        app.submit(Command("input", "laparoscopic"))
        n0 = app.snapshot.info.number
        app.submit(Command("start"))
        t_end = time.monotonic() + 120
        while time.monotonic() < t_end and not (
                app.snapshot.info.number > n0 and app.controller.instrument is not None
                and app.controller.countdown_until is None):
            time.sleep(0.05)
        info = app.snapshot.info
        assert app.controller.instrument is not None, app.errors[-3:]
        assert isinstance(app.controller.instrument.mapping, InputMapping)
        limit = float(info.config.max_time)
        assert limit == TEST_LIMIT_S
        trainee = PageTrainee(app, page, cdp)
        wall0 = time.monotonic()
        trainee.steer(app, timeout=1300.0)
        frame = app.snapshot.frame
        wall = time.monotonic() - wall0
        reached = min(int(frame.goal_index), frame.n_points)
        flow = app.flow_stats()
        print(f"\nkeyboard trial at 1280x800, CPU {THROTTLE:g}x throttled, abdomen on: "
              f"{reached} of {frame.n_points} points, trial time {frame.t:.1f} s "
              f"({'within' if frame.t <= TRAINING_LIMIT_S else 'over'} the "
              f"{TRAINING_LIMIT_S:.0f} s of a free trial), wall {wall:.1f} s; {trainee.looks} "
              f"looks, {trainee.presses} key holds; page updates "
              f"{flow['trainee_page_update_hz_min']:.1f}/s, windows in flight peak "
              f"{flow['trainee_windows_ahead_peak']:.0f}, loop "
              f"{flow['realtime_factor_recent']:.2f}x real time; the page said it was behind: "
              f"{trainee.told_behind}")
        assert reached == frame.n_points, (reached, frame.n_points, frame.t, flow)
        assert frame.t <= limit
    finally:
        page.close()
