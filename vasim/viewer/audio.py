"""AG audible in the browser: a WebAudio synth per page, fed a small parameter stream.

viser 1.1.1 has no audio API (guides/viewer.md). The route taken (**decision**):

* On connect, each client gets one JavaScript snippet (:data:`SYNTH_JS`) through viser's
  private ``RunJavascriptMessage``, queued on **that client's** connection only — never a
  broadcast, which viser stores and replays to every future client forever.
* The snippet builds an oscillator and a gain node and a beep scheduler (25 ms timer,
  100 ms look-ahead on the AudioContext clock): beeps of ``beep`` seconds at ``pitch`` Hz
  every ``period`` seconds, at ``volume``, as the AG fixture's ``AudioCue`` says.
* The server streams the cue as tiny snippets calling ``window.__vasimAudioSet({...})`` at
  ``rate_hz`` (20 Hz: inside the issue's 10-30 Hz) while a cue exists, and one
  ``{on: false}`` when it goes away (a schema without AG). Latest wins (issue #26.2): a
  parameter update still waiting in a page's queue when the next is queued is replaced by
  it (:func:`run_js` with a ``key``), so a slow page's stream never piles up snippets it
  will only overwrite (viser never coalesces ``RunJavascriptMessage``: before this, a
  page paced by :mod:`vasim.viewer.flow` received them in windows of up to 128).
* Browsers start audio only after a user gesture. The synth stays muted until the page's
  "Enable audio" control is used; its click (a pointerdown on the page) also resumes the
  AudioContext inside the gesture, which is what browsers require.
* ``window.__vasimAudio`` exposes the state for tests: ``params`` (the last parameters
  received), ``count`` (updates received), ``enabled``, ``beeps`` (beeps scheduled),
  ``state`` (the AudioContext state).
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time
from typing import Any

import viser
from viser import _messages  # private: the only way to run JS on one client (see above)

from vasim.fixtures.types import AudioCue

log = logging.getLogger(__name__)

SYNTH_JS = r"""
(function () {
  if (window.__vasimAudio) { return; }
  var A = window.__vasimAudio = {count: 0, params: null, enabled: false, beeps: 0,
                                 state: "idle"};
  var ctx = null, osc = null, gain = null, next = 0;
  function ensure() {
    if (ctx) { return ctx; }
    var C = window.AudioContext || window.webkitAudioContext;
    if (!C) { A.state = "unsupported"; return null; }
    ctx = new C();
    osc = ctx.createOscillator();
    gain = ctx.createGain();
    gain.gain.value = 0;
    osc.connect(gain);
    gain.connect(ctx.destination);
    osc.start();
    A.state = ctx.state;
    return ctx;
  }
  function resume() {
    var c = ensure();
    if (c && c.state !== "running") {
      c.resume().then(function () { A.state = c.state; }, function () {});
    }
  }
  function gesture() { if (A.enabled) { resume(); } }
  document.addEventListener("pointerdown", gesture, true);
  document.addEventListener("keydown", gesture, true);
  window.__vasimAudioEnable = function (on) {
    A.enabled = !!on;
    if (A.enabled) { resume(); }
    else if (gain) { gain.gain.cancelScheduledValues(0); gain.gain.value = 0; }
  };
  window.__vasimAudioSet = function (p) { A.params = p; A.count += 1; };
  setInterval(function () {
    var p = A.params;
    if (!ctx || !A.enabled || !p || !p.on || !(p.volume > 0)) { return; }
    A.state = ctx.state;
    if (ctx.state !== "running") { return; }
    var now = ctx.currentTime, level = 0.3 * Math.min(1, p.volume);
    osc.frequency.setTargetAtTime(p.pitch, now, 0.01);
    if (next < now) { next = now; }
    while (next < now + 0.1) {
      gain.gain.setValueAtTime(0, next);
      gain.gain.linearRampToValueAtTime(level, next + 0.005);
      gain.gain.setValueAtTime(level, next + p.beep);
      gain.gain.linearRampToValueAtTime(0, next + p.beep + 0.01);
      next += Math.max(p.period, p.beep + 0.02);
      A.beeps += 1;
    }
  }, 25);
})();
"""


def cue_params(cue: AudioCue | None) -> dict[str, Any]:
    """The parameters streamed for one cue (JSON-able; rounded to keep messages small).

    >>> cue_params(AudioCue(620.0, 0.25, 0.5))
    {'on': True, 'pitch': 620.0, 'period': 0.25, 'volume': 0.5, 'beep': 0.06}
    >>> cue_params(None)
    {'on': False}
    """
    if cue is None:
        return {"on": False}
    vals = {"pitch": cue.pitch_hz, "period": cue.period_s, "volume": cue.volume,
            "beep": cue.beep_s}
    out: dict[str, Any] = {"on": True}
    for k, v in vals.items():
        v = float(v)
        out[k] = round(v, 4) if math.isfinite(v) else 0.0
    return out


def run_js(client: viser.ClientHandle, source: str, key: str | None = None) -> None:
    """Runs ``source`` in one client's page (never a broadcast; module docstring).

    Args:
        key: None: every snippet runs. A key: latest wins — a snippet with the same key
            still waiting to be sent to this client is dropped for this one (the snippet
            must then be a state update whose newest value is all that matters).
    """
    msg = _messages.RunJavascriptMessage(source=source)
    if key is not None:
        # viser culls a waiting message whose redundancy key a newer one shares; its
        # RunJavascriptMessage draws a fresh key per call (never culled), so the instance
        # gets a fixed one (an instance attribute shadows the method; the wire format
        # holds only the dataclass fields, so the page sees a plain RunJavascriptMessage).
        fixed = f"RunJavascriptMessage_vasim_{key}"
        object.__setattr__(msg, "redundancy_key", lambda: fixed)
    client._websock_connection.queue_message(msg)  # private API, viser 1.1.1


class AudioStream:
    """Installs the synth on each client and streams the AG cue to all of them.

    Args:
        server: the viser server.
        rate_hz: stream rate while a cue exists [Hz].

    Attributes:
        sent: parameter updates sent so far (all clients).
        enabled: whether each client's synth was last told to play, by client id.
    """

    def __init__(self, server: viser.ViserServer, *, rate_hz: float = 20.0):
        self.server = server
        self.min_interval = 1.0 / float(rate_hz)
        self._installed: set[int] = set()
        # install() runs on viser's callback threads while update() runs on the
        # view thread; the lock guards _installed and update() iterates over a snapshot
        # (iterating the live set raised "Set changed size during iteration").
        self._lock = threading.Lock()
        self._next_t = -math.inf
        self._last: dict[str, Any] | None = None
        self.sent = 0
        self.enabled: dict[int, bool] = {}
        """Whether each client's synth was last told to play (by client id)."""

    def install(self, client: viser.ClientHandle) -> None:
        """Sends the synth to a newly connected client (a reload is a new client)."""
        run_js(client, SYNTH_JS)
        with self._lock:
            self._installed.add(client.client_id)
        if self._last is not None:
            self._send(client, self._last)

    def enable(self, client: viser.ClientHandle, on: bool) -> None:
        """Unmutes (``on``) or mutes one client's synth."""
        self.enabled[client.client_id] = bool(on)
        run_js(client, f"window.__vasimAudioEnable && window.__vasimAudioEnable({json.dumps(on)});")

    def update(self, cue: AudioCue | None, now: float | None = None) -> None:
        """Streams ``cue`` at ``rate_hz``; a disappearing cue is sent once as ``on: false``."""
        now = time.perf_counter() if now is None else now
        params = cue_params(cue)
        if cue is None and (self._last is None or not self._last["on"]):
            return
        if cue is not None:
            if now < self._next_t:
                return
            # A fixed schedule (not "interval since the last send"): with view updates at
            # 30-40 Hz the stream keeps its rate instead of dropping to every other update.
            iv = self.min_interval
            self._next_t = self._next_t + iv if now - self._next_t < iv else now + iv
        self._last = params
        clients = self.server.get_clients()
        with self._lock:
            self._installed &= set(clients)
            installed = tuple(self._installed)
        for cid in installed:
            client = clients.get(cid)
            if client is not None:
                self._send(client, params)

    def _send(self, client: viser.ClientHandle, params: dict[str, Any]) -> None:
        try:
            run_js(client, f"window.__vasimAudioSet && window.__vasimAudioSet("
                           f"{json.dumps(params)});", key="audio_params")
            self.sent += 1
        except Exception:  # a closing connection: the next update skips it
            log.debug("audio update to client %s failed", client.client_id, exc_info=True)


__all__ = ["SYNTH_JS", "AudioStream", "cue_params", "run_js"]
