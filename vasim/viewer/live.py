"""A trial running in real time for the viewer, with the shape of ``RealtimeTrial``.

``vasim.trials.realtime.RealtimeTrial`` is the servo loop driving a trial at 1 kHz on its
own thread (physics on another). The viewer codes against its interface::

    RealtimeTrial(config, device=None, *, schema=None, physics=..., servo=None)
    .start(); .stop(); .done; .frame() -> TrialFrame; .timing(); .result(**kw)

:class:`SimThreadTrial` is the viewer's own implementation of that shape: one thread
advances a ``TrialRunner`` by the wall-clock time elapsed since its previous iteration
(``loop_hz``, 120 Hz), capped at ``max_catch_up_s`` so a stall slows the trial down
instead of fast-forwarding it; the sub-step remainder is carried over, so simulated time
tracks wall time (times ``speed``). :func:`make_live_trial` picks ``RealtimeTrial`` when the
module exists and ``speed`` is 1, else this class: swapping is that one function.

Input devices: a ``TrialRunner`` asks its operator for the master increment dX_M each step
(``act(percept)``, ``vasim.operator.port``). :class:`DeviceOperator` turns any
``vasim.haptics`` ``Device`` (the browser's dragged tool tip, a haptic device) into such an
operator: dX_M is the difference of two successive readings; an invalid reading or a held
clutch button (``BUTTON_2``, the servo loop's clutch) moves nothing, and the first reading
after either is the new reference (indexing, as the servo loop's clutch does).
"""

from __future__ import annotations

import abc
import importlib.util
import logging
import threading
import time
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from vasim.core.config import check_number, expect
from vasim.fixtures.schema import Schema
from vasim.haptics.device import BUTTON_2, Device
from vasim.haptics.observation import OperatorObservation
from vasim.operator.port import Percept
from vasim.trials.vf import TrialConfig, TrialFrame, TrialResult, TrialRunner

log = logging.getLogger(__name__)


class LiveTrial(Protocol):
    """What the viewer needs from a trial running in real time (``RealtimeTrial``'s shape)."""

    @property
    def done(self) -> bool: ...

    def start(self) -> Any: ...

    def stop(self) -> None: ...

    def frame(self) -> TrialFrame: ...

    def timing(self) -> Any: ...

    def result(self, **kw: Any) -> TrialResult: ...


class DeviceOperator:
    """A ``Device`` as a ``TrialRunner`` operator (module docstring).

    Args:
        device: a started device.
        clutch_button: button bitmask that decouples the master while held.

    Attributes:
        steps, moved: steps answered and steps with a non-zero increment.
    """

    def __init__(self, device: Device, *, clutch_button: int = BUTTON_2):
        self.device = device
        self.clutch_button = int(clutch_button)
        self._ref: tuple[float, float, float] | None = None
        self.steps = 0
        self.moved = 0

    @property
    def profile(self) -> None:
        """No simulated person behind a device (``trial_meta`` reads this attribute)."""
        return None

    def reset(self, start: np.ndarray) -> None:
        self._ref = None

    def act(self, percept: Percept) -> tuple[float, float, float]:
        """The trial operator protocol (``vasim.operator.port``): :meth:`step`."""
        return self.step(percept.observation())

    def step(self, obs: OperatorObservation) -> tuple[float, float, float]:
        """The master increment dX_M [m] since the previous step."""
        self.steps += 1
        self.device.write_force(np.asarray(obs.force, dtype=np.float64))
        s = self.device.read()
        if not s.valid or (s.buttons & self.clutch_button):
            self._ref = None
            return (0.0, 0.0, 0.0)
        p = (float(s.position[0]), float(s.position[1]), float(s.position[2]))
        ref, self._ref = self._ref, p
        if ref is None:
            return (0.0, 0.0, 0.0)
        d = (p[0] - ref[0], p[1] - ref[1], p[2] - ref[2])
        if d != (0.0, 0.0, 0.0):
            self.moved += 1
        return d


