r"""The 1 kHz servo loop: device -> guard -> clutch -> plant -> saturation -> device.

:class:`ServoLoop` is a thin stateful shell (it owns the timing, nothing else): each tick it

1. lets an observing device see the task (``device.observe(plant.observation())``, the
   scripted operator's hook; see ``vasim.haptics.device.ObservingDevice``);
2. reads the device (``device.read()``) and, if recording, stores the raw reading;
3. guards the reading (``vasim.haptics.guard``): invalid, NaN/inf or out-of-workspace data
   is replaced by the last good state (position, buttons), the force of the tick is zero,
   and an event (kind, tick, value) is logged; the plant still ticks (its time goes on),
   with the held master position;
4. clutch / indexing (:func:`clutch_update`): while the clutch button is held the master is
   decoupled (its position frozen, zero force); on release the offset master - device is
   re-indexed so that the master continues from where it stopped; presses are counted. The
   first good reading is indexed the same way onto ``home`` (when given), so a trial starts
   with the master at the task's start whatever the stylus' position;
5. calls the plant, ``force = plant.tick(t, master, buttons)`` (the trial: MS, task, FF,
   coupling), guards its force (NaN/inf -> zero, logged);
6. saturates the force to ``device.limits.max_force_n`` keeping its direction and writes it;
7. records timing (``vasim.haptics.timing``) and publishes a :class:`ServoSnapshot`.

Three ways to run it:

* ``run_ticks(n)`` — deterministic: simulated time t = k / rate, no sleeping (tests,
  headless trials, replays);
* ``start()`` — real time, on its own thread (below);
* ``start(driver="device")`` — inside the device driver's scheduler callback (OpenHaptics),
  for a device that implements ``ScheduledDevice``.

Real-time policy (own thread), **decisions**:

* Waiting: sleep until ``spin_s`` (default 0.2 ms) before the deadline, then spin on
  ``perf_counter_ns``. ``time.sleep`` overshoots by ~0.1 ms typically and by several ms
  under load (measured on the 2-core development host: p50 75 us, p99 0.57 ms, for a
  0.5 ms sleep); the spin absorbs the typical overshoot at the cost of ``spin_s`` of CPU
  per tick. The deadlines lie on a fixed grid t0 + k T (no drift).
* Missed deadlines are counted, not caught up: a tick that starts late runs at once, every
  slot that passed entirely meanwhile is skipped (``missed_deadlines``) and the loop goes
  back to the grid. A burst of catch-up ticks would feed the plant a train of
  near-zero-length periods and the device a force staircase; skipping costs only the
  missed samples.
* The GIL: the loop shares the interpreter with the physics and the viewer. CPython hands
  the lock to a waiting thread only every ``sys.getswitchinterval()`` (5 ms by default), so
  a waking servo thread can wait up to 5 ms for a busy Python thread. Measured
  (``bench/haptics.py``, trivial plant beside a pure-Python busy thread, shared and loaded
  2-core host, two runs): 319-434 Hz achieved, p99 period 9-12 ms with the default 5 ms
  interval; 811-972 Hz, p99 2.1-8.8 ms with 0.5 ms. So ``switch_interval_s`` defaults to
  5e-4: the loop sets it while it runs in real time and restores the previous value on
  stop (None leaves it alone; ``run_ticks`` never touches it). numpy and numba
  (``nogil=True``) kernels release the lock; pure-Python work does not. A separate process
  with shared memory remains the fallback if the measurements with the physics running
  demand it.
* Errors never leave the thread: an exception in the device or plant zeroes the force,
  stops the loop, is logged (``logging`` and ``events``) and kept in ``error``.

Example (deterministic mode, the emulator pushed by a spring plant):
    >>> import numpy as np
    >>> from vasim.haptics.devices.emulator import EmulatorDevice
    >>> class Spring:
    ...     def on_start(self, t): pass
    ...     def tick(self, t, master, buttons): return -200.0 * master
    ...     def on_stop(self): pass
    >>> dev = EmulatorDevice(hand=np.array([0.0, 0.0, 0.01]))
    >>> loop = ServoLoop(dev, Spring())
    >>> loop.run_ticks(500)
    500
    >>> round(loop.latest.force[2], 2)             # hand 300 N/m vs spring 200 N/m: 1.2 N
    -1.2
    >>> loop.stop()                                # zeroes the force, stops the device
    >>> dev.applied_force.tolist()
    [0.0, 0.0, 0.0]
"""

