"""Browser input: positions dragged in the viewer, resampled to the servo rate.

The viewer's side channel calls :meth:`BrowserDevice.push` with timestamped samples
``(t, position, buttons)`` at browser rates (30-60 Hz): jittery, sometimes late, sometimes
out of order. The servo loop reads at 1 kHz. Policy (**decision**):

* Clock mapping. Sample times are on the browser's clock; the device maps them to its own
  (``clock``, monotonic) with the offset of the least-delayed sample seen so far,
  offset = min over samples of (arrival - t): the transport delay is never negative, so the
  minimum is the best estimate of the clock difference (it can only improve).
* Fixed render delay. ``read()`` at local time ``now`` renders the stream at
  r = now - ``delay_s`` (default 40 ms: longer than a 30 Hz sample interval, so r is
  normally bracketed by two received samples) and **linearly interpolates** between them.
* Late samples. When r is past the newest sample, the position is **extrapolated** from
  the last two samples for at most ``max_extrapolation_s`` (default one 30 Hz period) and
  never by more than the last sample-to-sample displacement: the extrapolated point is
  x_n + min((r - t_n) / (t_n - t_(n-1)), h / (t_n - t_(n-1)), 1) (x_n - x_(n-1)). Beyond
  that it holds. So a burst of jittery samples cannot fling the tool: the overshoot is
  bounded by one sample step. When late samples arrive, the interpolation takes over again.
* Out-of-order and duplicate samples (t <= the newest accepted t) are dropped and counted;
  so are non-finite ones. Finite positions are clamped to the workspace box of ``limits``
  (default ``BROWSER_WORKSPACE_HALF_M`` = 1 m around the scene origin), on receipt and
  after interpolation, so a client cannot send the tool to 1e200 m.
* Before the first sample, readings are ``valid=False`` (the servo loop holds its home);
  after it, a pause of the user (no new samples) simply holds the last position.
* Buttons come from the newest sample at or before r (no interpolation).
* A browser renders no force: ``limits.max_force_n`` is 0, so the loop writes zeros; the
  force the plant asked for is drawn by the viewer instead.

Example:
    >>> import numpy as np
    >>> now = [0.0]
    >>> dev = BrowserDevice(delay_s=0.02, clock=lambda: now[0])
    >>> dev.start()
    >>> dev.push(0.00, [0.0, 0.0, 0.0])                    # arrives at now = 0
    True
    >>> now[0] = 0.02
    >>> dev.push(0.02, [0.02, 0.0, 0.0])
    True
    >>> now[0] = 0.03                                      # renders t = 0.01
    >>> round(float(dev.read().position[0]), 12)          # halfway: linear
    0.01
    >>> dev.push(0.01, [9.0, 9.0, 9.0])                    # out of order: dropped
    False
"""

from __future__ import annotations

import bisect
import math
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from vasim.core.config import check_int, check_number
from vasim.core.errors import DeviceError
from vasim.haptics.device import DeviceLimits, DeviceSample, FloatArray, as_force

BROWSER_WORKSPACE_HALF_M = 1.0
"""Half edge of the browser pointer's workspace box around the scene origin [m].

**decision**: a viewer client can send any finite coordinate (1e200 passed the
NaN guard and overflowed the physics), so the pointer lives in a finite box. The default
abdomen spans about x -0.15..0.15, y -0.12..0.18, z 0..0.16 m and the tasks lie inside it;
+-1 m around the origin (larger than any abdomen) holds the whole scene with a wide margin
for clutching and for dragging the gizmo past the scene, yet keeps every value far from
overflow."""

BROWSER_LIMITS = DeviceLimits(
    workspace_min=(-BROWSER_WORKSPACE_HALF_M, -BROWSER_WORKSPACE_HALF_M,
                   -BROWSER_WORKSPACE_HALF_M),
    workspace_max=(BROWSER_WORKSPACE_HALF_M, BROWSER_WORKSPACE_HALF_M,
                   BROWSER_WORKSPACE_HALF_M),
    max_force_n=0.0, max_continuous_force_n=0.0)
