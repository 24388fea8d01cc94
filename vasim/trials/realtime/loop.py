"""The threaded real-time trial: the runner in the 1 kHz servo loop, physics in a thread
beside it (scheduling and the measurements behind it: the package docstring,
``vasim.trials.realtime``)."""

from __future__ import annotations

import gc
import math
import time
from dataclasses import asdict, dataclass, field
from typing import Any

from vasim.abdomen.runner import PhysicsThread
from vasim.core.config import check_choice, expect
from vasim.fixtures.schema import Schema
from vasim.haptics.coupling import CouplingParams
from vasim.haptics.device import BUTTON_2, Device, ScheduledDevice
from vasim.haptics.servo import ServoLoop
from vasim.operator.device import ScriptedDevice
from vasim.trials.realtime.plant import (
    DEFAULT_BLEND_S,
    InlineFeed,
    PhysicsMode,
    RecordingWorld,
    ReplayFeed,
    ThreadFeed,
    TrialPlant,
)
from vasim.trials.realtime.recording import PhysicsLog, RealtimeRecording
from vasim.trials.realtime.timing import RealtimeTiming
from vasim.trials.vf import (
    TrialConfig,
    TrialFrame,
    TrialResult,
    TrialRunner,
)

DEFAULT_RT_PRIORITY = 40
"""``SCHED_FIFO`` priority the servo thread asks for (module docstring): above every
normal thread, below the kernel's threaded interrupt handlers (50)."""


@dataclass(frozen=True)
class ServoSettings:
    """How the servo loop of a real-time trial runs (grouped out of ``RealtimeTrial``'s
    and ``ProcessRealtimeTrial``'s parameters, issue #29).

    Attributes:
        rate_hz: the servo rate [Hz]; must equal 1 / ``config.dt``.
        coupling: virtual-coupling parameters.
        record: keep the device stream and the physics log (for replays).
        clutch_button: the clutch's button bitmask.
        switch_interval_s: the interpreter's switch interval while the loop runs in real
            time (``ServoLoop``).
        rt_priority: real-time (``SCHED_FIFO``) priority asked for the servo thread
            (``ServoLoop``; module docstring); None: normal scheduling.
        blend_s: ``TrialPlant``'s blending of physics updates into the force [s].
        freeze_gc: collect and freeze the garbage collector's heap when the run starts
            (``gc.freeze``; undone by ``stop``), so that a full collection during the run
            scans only what the run allocates (module docstring).
    """

    rate_hz: float = 1000.0
    coupling: CouplingParams = field(default_factory=CouplingParams)
    record: bool = True
    clutch_button: int = BUTTON_2
    switch_interval_s: float | None = 5e-4
    rt_priority: int | None = DEFAULT_RT_PRIORITY
    blend_s: float = DEFAULT_BLEND_S
    freeze_gc: bool = True