from __future__ import annotations

import logging
import math
import os
import sys
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from math import isfinite
from typing import Literal, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vasim.core.errors import DeviceError
from vasim.haptics.coupling import (
    CouplingParams,
    LinearForce,
    ProxyState,
    TissueModel,
    proxy_step_xyz,
    tissue_force,
    velocity_alpha,
)
from vasim.haptics.device import (
    BUTTON_2,
    Device,
    FloatArray,
    ObservationSource,
    ObservingDevice,
    ScheduledDevice,
)
from vasim.haptics.guard import GuardLog, check_force, check_sample
from vasim.haptics.observation import OperatorObservation
from vasim.haptics.timing import TimingMode, TimingRecorder, TimingStats

log = logging.getLogger(__name__)

Vec = tuple[float, float, float]


# ---------------------------------------------------------------------------------------
# The plant interface


@runtime_checkable
class Plant(Protocol):
    """What the servo loop drives (the trial runner provides one), in dm_control's spirit
    of lifecycle hooks: the loop owns the timing and only calls these.

    * ``on_start(t)`` — once, before the first tick (t [s], the loop's clock);
    * ``tick(t, master, buttons) -> force`` — every tick: ``master`` (3,) is the master
      position [m] (device frame, after guard and clutch), ``buttons`` the button bitmask;
      returns the (3,) force [N] to render on the device (the loop guards and saturates
      it). Called from the servo thread: must be quick (well below 1 ms) and must not block.
    * ``on_stop()`` — once, after the last tick (also after an error).

    A plant may also implement ``observation() -> OperatorObservation | None``
    (``ObservationSource``) for observing devices (the scripted operator).
    """

    def on_start(self, t: float) -> None: ...

    def tick(self, t: float, master: FloatArray, buttons: int
             ) -> FloatArray | Sequence[float]: ...

    def on_stop(self) -> None: ...


class NullPlant:
    """A plant that renders no force (the master moves nothing): for timing and devices."""

    def on_start(self, t: float) -> None:
        del t

    def tick(self, t: float, master: FloatArray, buttons: int) -> FloatArray:
        del t, master, buttons
        return np.zeros(3)

    def on_stop(self) -> None:
        pass