@dataclass(frozen=True)
class LoopStats:
    """Timing of a :class:`SimThreadTrial` so far.

    Attributes:
        iterations: loop iterations. wall_s: wall time the trial has run [s].
        sim_s: simulated time [s]. control_hz: control steps per wall second (the rate the
        1 kHz loop actually achieved, in bursts of ~1000 / ``loop_hz`` steps).
        realtime_factor: sim_s / wall_s. load: CPU seconds in the loop per wall second.
    """

    iterations: int
    wall_s: float
    sim_s: float
    control_hz: float
    realtime_factor: float
    load: float

    def to_dict(self) -> dict[str, float | int | str]:
        d: dict[str, float | int | str] = {k: getattr(self, k) for k in self.__annotations__}
        d["mode"] = "viewer-sim-thread"
        return d


class PacedThread(abc.ABC):
    """A trial advanced in real time on its own thread, the part :class:`SimThreadTrial`
    and the teleoperation trial (``teleop_live.LiveTeleopTrial``) share (module
    docstring): each iteration advances by the wall time elapsed since the previous one
    (times ``speed``, at most ``max_catch_up_s``), in whole steps of ``dt``, the remainder
    carried over.

    Subclasses give ``_advance(n)`` (run n steps; under ``_lock``), ``_finished()``,
    ``_clock()`` (simulated time [s], steps run) and may extend ``stop()``.
    """

    def __init__(self, device: Device | None, *, dt: float, speed: float, loop_hz: float,
                 max_catch_up_s: float) -> None:
        check_number(speed, "speed", gt=0)
        self.device = device
        self.dt = float(dt)
        self.speed = float(speed)
        self.period = 1.0 / float(loop_hz)
        self.max_catch_up_s = float(max_catch_up_s)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()  # result() vs the loop
        self._iterations = 0
        self._wall = 0.0
        self._cpu = 0.0
        self._t0_wall: float | None = None
        self.error: BaseException | None = None
        """An exception that stopped the loop (the trial is then done)."""

    @abc.abstractmethod
    def _advance(self, n: int) -> None:
        """Runs ``n`` steps of the trial (called under ``_lock``)."""

    @abc.abstractmethod
    def _finished(self) -> bool:
        """True once the trial has ended by itself."""

    @abc.abstractmethod
    def _clock(self) -> tuple[float, int]:
        """(simulated time [s], steps run so far)."""

    @property
    def done(self) -> bool:
        return self._finished() or self.error is not None

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def start(self) -> Any:
        """Starts the device and the thread; returns self."""
        if self._thread is not None:
            raise RuntimeError(f"{type(self).__name__}.start() was already called")
        if self.device is not None:
            self.device.start()
        self._t0_wall = time.perf_counter()
        self._thread = threading.Thread(target=self._loop, name="vasim-viewer-trial",
                                        daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout: float = 5.0) -> None:
        """Stops the loop (joined); the trial keeps what it recorded. Idempotent."""
        self._stop.set()
        t = self._thread
        if t is not None and t is not threading.current_thread():
            t.join(timeout)
        if self.device is not None:
            try:
                self.device.stop()
            except Exception:  # a device that fails to stop must not block the viewer
                log.exception("device %s failed to stop", getattr(self.device, "name", "?"))

    def timing(self) -> LoopStats:
        wall = self._wall
        sim, steps = self._clock()
        return LoopStats(iterations=self._iterations, wall_s=wall, sim_s=sim,
                         control_hz=steps / wall if wall > 0 else 0.0,
                         realtime_factor=sim / wall if wall > 0 else 0.0,
                         load=self._cpu / wall if wall > 0 else 0.0)

    def _loop(self) -> None:
        dt = self.dt
        last = time.perf_counter()
        debt = 0.0
        while not self._stop.is_set() and not self._finished():
            tick = time.perf_counter()
            elapsed = min(tick - last, self.max_catch_up_s)
            last = tick
            cpu0 = time.thread_time()
            debt += elapsed * self.speed
            n = int(debt / dt + 1e-9)
            try:
                if n > 0:
                    debt -= n * dt
                    self._advance(n)
            except Exception as exc:
                log.exception("live trial step failed")
                self.error = exc
                return
            self._cpu += time.thread_time() - cpu0
            self._wall += elapsed
            self._iterations += 1
            self._stop.wait(max(0.0, self.period - (time.perf_counter() - tick)))


