"""The trainee's instrument in the browser: mouse (pointer lock), keyboard, gamepad.

Without a haptic device the trainee moves a laparoscopic instrument pivoting about its
trocar (:mod:`vasim.haptics.laparoscopic`). The page captures the input and sends it to the
server in batches; the server turns each batch into motion of the running trial's
:class:`~vasim.haptics.devices.laparoscopic.LaparoscopicDevice`, which the 1 kHz loop reads
like any device (guarded, recorded, replayable).

Controls (shown on the trainee's page):

* **Mouse**: click the view to lock the pointer (Esc releases it); moving the mouse turns
  the instrument about its port; the wheel advances/withdraws it (over the view also
  without the lock: the trainee's camera is the endoscope, which the wheel never zooms).
* **Keyboard**: arrow keys turn the instrument, W/S advance/withdraw, Q/E roll.
* **Gamepad** (the browser's Gamepad API, when one is connected): the left stick turns,
  the right stick's vertical axis advances/withdraws and its horizontal axis rolls.

The fulcrum effect is on by default (the tip moves opposite to the hand, as through a real
port); the experimenter's page can switch it off and set the sensitivity (stored with the
trial's configuration).

Transport (**decision**): viser 1.1 has no client-to-server channel for custom data, so the
page writes each batch as JSON into a hidden GUI text field through viser's own message
(``GuiUpdateMessage``), which reaches :meth:`InstrumentInput._apply` through the field's
``on_update`` callback. Batches are sent every 33 ms while there is input (30 Hz: the
device smooths them for the 1 kHz loop), and at once when a key is pressed or released,
and carry a sequence number so that two equal batches are both delivered. **Latency**
(issue #26.2, measured with ``bench/viewer.py``'s throttled run, 4x, 2026-12-02): on a page
drawing a frame every ~300 ms, the key handler ran 3-330 ms after the press and the next
timer tick sent its batch up to 230 ms after that; a press now leaves with its handler.
The page's keys are taken in the capture phase, so viser's own keyboard camera controls
never see them; pointer events over the 3-D view are taken too (**decision**: the trainee's
camera is the endoscope, so viser's orbit controls must not move it; only Mag or the scope's
aim do). ``window.__vasimInput`` exposes counters for tests.
"""

from __future__ import annotations

import collections
import json
import logging
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import viser

from vasim.haptics.devices.laparoscopic import LaparoscopicDevice
from vasim.haptics.laparoscopic import Increment, InputMapping, InstrumentPose, Port
from vasim.viewer.audio import run_js

log = logging.getLogger(__name__)

MAX_BATCH_CHARS = 2000
"""Longest batch accepted from a page (a batch is ~150 characters)."""

CONTROLS_TEXT = (
    "**Instrument**: click the view to take the mouse (Esc gives it back), then move it to "
    "turn the instrument about its port; wheel = advance/withdraw. Keyboard: arrows turn, "
    "W/S advance/withdraw, Q/E roll. A gamepad works too.")

