"""A whole trajectory trial by keyboard on a laptop-sized, CPU-throttled page (issue #26.3).

The trainee's page at 1280x800 with the deforming abdomen, Chromium's CPU throttled 4x
(DevTools ``Emulation.setCPUThrottlingRate``), a scripted trainee steering the instrument
with the arrow keys and W/S in a closed loop *on what the page shows*:

1. look: the page's drawn tool tip (``/tool/tip``), the highlighted next point
   (``/trajectory/goal``) and the HUD's "Points reached" (its text content: no layout
   forced), read from the page as it was last drawn, never from the server;
2. plan: how long to hold each key so the tip moves from where it is drawn to the point,
   from the instrument's known behaviour (it pivots about its port; the arrows turn it
   along the view's right/up axes with the fulcrum effect, W/S advance/withdraw it at the
   mapping's rates), as a trainee who knows the controls would;
3. act: hold those keys for those durations (key-down/key-up events through DevTools'
   ``Input.dispatchKeyEvent``, all pressed at once, each stamped with the time it
   happens at, as a real keyboard's events are);
4. wait for the page to show the result: another point reached (the HUD counts it), or
   the drawn tip at rest for a moment (the last key presses have all arrived and been
   drawn); look again.

The test asserts that the trainee reaches every point of the trajectory by keyboard on this
page, and prints the trial time against the viewer's 180 s limit for free trials. The trial's
own limit here is :data:`TEST_LIMIT_S`: how fast a look comes is the host's figure, not the
code's (issue #31: a suite that fails by the machine's load blocks every landing). On a quiet
2-core host: 30 of 30 points in 143 s of trial time; beside a clean-clone ``make test`` and two
busy loops on the same 2 cores (load 4-7), 7 points in the first 180 s, the page applying under
one update a second. It prints whether the page said it was behind.
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
from vasim.viewer.app_options import TrialOptions
from vasim.viewer.controller import Command

LAPTOP = {"width": 1280, "height": 800}
THROTTLE = 4.0
LONGEST_PRESS_S = 0.6
"""Longest single key hold: a longer move is done in several looks (the instrument's
motion is not linear in the key time over large angles)."""
TRAINING_LIMIT_S = 180.0
"""The viewer's time limit of a free trial (``TrialOptions().max_time``), reported against."""
TEST_LIMIT_S = 900.0
"""This trial's limit: long enough for a loaded host (module doc)."""
REST_S = 0.25
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
        self.fulcrum = np.asarray(dev.port.fulcrum, dtype=float)
        self.right, self.up = (np.asarray(v, dtype=float) for v in app.controller.screen)
        m = dev.mapping
        self.turn = m.stick_rad_per_s * m.sensitivity       # rad per second of a held arrow
        self.advance = m.insert_m_per_s * m.sensitivity     # m per second of W/S
        self.fulcrum_effect = m.fulcrum_effect
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
        """Key holds [s] that move the tip from ``tip`` toward ``goal`` (one look's worth:
        all of the way, or :data:`LONGEST_PRESS_S` of it) and where they should take it."""
        shaft = tip - self.fulcrum
        depth = float(np.linalg.norm(shaft))
        shaft /= depth
        sign = -1.0 if self.fulcrum_effect else 1.0
        # Tip motion per radian along the view's right / up (the shaft turns about the
        # port: its component along the shaft is lost), and per metre of insertion.
        jac = np.column_stack([sign * (v - float(v @ shaft) * shaft) * depth
                               for v in (self.right, self.up)] + [shaft])
        a_r, a_u, ins = np.linalg.lstsq(jac, goal - tip, rcond=None)[0]
        holds = [("ArrowRight" if a_r > 0 else "ArrowLeft", abs(a_r) / self.turn),
                 ("ArrowUp" if a_u > 0 else "ArrowDown", abs(a_u) / self.turn),
                 ("KeyW" if ins > 0 else "KeyS", abs(ins) / self.advance)]
        longest = max(d for _, d in holds)
        scale = min(1.0, LONGEST_PRESS_S / longest) if longest > 0 else 1.0
        # A hold under 20 ms is left out (the page's batches come every 33 ms).
        return ([(k, d * scale) for k, d in holds if d * scale >= 0.02],
                tip + scale * (goal - tip))

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
                   timeout: float = 10.0) -> None:
        """Until the page shows another point reached, or draws the tip at rest after it
        has moved at least half way to ``aim`` (a page that has not drawn the presses yet
        shows the tip at rest where it was: looking then would repeat the presses), or
        ``timeout`` [s] (the tip blocked, e.g. by tissue)."""
        tip0, goal0 = before["tip"], before["goal"]
        half = 0.5 * float(np.linalg.norm(aim - tip0))
        last, since = None, time.monotonic()
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            s = self.shown()
            if s is None:
                return
            if (not s["goal_shown"] or s["reached"] != before["reached"]
                    or np.linalg.norm(s["goal"] - goal0) > 0.004):
                return                         # reached: the next point is highlighted
            if last is None or np.linalg.norm(s["tip"] - last) > 1e-5:
                last, since = s["tip"], time.monotonic()
            elif (time.monotonic() - since >= REST_S
                  and np.linalg.norm(s["tip"] - tip0) >= half):
                return
            time.sleep(0.1)  # each look costs the throttled page a little

    def steer(self, app: ViewerApp, timeout: float) -> None:
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            frame = app.snapshot.frame   # only to know when the trial is over
            if frame.done or frame.goal_index >= frame.n_points:
                return
            s = self.shown()
            if s is None or not s["goal_shown"]:
                time.sleep(0.1)
                continue
            self.looks += 1
            holds, aim = self.plan(s["tip"], s["goal"])
            if holds:
                self.act(holds)
            self.wait_shown(s, aim)


@pytest.mark.timeout(1500)  # 150 s on a quiet host; a loaded one runs the loop slower
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