class SimThreadTrial(PacedThread):
    """A ``TrialRunner`` advanced in real time on its own thread (module docstring).

    Args:
        config: the trial. device: input device (None: the scripted operator of ``config``).
        schema: a loaded schema overriding ``config.schema`` (the f5PL editor's).
        physics: accepted for interface compatibility; the physics runs inside the
            runner's steps on this thread.
        rate_hz: the control rate [Hz]; must equal 1 / ``config.dt``.
        speed: simulated seconds per wall second (1 = real time; demos and tests go faster).
        loop_hz: iterations per second of the thread.
        max_catch_up_s: most simulated time one iteration may advance [s].

    Raises:
        ConfigError: a bad schema/task (from ``TrialRunner``), rate or speed.
    """

    def __init__(self, config: TrialConfig, device: Device | None = None, *,
                 schema: Schema | None = None, physics: str = "thread",
                 rate_hz: float = 1000.0, speed: float = 1.0, loop_hz: float = 120.0,
                 max_catch_up_s: float = 0.05):
        expect(abs(rate_hz * config.dt - 1.0) <= 1e-9, rate_hz,
               f"1 / the trial's dt ({config.dt!r} s)", field="rate_hz")
        super().__init__(device, dt=config.dt, speed=speed, loop_hz=loop_hz,
                         max_catch_up_s=max_catch_up_s)
        self.config = config
        self.runner = TrialRunner(config, schema)
        if device is not None:
            self.runner.operator = DeviceOperator(device)

    def _finished(self) -> bool:
        return bool(self.runner.done)

    def _clock(self) -> tuple[float, int]:
        f = self.runner.frame
        return (f.t if f.k >= 0 else 0.0), f.k + 1

    def _advance(self, n: int) -> None:
        # **Decision** (issue #31): the runner publishes its frame (what the pages draw and
        # the "running behind" meter reads) once per ``advance``; an iteration's steps are
        # run in chunks of at most FRAME_STEPS so that a long catch-up (``speed`` x
        # ``max_catch_up_s`` of simulated time: 50 s at 1000x, seconds of wall time on a
        # slow machine) is seen as it goes, not as one jump at its end. The same steps run
        # in the same order: only the frames in between are new.
        with self._lock:
            while n > 0:
                k = min(n, FRAME_STEPS)
                self.runner.advance(k * self.dt)
                n -= k

    def frame(self) -> TrialFrame:
        return self.runner.frame

    def result(self, **kw: Any) -> TrialResult:
        """The runner's result (call after ``stop()`` or once ``done``)."""
        with self._lock:
            return self.runner.result(**kw)


FRAME_STEPS = 100
"""Most control steps :class:`SimThreadTrial` runs between two published frames (0.1 s of
simulated time at 1 ms; publishing costs well under 1 % of 100 steps)."""


def realtime_available() -> bool:
    """True when ``vasim.trials.realtime`` (the 1 kHz servo-loop trial) is installed."""
    return importlib.util.find_spec("vasim.trials.realtime") is not None


def make_live_trial(config: TrialConfig, device: Device | None = None, *,
                    schema: Schema | None = None, speed: float = 1.0) -> LiveTrial:
    """The trial the viewer runs: ``RealtimeTrial`` in real time when it exists (not
    started), else :class:`SimThreadTrial` (also for ``speed`` != 1, which the servo loop
    does not offer)."""
    if speed == 1.0 and realtime_available():
        from vasim.trials.realtime import RealtimeTrial

        return RealtimeTrial(config, device, schema=schema)
    return SimThreadTrial(config, device, schema=schema, speed=speed)


__all__ = ["DeviceOperator", "LiveTrial", "LoopStats", "PacedThread", "SimThreadTrial",
           "make_live_trial", "realtime_available"]