"""A browser pointer: the ``BROWSER_WORKSPACE_HALF_M`` box (positions are clamped to it),
no force output."""

InterpMode = Literal["empty", "before", "interpolate", "extrapolate", "hold"]


def interpolate_stream(times: Sequence[float], positions: Sequence[Sequence[float]], t: float,
                       max_extrapolation_s: float) -> tuple[tuple[float, float, float] | None,
                                                            InterpMode]:
    """Position of a sampled stream at time ``t`` (module docstring for the policy).

    Args:
        times: (n,) strictly increasing sample times [s].
        positions: (n, 3) sample positions [m].
        t: query time [s], same clock.
        max_extrapolation_s: h, the longest extrapolation past the newest sample [s].

    Returns:
        (position or None when empty, mode): ``"before"`` (t before the first sample: the
        first position), ``"interpolate"``, ``"extrapolate"`` (bounded), ``"hold"`` (the
        newest position: one sample only, or an exact hit on the newest sample).

    >>> interpolate_stream([0.0, 0.1], [[0, 0, 0], [1, 0, 0]], 0.025, 0.03)
    ((0.25, 0.0, 0.0), 'interpolate')
    >>> interpolate_stream([0.0, 0.1], [[0, 0, 0], [1, 0, 0]], 0.5, 0.03)   # bounded
    ((1.3, 0.0, 0.0), 'extrapolate')
    """
    n = len(times)
    if n == 0:
        return None, "empty"
    if t <= times[0]:
        p = positions[0]
        return (float(p[0]), float(p[1]), float(p[2])), "before"
    if t >= times[-1]:
        p1 = positions[-1]
        if n == 1 or t == times[-1]:
            return (float(p1[0]), float(p1[1]), float(p1[2])), "hold"
        p0 = positions[-2]
        span = times[-1] - times[-2]
        u = min((t - times[-1]) / span, max_extrapolation_s / span, 1.0)
        return (float(p1[0]) + u * (float(p1[0]) - float(p0[0])),
                float(p1[1]) + u * (float(p1[1]) - float(p0[1])),
                float(p1[2]) + u * (float(p1[2]) - float(p0[2]))), "extrapolate"
    j = bisect.bisect_right(times, t)  # times[j-1] <= t < times[j]
    t0, t1 = times[j - 1], times[j]
    a, b = positions[j - 1], positions[j]
    u = (t - t0) / (t1 - t0)
    return (float(a[0]) + u * (float(b[0]) - float(a[0])),
            float(a[1]) + u * (float(b[1]) - float(a[1])),
            float(a[2]) + u * (float(b[2]) - float(a[2]))), "interpolate"


