"""The abdomen physics at its own rate, in its own thread (real-time runs).

A headless trial steps the abdomen inline, in simulated time, every ``dt_physics / dt``
control steps (deterministic; :class:`vasim.trials.vf.TrialRunner`). A real-time run (the
viewer, the haptic servo loop) instead runs :class:`PhysicsThread`: it steps the
:class:`~vasim.abdomen.world.Abdomen` every ``dt`` of wall-clock time with the latest tool
pose it was given, and publishes each step's immutable snapshot by swapping one reference.
Readers (the servo loop at 1 kHz, the viewer at 30 Hz) take ``latest`` and never see a
half-updated mesh; writers only post the tool pose. This is the hand-off of the
architecture guide: one direction, snapshots between loops.

The mass-spring kernels release the interpreter lock (numba ``nogil``), so the solver runs
beside the servo thread; the Python glue of a step does hold it for a fraction of a
millisecond. A step that takes longer than ``dt`` delays the next one (the physics falls
behind real time and the snapshot's ``t`` says so); no burst of catch-up steps is run.

Example:
    >>> import time
    >>> from vasim.abdomen.world import Abdomen
    >>> with PhysicsThread(Abdomen("default")) as physics:
    ...     time.sleep(0.1)
    ...     snap = physics.latest
    >>> snap.seq > 0 and physics.stats()["steps"] > 0
    True
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

import numpy as np

from vasim.abdomen.contact import ToolPose
from vasim.abdomen.snapshot import AbdomenSnapshot
from vasim.abdomen.world import Abdomen

log = logging.getLogger(__name__)

MAX_PENDING_EVENTS = 10_000
"""Events kept between two :meth:`PhysicsThread.drain_events` calls (the newest)."""


class PhysicsThread:
    """Steps an :class:`Abdomen` in real time in a daemon thread.

    Args:
        abdomen: the world to step (owned by the thread while it runs).
        rate_hz: stepping rate; default ``1 / abdomen.dt`` (real time).
    """

    def __init__(self, abdomen: Abdomen, *, rate_hz: float | None = None) -> None:
        self.abdomen = abdomen
        self.period = 1.0 / rate_hz if rate_hz else abdomen.dt
        self._tool: ToolPose | None = None
        self._latest: AbdomenSnapshot = abdomen.latest
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._periods: list[float] = []
        self._costs: list[float] = []
        self._cpu: list[float] = []
        self._steps = 0  # all steps (the timing lists above are trimmed)
        # Events of the steps since the last drain_events() (they travelled only
        # inside each snapshot, so a reader skipping snapshots lost organ resets).
        self._events: list[tuple[float, str, str]] = []
        self._events_lock = threading.Lock()
        self.error: BaseException | None = None

    # -- the hand-off ---------------------------------------------------------------------
    def set_tool(self, pose: ToolPose | None) -> None:
        """Posts the tool pose the next step uses (a reference swap; any thread)."""
        if pose is not None and not (np.all(np.isfinite(pose.tip))
                                     and np.all(np.isfinite(pose.fulcrum))):
            return  # a non-finite pose never reaches the physics; the last good one stays
        self._tool = pose

    @property
    def latest(self) -> AbdomenSnapshot:
        """The newest complete snapshot (immutable)."""
        return self._latest

    def drain_events(self) -> list[tuple[float, str, str]]:
        """The events ``(t, kind, detail)`` of every step since the last call, oldest first
        (lossless, unlike a snapshot's ``events``: those are one step's only, and a reader
        that skips snapshots would miss them). At most ``MAX_PENDING_EVENTS`` are kept
        between calls (the newest)."""
        with self._events_lock:
            out, self._events = self._events, []
        return out

    # -- life cycle -----------------------------------------------------------------------
    def start(self) -> PhysicsThread:
        if self._thread is not None:
            raise RuntimeError("the physics thread is already running")
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="vasim-physics", daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout: float = 5.0) -> None:
        """Stops the thread and waits for it (at most ``timeout`` s).

        A thread still stepping after the timeout is logged and stays registered
        (forgetting it let a later :meth:`start` step the abdomen from two threads; ``start``
        refuses while it is registered, ``running`` stays true until it ends).
        """
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=timeout)
            if self._thread.is_alive():
                log.error("the abdomen physics thread did not stop within %.1f s (a step is "
                          "still running); it stays registered", timeout)
                return
            self._thread = None

    def __enter__(self) -> PhysicsThread:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _run(self) -> None:
        period = self.period
        next_t = time.perf_counter()
        last = None
        try:
            while not self._stop.is_set():
                now = time.perf_counter()
                if last is not None:
                    self._periods.append(now - last)
                last = now
                c0 = time.thread_time()
                snap = self.abdomen.step(self._tool)
                if snap.events and snap.seq != self._latest.seq:  # a new step's events
                    with self._events_lock:
                        self._events.extend((snap.t, k, d) for k, d in snap.events)
                        if len(self._events) > MAX_PENDING_EVENTS:
                            del self._events[:-MAX_PENDING_EVENTS]
                self._latest = snap
                self._steps += 1
                self._costs.append(time.perf_counter() - now)
                self._cpu.append(time.thread_time() - c0)
                next_t += period
                delay = next_t - time.perf_counter()
                if delay > 0:
                    self._stop.wait(delay)
                else:
                    next_t = time.perf_counter()  # behind: no catch-up burst
                if len(self._periods) > 100_000:  # keep memory bounded in long sessions
                    del self._periods[:50_000]
                    del self._costs[:50_000]
                    del self._cpu[:50_000]
        except BaseException as exc:  # the thread must not die silently
            log.exception("abdomen physics thread failed")
            self.error = exc

    def stats(self) -> dict[str, Any]:
        """Achieved rate and step cost so far (seconds; NaN before two steps).

        ``cost_*`` is the wall-clock time of a step, ``cpu_*`` the CPU time the physics
        thread spent in it (the cost on one core: on a busy machine the wall clock also
        counts the waits for a core).
        """
        p = np.asarray(self._periods[-10_000:])
        c = np.asarray(self._costs[-10_000:])
        u = np.asarray(self._cpu[-10_000:])
        return {
            "steps": self._steps,
            "rate_hz": float(1.0 / p.mean()) if len(p) else float("nan"),
            "period_p50": float(np.median(p)) if len(p) else float("nan"),
            "period_p99": float(np.percentile(p, 99)) if len(p) else float("nan"),
            "cost_p50": float(np.median(c)) if len(c) else float("nan"),
            "cost_max": float(c.max()) if len(c) else float("nan"),
            "cpu_p50": float(np.median(u)) if len(u) else float("nan"),
            "cpu_max": float(u.max()) if len(u) else float("nan"),
        }


__all__ = ["MAX_PENDING_EVENTS", "PhysicsThread"]
