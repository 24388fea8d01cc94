"""The guard between the device and the rest of vasim: bad data never reaches the physics.

Pure checks, called by the servo loop on every tick:

* :func:`check_sample` — a device reading is rejected when the device marks it invalid, when
  its position or orientation holds NaN/inf, or when the position lies outside the device's
  workspace box grown by ``margin`` [m] on every side;
* :func:`check_force` — a force computed by the plant is rejected when a component is
  NaN/inf.

What the loop does with a rejection (``vasim.haptics.servo``): it holds the last good state
(position, orientation, buttons), renders a zero force on that tick and logs a
:class:`GuardEvent` (kind, tick, offending value). **decision** (workspace margin): the
usable-workspace box of a data sheet is conservative — the Omni's arm reaches a little
beyond it — so the check uses the box grown by ``margin`` (the loop's default 10 mm);
readings further out are physically impossible for the device (an encoder glitch, a lost
calibration) and are treated as corrupt.

Events are rate limited by :func:`should_log` (the first ``first`` of each kind, then one
every ``every`` ticks), while :class:`GuardLog` counts all of them.

Example:
    >>> import numpy as np
    >>> from vasim.haptics.device import OMNI_LIMITS, DeviceSample
    >>> ok = DeviceSample(t=0.0, position=np.zeros(3))
    >>> check_sample(ok, OMNI_LIMITS, tick=0) is None
    True
    >>> bad = DeviceSample(t=0.001, position=np.array([0.0, np.nan, 0.0]))
    >>> check_sample(bad, OMNI_LIMITS, tick=1)
    GuardEvent(kind='nonfinite_position', tick=1, value=(0.0, nan, 0.0))
    >>> check_force(0.1, float("inf"), 0.0, tick=2).kind
    'nonfinite_force'
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Literal

from vasim.haptics.device import DeviceLimits, DeviceSample

GuardKind = Literal[
    "invalid_sample",
    "nonfinite_position",
    "nonfinite_orientation",
    "out_of_workspace",
    "nonfinite_force",
]
GUARD_KINDS: tuple[GuardKind, ...] = ("invalid_sample", "nonfinite_position",
                                      "nonfinite_orientation", "out_of_workspace",
                                      "nonfinite_force")


@dataclass(frozen=True)
class GuardEvent:
    """One rejected reading or force.

    Attributes:
        kind: what was wrong (one of ``GUARD_KINDS``).
        tick: servo tick index at which it happened.
        value: the offending values (position [m], orientation, or force [N]).
    """

    kind: GuardKind
    tick: int
    value: tuple[float, ...]

    def describe(self) -> str:
        """One line for logs: ``tick 12: nonfinite_force (nan, 0.0, 0.0)``."""
        vals = ", ".join(repr(float(v)) for v in self.value)
        return f"tick {self.tick}: {self.kind} ({vals})"


def _finite3(a: float, b: float, c: float) -> bool:
    return math.isfinite(a) and math.isfinite(b) and math.isfinite(c)


def check_sample(sample: DeviceSample, limits: DeviceLimits, tick: int,
                 margin: float = 0.0) -> GuardEvent | None:
    """Checks one device reading; None when it may pass.

    Args:
        sample: the reading.
        limits: the device's limits (workspace box [m], device frame).
        tick: servo tick index (copied into the event).
        margin: how far outside the box [m] a reading is still accepted (>= 0).

    Returns:
        The first problem found, in the order invalid flag, non-finite position, non-finite
        orientation, out of workspace; None for a good reading.
    """
    p = sample.position
    p0, p1, p2 = float(p[0]), float(p[1]), float(p[2])
    if not sample.valid:
        return GuardEvent("invalid_sample", tick, (p0, p1, p2))
    if not _finite3(p0, p1, p2):
        return GuardEvent("nonfinite_position", tick, (p0, p1, p2))
    q = sample.orientation
    if not all(math.isfinite(float(v)) for v in q):
        return GuardEvent("nonfinite_orientation", tick, tuple(float(v) for v in q))
    lo, hi = limits.workspace_min, limits.workspace_max
    if not (lo[0] - margin <= p0 <= hi[0] + margin and lo[1] - margin <= p1 <= hi[1] + margin
            and lo[2] - margin <= p2 <= hi[2] + margin):
        return GuardEvent("out_of_workspace", tick, (p0, p1, p2))
    return None


def check_force(fx: float, fy: float, fz: float, tick: int) -> GuardEvent | None:
    """Checks a force [N] computed by the plant; None when every component is finite."""
    if _finite3(fx, fy, fz):
        return None
    return GuardEvent("nonfinite_force", tick, (float(fx), float(fy), float(fz)))


def should_log(count: int, tick: int, first: int = 10, every: int = 1000) -> bool:
    """Whether the ``count``-th event of a kind (1-based) at ``tick`` is logged.

    The first ``first`` are logged one by one; after that, one per ``every`` ticks (one per
    second at 1 kHz), so a device that keeps failing cannot flood the log.

    >>> [should_log(c, t, first=2, every=10) for c, t in [(1, 0), (2, 1), (3, 2), (4, 10)]]
    [True, True, False, True]
    """
    return count <= first or tick % every == 0


@dataclass
class GuardLog:
    """Counts every rejection and keeps the rate-limited events (see ``should_log``).

    Attributes:
        counts: number of rejections per kind (all of them, logged or not).
        events: the logged events, oldest first.
        first: events logged one by one per kind. every: then one per this many ticks.
    """

    first: int = 10
    every: int = 1000
    counts: Counter[str] = field(default_factory=Counter)
    events: list[GuardEvent] = field(default_factory=list)

    def add(self, event: GuardEvent) -> bool:
        """Counts ``event`` and keeps it if ``should_log`` says so; returns whether kept."""
        self.counts[event.kind] += 1
        if should_log(self.counts[event.kind], event.tick, self.first, self.every):
            self.events.append(event)
            return True
        return False

    @property
    def total(self) -> int:
        """Number of rejections of every kind."""
        return sum(self.counts.values())


__all__ = [
    "GUARD_KINDS",
    "GuardEvent",
    "GuardKind",
    "GuardLog",
    "check_force",
    "check_sample",
    "should_log",
]
