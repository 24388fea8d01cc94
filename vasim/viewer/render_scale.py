"""Draw fewer pixels when a page cannot keep up (issue #26.2, "keep up, or say so").

A page drawing in software (no GPU: Chromium's SwiftShader) pays for every pixel of every
frame. Measured on the trainee page of the default abdomen at 1280x800 (2026-11-28, this
2-core machine, CPU seconds of Chromium's GPU process per drawn frame, which does not
depend on how loaded the host is; ``bench/viewer.py`` prints the same figure): **1,517 ms
at full resolution, 179 ms at half, 67 ms at a quarter** (a bare viser page with one box:
0.7 ms). Without viser's environment map (:mod:`vasim.viewer.lighting`, 2026-12-02): 518 ms
at full, 263 ms at 0.7, 179 ms at half, 123 ms at 0.35.
The cost is the pixels: the organs, the translucent abdominal wall over them and
the lit tissue cover the endoscope's whole view, so halving the resolution cuts the
fragments (and the cost) about four- to eight-fold. The scene, the camera and the
simulation are unchanged: only the canvas's backing store shrinks (the browser scales it
up), so what the trainee sees is the same picture, softer.

Per page (both servers' pages: the trainee's and the experimenter's), the page's own update
rate (:class:`vasim.viewer.flow.PageFlow`, frames it applied per second) is compared with
the rate the view thread produced frames at:

* a page below :data:`LOW_FRACTION` of it for :data:`DOWN_AFTER_S` draws one step coarser
  (:data:`SCALES`: 1, 0.7, 0.5, 0.35 of the device's pixel ratio);
* a page at :data:`HIGH_FRACTION` or more for :data:`UP_AFTER_S` draws one step finer;
* **decision**: steps of one level with a longer wait up than down (hysteresis), so a page
  near a threshold does not flicker between resolutions; 0.35 is the floor (at a quarter
  the instrument's tip, a few pixels at 1280x800, would blur into the tissue).

The page is told with one line of script (:data:`SCALE_JS`, installed on connect): it
takes three.js's renderer from the scene's ``onBeforeRender`` (viser 1.1.1 exposes the
scene, not the renderer) and sets its pixel ratio after each animation frame where it
differs (React-three-fiber resets it on a resize). The page's notice line says so, and
the trial record stores the coarsest scale a trainee page drew at
(``ViewerApp.viewer_timing``).
"""

from __future__ import annotations

import collections
import dataclasses
import math
import threading
from collections.abc import Callable

SCALES = (1.0, 0.7, 0.5, 0.35)
"""Fractions of the device's pixel ratio a page draws at, finest first."""
LOW_FRACTION = 0.5
"""A page applying fewer than this fraction of the frames produced is too slow."""
HIGH_FRACTION = 0.9
"""A page applying at least this fraction of the frames produced keeps up."""
DOWN_AFTER_S = 2.0
"""Seconds a page must be too slow before it draws one step coarser."""
UP_AFTER_S = 15.0
"""Seconds a page must keep up before it draws one step finer."""


@dataclasses.dataclass(frozen=True)
class ScaleState:
    """One page's resolution step and since when it has been too slow / keeping up."""

    level: int = 0
    slow_since: float | None = None
    fast_since: float | None = None

    @property
    def scale(self) -> float:
        return SCALES[self.level]


def next_state(state: ScaleState, page_hz: float | None, produced_hz: float | None,
               now: float) -> ScaleState:
    """The page's next resolution step (module doc) from its update rate ``page_hz`` and
    the frames produced per second ``produced_hz`` at time ``now`` [s].

    No figure (None, NaN, nothing produced: an idle viewer between trials) keeps the step
    and restarts both waits.

    Example:
        >>> s = next_state(ScaleState(), 5.0, 40.0, 0.0)      # too slow: the wait starts
        >>> s.level, next_state(s, 5.0, 40.0, 2.0).level       # 2 s later: one step down
        (0, 1)
    """
    known = (page_hz is not None and produced_hz is not None and math.isfinite(page_hz)
             and math.isfinite(produced_hz) and produced_hz > 0)
    if not known:
        return ScaleState(state.level)
    assert page_hz is not None and produced_hz is not None
    ratio = page_hz / produced_hz
    if ratio < LOW_FRACTION:
        since = state.slow_since if state.slow_since is not None else now
        if now - since >= DOWN_AFTER_S and state.level < len(SCALES) - 1:
            return ScaleState(state.level + 1, slow_since=now)
        return ScaleState(state.level, slow_since=since)
    if ratio >= HIGH_FRACTION:
        since = state.fast_since if state.fast_since is not None else now
        if now - since >= UP_AFTER_S and state.level > 0:
            return ScaleState(state.level - 1, fast_since=now)
        return ScaleState(state.level, fast_since=since)
    return ScaleState(state.level)


