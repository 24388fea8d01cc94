"""Timing statistics of the servo loop: measured, stored with every trial, never assumed.

The servo loop stamps every tick with ``time.perf_counter_ns()`` at its start and at its
end; :class:`TimingRecorder` keeps the stamps (in preallocated chunks: no allocation per
tick) and :func:`timing_stats` reduces them to a compact :class:`TimingStats`, whose
``to_dict()`` is what goes into the ``timing_json`` column of the trials table.

Definitions (``T`` = nominal period = 1 / ``nominal_hz``, ``p_k`` = start_(k+1) - start_k):

* achieved rate = (n - 1) / (start_(n-1) - start_0) [Hz], n = number of ticks;
* period percentiles p50 / p99 / max and mean of p_k [ms]; ``max`` is the longest gap
  between two ticks;
* jitter = RMS of (p_k - T) [ms]: the deviation from the *nominal* period (a loop that runs
  steadily but slow has jitter, as a device feels it);
* overruns = number of periods with p_k > ``OVERRUN_FACTOR`` x T. **decision**
  (``OVERRUN_FACTOR`` = 1.5): a tick more than half a period late has lost its slot — the
  next deadline is nearer than the last tick — whereas smaller deviations are jitter;
* missed deadlines: how many nominal slots the loop skipped (counted by the loop, which
  does not "catch up" in a burst; see ``vasim.haptics.servo``);
* tick cost = end_k - start_k percentiles [ms]: the work done per tick (device, plant,
  output), without the sleep.

Example:
    >>> import numpy as np
    >>> starts = np.arange(0, 11) * 1_000_000            # 11 ticks, exactly 1 ms apart
    >>> starts[5:] += 1_000_000                          # one 2 ms gap
    >>> s = timing_stats(starts, starts + 200_000, nominal_hz=1000.0)
    >>> s.n_ticks, s.overruns, s.period_max_ms, round(s.achieved_hz, 1)
    (11, 1, 2.0, 909.1)
    >>> round(s.jitter_rms_ms, 4), round(s.tick_cost_p50_ms, 9)
    (0.3162, 0.2)
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

OVERRUN_FACTOR = 1.5
"""A period longer than this many nominal periods is an overrun (module docstring)."""

TimingMode = Literal["realtime", "simulated", "device"]


@dataclass(frozen=True)
class TimingStats:
    """Compact timing statistics of one servo-loop run (module docstring for definitions).

    Attributes:
        mode: ``"realtime"`` (own timer), ``"device"`` (inside a device scheduler) or
            ``"simulated"`` (``run_ticks``: no sleeping; periods are then the tick costs).
        nominal_hz: the target rate [Hz].
        n_ticks: ticks recorded.
        duration_s: first tick start to last tick start [s].
        achieved_hz: achieved rate [Hz] (NaN with fewer than 2 ticks).
        period_p50_ms, period_p99_ms, period_max_ms, period_mean_ms: period statistics [ms].
        jitter_rms_ms: RMS deviation of the period from the nominal period [ms].
        overruns: periods longer than ``OVERRUN_FACTOR`` nominal periods.
        missed_deadlines: nominal slots skipped by the loop.
        tick_cost_p50_ms, tick_cost_p99_ms, tick_cost_max_ms: work per tick [ms].
    """

    mode: TimingMode
    nominal_hz: float
    n_ticks: int
    duration_s: float
    achieved_hz: float
    period_p50_ms: float
    period_p99_ms: float
    period_max_ms: float
    period_mean_ms: float
    jitter_rms_ms: float
    overruns: int
    missed_deadlines: int
    tick_cost_p50_ms: float
    tick_cost_p99_ms: float
    tick_cost_max_ms: float

    def to_dict(self) -> dict[str, float | int | str | None]:
        """Plain JSON-able data (NaN becomes None), with ``overrun_factor`` added."""
        d: dict[str, float | int | str | None] = {}
        for k, v in asdict(self).items():
            d[k] = None if isinstance(v, float) and not math.isfinite(v) else v
        d["overrun_factor"] = OVERRUN_FACTOR
        return d

    def summary(self) -> str:
        """One human-readable line."""
        return (f"{self.n_ticks} ticks, {self.achieved_hz:.1f} Hz achieved "
                f"(nominal {self.nominal_hz:g}), period p50 {self.period_p50_ms:.3f} / "
                f"p99 {self.period_p99_ms:.3f} / max {self.period_max_ms:.3f} ms, jitter "
                f"{self.jitter_rms_ms:.3f} ms, {self.overruns} overruns, "
                f"{self.missed_deadlines} missed, tick cost p50 {self.tick_cost_p50_ms:.4f} "
                f"ms")


def _pct(a: NDArray[np.float64], q: float) -> float:
    return float(np.percentile(a, q)) if a.size else math.nan


def timing_stats(starts_ns: ArrayLike, ends_ns: ArrayLike | None, nominal_hz: float, *,
                 missed_deadlines: int = 0, mode: TimingMode = "realtime") -> TimingStats:
    """Reduces tick time stamps to :class:`TimingStats`.

    Args:
        starts_ns: (n,) tick start stamps [ns], non-decreasing (``perf_counter_ns``).
        ends_ns: (n,) tick end stamps [ns], or None (no tick-cost figures).
        nominal_hz: target rate [Hz], > 0.
        missed_deadlines: slots the loop skipped (it counts them).
        mode: how the loop ran.

    Raises:
        ValueError: for a non-positive rate, mismatched lengths or decreasing stamps.
    """
    if not (math.isfinite(nominal_hz) and nominal_hz > 0):
        raise ValueError(f"nominal_hz must be > 0, got {nominal_hz!r}")
    s = np.asarray(starts_ns, dtype=np.int64).reshape(-1)
    periods = np.diff(s).astype(np.float64) * 1e-6  # ms
    if periods.size and periods.min() < 0:
        raise ValueError("tick start stamps must be non-decreasing")
    nominal_ms = 1e3 / nominal_hz
    if ends_ns is not None:
        e = np.asarray(ends_ns, dtype=np.int64).reshape(-1)
        if e.shape != s.shape:
            raise ValueError(f"ends_ns has {e.size} stamps, starts_ns {s.size}")
        cost = (e - s).astype(np.float64) * 1e-6
    else:
        cost = np.zeros(0)
    n = int(s.size)
    duration = float(s[-1] - s[0]) * 1e-9 if n >= 2 else 0.0
    return TimingStats(
        mode=mode,
        nominal_hz=float(nominal_hz),
        n_ticks=n,
        duration_s=duration,
        achieved_hz=(n - 1) / duration if duration > 0 else math.nan,
        period_p50_ms=_pct(periods, 50),
        period_p99_ms=_pct(periods, 99),
        period_max_ms=float(periods.max()) if periods.size else math.nan,
        period_mean_ms=float(periods.mean()) if periods.size else math.nan,
        jitter_rms_ms=(float(np.sqrt(np.mean((periods - nominal_ms) ** 2)))
                       if periods.size else math.nan),
        overruns=int(np.count_nonzero(periods > OVERRUN_FACTOR * nominal_ms)),
        missed_deadlines=int(missed_deadlines),
        tick_cost_p50_ms=_pct(cost, 50),
        tick_cost_p99_ms=_pct(cost, 99),
        tick_cost_max_ms=float(cost.max()) if cost.size else math.nan,
    )


class TimingRecorder:
    """Keeps the (start, end) stamps of every tick, in preallocated chunks.

    Written by the servo thread only (``record``); other threads may call ``stats`` at any
    time (they see the ticks completed so far). A chunk of ``chunk`` ticks (64 s at 1 kHz by
    default, 1 MB) is allocated when the previous one is full: no allocation per tick.

    Args:
        chunk: ticks per chunk (> 0).

    Example:
        >>> rec = TimingRecorder(chunk=4)
        >>> for k in range(10):
        ...     rec.record(k * 1_000_000, k * 1_000_000 + 50_000)
        >>> len(rec), rec.stats(1000.0).period_p50_ms
        (10, 1.0)
    """

    def __init__(self, chunk: int = 65_536):
        if chunk <= 0:
            raise ValueError(f"chunk must be > 0, got {chunk!r}")
        self._chunk = int(chunk)
        self.clear()

    def clear(self) -> None:
        """Forgets every stamp."""
        self._full: list[NDArray[np.int64]] = []
        self._cur = np.empty((self._chunk, 2), dtype=np.int64)
        self._i = 0
        self._n = 0

    def record(self, start_ns: int, end_ns: int) -> None:
        """Stores one tick's start and end stamps [ns]."""
        i = self._i
        if i == self._chunk:
            self._full.append(self._cur)
            self._cur = np.empty((self._chunk, 2), dtype=np.int64)
            i = 0
        cur = self._cur
        cur[i, 0] = start_ns
        cur[i, 1] = end_ns
        self._i = i + 1
        self._n += 1

    def __len__(self) -> int:
        return self._n

    def stamps(self) -> NDArray[np.int64]:
        """(n, 2) array of (start, end) stamps [ns] of the ticks recorded so far."""
        full, cur, i = list(self._full), self._cur, self._i
        parts = [*full, cur[:i]]
        return np.concatenate(parts) if parts else np.zeros((0, 2), dtype=np.int64)

    def stats(self, nominal_hz: float, *, missed_deadlines: int = 0,
              mode: TimingMode = "realtime") -> TimingStats:
        """:func:`timing_stats` of the ticks recorded so far."""
        st = self.stamps()
        return timing_stats(st[:, 0], st[:, 1], nominal_hz,
                            missed_deadlines=missed_deadlines, mode=mode)


__all__ = ["OVERRUN_FACTOR", "TimingMode", "TimingRecorder", "TimingStats", "timing_stats"]