class CoupledToolPlant:
    """A simulated tool tip (the proxy) tied to the master by the virtual coupling.

    The proxy is pushed by a tissue model (``set_tissue``: a ``LinearForce`` extrapolated
    between physics updates, a ``PatchForce`` re-evaluated with ``patch_force``, or None)
    and optionally by ``extra_force(t, x_proxy, v_proxy) -> (3,)`` [N] (e.g. a fixture's
    force field, taken as constant over the step). The rendered force is the coupling force
    (``vasim.haptics.coupling``). The step uses the nominal ``dt`` (deterministic; the
    loop's missed ticks do not change the dynamics). Works on floats (``proxy_step_xyz``).

    Args:
        params: coupling parameters.
        dt: the servo period [s].
        tissue: initial tissue model.
        extra_force: optional external force on the proxy [N].
    """

    # The servo-thread state (floats, not arrays: cheaper at 1 kHz); set by ``on_start``.
    _xp: tuple[float, ...] | None  # proxy position [m], None before the first tick
    _vp: tuple[float, ...]  # proxy velocity [m/s]
    _x_prev: tuple[float, ...] | None  # last master position [m]
    _vd: tuple[float, ...]  # filtered device velocity [m/s]

    def __init__(self, params: CouplingParams | None = None, *, dt: float = 1e-3,
                 tissue: TissueModel = None,
                 extra_force: Callable[[float, FloatArray, FloatArray], ArrayLike] | None = None):
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be > 0 s, got {dt!r}")
        self.params = params if params is not None else CouplingParams()
        self.dt = float(dt)
        self._alpha = velocity_alpha(self.params.velocity_cutoff_hz, self.dt)
        self._tissue = tissue
        self._extra = extra_force
        self.on_start(0.0)

    def set_tissue(self, tissue: TissueModel) -> None:
        """Replaces the tissue model (atomic: safe to call from the physics thread)."""
        self._tissue = tissue

    @property
    def proxy(self) -> ProxyState | None:
        """The proxy (None before the first tick)."""
        if self._xp is None:
            return None
        return ProxyState(np.array(self._xp), np.array(self._vp))

    @proxy.setter
    def proxy(self, state: ProxyState) -> None:
        self._xp = tuple(np.asarray(state.x, dtype=np.float64).tolist())
        self._vp = tuple(np.asarray(state.v, dtype=np.float64).tolist())

    def reset_proxy(self, x: ArrayLike, v: ArrayLike = (0.0, 0.0, 0.0)) -> None:
        """Puts the proxy at x [m] with velocity v [m/s], the device-velocity estimate at v
        and the last master position at x (a tool already moving with the hand)."""
        xs = tuple(float(c) for c in np.asarray(x, dtype=np.float64).reshape(3))
        vs = tuple(float(c) for c in np.asarray(v, dtype=np.float64).reshape(3))
        self._xp, self._vp, self._vd, self._x_prev = xs, vs, vs, xs

    @property
    def device_velocity(self) -> FloatArray:
        """(3,) the filtered device velocity [m/s]."""
        return np.array(self._vd)

    def on_start(self, t: float) -> None:
        del t
        self._xp = None
        self._vp = (0.0, 0.0, 0.0)
        self._x_prev = None
        self._vd = (0.0, 0.0, 0.0)
        self.proxy_resets = 0

    def tick(self, t: float, master: FloatArray, buttons: int) -> tuple[float, float, float]:
        del buttons
        x0, x1, x2 = master.tolist()
        if self._xp is None or self._x_prev is None:
            self._xp = self._x_prev = (x0, x1, x2)
        p, a, dt = self._x_prev, self._alpha, self.dt
        vd = self._vd
        vd = self._vd = (vd[0] + a * ((x0 - p[0]) / dt - vd[0]),
                         vd[1] + a * ((x1 - p[1]) / dt - vd[1]),
                         vd[2] + a * ((x2 - p[2]) / dt - vd[2]))
        self._x_prev = (x0, x1, x2)
        tissue = self._tissue
        if self._extra is not None:
            x_proxy = np.array(self._xp)
            f_t, k_t = tissue_force(tissue, x_proxy)
            fe = np.asarray(self._extra(t, x_proxy, np.array(self._vp)), dtype=np.float64)
            tissue = LinearForce(f_t + fe, k_t, x_proxy)
        xp, vp, force = proxy_step_xyz(self._xp, self._vp, (x0, x1, x2), vd, tissue,
                                       self.params, dt)
        if not (isfinite(xp[0]) and isfinite(xp[1]) and isfinite(xp[2])
                and isfinite(vp[0]) and isfinite(vp[1]) and isfinite(vp[2])):
            # A non-finite tissue or extra force would leave the proxy NaN for good (every
            # later force NaN, zeroed by the guard: force feedback silently off for the rest
            # of the trial). The proxy restarts at the hand instead; this tick outputs 0.
            self.proxy_resets += 1
            log.warning("proxy state became non-finite at t=%.3f s; reset to the master", t)
            self._xp, self._vp = (x0, x1, x2), (0.0, 0.0, 0.0)
            return (0.0, 0.0, 0.0)
        self._xp, self._vp = xp, vp
        return force

    def on_stop(self) -> None:
        pass


