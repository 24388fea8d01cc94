"""The suture thread: an inextensible chain of segments (issue #28 item 1, seed sec. 5.5).

The thread of a continuous suture runs from its anchor (the knot that starts the suture)
through the stitches already made (each pins the thread at its entry and exit points) to
the needle's tail, where it is swaged on. :class:`SutureThread` keeps four parts whose
lengths always add up to the thread's length ``L``:

* the **pinned path**: the polyline anchor -> entry_1 -> exit_1 -> entry_2 -> ... -> last
  exit, in the tissue's frame (the points ride on the breathing tissue);
* the **slack** [m]: thread in the stitches not yet tightened (a loose loop between the
  previous stitch and the newest one);
* the **free chain**: ``n`` segments of equal length ``l`` from the last pinned point to
  the needle's tail;
* the **reserve** [m]: thread not yet in play, counted at the needle (see the omissions).

Each update places the chain: a downward step of the interior nodes (the sag), then
FABRIK passes (backward from the needle's tail, forward from the last pinned point; each
pass sets every segment to exactly ``l``) until the chain's end meets the tail; a taut
chain is the straight line. The forward pass comes last, so the segments are always
exactly ``l`` long and the only possible error is the gap left between the chain's end
and the needle's tail (:attr:`SutureThread.attach_gap`). When the needle pulls the chain taut
(the tail farther than the free length from the last pinned point) the pull draws the
slack through the stitches into the free chain first (the stitches tighten), then pays
out reserve. A tail farther than the free length with neither left is an overstretched
thread: the chain cannot reach it and the gap reports by how much. A stitch
(:meth:`SutureThread.pin`) takes the thread it consumes (the crossing from the last pinned
point to the entry and the chord through the tissue) from the free chain and then the
reserve, and leaves a loose loop of ``LOOP_SLACK`` behind the needle (the stitch's slack).

What this model omits (**decision**: the brief asks for a chain with a length constraint;
everything else is left out and said here):

* no dynamics: no mass, velocity, inertia or damping; the sag is a fixed downward step per
  solver pass, not a weight, and the chain settles instantly;
* no bending or torsional stiffness (a real suture has both) and no friction;
* no contact: the thread passes through the tools, the needle, itself and the tissue; its
  route inside the tissue is the straight chord from the entry to the exit point, not the
  needle's arc;
* no sliding of individual stitches: a stitch's pinned points are fixed on the tissue once
  made, and tightening only draws the slack (one number for all untightened stitches) into
  the free chain; the pull does not close the incision (the lips do not move);
* no knot: the anchor is a fixed point, and knot tying winds the free chain only as far as
  the tools carry it;
* the reserve is not drawn: the thread a continuous suture pulls through each stitch (all
  of the thread still to be used) would need strokes far longer than the instruments' in
  the body; the model keeps that length as a number at the needle, so a tightening stroke
  only takes up the free chain and the stitch's loop (**decision**).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: Most FABRIK passes per update.
ITERATIONS = 40
#: Downward step of each interior node per update [m] (the sag; see the omissions).
SAG_STEP = 8e-4
#: Taut: the free chain's end-to-end distance over its length at least this.
TAUT = 0.995
#: The loose loop a stitch leaves behind the needle [m] (what tightening takes up).
LOOP_SLACK = 0.015


def _fabrik(x: list[list[float]], start: list[float], tail: list[float], seg: float
            ) -> list[list[float]]:
    """FABRIK on plain floats (a few hundred tiny vector operations per call: numpy's
    per-call cost would dominate): backward passes from ``tail``, forward passes from
    ``start``, until the chain's end is within 1e-7 m of the tail; every segment is then
    exactly ``seg`` long (the forward pass comes last)."""
    n = len(x) - 1

    def toward(a: list[float], b: list[float]) -> list[float]:
        """The point ``seg`` from ``a`` toward ``b`` (straight down when they coincide)."""
        dx, dy, dz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        if d < 1e-15:
            return [a[0], a[1], a[2] - seg]
        f = seg / d
        return [a[0] + f * dx, a[1] + f * dy, a[2] + f * dz]

    for _ in range(ITERATIONS):
        x[n] = list(tail)
        for i in range(n - 1, -1, -1):
            x[i] = toward(x[i + 1], x[i])
        x[0] = list(start)
        for i in range(n):
            x[i + 1] = toward(x[i], x[i + 1])
        e = x[n]
        if math.dist(e, tail) < 1e-7:
            break
    return x


def _polyline_length(points: FloatArray) -> float:
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    return float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()) if len(pts) > 1 else 0.0


@dataclass(frozen=True)
class ThreadState:
    """A snapshot (tissue frame): the pinned points, the chain's nodes, the slack, the free
    length, the reserve and the gap between the chain's end and the needle's tail [m]."""

    pinned: FloatArray
    nodes: FloatArray
    slack: float
    free_length: float
    reserve: float
    attach_gap: float

    @property
    def total_length(self) -> float:
        """Pinned path + slack + the chain measured node to node + reserve [m]."""
        return (_polyline_length(self.pinned) + self.slack + _polyline_length(self.nodes)
                + self.reserve)


class SutureThread:
    """A thread of length ``length`` anchored at ``anchor`` (tissue frame) whose other end
    is the needle's tail (see the module docstring for the model and what it omits).

    Args:
        anchor: ``(3,)`` the anchor knot [m], tissue frame.
        tail: ``(3,)`` the needle's tail at start [m], tissue frame.
        length: the thread's length [m].
        free: the free chain's length at start [m] (> the anchor-tail distance); the rest
            is the reserve.
        segments: nodes of the free chain minus one (>= 2).

    Raises:
        ValueError: for a free chain shorter than the anchor-tail distance, one longer than
            the thread, or too few segments.

    Example:
        >>> th = SutureThread(np.zeros(3), np.array([0.05, 0.0, 0.0]), 0.2, 0.08, 8)
        >>> s = th.update(np.array([0.09, 0.0, 0.0]))       # pulled past the free length
        >>> round(s.total_length, 9), round(s.free_length, 9), round(s.reserve, 9)
        (0.2, 0.09, 0.11)
        >>> s.attach_gap < 1e-4, th.taut()
        (True, True)
    """

    def __init__(self, anchor: FloatArray, tail: FloatArray, length: float, free: float,
                 segments: int = 16) -> None:
        anchor = np.asarray(anchor, dtype=float)
        tail = np.asarray(tail, dtype=float)
        span = float(np.linalg.norm(tail - anchor))
        if segments < 2:
            raise ValueError(f"SutureThread: segments must be >= 2, got {segments!r}")
        if not span < free <= length:
            raise ValueError(f"SutureThread: the free chain ({free!r} m) must reach from the "
                             f"anchor to the tail ({span:.4f} m) and fit in the thread "
                             f"({length!r} m)")
        self.length = float(length)
        self.n = int(segments)
        self.pinned: list[FloatArray] = [anchor.copy()]
        self.slack = 0.0
        self.reserve = float(length - free)
        self.free_length = float(free)
        self.nodes = self._initial_chain(anchor, tail, self.free_length)
        self.attach_gap = 0.0
        self.update(tail)

    # ------------------------------------------------------------------ geometry
    def _initial_chain(self, start: FloatArray, end: FloatArray, length: float) -> FloatArray:
        """A sagging curve from ``start`` to ``end`` about ``length`` long (a parabola below
        the chord, its depth found by bisection); the solver makes it exact."""
        s = np.linspace(0.0, 1.0, self.n + 1)
        chord = start[None, :] + s[:, None] * (end - start)[None, :]
        bump = (4.0 * s * (1.0 - s))[:, None] * np.array([0.0, 0.0, -1.0])[None, :]
        lo, hi = 0.0, length
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if _polyline_length(chord + mid * bump) < length:
                lo = mid
            else:
                hi = mid
        return np.asarray(chord + lo * bump, dtype=float)

    @property
    def segment_length(self) -> float:
        return self.free_length / self.n

    def pinned_length(self) -> float:
        """The pinned polyline's length [m] (without the slack)."""
        return _polyline_length(np.array(self.pinned))

    def taut(self) -> bool:
        """True when the free chain is (nearly) straight: its end-to-end distance is at
        least :data:`TAUT` of its length."""
        return float(np.linalg.norm(self.nodes[-1] - self.nodes[0])) >= TAUT * self.free_length

    # ------------------------------------------------------------------ updates
    def update(self, tail: FloatArray) -> ThreadState:
        """Places the chain for the needle's tail at ``tail`` (tissue frame); a pull beyond
        the free length draws slack through the stitches. Returns the state (tissue frame)."""
        tail = np.asarray(tail, dtype=float)
        start = self.pinned[-1]
        need = float(np.linalg.norm(tail - start))
        if need > self.free_length and self.slack > 0.0:      # tightening
            drawn = min(self.slack, need - self.free_length)
            self.slack -= drawn
            self.free_length += drawn
        if need > self.free_length and self.reserve > 0.0:    # paying out
            drawn = min(self.reserve, need - self.free_length)
            self.reserve -= drawn
            self.free_length += drawn
        seg = self.segment_length
        x = self.nodes.copy()
        if need >= self.free_length:        # taut (or overstretched): the straight chain
            u = (tail - start) / need if need > 1e-15 else np.array([0.0, 0.0, -1.0])
            x = start[None, :] + (seg * np.arange(self.n + 1))[:, None] * u[None, :]
        else:
            x[1:-1, 2] -= SAG_STEP
            x = np.array(_fabrik(x.tolist(), start.tolist(), tail.tolist(), seg))
        self.nodes = x
        self.attach_gap = float(np.linalg.norm(x[-1] - tail))
        return self.state()

    def pin(self, entry: FloatArray, exit_: FloatArray, tail: FloatArray) -> None:
        """A stitch was made: the thread now passes through ``entry`` and ``exit_`` (tissue
        frame). The free chain restarts at the exit, a little longer than the exit-tail
        distance (the thread trails the needle loosely); the stitch leaves a loop of
        ``LOOP_SLACK`` (plus whatever of the old chain the stitch did not use) as slack; the
        reserve pays for the rest. The thread's length is kept.

        Raises:
            ValueError: when the thread is too short for the stitch.
        """
        entry = np.asarray(entry, dtype=float)
        exit_ = np.asarray(exit_, dtype=float)
        tail = np.asarray(tail, dtype=float)
        consumed = (float(np.linalg.norm(entry - self.pinned[-1]))
                    + float(np.linalg.norm(exit_ - entry)))
        free = 1.05 * float(np.linalg.norm(tail - exit_)) + 1e-3
        need = consumed + free + LOOP_SLACK
        if need > self.free_length + self.reserve:
            raise ValueError(f"SutureThread.pin: the stitch needs {need:.4f} m of thread, "
                             f"{self.free_length + self.reserve:.4f} m are left")
        left = self.free_length - consumed - free     # the old chain's excess, if any
        self.slack += LOOP_SLACK + max(0.0, left)
        self.reserve -= LOOP_SLACK + max(0.0, -left)
        self.free_length = free
        self.pinned += [entry.copy(), exit_.copy()]
        self.nodes = self._initial_chain(exit_, tail, free)
        self.update(tail)

    def state(self) -> ThreadState:
        return ThreadState(np.array(self.pinned), self.nodes.copy(), self.slack,
                           self.free_length, self.reserve, self.attach_gap)


__all__ = ["ITERATIONS", "LOOP_SLACK", "SAG_STEP", "TAUT", "SutureThread", "ThreadState"]
