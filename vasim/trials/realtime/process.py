r"""The real-time trial with the servo loop in its own process (no shared interpreter lock).

:class:`ProcessRealtimeTrial` has the surface of
:class:`~vasim.trials.realtime.loop.RealtimeTrial` (``start``, ``stop``, ``done``, ``frame``,
``timing``, ``result``, ``recording``) but runs the device, the 1 kHz servo loop and the
trial runner (task, fixtures, coupling) in a child process; this process keeps the abdomen
physics thread and whatever else runs here (the viewer, the caller). **Why, measured**
(``bench/haptics.py``, 20 s runs, every organ awake, a viewer stream at 60 Hz, host load
average 5-6 from other jobs; two alternating repetitions): all in threads 971-984 Hz,
p99 1.9 ms, longest gap 49-101 ms; servo in its own process 999.9 Hz, p99 1.000 ms,
longest gap 4.5-4.8 ms. In one process a normally scheduled thread (physics glue, viewer)
that the OS preempts while it holds the interpreter lock stalls the real-time servo thread
(priority inversion); a process of its own has no such thread. The 30 s bench at load
average 6.7-7.6 (physics default / every organ awake): servo process 998.9 / 999.3 Hz,
p99 1.000 / 1.011 ms, longest gap 33.8 / 6.4 ms, 6 / 18 overruns; threads 997.5 / 964.6
Hz, p99 1.018 / 2.909 ms, longest gap 12.4 / 121.3 ms, 59 / 919 overruns; at load 3-5:
servo process 999.7 / 999.5 Hz, p99 1.000 / 1.000 ms, longest gap 4.76 / 5.21 ms; threads
999.5 / 992.8 Hz, p99 1.018 / 1.902 ms, longest gap 5.02 / 10.74 ms.

Hand-offs (one direction each, never a half-written value):

* tool pose, child -> physics: a shared array under a sequence counter (seqlock: odd while
  written; the reader retries); the physics steps with the newest complete pose;
* physics -> child: each step's contact snapshot (POIs, normals, contact planes, torque,
  events: a few kB) through a pipe; the child's feed drains it at the start of each
  control step and takes the newest (``TrialRunner.set_physics_feed``). The organ meshes
  never cross: the viewer gets them here from the physics thread;
* frames, child -> here: every ``frame_every`` ticks the trial frame (without the
  abdomen) through a pipe, at most ``_MAX_IN_FLIGHT`` unread, so the servo thread never
  blocks on a slow reader; ``frame()`` adds the newest physics snapshot;
* the end: the child sends the runner's state (samples, reach times, POIs, events), the
  loop's timing and the device recording; ``result()`` evaluates it here with the same
  ``TrialRunner.result`` (the abdomen's tissue statistics are this process').

Devices live in the child, so they are named by a picklable factory (``device_factory``,
e.g. ``functools.partial(OpenHapticsDevice)``; None: the scripted operator). A device fed
from this process (the viewer's browser device) needs the threaded ``RealtimeTrial``.

The recording has the same format as the threaded trial's: a replay
(``vasim.trials.realtime.replay.replay_trial``) reproduces the samples exactly.
"""

from __future__ import annotations

import contextlib
import logging
import math
import multiprocessing as mp
import signal
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from vasim.abdomen.contact import ContactPatch, ToolPose
from vasim.abdomen.runner import PhysicsThread
from vasim.core.config import check_choice, expect
from vasim.core.errors import DeviceError
from vasim.fixtures.schema import Schema
from vasim.haptics.device import Device
from vasim.haptics.devices.replay import DeviceStream
from vasim.haptics.timing import TimingStats
from vasim.trials.realtime.loop import RealtimeTrial, ServoSettings
from vasim.trials.realtime.recording import PhysicsLog, RealtimeRecording
from vasim.trials.realtime.timing import RealtimeTiming
from vasim.trials.vf import TrialConfig, TrialFrame, TrialResult, TrialRunner
from vasim.trials.vf_model import VfGeometry