# ---------------------------------------------------------------------------------------
# Clutch / indexing (pure)


@dataclass(frozen=True)
class ClutchState:
    """Clutch state: master = device + offset while coupled, frozen while clutched.

    Attributes:
        offset: master - device [m] while coupled.
        engaged: True while the clutch button is held (master decoupled).
        held: the frozen master position while engaged [m].
        count: number of clutch presses so far.
    """

    offset: Vec = (0.0, 0.0, 0.0)
    engaged: bool = False
    held: Vec = (0.0, 0.0, 0.0)
    count: int = 0


def clutch_update(state: ClutchState, device: Vec, pressed: bool) -> tuple[ClutchState, Vec]:
    """One clutch step.

    Args:
        state: the clutch before this tick.
        device: device position (3 floats) [m].
        pressed: whether the clutch button is held.

    Returns:
        (new state, master position (3 floats) [m]). Pressing freezes the master at its
        current position; releasing re-indexes the offset so that master = frozen position
        (no jump); the master then follows the device's increments again.

    >>> s, m = clutch_update(ClutchState(), (0.01, 0.0, 0.0), True)     # press: freeze
    >>> s, m = clutch_update(s, (0.05, 0.0, 0.0), True)                  # device moves
    >>> m
    (0.01, 0.0, 0.0)
    >>> s, m = clutch_update(s, (0.05, 0.0, 0.0), False)                 # release
    >>> s, m = clutch_update(s, (0.06, 0.0, 0.0), False)                 # +1 cm
    >>> [round(v, 12) for v in m], s.count
    ([0.02, 0.0, 0.0], 1)
    """
    o = state.offset
    if state.engaged:
        if pressed:
            return state, state.held
        h = state.held
        offset = (h[0] - device[0], h[1] - device[1], h[2] - device[2])
        return ClutchState(offset, False, h, state.count), h
    master = (device[0] + o[0], device[1] + o[1], device[2] + o[2])
    if pressed:
        return ClutchState(o, True, master, state.count + 1), master
    return state, master


# ---------------------------------------------------------------------------------------
# What the loop publishes and records


@dataclass(frozen=True)
class ServoSnapshot:
    """The loop's latest tick, safe to read from another thread (immutable).

    Attributes:
        tick: tick index. t: loop time [s]. master: master position [m]. force: force
        written to the device [N]. buttons: button bitmask. clutched: clutch engaged.
        held: the reading was rejected by the guard (state held). saturated: the force was
        scaled down to the device's peak.
    """

    tick: int
    t: float
    master: Vec
    force: Vec
    buttons: int
    clutched: bool
    held: bool
    saturated: bool


@dataclass(frozen=True)
class ServoEvent:
    """Something the loop logged besides guard events: ``kind`` (``error``, ``indexed``),
    the tick and a message."""

    kind: str
    tick: int
    message: str


TRACE_COLUMNS = ("tick", "t", "master_x", "master_y", "master_z", "force_x", "force_y",
                 "force_z", "flags")
"""Columns of :class:`ServoTrace` rows. ``flags``: bit 0 held (guard), bit 1 clutched,
bit 2 saturated, bit 3 plant force rejected (non-finite)."""


class ServoTrace:
    """The loop's outputs per tick (float64 rows, ``TRACE_COLUMNS``), in preallocated chunks.

    Args:
        chunk: rows per chunk (> 0).
    """

    def __init__(self, chunk: int = 65_536):
        self._chunk = int(chunk)
        self._full: list[NDArray[np.float64]] = []
        self._cur = np.empty((self._chunk, len(TRACE_COLUMNS)))
        self._i = 0

    def append(self, row: tuple[float, ...]) -> None:
        if self._i == self._chunk:
            self._full.append(self._cur)
            self._cur = np.empty((self._chunk, len(TRACE_COLUMNS)))
            self._i = 0
        self._cur[self._i] = row
        self._i += 1

    def __len__(self) -> int:
        return len(self._full) * self._chunk + self._i

    def array(self) -> NDArray[np.float64]:
        """(n, 9) rows recorded so far."""
        return np.concatenate([*self._full, self._cur[:self._i]])


