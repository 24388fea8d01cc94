"""A whole trajectory trial by keyboard on a laptop-sized, CPU-throttled page (issue #26.3).

The trainee's page at 1280x800 with the deforming abdomen, Chromium's CPU throttled 4x
(DevTools ``Emulation.setCPUThrottlingRate``), a scripted trainee steering the instrument
with the arrow keys and W/S in a closed loop *on what the page shows*:

1. look: the page's drawn tool tip (``/tool/tip``), the highlighted next point
   (``/trajectory/goal``) and the HUD's "Points reached" (its text content: no layout
   forced), read from the page as it was last drawn, never from the server;
2. plan: how long to hold each key so the tip moves from where it is drawn to the point,
   as a trainee who knows the controls would: the holds are solved on the instrument's own
   mapping (it pivots about its port; the arrows turn it along the view's right/up axes
   with the fulcrum effect, W/S advance/withdraw it);
3. act: hold those keys for those durations (key events stamped with the times they stand
   for, handed to the page together: :meth:`PageTrainee.act` says why);
4. wait for the page to draw the result, a frame known to hold it (:meth:`PageTrainee
   .wait_shown`), or the HUD counting the point (then the next move is planned from where
   the holds take the tip, which the page has not drawn yet); look again.

Two earlier versions of this driver failed on a loaded host, and both taught something:
waiting for the drawn tip to rest looked mid-move (a page that updates twice a second draws
the tip still for half a second), and DevTools key events, each handed over only once the
page has handled it, made the page send detours the instrument does not undo exactly. The
second also found a product bug: a batch of input read after the next had replaced it
(``tests/viewer/test_instrument_batches.py``).

The test asserts that the trainee reaches every point of the trajectory by keyboard on this
page, and prints the trial time against the viewer's 180 s limit for free trials. The trial's
own limit here is :data:`TEST_LIMIT_S`: how fast a look comes is the host's figure, not the
code's (issue #31: a suite that fails by the machine's load blocks every landing). On a quiet
2-core host and beside two busy loops: see the figures printed (the closing notes of issues
#26 and #31 record them). It prints whether the page said it was behind.
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
from vasim.viewer.flow import MARK_NODE

LAPTOP = {"width": 1280, "height": 800}
THROTTLE = 4.0
LONGEST_PRESS_S = 0.8
"""Longest single key hold: a longer move is done in several looks (a batch turns the
instrument at most 45 degrees: 1 s of an arrow key)."""
TRAINING_LIMIT_S = 180.0
"""The viewer's time limit of a free trial (``TrialOptions().max_time``), reported against."""
TEST_LIMIT_S = 900.0
"""This trial's limit: long enough for a loaded host (module doc)."""
SETTLE_FRAMES = 4
"""View frames (40 Hz) after the instrument has taken the last batch by which it has
settled (its smoothing: 15 ms)."""
"""The drawn tip has not moved for this long: the page shows the result of the presses."""

KEYS = {"ArrowLeft": "ArrowLeft", "ArrowUp": "ArrowUp", "ArrowRight": "ArrowRight",
        "ArrowDown": "ArrowDown", "KeyW": "w", "KeyS": "s"}
"""DOM ``code`` -> ``key`` of the keys the driver uses."""

KEYS_JS = r"""(holds) => {
  const t0 = performance.now();
  const key = (type, code, name, t) => {
    const e = new KeyboardEvent(type, {code: code, key: name, bubbles: true,
                                       cancelable: true});
    Object.defineProperty(e, "timeStamp", {value: t});
    window.dispatchEvent(e);
  };
  for (const [code, name] of holds) { key("keydown", code, name, t0); }
  for (const [code, name, ms] of holds) { key("keyup", code, name, t0 + ms); }
}"""
"""Presses and releases keys in the page, each event stamped with the time it stands for."""