class RealtimeTrial:
    """One trial driven by the 1 kHz servo loop (module docstring).

    Args:
        config: the trial.
        device: the input device; None: the config's scripted operator as a device.
        schema: a loaded schema overriding ``config.schema``.
        physics: ``"thread"``, ``"inline"`` or ``"off"`` (``PhysicsMode``), or a
            :class:`PhysicsLog` to replay.
        servo: how the servo loop runs (``ServoSettings``; default: its defaults).

    Raises:
        ConfigError: a rate that does not match ``dt``, an unknown physics mode, or what
            ``TrialRunner`` refuses (schema for another task, ...).
    """

    def __init__(self, config: TrialConfig, device: Device | None = None, *,
                 schema: Schema | None = None, physics: PhysicsMode | PhysicsLog = "thread",
                 servo: ServoSettings | None = None):
        servo = servo if servo is not None else ServoSettings()
        rate_hz = servo.rate_hz
        expect(math.isfinite(rate_hz) and abs(rate_hz * config.dt - 1.0) <= 1e-9, rate_hz,
               f"1 / dt of the trial (dt {config.dt!r})", field="rate_hz")
        if not isinstance(physics, PhysicsLog):
            check_choice(physics, "physics", ("thread", "inline", "off"))
        self.config = config
        self.servo = servo
        self.runner = TrialRunner(config, schema)
        person = self.runner.person  # the config's simulated person
        self.profile = person.profile
        if device is None:
            device = ScriptedDevice(person, self.runner.task.start, dt=config.dt)
        self.device = device
        self.coupling = servo.coupling
        self.plant = TrialPlant(self.runner, self.coupling, dt=config.dt,
                                blend_s=servo.blend_s)
        self.physics_mode = "replay" if isinstance(physics, PhysicsLog) else str(physics)
        self.physics_log: PhysicsLog | None = None
        self.physics_thread: PhysicsThread | None = None
        self._world: RecordingWorld | None = None
        self._replay: ReplayFeed | None = None
        abdomen = self.runner.abdomen
        if abdomen is not None:
            if isinstance(physics, PhysicsLog):
                self._replay = ReplayFeed(abdomen, physics)
                self.runner.set_physics_feed(self._replay)
            elif physics == "thread":
                self.physics_log = PhysicsLog()
                self._world = RecordingWorld(abdomen, self.physics_log)
                self.physics_thread = PhysicsThread(self._world)  # type: ignore[arg-type]  # Record
                self.runner.set_physics_feed(ThreadFeed(self.physics_thread,
                                                         self.physics_log))
                self.plant.on_done.append(self._world.freeze)
            elif physics == "inline":
                self.physics_log = PhysicsLog()
                every = max(1, round(abdomen.dt / config.dt))
                self.runner.set_physics_feed(InlineFeed(abdomen, every, self.physics_log))
            else:  # "off": the abdomen is never stepped
                self.runner.set_physics_feed(lambda k, pose: None)
        self.loop = ServoLoop(device, self.plant, rate_hz=rate_hz,
                              home=self.runner.task.start, clutch_button=servo.clutch_button,
                              record=servo.record, switch_interval_s=servo.switch_interval_s,
                              rt_priority=servo.rt_priority)
        self.plant.on_done.append(self._mark_done)
        self.freeze_gc = servo.freeze_gc
        self._gc_frozen = False
        self._t_start: float | None = None
        self._t_done: float | None = None
        self._started = False

    # -- life cycle -----------------------------------------------------------------------
    def _mark_done(self) -> None:
        if self._t_done is None:
            self._t_done = time.perf_counter()

    def start(self) -> RealtimeTrial:
        """Starts the physics thread and the servo loop in real time; returns self.

        Raises:
            RuntimeError: if started before. DeviceError: the device failed to start.
        """
        if self._started:
            raise RuntimeError("RealtimeTrial.start() was already called")
        if self._replay is not None or self.physics_mode == "inline":
            raise RuntimeError(f"physics {self.physics_mode!r} runs in simulated time: use "
                               "run_ticks()")
        self._started = True
        if self.freeze_gc:
            gc.collect()
            gc.freeze()
            self._gc_frozen = True
        if self.physics_thread is not None:
            self.physics_thread.start()
        self._t_start = time.perf_counter()
        try:  # a device with its own servo scheduler (OpenHaptics) runs the loop in it
            self.loop.start(driver="device" if isinstance(self.device, ScheduledDevice)
                            else "thread")
        except BaseException:
            if self.physics_thread is not None:
                self.physics_thread.stop()
            self._unfreeze()
            raise
        return self

    def _unfreeze(self) -> None:
        if self._gc_frozen:
            gc.unfreeze()
            self._gc_frozen = False

    def run_ticks(self, n: int) -> int:
        """Runs ``n`` ticks in simulated time (deterministic; physics ``inline``, ``off``
        or a replay); returns the ticks run."""
        if self.physics_thread is not None:
            raise RuntimeError("physics 'thread' runs in real time: use start()")
        if self._t_start is None:
            self._t_start = time.perf_counter()
        self._started = True
        return self.loop.run_ticks(n)

    def stop(self, timeout: float = 2.0) -> None:
        """Stops the loop (zero force, device stopped) and the physics. Idempotent."""
        self.loop.stop(timeout)
        if self._world is not None:
            self._world.freeze()
        if self.physics_thread is not None:
            self.physics_thread.stop()
        if self._t_done is None and self._t_start is not None:
            self._t_done = time.perf_counter()
        self._unfreeze()

    def __enter__(self) -> RealtimeTrial:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def done(self) -> bool:
        """The trial is over: every point reached or time up, or the loop stopped on an
        error (``error``)."""
        return bool(self.runner.done) or self.error is not None

    @property
    def error(self) -> BaseException | None:
        """What stopped the servo loop or the physics thread, if anything did."""
        if self.loop.error is not None:
            return self.loop.error
        return None if self.physics_thread is None else self.physics_thread.error

    @property
    def running(self) -> bool:
        return self.loop.running

    # -- reading (any thread) -------------------------------------------------------------
    def frame(self) -> TrialFrame:
        """The latest frame (immutable; the servo thread publishes one per tick)."""
        return self.runner.frame

    def timing(self) -> RealtimeTiming:
        """Timing so far (servo loop and physics thread)."""
        return RealtimeTiming(
            servo=self.loop.stats(),
            physics=None if self.physics_thread is None else self.physics_thread.stats(),
            saturated_ticks=self.loop.saturated_ticks,
            guard_events=self.loop.guard.total,
            clutch_presses=self.loop.clutch.count, physics_mode=self.physics_mode,
            priority_granted=self.loop.priority_granted)

    def result(self, **kw: Any) -> TrialResult:
        """The runner's result (``TrialRunner.result``; keywords passed on). Call it once
        the trial is ``done`` or after ``stop()``.

        Raises:
            RuntimeError: while the trial is still running.
        """
        if self.loop.running and not self.runner.done:
            raise RuntimeError("the trial is still running: stop() it or wait until done")
        if self._replay is not None:
            self._replay.finish()
        if self._world is not None:
            self._world.freeze()  # waits for a physics step in flight
        kw.setdefault("wall_time", self.wall_time())
        return self.runner.result(**kw)

    def wall_time(self) -> float:
        """Wall-clock time from the start to the end (or to now while it runs) [s]; 0
        before the start."""
        if self._t_start is None:
            return 0.0
        return (self._t_done or time.perf_counter()) - self._t_start

    def recording(self) -> RealtimeRecording:
        """The device stream and the physics log of the run so far (``record=True``)."""
        rec = self.loop.recording
        if rec is None:
            raise RuntimeError("this trial was built with record=False")
        plog = self.physics_log
        meta = {"rate_hz": self.loop.rate_hz, "clutch_button": self.loop.clutch_button,
                "workspace_margin_m": self.loop.workspace_margin_m,
                "coupling": asdict(self.coupling), "physics_mode": self.physics_mode,
                "blend_s": self.plant.blend_s,
                "device": getattr(self.device, "name", "?"), "ticks": self.loop.ticks}
        return RealtimeRecording(rec.stream(), plog, meta)


__all__ = ["DEFAULT_RT_PRIORITY", "RealtimeTrial", "ServoSettings"]