def scale_notice(scale: float) -> str:
    """The page's line about its resolution ('' at full resolution).

    Example:
        >>> scale_notice(0.5)
        'Drawn at 50 % resolution to keep up (this computer draws the view slowly)'
    """
    if scale >= 1.0:
        return ""
    return (f"Drawn at {round(scale * 100)} % resolution to keep up (this computer draws "
            "the view slowly)")


def set_scale_js(scale: float) -> str:
    """The script that tells a page (with :data:`SCALE_JS` installed) its scale."""
    if not (math.isfinite(scale) and 0 < scale <= 1):
        raise ValueError(f"a render scale is in (0, 1], got {scale!r}")
    return f"window.__vasimScale && window.__vasimScale.set({scale:.3f});"


class PageScales:
    """The resolution steps of a viewer's pages, by (server port, client id): the stateful
    shell around :func:`next_state`.

    Args:
        send: ``send(key, scale)`` tells the page ``key`` its new scale.
        window_s: window of the produced-frames rate [s].
    """

    def __init__(self, send: Callable[[tuple[int, int], float], None], window_s: float):
        self._send, self._window = send, float(window_s)
        self._states: dict[tuple[int, int], ScaleState] = {}
        self._produced: collections.deque[tuple[float, int]] = collections.deque()
        self._lock = threading.Lock()
        self.coarsest: dict[int, float] = {}
        """Per server port: the coarsest scale one of its pages drew at since
        :meth:`restart`."""

    def add(self, key: tuple[int, int]) -> None:
        with self._lock:
            self._states[key] = ScaleState()

    def drop(self, key: tuple[int, int]) -> None:
        with self._lock:
            self._states.pop(key, None)

    def produced(self, now: float, frames: int) -> float | None:
        """Frames produced per second over the window, given the count ``frames`` made so
        far at ``now`` (None until a second of samples)."""
        with self._lock:
            q = self._produced
            q.append((now, frames))
            while len(q) > 2 and now - q[0][0] > self._window:
                q.popleft()
            (t0, n0), (t1, n1) = q[0], q[-1]
        return (n1 - n0) / (t1 - t0) if t1 - t0 >= 1.0 else None

    def update(self, key: tuple[int, int], page_hz: float | None,
               produced_hz: float | None, now: float) -> float:
        """The page's next step (sent to it when it changes); returns its scale."""
        with self._lock:
            old = self._states.get(key, ScaleState())
            new = next_state(old, page_hz, produced_hz, now)
            self._states[key] = new
            port = key[0]
            self.coarsest[port] = min(self.coarsest.get(port, 1.0), new.scale)
        if new.level != old.level:
            self._send(key, new.scale)
        return new.scale

    def restart(self, port: int) -> None:
        """A new trial: the coarsest scale of ``port``'s pages restarts from their present
        ones."""
        with self._lock:
            self.coarsest[port] = min((st.scale for (p, _), st in self._states.items()
                                       if p == port), default=1.0)


SCALE_JS = r"""
(function () {
  if (window.__vasimScale) { return; }
  var S = window.__vasimScale = {want: 1.0, gl: null, hooked: null, ratio: null, renders: 0};
  S.set = function (s) { S.want = s; };
  function hook() {
    var m = window.__viserMutable;
    if (!m || !m.scene || S.hooked === m.scene) { return; }
    var scene = m.scene, prev = scene.onBeforeRender;
    scene.onBeforeRender = function (renderer) {
      S.gl = renderer;
      S.renders += 1;
      return prev.apply(this, arguments);
    };
    S.hooked = scene;
    if (m.requestRender) { m.requestRender(); }
  }
  function tick() {
    hook();
    var r = S.gl;
    if (r) {
      var ratio = (window.devicePixelRatio || 1) * S.want;
      if (Math.abs(r.getPixelRatio() - ratio) > 1e-6) {
        r.setPixelRatio(ratio);
        S.ratio = ratio;
        var m = window.__viserMutable;
        if (m && m.requestRender) { m.requestRender(); }
      }
    }
    requestAnimationFrame(tick);
  }
  requestAnimationFrame(tick);
})();
"""
"""Installed once per page: keeps three.js's pixel ratio at the device's times the page's
scale (module doc); ``window.__vasimScale.renders`` counts the frames three.js drew."""


__all__ = ["DOWN_AFTER_S", "HIGH_FRACTION", "LOW_FRACTION", "SCALES", "SCALE_JS", "UP_AFTER_S",
           "PageScales", "ScaleState", "next_state", "scale_notice", "set_scale_js"]