class BrowserDevice:
    """Browser pointer input resampled to the servo rate (module docstring).

    Args:
        delay_s: fixed render delay [s] (>= 0).
        max_extrapolation_s: longest extrapolation past the newest sample [s] (>= 0).
        history: samples kept (>= 2).
        clock: the device's clock [s] (monotonic; default ``time.perf_counter``).
        limits: device limits (default ``BROWSER_LIMITS``: the +-1 m box, no force);
            positions are clamped to its workspace box.
        name: device name.

    Attributes:
        accepted, dropped: numbers of samples accepted and dropped (out of order/duplicate).
        last_force: the last force the loop wrote (always zero with the default limits).
        last_mode: the interpolation mode of the last ``read()``.
    """

    def __init__(self, *, delay_s: float = 0.04, max_extrapolation_s: float = 1.0 / 30.0,
                 history: int = 64, clock: Callable[[], float] = time.perf_counter,
                 limits: DeviceLimits = BROWSER_LIMITS, name: str = "browser"):
        for fname, v in (("delay_s", delay_s), ("max_extrapolation_s", max_extrapolation_s)):
            check_number(v, f"browser.{fname}", ge=0)
        check_int(history, "browser.history", lo=2)
        self.name = name
        self.delay_s = float(delay_s)
        self.max_extrapolation_s = float(max_extrapolation_s)
        self._limits = limits
        self._clock = clock
        self._lock = threading.Lock()
        self._times: deque[float] = deque(maxlen=history)  # browser clock
        self._pos: deque[tuple[float, float, float]] = deque(maxlen=history)
        self._buttons: deque[int] = deque(maxlen=history)
        self._offset = math.inf
        self.accepted = 0
        self.dropped = 0
        self.last_force = np.zeros(3)
        self.last_mode: InterpMode = "empty"
        self._started = False

    @property
    def limits(self) -> DeviceLimits:
        return self._limits

    def start(self) -> None:
        self._started = True

    def stop(self) -> None:
        self._started = False

    def push(self, t: float, position: ArrayLike, buttons: int = 0, *,
             arrival: float | None = None) -> bool:
        """Receives one browser sample (thread-safe; called by the viewer).

        Args:
            t: the sample's time on the browser's clock [s].
            position: (3,) pointer position [m].
            buttons: button bitmask.
            arrival: local arrival time [s] (default: ``clock()`` now).

        Returns:
            True if accepted; False if dropped (out of order, duplicate, or non-finite
            values, which never enter the stream).
        """
        p = np.asarray(position, dtype=np.float64).reshape(-1)
        if p.shape != (3,):
            raise ValueError(f"a browser sample needs 3 coordinates, got {position!r}")
        t = float(t)
        p0, p1, p2 = (float(v) for v in p)
        if not (math.isfinite(t) and math.isfinite(p0) and math.isfinite(p1)
                and math.isfinite(p2)):
            with self._lock:
                self.dropped += 1
            return False
        p0, p1, p2 = self._clamp((p0, p1, p2))
        now = self._clock() if arrival is None else float(arrival)
        with self._lock:
            if self._times and t <= self._times[-1]:
                self.dropped += 1
                return False
            self._times.append(t)
            self._pos.append((p0, p1, p2))
            self._buttons.append(int(buttons))
            self._offset = min(self._offset, now - t)
            self.accepted += 1
        return True

    def read(self) -> DeviceSample:
        """The stream at ``clock() - delay_s``, interpolated (module docstring)."""
        if not self._started:
            raise DeviceError(f"{self.name}: read() before start()")
        now = self._clock()
        with self._lock:
            if not self._times:
                self.last_mode = "empty"
                return DeviceSample(t=now, position=np.zeros(3), valid=False)
            r = now - self.delay_s - self._offset  # render time, browser clock
            times = list(self._times)
            pos = list(self._pos)
            j = bisect.bisect_right(times, r)
            buttons = self._buttons[max(j - 1, 0)]
        x, mode = interpolate_stream(times, pos, r, self.max_extrapolation_s)
        self.last_mode = mode
        assert x is not None
        # Extrapolation can step one sample past a clamped sample: clamp again.
        return DeviceSample(t=now, position=np.array(self._clamp(x)), buttons=buttons)

    def _clamp(self, p: tuple[float, float, float]) -> tuple[float, float, float]:
        """``p`` clamped to the workspace box of ``limits`` (huge finite coordinates from a
        client never reach the physics; module docstring)."""
        lo, hi = self._limits.workspace_min, self._limits.workspace_max
        return (min(max(p[0], lo[0]), hi[0]), min(max(p[1], lo[1]), hi[1]),
                min(max(p[2], lo[2]), hi[2]))

    def write_force(self, force: FloatArray) -> None:
        self.last_force = as_force(force)


__all__ = ["BROWSER_LIMITS", "BROWSER_WORKSPACE_HALF_M", "BrowserDevice", "InterpMode",
           "interpolate_stream"]