CONTROL_JS = r"""
(function () {
  var UUID = "%(uuid)s";
  if (window.__vasimInput && window.__vasimInput.uuid === UUID) { return; }
  var S = window.__vasimInput = {uuid: UUID, sent: 0, locked: false, seq: 0, held: {},
                                 quiet: true};
  var acc = {dx: 0, dy: 0, wheel: 0}, heldFor = {};
  var KEYS = {ArrowLeft: 1, ArrowRight: 1, ArrowUp: 1, ArrowDown: 1, KeyW: 1, KeyS: 1,
              KeyQ: 1, KeyE: 1};
  // Held keys count by their real duration (event time stamps), not by how often the
  // batch timer fires: a busy page (software WebGL) fires it late and handles events late.
  function release(code, now) {
    if (S.held[code] === undefined) { return; }
    heldFor[code] = (heldFor[code] || 0) + (now - S.held[code]) / 1000;
    delete S.held[code];
  }
  function onKey(down) {
    return function (e) {
      if (!KEYS[e.code]) { return; }
      var t = e.target;
      if (t && (t.tagName === "INPUT" || t.tagName === "TEXTAREA")) { return; }
      // The event's own time stamp: when the key moved, even if a busy page handles the
      // event later.
      var now = e.timeStamp || performance.now();
      S.quiet = false;
      var fresh = false;
      if (down) {
        fresh = S.held[e.code] === undefined;
        if (fresh) { S.held[e.code] = now; }
        S.lastDown = {code: e.code, t: now};  // for bench/viewer.py's latency (it cannot
      }                                       // listen itself: the event stops here)
      else { release(e.code, now); }
      e.preventDefault(); e.stopImmediatePropagation();
      // A new press or a release is sent at once, not at the next tick: on a busy page the
      // handler itself runs late (the time since the press is then already held time) and
      // the 33 ms timer later still (module doc, "latency").
      var sent = S.sent;
      if (fresh || !down) { flush(); }
      // the handler's time and the press's batch (0: none was sent), for the bench
      if (fresh) { S.lastDown.h = performance.now(); S.lastDown.seq = S.sent > sent ? S.seq : 0; }
    };
  }
  window.addEventListener("keydown", onKey(true), true);
  window.addEventListener("keyup", onKey(false), true);
  window.addEventListener("blur", function () {
    var now = performance.now();
    for (var c in S.held) { release(c, now); }
  });
  // The 3-D view is the canvas that fills the page (the page has other, small canvases).
  function isView(el) {
    return !!el && el.tagName === "CANVAS" && el.clientWidth >= window.innerWidth * 0.5;
  }
  document.addEventListener("pointerlockchange", function () {
    S.locked = isView(document.pointerLockElement);
  });
  document.addEventListener("click", function (e) {
    var c = e.target;
    if (isView(c) && !S.locked && c.requestPointerLock) {
      try { var r = c.requestPointerLock(); if (r && r.catch) { r.catch(function () {}); } }
      catch (err) { /* no pointer lock here: keyboard and gamepad still work */ }
    }
  }, true);
  // The trainee's camera is the endoscope: viser's orbit controls never get the pointer
  // over the 3-D view (the click that takes the pointer still fires).
  ["pointerdown", "pointermove", "pointerup"].forEach(function (type) {
    document.addEventListener(type, function (e) {
      if (isView(e.target)) { e.stopImmediatePropagation(); }
    }, true);
  });
  document.addEventListener("mousemove", function (e) {
    if (!S.locked) { return; }
    acc.dx += e.movementX || 0; acc.dy += e.movementY || 0;
    e.stopImmediatePropagation();
  }, true);
  document.addEventListener("wheel", function (e) {
    if (!S.locked && !isView(e.target)) { return; }
    acc.wheel += -e.deltaY / 100.0;
    e.preventDefault(); e.stopImmediatePropagation();
  }, {capture: true, passive: false});
  function axis(v) { return Math.abs(v) < 0.15 ? 0 : v; }
  function held(code) { return heldFor[code] || 0; }
  var last = performance.now();
  function flush() {
    var now = performance.now(), dt = Math.min(0.25, (now - last) / 1000); last = now;
    for (var c in S.held) { release(c, now); S.held[c] = now; }
    var b = {dx: acc.dx, dy: acc.dy, wheel: acc.wheel,
             sx: held("ArrowRight") - held("ArrowLeft"),
             sy: held("ArrowDown") - held("ArrowUp"),
             ins: held("KeyW") - held("KeyS"), roll: held("KeyE") - held("KeyQ")};
    var pads = [];
    try { pads = navigator.getGamepads ? navigator.getGamepads() : []; } catch (err) {}
    for (var i = 0; i < pads.length; i++) {
      var g = pads[i];
      if (!g || !g.connected || g.axes.length < 4) { continue; }
      b.sx += axis(g.axes[0]) * dt; b.sy += axis(g.axes[1]) * dt;
      b.ins += -axis(g.axes[3]) * dt; b.roll += axis(g.axes[2]) * dt;
      break;
    }
    acc = {dx: 0, dy: 0, wheel: 0}; heldFor = {};
    if (!(b.dx || b.dy || b.wheel || b.sx || b.sy || b.ins || b.roll)) {
      // Every key event so far has been sent (tests wait for this before they look).
      S.quiet = Object.keys(S.held).length === 0;
      return;
    }
    var m = window.__viserMutable;
    if (!m || !m.sendMessage) { return; }
    S.seq += 1; b.seq = S.seq;
    m.sendMessage({type: "GuiUpdateMessage", uuid: UUID,
                   updates: {value: JSON.stringify(b)}});
    S.sent += 1;
  }
  setInterval(flush, 33);
})();
"""


def parse_batch(text: str) -> Increment | None:
    """The :class:`Increment` a page sent, or None for anything malformed.

    Example:
        >>> inc = parse_batch('{"dx": 3, "dy": -1, "wheel": 0, "sx": 0, "sy": 0, '
        ...                   '"ins": 0.03, "roll": 0, "seq": 7}')
        >>> inc.dx_px, inc.dy_px, inc.insert_s
        (3.0, -1.0, 0.03)
        >>> parse_batch('{"dx": "NaN"}') is None, parse_batch("not json") is None
        (True, True)
        >>> parse_batch('{"dx": 1' + 400 * '0' + '}') is None
        True
    """
    if not isinstance(text, str) or not text or len(text) > MAX_BATCH_CHARS:
        return None
    try:
        raw = json.loads(text)
    except ValueError:
        return None
    if not isinstance(raw, dict):
        return None
    vals: dict[str, float] = {}
    for key in ("dx", "dy", "wheel", "sx", "sy", "ins", "roll"):
        v = raw.get(key, 0.0)
        if isinstance(v, bool) or not isinstance(v, int | float):
            return None
        try:  # an integer beyond the float range (400 digits) is malformed too (issue #30)
            x = float(v)
        except OverflowError:
            return None
        if not math.isfinite(x):
            return None
        vals[key] = x
    return Increment(dx_px=vals["dx"], dy_px=vals["dy"], wheel=vals["wheel"],
                     insert_s=vals["ins"], roll_s=vals["roll"], stick_x_s=vals["sx"],
                     stick_y_s=vals["sy"])