SHOWN_JS = r"""(markName) => {
  const n = window.__viserMutable && window.__viserMutable.nodeRefFromName;
  const tip = n && n['/tool/tip'], goal = n && n['/trajectory/goal'];
  const mark = n && n[markName], input = window.__vasimInput;
  if (!tip || !goal || !mark || !input) { return null; }
  const text = document.body.textContent;
  const hud = /Points reached\s*(\d+) of (\d+)/.exec(text);
  return {tip: tip.position.toArray(), goal: goal.position.toArray(),
          goalShown: goal.visible, reached: hud ? Number(hud[1]) : null,
          behind: /Running behind|This page is behind/.test(text),
          frame: Math.round(mark.position.x), quiet: input.quiet, sent: input.seq};
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

    def __init__(self, app: ViewerApp, page: Any):
        dev = app.controller.instrument
        assert dev is not None and app.controller.screen is not None
        self.page = page
        self.port, self.mapping = dev.port, dev.mapping
        self.fulcrum = np.asarray(dev.port.fulcrum, dtype=float)
        self.right, self.up = (np.asarray(v, dtype=float) for v in app.controller.screen)
        self.marks, self.input = app.acks.marks, app.instrument_input
        self.looks = 0
        self.timeouts = 0
        self.presses = 0
        self.told_behind = False
        """The page showed a "running behind" line at some look."""

    def shown(self) -> dict[str, Any] | None:
        s = self.page.evaluate(SHOWN_JS, MARK_NODE)
        if s is None:
            return None
        self.told_behind = self.told_behind or bool(s["behind"])
        return {"tip": np.asarray(s["tip"], dtype=float),
                "goal": np.asarray(s["goal"], dtype=float), "goal_shown": s["goalShown"],
                "reached": s["reached"], "frame": int(s["frame"]), "quiet": bool(s["quiet"]),
                "sent": int(s["sent"])}

    def plan(self, tip: np.ndarray,
             goal: np.ndarray) -> tuple[list[tuple[str, float]], np.ndarray]:
        """Key holds [s] that move the drawn tip from ``tip`` to ``goal`` (one look's worth:
        all of the way, or :data:`LONGEST_PRESS_S` of it) and where they should take it.

        The trainee knows the controls: the holds are solved (Newton's method) on the
        instrument's own mapping (:meth:`InputMapping.apply`, one batch: :meth:`act`) from
        the pose whose tip is at ``tip`` (the shaft passes the port)."""
        pose = self.pose_of(tip)   # the drawn tool is the instrument's tip
        aim = goal
        t = self._solve(pose, goal - tip)
        longest = float(np.max(np.abs(t)))
        if longest > LONGEST_PRESS_S:           # part of the way: re-solved for that part
            aim = tip + (LONGEST_PRESS_S / longest) * (goal - tip)
            t = self._solve(pose, aim - tip)
            t *= min(1.0, LONGEST_PRESS_S / float(np.max(np.abs(t))))
        t = np.where(np.abs(t) >= 0.01, t, 0.0)  # under 10 ms: under 0.5 mm, left out
        holds = [("ArrowRight" if t[0] > 0 else "ArrowLeft", abs(t[0])),
                 ("ArrowUp" if t[1] > 0 else "ArrowDown", abs(t[1])),
                 ("KeyW" if t[2] > 0 else "KeyS", abs(t[2]))]
        holds = [(k, float(d)) for k, d in holds if d > 0]
        return holds, aim

    def pose_of(self, tip: np.ndarray) -> InstrumentPose:
        """The pose whose tip is at ``tip`` (the shaft passes the port; roll is free)."""
        shaft = tip - self.fulcrum
        local = self.port.frame.T @ (shaft / np.linalg.norm(shaft))
        return InstrumentPose(yaw=math.atan2(local[0], local[2]),
                              pitch=-math.asin(float(np.clip(local[1], -1.0, 1.0))),
                              insertion=float(np.linalg.norm(shaft)))

    def predict(self, pose: InstrumentPose, t: np.ndarray) -> InstrumentPose:
        """The pose after holding right/up/advance for ``t`` [s] (signed: left/down/withdraw
        negative): the page sends such a set of holds as one batch (:meth:`act`)."""
        return self.mapping.apply(self.port, pose, Increment(
            stick_x_s=float(t[0]), stick_y_s=float(-t[1]), insert_s=float(t[2])),
            screen=(self.right, self.up))

    def _solve(self, pose: InstrumentPose, move: np.ndarray) -> np.ndarray:
        """Signed holds that move the tip of ``pose`` by ``move``, or as near as the port's
        cone allows (Gauss-Newton with step halving)."""
        tip0 = tip_position(self.port, pose)

        def moved(t: np.ndarray) -> np.ndarray:
            return tip_position(self.port, self.predict(pose, t)) - tip0

        t = np.zeros(3)
        miss = move.copy()
        for _ in range(10):
            if np.linalg.norm(miss) < 2e-4:
                break
            # Central differences over 20 ms of hold: at the cone's rim a one-sided
            # difference outward is zero and would leave that key out for good.
            jac = np.column_stack([(moved(t + h) - moved(t - h)) / 0.02
                                   for h in np.eye(3) * 0.01])
            step = np.linalg.lstsq(jac, miss, rcond=1e-3)[0]
            for _ in range(6):
                trial = np.clip(t + step, -3.0, 3.0)
                trial_miss = move - moved(trial)
                if np.linalg.norm(trial_miss) < np.linalg.norm(miss):
                    t, miss = trial, trial_miss
                    break
                step = step / 2
            else:
                break
        if np.linalg.norm(miss) > 0.5 * np.linalg.norm(move):
            # The model is stuck (the tip at the cone's rim, or a pose the drawn tip only
            # approximates): turn straight toward the point as the shaft pivots, linearly.
            shaft = tip0 - self.fulcrum
            depth = float(np.linalg.norm(shaft))
            shaft /= depth
            sign = -1.0 if self.mapping.fulcrum_effect else 1.0
            k = self.mapping.sensitivity
            jac = np.column_stack(
                [sign * (v - float(v @ shaft) * shaft) * depth * self.mapping.stick_rad_per_s * k
                 for v in (self.right, self.up)] + [shaft * self.mapping.insert_m_per_s * k])
            t = np.linalg.lstsq(jac, move, rcond=None)[0]
        return t

    def act(self, holds: list[tuple[str, float]]) -> None:
        """Holds the keys, all pressed at once, each released after its time.

        The page takes a hold's length from its key events' time stamps (a busy page
        handles events late; the stamps say when the key moved). The events are made in
        the page, stamped, and handed to it in one task (:data:`KEYS_JS`): the page sees
        the release with the press, as it does whenever it lags a hold behind the
        keyboard. (DevTools' ``Input.dispatchKeyEvent`` waits until the page has handled
        each event: on a loaded throttled page a press took a second to hand over, the
        page counted that second as held and sent it, and took it back with the release
        a batch later; the instrument, clipped at 45 degrees a batch and at its port's
        cone, does not undo such a detour exactly: moves came out 30-50 mm off.)"""
        self.page.evaluate(KEYS_JS, [[code, KEYS[code], d * 1000.0]
                                     for code, d in holds])
        self.presses += len(holds)

    def wait_shown(self, before: dict[str, Any], timeout: float = 120.0) -> bool:
        """Until the page shows another point reached (True: the HUD counts it) or draws
        the frame that holds the result of the holds (False).

        That frame is known, not guessed: the page says when it has sent every key event
        (``__vasimInput.quiet``, its last batch numbered ``seq``); the server says when the
        instrument has taken that batch (``InstrumentInput.last_seq``); the view frames it
        makes from then on (each carries a frame mark, ``/vasim/frame``) include the last of
        the motion once the instrument has settled (:data:`SETTLE_FRAMES`); the page's
        drawn mark says when it applied one. Only *when* comes from the server; *what* the
        trainee sees is the page's. (A margin of time instead failed at load 8: a loaded
        server took the last batch after the margin, the page drew the tip mid-move. A page
        that updates twice a second draws the tip still for half a second mid-move: "at
        rest for a moment" is not a result either.)"""
        t_end = time.monotonic() + timeout
        target: int | None = None
        while time.monotonic() < t_end:
            s = self.shown()
            if s is None:
                return False
            if not s["goal_shown"] or (s["reached"] or 0) > (before["reached"] or 0):
                return True
            if target is None and s["quiet"] and self.input.last_seq >= s["sent"]:
                target = self.marks.seq + SETTLE_FRAMES
            if target is not None and s["frame"] >= target:
                return False
            time.sleep(0.1)  # each look costs the throttled page a little
        self.timeouts += 1
        return False

    def steer(self, app: ViewerApp, timeout: float) -> None:
        t_end = time.monotonic() + timeout
        resting: np.ndarray | None = None
        first = self.marks.seq + SETTLE_FRAMES   # the trial runs: a frame of it
        while time.monotonic() < t_end:
            frame = app.snapshot.frame   # only to know when the trial is over
            if frame.done or frame.goal_index >= frame.n_points:
                return
            s = self.shown()
            if s is None or not s["goal_shown"] or s["frame"] < first:
                time.sleep(0.1)   # not yet a picture of this trial (a loaded page lags)
                continue
            self.looks += 1
            # Right after a point is reached the drawn tip is still on its way to where the
            # last holds take it: the trainee plans the next move from there.
            start = s["tip"] if resting is None else resting
            holds, aim = self.plan(start, s["goal"])
            if holds:
                self.act(holds)
            resting = aim if self.wait_shown(s) else None


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
        trainee = PageTrainee(app, page)
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
              f"looks ({trainee.timeouts} waited out), {trainee.presses} key holds; page updates "
              f"{flow['trainee_page_update_hz_min']:.1f}/s, windows in flight peak "
              f"{flow['trainee_windows_ahead_peak']:.0f}, loop "
              f"{flow['realtime_factor_recent']:.2f}x real time; the page said it was behind: "
              f"{trainee.told_behind}")
        assert reached == frame.n_points, (reached, frame.n_points, frame.t, flow)
        assert frame.t <= limit
    finally:
        page.close()