log = logging.getLogger(__name__)

_MAX_IN_FLIGHT = 4
"""Frames sent and not yet read at most (~1 kB each: far below a pipe's 64 kB), so a
writer never blocks on a full pipe."""

_MAX_SNAPSHOTS_IN_FLIGHT = 8
"""Contact snapshots sent and not yet taken at most (a few kB each); a snapshot beyond
that is not sent (the child takes the newest anyway; the log records what it took)."""


@dataclass(frozen=True, eq=False)
class ContactSnapshot:
    """What the trial runner takes from a physics step (``AbdomenSnapshot`` without the
    organ meshes): time [s], step counter, POIs and normals (p, 3) [m], contact planes,
    torque about the fulcrum (3,) [N m], delicate contact, events."""

    t: float
    seq: int
    targets: np.ndarray
    target_normals: np.ndarray
    patch: ContactPatch
    torque: np.ndarray
    delicate_contact: bool
    events: tuple[tuple[str, str], ...]

    @classmethod
    def of(cls, snap: Any) -> ContactSnapshot:
        return cls(float(snap.t), int(snap.seq), np.asarray(snap.targets),
                   np.asarray(snap.target_normals), snap.patch, np.asarray(snap.torque),
                   bool(snap.delicate_contact), tuple(snap.events))


class _PoseBoard:
    """A tool pose in shared memory under a sequence counter (seqlock)."""

    def __init__(self, ctx: Any):
        self.a = ctx.RawArray("d", 8)  # [counter, tip x y z, fulcrum x y z, valid]
        self._last: ToolPose | None = None      # the reader's last consistent pose

    def write(self, pose: ToolPose) -> None:
        a = self.a
        a[0] += 1.0  # odd: being written
        a[1:4] = pose.tip.tolist()
        a[4:7] = pose.fulcrum.tolist()
        a[7] = 1.0
        a[0] += 1.0

    def read(self) -> ToolPose | None:
        """The newest pose; None before the first write. A read that keeps meeting a write
        in progress (the writer preempted mid-write) returns the last consistent pose: None
        there would mean "no tool" and let go of the tissue for a step."""
        a = self.a
        for _ in range(100):
            c = a[0]
            if c % 2.0:
                continue
            vals = a[1:8]
            if a[0] == c:
                if vals[6] != 1.0:
                    return None
                self._last = ToolPose(fulcrum=np.array(vals[3:6]), tip=np.array(vals[0:3]))
                return self._last
        return self._last


class _PipeWorld:
    """The parent's abdomen as the physics thread steps it: the pose comes from the pose
    board; each step is logged and its contact snapshot sent to the child. Once the child
    says the trial is done (or ``freeze``) steps do nothing, so the log and the tissue
    statistics end with the trial."""

    def __init__(self, abdomen: Any, board: _PoseBoard, conn: Any, log: PhysicsLog,
                 taken: Any, done: Any):
        self.abdomen = abdomen
        self.taken = taken
        self.done = done
        self.sent = 0
        self.dt = abdomen.dt
        self.board = board
        self.conn = conn
        self.log = log
        self.lock = threading.Lock()
        self.frozen = False

    @property
    def latest(self) -> Any:
        return self.abdomen.latest

    def step(self, tool: ToolPose | None) -> Any:
        del tool  # the child's pose, from the board
        with self.lock:
            if self.frozen or self.done.value:  # the trial is over: so is its physics
                self.frozen = True
                return self.abdomen.latest
            pose = self.board.read()
            self.log.add_step(pose)
            snap = self.abdomen.step(pose)
            if self.sent - self.taken.value < _MAX_SNAPSHOTS_IN_FLIGHT:
                try:
                    self.conn.send(ContactSnapshot.of(snap))
                    self.sent += 1
                except (OSError, ValueError):  # the child is gone: stop sending
                    self.frozen = True
            return snap

    def freeze(self) -> None:
        with self.lock:
            self.frozen = True