# ---------------------------------------------------------------------------------------
# The loop


class ServoLoop:
    """The 1 kHz servo loop (module docstring for the pipeline and the timing policy).

    Args:
        device: the input/force device.
        plant: what the master drives.
        rate_hz: nominal rate [Hz] (> 0).
        home: (3,) master position of the first good reading [m] (the first reading is
            indexed onto it); None: master = device position.
        clutch_button: bitmask of the clutch button (0 disables the clutch).
        workspace_margin_m: readings up to this far outside the device's workspace box are
            accepted (``vasim.haptics.guard``) [m].
        spin_s: the part of each wait spent spinning instead of sleeping [s].
        switch_interval_s: ``sys.setswitchinterval`` while running in real time [s]
            (module docstring; None: leave it alone).
        rt_priority: ask the OS to run the servo thread under real-time scheduling
            (``SCHED_FIFO`` at this priority, 1-99) while it runs on its own thread; None
            (default): normal scheduling. Refused (no privilege, another OS) -> a logged
            ``priority`` event and normal scheduling; ``priority_granted`` tells which.
        record: keep every raw device reading (``recording``: a ``StreamRecorder`` for
            replay) and the per-tick outputs (``trace``).

    Attributes:
        guard: the guard's counts and events.
        events: other events (errors, indexing).
        error: the exception that stopped the loop, if any.
        clutch: the clutch state (``clutch.count`` = clutch presses).
        latest: the latest ``ServoSnapshot`` (None before the first tick).
        timing: the ``TimingRecorder``.
    """

    def __init__(self, device: Device, plant: Plant, *, rate_hz: float = 1000.0,
                 home: ArrayLike | None = None, clutch_button: int = BUTTON_2,
                 workspace_margin_m: float = 0.01, spin_s: float = 2e-4,
                 switch_interval_s: float | None = 5e-4, record: bool = False,
                 rt_priority: int | None = None):
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"rate_hz must be > 0, got {rate_hz!r}")
        if not (math.isfinite(spin_s) and spin_s >= 0):
            raise ValueError(f"spin_s must be >= 0 s, got {spin_s!r}")
        if not (math.isfinite(workspace_margin_m) and workspace_margin_m >= 0):
            raise ValueError(f"workspace_margin_m must be >= 0, got {workspace_margin_m!r}")
        if switch_interval_s is not None and not (switch_interval_s > 0):
            raise ValueError(f"switch_interval_s must be > 0 s, got {switch_interval_s!r}")
        if rt_priority is not None and (isinstance(rt_priority, bool)
                                        or not isinstance(rt_priority, int)
                                        or not 1 <= rt_priority <= 99):
            raise ValueError(f"rt_priority must be an integer in 1..99 or None, got "
                             f"{rt_priority!r}")
        self.rt_priority = rt_priority
        self.priority_granted: bool | None = None
        self.device = device
        self.plant = plant
        self.rate_hz = float(rate_hz)
        self.period_s = 1.0 / self.rate_hz
        self.home: Vec | None = (None if home is None else
                                 tuple(float(v) for v in np.asarray(home, dtype=np.float64)
                                       .reshape(3)))  # type: ignore[assignment]  # 3 floats after reshape(3)
        self.clutch_button = int(clutch_button)
        self.workspace_margin_m = float(workspace_margin_m)
        self.spin_s = float(spin_s)
        self.switch_interval_s = switch_interval_s
        self.record = record
        self._observing = isinstance(device, ObservingDevice) and isinstance(
            plant, ObservationSource)
        self._limits = device.limits
        self._max_force = float(self._limits.max_force_n)
        self.timing = TimingRecorder()
        self._reset_state()
        self._thread: threading.Thread | None = None
        self._stop_event = threading.Event()
        self._lock = threading.RLock()  # open/close vs. a tick in a device callback
        self._mode: TimingMode | None = None
        self._open = False
        self._old_switch: float | None = None

    def _reset_state(self) -> None:
        self.guard = GuardLog(every=max(1, round(self.rate_hz)))
        self.events: list[ServoEvent] = []
        self.error: BaseException | None = None
        self.clutch = ClutchState()
        self.latest: ServoSnapshot | None = None
        self.missed_deadlines = 0
        self.saturated_ticks = 0
        self._k = 0
        self._good: Vec | None = None
        self._good_buttons = 0
        self.trace = ServoTrace() if self.record else None
        self.recording = None
        if self.record:
            from vasim.haptics.devices.replay import StreamRecorder

            self.recording = StreamRecorder(device_name=getattr(self.device, "name", "?"),
                                            limits=self._limits, rate_hz=self.rate_hz)

    # -- lifecycle -----------------------------------------------------------------------
    @property
    def ticks(self) -> int:
        """Ticks run so far."""
        return self._k

    @property
    def running(self) -> bool:
        """True while the loop runs (started, not stopped, not stopped by an error)."""
        return self._open and not self._stop_event.is_set()

    def _open_run(self, mode: TimingMode) -> None:
        if self._open:
            if self._mode != mode:
                raise RuntimeError(f"the loop is already running in {self._mode!r} mode")
            return
        self._mode = mode
        self._stop_event.clear()
        self.device.start()
        try:
            self.plant.on_start(self._k / self.rate_hz if mode == "simulated" else 0.0)
        except BaseException:
            self.device.stop()
            raise
        self._open = True
        if mode != "simulated" and self.switch_interval_s is not None:
            self._old_switch = sys.getswitchinterval()
            sys.setswitchinterval(self.switch_interval_s)

    def _close_run(self) -> None:
        """Zero force, plant.on_stop, device.stop; never raises (errors are logged)."""
        with self._lock:
            if not self._open:
                return
            self._open = False
        for what, fn in (("zero force", lambda: self.device.write_force(np.zeros(3))),
                         ("plant.on_stop", self.plant.on_stop),
                         ("device.stop", self.device.stop)):
            try:
                fn()
            except Exception as exc:  # logged; closing must go on
                self._log_error(exc, f"{what} failed")
        if self._old_switch is not None:
            sys.setswitchinterval(self._old_switch)
            self._old_switch = None

    def run_ticks(self, n: int) -> int:
        """Runs ``n`` ticks in simulated time (t = k / rate, no sleeping).

        Opens the run on the first call (``device.start``, ``plant.on_start``); later calls
        continue it; ``stop()`` closes it. Returns the number of ticks run (fewer than ``n``
        if an error stopped the loop: see ``error``).
        """
        if n < 0:
            raise ValueError(f"n must be >= 0, got {n!r}")
        self._open_run("simulated")
        done = 0
        rec = self.timing.record
        clock = time.perf_counter_ns
        for _ in range(n):
            if not self._open:
                break
            t0 = clock()
            if not self._safe_tick(self._k / self.rate_hz):
                self._close_run()
                break
            rec(t0, clock())
            done += 1
        return done

    def start(self, *, driver: Literal["thread", "device"] = "thread") -> None:
        """Starts the loop in real time: on its own thread, or (``driver="device"``) inside
        the device driver's scheduler callback (``ScheduledDevice``).

        ``device.start()`` runs in the caller's thread, so a missing driver or device
        raises its ``DeviceError`` here.
        """
        if driver == "device":
            if not isinstance(self.device, ScheduledDevice):
                raise DeviceError(f"device {getattr(self.device, 'name', '?')!r} has no "
                                  "scheduler of its own: use driver='thread'")
            self._t0_ns = time.perf_counter_ns()
            self.device.set_servo_hook(self._device_tick)
            try:
                self._open_run("device")
            except BaseException:
                self.device.set_servo_hook(None)
                raise
            return
        if driver != "thread":
            raise ValueError(f"driver must be 'thread' or 'device', got {driver!r}")
        if self._thread is not None and self._thread.is_alive():
            raise RuntimeError("the servo loop is already running")
        self._open_run("realtime")
        self._thread = threading.Thread(target=self._run_realtime, name="vasim-servo",
                                        daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 2.0) -> None:
        """Stops the loop (any mode), zeroes the force and closes plant and device."""
        self._stop_event.set()
        th = self._thread
        if th is not None and th is not threading.current_thread():
            th.join(timeout)
            if th.is_alive():
                log.warning("servo thread did not stop within %.1f s", timeout)
        self._thread = None
        if self._mode == "device" and isinstance(self.device, ScheduledDevice):
            self.device.set_servo_hook(None)
        self._close_run()

    def __enter__(self) -> ServoLoop:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def stats(self) -> TimingStats:
        """Timing statistics of the ticks so far (``vasim.haptics.timing``)."""
        return self.timing.stats(self.rate_hz, missed_deadlines=self.missed_deadlines,
                                 mode=self._mode or "simulated")

    # -- real time ------------------------------------------------------------------------
    def _raise_priority(self) -> None:
        """Real-time scheduling for the calling (servo) thread, if the OS grants it."""
        prio = self.rt_priority
        if prio is None:
            return
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(prio))
        except (AttributeError, OSError) as exc:  # no privilege, or not Linux
            self.priority_granted = False
            msg = f"real-time priority {prio} refused ({type(exc).__name__}: {exc}); " \
                  "normal scheduling"
            self.events.append(ServoEvent("priority", self._k, msg))
            log.info("%s", msg)
            return
        self.priority_granted = True
        self.events.append(ServoEvent("priority", self._k, f"SCHED_FIFO priority {prio}"))

    def _run_realtime(self) -> None:
        self._raise_priority()
        period = round(1e9 / self.rate_hz)
        spin = round(self.spin_s * 1e9)
        clock = time.perf_counter_ns
        sleep = time.sleep
        rec = self.timing.record
        stop = self._stop_event
        t0 = clock()
        deadline = t0
        try:
            while not stop.is_set():
                now = clock()
                wait = deadline - now - spin
                if wait > 0:
                    sleep(wait * 1e-9)
                while clock() < deadline:
                    pass
                start = clock()
                if not self._safe_tick((start - t0) * 1e-9):
                    break
                end = clock()
                rec(start, end)
                deadline += period
                if end >= deadline:
                    # Late: the next tick runs at once; slots that passed entirely are
                    # skipped and counted (no catch-up burst).
                    skipped = (end - deadline) // period
                    if skipped:
                        self.missed_deadlines += skipped
                        deadline += skipped * period
        except BaseException as exc:  # never leaves the thread
            self._log_error(exc, "servo thread failed")
        finally:
            self._close_run()

    def _device_tick(self) -> None:
        """Called by a ``ScheduledDevice`` from its scheduler callback (``driver="device"``).

        Holds the loop's lock for the tick, so ``stop()`` from another thread waits for a
        tick in flight before it closes the plant and the device.
        """
        with self._lock:
            if not self._open or self._stop_event.is_set():
                return
            start = time.perf_counter_ns()
            if self._safe_tick((start - self._t0_ns) * 1e-9):
                self.timing.record(start, time.perf_counter_ns())
            else:
                self._stop_event.set()
                if isinstance(self.device, ScheduledDevice):
                    self.device.set_servo_hook(None)

    # -- one tick -------------------------------------------------------------------------
    def _safe_tick(self, t: float) -> bool:
        """One tick; on an exception: log it, zero the force, return False (the caller
        ends the run: ``run_ticks`` and the thread close it at once; in a device callback
        the loop unhooks itself and ``stop()`` closes it from the caller's thread, since a
        driver cannot be stopped from inside its own scheduler callback)."""
        try:
            self._tick(t)
            return True
        except Exception as exc:
            self._log_error(exc, "servo tick failed")
            try:
                self.device.write_force(np.zeros(3))
            except Exception as exc2:
                self._log_error(exc2, "zeroing the force failed")
            return False

    def _log_error(self, exc: BaseException, what: str) -> None:
        if self.error is None:
            self.error = exc
        msg = f"{what}: {type(exc).__name__}: {exc}"
        self.events.append(ServoEvent("error", self._k, msg))
        log.error("%s\n%s", msg, "".join(traceback.format_exception(exc)).rstrip())

    def _tick(self, t: float) -> None:
        k = self._k
        dev = self.device
        if self._observing:
            obs: OperatorObservation | None = self.plant.observation()  # type: ignore[attr-defined]  # checked: ObservationSource
            if obs is not None:
                dev.observe(obs)  # type: ignore[attr-defined]  # checked: an observing device
        sample = dev.read()
        if self.recording is not None:
            self.recording.append(k, sample)
        event = check_sample(sample, self._limits, k, self.workspace_margin_m)
        held = event is not None
        if held:
            self.guard.add(event)  # type: ignore[arg-type]  # held: not None
            good = self._good
            buttons = self._good_buttons
        else:
            p = sample.position
            good = (float(p[0]), float(p[1]), float(p[2]))
            buttons = int(sample.buttons)
            if self._good is None and self.home is not None:
                h = self.home
                self.clutch = ClutchState((h[0] - good[0], h[1] - good[1], h[2] - good[2]))
                self.events.append(ServoEvent("indexed", k, f"first reading {good!r} "
                                              f"indexed onto home {h!r}"))
            self._good = good
            self._good_buttons = buttons
        if good is None:  # nothing good yet: the master waits at home (or the origin)
            master = self.home if self.home is not None else (0.0, 0.0, 0.0)
            clutched = False
        else:
            pressed = bool(buttons & self.clutch_button)
            self.clutch, master = clutch_update(self.clutch, good, pressed)
            clutched = self.clutch.engaged
        f = self.plant.tick(t, np.array(master), buttons)
        f0, f1, f2 = f.tolist() if isinstance(f, np.ndarray) else (float(v) for v in f)
        fevent = check_force(f0, f1, f2, k)
        flags = 0
        if fevent is not None:
            self.guard.add(fevent)
            f0 = f1 = f2 = 0.0
            flags |= 8
        if held or clutched or good is None:
            f0 = f1 = f2 = 0.0
        n2 = f0 * f0 + f1 * f1 + f2 * f2
        mx = self._max_force
        saturated = n2 > mx * mx
        if saturated:
            s = mx / math.sqrt(n2)
            f0, f1, f2 = f0 * s, f1 * s, f2 * s
            self.saturated_ticks += 1
        dev.write_force(np.array((f0, f1, f2)))
        flags |= (1 if held else 0) | (2 if clutched else 0) | (4 if saturated else 0)
        force = (f0, f1, f2)
        if self.trace is not None:
            self.trace.append((k, t, master[0], master[1], master[2], f0, f1, f2, flags))
        self.latest = ServoSnapshot(k, t, master, force, buttons, clutched, held, saturated)
        self._k = k + 1


__all__ = [
    "TRACE_COLUMNS",
    "ClutchState",
    "CoupledToolPlant",
    "NullPlant",
    "Plant",
    "ServoEvent",
    "ServoLoop",
    "ServoSnapshot",
    "ServoTrace",
    "clutch_update",
]