def batch_seq(text: str) -> int:
    """The sequence number a page gave a batch (0 when it has none: the page numbers from 1).

    Example:
        >>> batch_seq('{"dx": 3, "seq": 7}'), batch_seq('{"dx": 3}'), batch_seq('{"seq": 1e400}')
        (7, 0, 0)
    """
    try:
        seq = json.loads(text).get("seq", 0)
    except (ValueError, AttributeError):
        return 0
    return seq if isinstance(seq, int) and not isinstance(seq, bool) and seq > 0 else 0


def instrument_device(trocar: np.ndarray, start: np.ndarray,
                      mapping: InputMapping | None = None,
                      screen: tuple[np.ndarray, np.ndarray] | None = None,
                      ) -> LaparoscopicDevice:
    """The device of a trial whose instrument enters through ``trocar`` and starts with its
    tip at the task's ``start`` (the port's neutral axis points there, so the device's tip
    and the trial's tool start at the same point and move by the same increments)."""
    start = np.asarray(start, dtype=float)
    trocar = np.asarray(trocar, dtype=float)
    port = Port.toward(trocar, start)
    dev = LaparoscopicDevice(port, mapping, start=InstrumentPose(
        insertion=float(np.linalg.norm(start - trocar))))
    if screen is not None:
        dev.set_screen(*screen)
    return dev


def screen_axes(position: np.ndarray, look_at: np.ndarray,
                up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(right, up) unit vectors of a camera's image in the world frame."""
    forward = np.asarray(look_at, dtype=float) - np.asarray(position, dtype=float)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(up, dtype=float))
    right /= np.linalg.norm(right)
    return right, np.cross(right, forward)


class InstrumentInput:
    """The trainee page's input channel: the hidden field, the page script, the routing.

    Args:
        server: the trainee's server.
        device: returns the running trial's ``LaparoscopicDevice`` (or None).
        guard: wraps the callback (errors logged and notified, never raised into viser).
    """

    def __init__(self, server: viser.ViserServer,
                 device: Callable[[], LaparoscopicDevice | None],
                 guard: Callable[[Callable[..., Any]], Callable[..., Any]]):
        self.handle = server.gui.add_text("vasim-instrument-input", initial_value="",
                                          visible=False)
        self._device = device
        self.batches = 0
        """Batches delivered to a running trial's instrument."""
        self.refused = 0
        """Malformed batches (or batches with no instrument-driven trial running)."""
        self.last_seq = 0
        """The page's sequence number of the last batch applied to an instrument (a test
        that has seen the page send batch n knows when the instrument has taken it)."""
        self.arrivals: collections.deque[tuple[int, float]] = collections.deque(maxlen=256)
        """(sequence number, wall-clock time [s]) of recent batches as they arrived
        (``bench/viewer.py`` splits the key-to-picture latency with them)."""
        apply = guard(self._apply)

        async def on_batch(event: Any) -> None:
            # **Decision**: the batch is read and applied in its own message's turn of
            # viser's event loop (a coroutine callback, awaited there). A plain callback
            # runs later on viser's thread pool and reads the field's value *then*: on a
            # loaded host a later batch had already replaced it, so one batch was applied
            # twice and another never (the keyboard trial's moves doubled at load 8). The
            # work is one pose update under a lock (~30 us).
            apply(self.handle.value)

        self.handle.on_update(on_batch)

    @property
    def uuid(self) -> str:
        return str(self.handle._impl.uuid)  # private: the id the page must address

    def install(self, client: viser.ClientHandle) -> None:
        """Sends the page script to a newly connected trainee page."""
        run_js(client, CONTROL_JS % {"uuid": self.uuid})

    def _apply(self, text: str) -> None:
        seq = batch_seq(text)
        self.arrivals.append((seq, time.time()))
        inc = parse_batch(text)
        dev = self._device()
        if inc is None or dev is None or not dev.push(inc):
            self.refused += 1
            return
        self.batches += 1
        self.last_seq = seq


__all__ = ["CONTROLS_TEXT", "InstrumentInput", "instrument_device", "parse_batch",
           "screen_axes"]