# ---------------------------------------------------------------------------------------
# The child


class _PipeFeed:
    """The child's physics feed: posts the pose, takes the newest contact snapshot."""

    def __init__(self, board: _PoseBoard, conn: Any, taken: Any):
        self.board = board
        self.conn = conn
        self.taken = taken
        self.applied: list[tuple[int, int]] = []

    def __call__(self, k: int, pose: ToolPose) -> Any:
        self.board.write(pose)
        snap = None
        conn = self.conn
        while conn.poll():
            snap = conn.recv()
            self.taken.value += 1
        if snap is not None:
            self.applied.append((k, snap.seq))
        return snap


class _FramePublisher:
    """Wraps the plant: every ``every`` ticks sends the frame (without abdomen) unless
    ``_MAX_IN_FLIGHT`` are unread."""

    def __init__(self, plant: Any, runner: TrialRunner, conn: Any, sent: Any, read: Any,
                 every: int):
        self.plant = plant
        self.runner = runner
        self.conn = conn
        self.sent = sent
        self.read = read
        self.every = every
        self._n = 0

    def on_start(self, t: float) -> None:
        self.plant.on_start(t)

    def on_stop(self) -> None:
        self.plant.on_stop()

    def observation(self) -> Any:
        return self.plant.observation()

    def tick(self, t: float, master: Any, buttons: int) -> Any:
        f = self.plant.tick(t, master, buttons)
        self._n += 1
        if self._n % self.every == 0 and self.sent.value - self.read.value < _MAX_IN_FLIGHT:
            self.conn.send(replace(self.runner.frame, abdomen=None))
            self.sent.value += 1
        return f


def _child(spec: dict[str, Any], board: _PoseBoard, snaps: Any, frames: Any, control: Any,
           stop: Any, done: Any, sent: Any, read: Any, taken: Any) -> None:
    """The servo process: builds the trial, runs it until ``stop``, sends the end state.

    It ignores SIGINT: a Ctrl-C in the terminal reaches the whole process group, and the
    parent, which owns the trial's storage, stops this process through ``stop`` so that the
    end state (samples, recording) still arrives and the force is zeroed on the way out.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    trial: RealtimeTrial | None = None
    try:
        factory = spec["device_factory"]
        device = factory() if factory is not None else None
        trial = RealtimeTrial(spec["config"], device, schema=spec["schema"], physics="off",
                              servo=spec["servo"])
        runner = trial.runner
        feed = _PipeFeed(board, snaps, taken)
        if runner.abdomen is not None:
            runner.set_physics_feed(feed)
        trial.plant.on_done.append(lambda: setattr(done, "value", 1))
        trial.loop.plant = _FramePublisher(trial.plant, runner, frames, sent, read,
                                           spec["frame_every"])
        trial.start()  # a device that cannot start fails start() in the parent
        control.send(("ready", getattr(trial.device, "name", "?")))
        while not stop.wait(0.1):  # rare wake-ups: this thread shares the lock
            if not trial.loop.running:
                break
        trial.stop()
        err = trial.error
        rec = trial.loop.recording
        st = runner.state
        control.send(("end", {
            "error": None if err is None else f"{type(err).__name__}: {err}",
            "error_trace": None if err is None else "".join(traceback.format_exception(err)),
            "samples": st.samples, "reach_times": list(st.reach_times),
            "i": st.i, "t": st.t, "k": st.k, "done": st.done,
            "points": st.geometry.points, "events": list(st.events),
            "n_bad_input": st.n_bad_input, "frame": replace(runner.frame, abdomen=None),
            "servo": trial.loop.stats(), "saturated": trial.loop.saturated_ticks,
            "guard": trial.loop.guard.total, "clutch": trial.loop.clutch.count,
            "priority_granted": trial.loop.priority_granted,
            "stream": None if rec is None else rec.stream(), "applied": feed.applied,
            "ticks": trial.loop.ticks, "meta": trial.recording().meta if rec else None,
            "wall": trial.wall_time(),
        }))
    except BaseException as exc:  # reported to the parent, never silent
        if trial is not None:
            with contextlib.suppress(Exception):
                trial.stop()            # zero the force, stop the device
        try:
            what = str(exc) if isinstance(exc, DeviceError) else f"{type(exc).__name__}: {exc}"
            control.send(("failed", what, "".join(traceback.format_exception(exc))))
        except Exception:
            pass


# ---------------------------------------------------------------------------------------
# The parent


class ProcessRealtimeTrial:
    """A real-time trial whose servo loop runs in a child process (module docstring).

    Args:
        config: the trial.
        device_factory: a picklable callable building the device in the child; None: the
            config's scripted operator.
        schema: a loaded schema overriding ``config.schema``.
        physics: ``"thread"`` (the abdomen here, in a thread) or ``"off"``.
        servo: how the child's servo loop runs (``ServoSettings``, as ``RealtimeTrial``).
        frame_every: ticks between frames sent to this process (10: 100 Hz).
        start_timeout_s: how long the child may take to build the trial [s].

    Raises:
        ConfigError: a bad physics mode or rate (and what ``TrialRunner`` refuses).
    """

    def __init__(self, config: TrialConfig,
                 device_factory: Callable[[], Device] | None = None, *,
                 schema: Schema | None = None, physics: str = "thread",
                 servo: ServoSettings | None = None,
                 frame_every: int = 10, start_timeout_s: float = 120.0):
        check_choice(physics, "physics", ("thread", "off"))
        servo = servo if servo is not None else ServoSettings()
        rate_hz = servo.rate_hz
        expect(math.isfinite(rate_hz) and abs(rate_hz * config.dt - 1.0) <= 1e-9, rate_hz,
               f"1 / dt of the trial (dt {config.dt!r})", field="rate_hz")
        self.config = config
        self.runner = TrialRunner(config, schema)  # for the abdomen and the result
        self.coupling = servo.coupling
        self.physics_mode = ("process" if physics == "thread"
                             and self.runner.abdomen is not None else "off")
        self._ctx = mp.get_context("spawn")
        self._board = _PoseBoard(self._ctx)
        self._snap_rx, self._snap_tx = self._ctx.Pipe(duplex=False)
        self._frame_rx, self._frame_tx = self._ctx.Pipe(duplex=False)
        self._ctl_rx, self._ctl_tx = self._ctx.Pipe(duplex=False)
        self._stop = self._ctx.Event()
        self._done = self._ctx.Value("i", 0, lock=False)
        self._sent = self._ctx.Value("l", 0, lock=False)
        self._read = self._ctx.Value("l", 0, lock=False)
        self._taken = self._ctx.Value("l", 0, lock=False)
        self._spec = {"config": config, "schema": self.runner.schema,
                      "device_factory": device_factory, "servo": servo,
                      "frame_every": int(frame_every)}
        self.start_timeout_s = float(start_timeout_s)
        self.physics_log: PhysicsLog | None = None
        self.physics_thread: PhysicsThread | None = None
        self._world: _PipeWorld | None = None
        if self.runner.abdomen is not None and physics == "thread":
            self.physics_log = PhysicsLog()
            self._world = _PipeWorld(self.runner.abdomen, self._board, self._snap_tx,
                                     self.physics_log, self._taken, self._done)
            self.physics_thread = PhysicsThread(self._world)  # type: ignore[arg-type]  # duck-typed world
        self._proc: Any = None
        self._frame: TrialFrame = self.runner.frame
        self._rx_thread: threading.Thread | None = None
        self._end: dict[str, Any] | None = None
        self._failure: str | None = None
        self.device_name = "?"

    # -- life cycle -----------------------------------------------------------------------
    def start(self) -> ProcessRealtimeTrial:
        """Starts the child (waits until its trial is built), then the physics thread.

        Raises:
            RuntimeError: started twice. DeviceError: the child failed to build or start.
        """
        if self._proc is not None:
            raise RuntimeError("ProcessRealtimeTrial.start() was already called")
        self._proc = self._ctx.Process(
            target=_child, name="vasim-servo",
            args=(self._spec, self._board, self._snap_rx, self._frame_tx, self._ctl_tx,
                  self._stop, self._done, self._sent, self._read, self._taken), daemon=True)
        self._proc.start()
        # The child has its copies of these ends now: closing ours lets the frame reader
        # see end-of-file when the child exits (no reader thread or descriptors left over).
        for end in (self._snap_rx, self._frame_tx, self._ctl_tx):
            end.close()
        deadline = time.monotonic() + self.start_timeout_s
        while not self._ctl_rx.poll(0.1):
            if not self._proc.is_alive():
                self._proc.join()
                self._failure = f"the servo process exited (code {self._proc.exitcode})"
                self._close_pipes()
                raise DeviceError(f"{self._failure} before it was ready")
            if time.monotonic() > deadline:
                self._proc.kill()
                self._proc.join()
                self._failure = "the servo process did not start"
                self._close_pipes()
                raise DeviceError(f"the servo process did not start within "
                                  f"{self.start_timeout_s:g} s")
        try:
            msg = self._ctl_rx.recv()
        except EOFError:                # it exited: our copy of its end is closed
            self._proc.join()
            self._failure = f"the servo process exited (code {self._proc.exitcode})"
            self._close_pipes()
            raise DeviceError(f"{self._failure} before it was ready") from None
        if msg[0] != "ready":
            self._proc.join(5.0)
            self._failure = str(msg[1])
            log.debug("servo process traceback:\n%s", msg[2])
            self._close_pipes()
            raise DeviceError(f"the servo process failed: {msg[1]}")
        self.device_name = msg[1]
        self._rx_thread = threading.Thread(target=self._receive, name="vasim-frames",
                                           daemon=True)
        self._rx_thread.start()
        if self.physics_thread is not None:
            self.physics_thread.start()
        return self

    def _receive(self) -> None:
        rx = self._frame_rx
        while True:
            try:
                frame = rx.recv()
            except (EOFError, OSError):
                return
            self._frame = frame
            self._read.value += 1

    def stop(self, timeout: float = 10.0) -> None:
        """Stops the physics and the child (which zeroes the force and stops the device),
        and collects the child's end state. Idempotent."""
        if self._world is not None:
            self._world.freeze()
        self._stop.set()
        if self.physics_thread is not None:
            self.physics_thread.stop()
        if self._proc is None or self._end is not None or self._failure is not None:
            return
        deadline = time.monotonic() + timeout
        while self._end is None and self._failure is None and time.monotonic() < deadline:
            if self._ctl_rx.poll(0.05):
                try:
                    msg = self._ctl_rx.recv()
                except EOFError:
                    self._proc.join(1.0)
                    self._failure = (f"the servo process exited (code {self._proc.exitcode})"
                                     " without its end state")
                    break
                if msg[0] == "end":
                    self._end = msg[1]
                elif msg[0] == "failed":
                    self._failure = str(msg[1])
                    log.debug("servo process traceback:\n%s", msg[2])
            elif not self._proc.is_alive():
                self._failure = f"the servo process exited (code {self._proc.exitcode})"
        self._proc.join(max(0.1, deadline - time.monotonic()))
        if self._proc.is_alive():
            log.warning("servo process did not exit; killing it")
            self._proc.kill()
            self._proc.join(1.0)
        if self._end is None and self._failure is None:
            self._failure = "the servo process sent no end state"
        self._close_pipes()

    def _close_pipes(self) -> None:
        """Our pipe ends, once the child is gone (the frame reader ends on end-of-file)."""
        if self._rx_thread is not None:
            self._rx_thread.join(1.0)
        for end in (self._snap_tx, self._frame_rx, self._ctl_rx):
            with contextlib.suppress(OSError):
                end.close()

    def __enter__(self) -> ProcessRealtimeTrial:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        return self._proc is not None and self._proc.is_alive() and not self._stop.is_set()

    @property
    def done(self) -> bool:
        """Every point reached or time up, or the servo process or the physics failed."""
        if self._done.value or self._physics_error() is not None:
            return True
        if self._end is not None:
            return bool(self._end["done"]) or self._end["error"] is not None
        return self._failure is not None or (
            self._proc is not None and not self._proc.is_alive())

    @property
    def error(self) -> str | None:
        """Why the servo process, or the physics thread here, stopped early, if one did
        (a trial whose tissue froze is not a completed trial)."""
        if self._failure is not None:
            return self._failure
        if self._end is not None and self._end["error"] is not None:
            return str(self._end["error"])
        phys = self._physics_error()
        return None if phys is None else f"physics: {type(phys).__name__}: {phys}"

    def _physics_error(self) -> BaseException | None:
        return None if self.physics_thread is None else self.physics_thread.error

    # -- reading --------------------------------------------------------------------------
    def frame(self) -> TrialFrame:
        """The newest frame from the child, with the newest physics snapshot here."""
        f = self._frame
        if self._end is not None:
            f = self._end["frame"]
        snap = self.physics_thread.latest if self.physics_thread is not None else (
            self.runner.abdomen.latest if self.runner.abdomen is not None else None)
        return replace(f, abdomen=snap) if snap is not None else f

    def timing(self) -> RealtimeTiming:
        """The servo loop's timing (after ``stop``; before it, physics only) and the
        physics thread's."""
        end = self._end
        servo = end["servo"] if end is not None else TimingStats(
            "realtime", 1.0 / self.config.dt, 0, 0.0, math.nan, math.nan, math.nan,
            math.nan, math.nan, math.nan, 0, 0, math.nan, math.nan, math.nan)
        return RealtimeTiming(
            servo=servo,
            physics=None if self.physics_thread is None else self.physics_thread.stats(),
            saturated_ticks=0 if end is None else end["saturated"],
            guard_events=0 if end is None else end["guard"],
            clutch_presses=0 if end is None else end["clutch"],
            physics_mode=self.physics_mode,
            priority_granted=None if end is None else end["priority_granted"])

    def result(self, **kw: Any) -> TrialResult:
        """The trial's result, evaluated here from the child's end state (stops the child
        first if it still runs)."""
        self.stop()
        end = self._end
        if end is None:
            raise DeviceError(f"the servo process failed: {self._failure}")
        r = self.runner
        st = r.state  # the child's end state, taken over by this process's runner
        st.samples = end["samples"]
        st.reach_times = end["reach_times"]
        st.i, st.t, st.k, st.done = end["i"], end["t"], end["k"], end["done"]
        st.geometry = VfGeometry(end["points"], st.geometry.normals, r.model.start_xyz)
        st.events = end["events"]
        st.n_bad_input = end["n_bad_input"]
        kw.setdefault("wall_time", float(end["wall"]))
        return r.result(**kw)

    def recording(self) -> RealtimeRecording:
        """The device stream and the physics log (poses here, hand-overs from the child)."""
        end = self._end
        if end is None or end["stream"] is None:
            raise RuntimeError("no recording: stop() the trial first (record=True)")
        stream: DeviceStream = end["stream"]
        plog = None
        if self.physics_log is not None:
            plog = PhysicsLog(list(self.physics_log.poses), list(end["applied"]))
        meta = dict(end["meta"])
        meta.update(physics_mode=self.physics_mode, coupling=asdict(self.coupling))
        return RealtimeRecording(stream, plog, meta)


__all__ = ["ContactSnapshot", "ProcessRealtimeTrial"]
