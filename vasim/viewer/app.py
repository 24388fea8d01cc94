"""The demo training viewer: a scripted trial runs in real time and the browser shows it.

Threads and hand-offs (guides/architecture.md):

* The **simulation thread** owns the ``TrialRunner``. Each iteration (``sim_hz``, 60 Hz) it
  drains the command queue (schema, task, restart), then advances the 1 kHz control loop by
  the wall-clock time elapsed since the previous iteration — capped at ``max_catch_up_s``
  (50 ms) so a stall slows the trial down instead of fast-forwarding it; the sub-step
  remainder is carried over, so simulated time tracks wall time exactly. It then publishes a
  :class:`Snapshot` (the static :class:`TrialInfo` of the trial plus the runner's latest
  immutable ``TrialFrame``) by swapping one reference. When a trial ends it holds the final
  frame for ``pause_s`` and starts the next one (next trajectory variant, next seed).
* The **view thread** (``view_hz``, 30 Hz) reads the latest snapshot and, if it is new,
  updates every view inside one ``server.atomic()`` block; the HUD and the camera are
  rate-limited further inside their views. Views never touch the runner.
* **GUI callbacks** (viser's thread pool) only put a :class:`Command` on the queue. Every
  callback is wrapped: an exception is logged and shown as a notification, never raised
  into viser (which would print and swallow it).
"""

from __future__ import annotations

import collections
import functools
import ipaddress
import logging
import queue
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np
import trimesh
import viser
from numpy.typing import NDArray

from vasim.abdomen.anatomy import TROCAR_NAMES, Organ, default_anatomy, trocar_points
from vasim.errors import ConfigError, VasimError
from vasim.fixtures.mag import MagParams
from vasim.fixtures.schema import available_schemas, load_schema
from vasim.study.trial import TrialConfig, TrialFrame, TrialRunner, tool_trocar
from vasim.tasks import TRAJECTORY_VARIANTS
from vasim.viewer.views import (
    ArrowView,
    CameraController,
    CameraPose,
    GhostView,
    HudInfo,
    HudView,
    OrganView,
    ToolView,
    TrajectoryView,
)

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
TaskName = Literal["trajectory", "point"]

DEFAULT_SCHEMA_FOR_TASK: dict[str, str] = {
    "trajectory": "trajectory_following",
    "point": "point_targeting",
}
"""Schema switched to when the chosen task does not fit the current task-specific schema."""


def check_bind_address(host: str, port: int) -> None:
    """Raises ``ConfigError`` unless ``port`` is a valid TCP port and ``host`` an address of
    this machine (viser would otherwise fail in a background thread and hang the server).
    A busy port is fine: viser moves to the next free one."""
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
        raise ConfigError(f"port must be an integer in 0..65535, got {port!r}", field="port")
    try:
        infos = socket.getaddrinfo(host, 0, type=socket.SOCK_STREAM)
        family, _, _, _, addr = infos[0]
        with socket.socket(family, socket.SOCK_STREAM) as probe:
            probe.bind(addr)
    except OSError as exc:
        raise ConfigError(f"cannot bind to host {host!r}: {exc.strerror or exc}",
                          field="host") from None


def is_loopback(host: str) -> bool:
    """True when ``host`` only accepts connections from this machine."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def endoscope_pose(look_at: tuple[float, float, float] = (0.0, 0.02, 0.085),
                   distance: float = 0.16) -> CameraPose:
    """The fixed camera without Mag: Mag's own zoom-1 navigation view (a laparoscope through
    the umbilical port, from above and caudal: ``MagParams.view_dir`` and ``fov_deg``)
    aimed between the trajectory workspace and the organs below it, so that switching Mag on
    or off does not swing the view around. From 16 cm (Mag's zoom-1 distance is 15 cm) the
    whole workspace box stays within 30 deg of the view axis (the half fov is 35 deg).

    Args:
        look_at: (3,) point aimed at [m], world frame.
        distance: camera distance from ``look_at`` [m].
    """
    mag = MagParams()
    w = np.asarray(mag.view_dir, dtype=np.float64)
    w /= np.linalg.norm(w)
    target = np.asarray(look_at, dtype=np.float64)
    return CameraPose(position=target + float(distance) * w, look_at=target,
                      up=np.array([0.0, 0.0, 1.0]), fov=float(np.radians(mag.fov_deg)))


@dataclass(frozen=True)
class Command:
    """A request from the GUI (or an API caller) to the simulation thread.

    Attributes:
        kind: ``"schema"`` (value: schema name; restarts the trial with it), ``"task"``
            (value: ``"trajectory"`` | ``"point"``) or ``"restart"``.
        value: the argument.
    """

    kind: Literal["schema", "task", "restart"]
    value: str = ""


@dataclass(frozen=True, eq=False)
class TrialInfo:
    """What does not change during one trial (built once per trial by the sim thread).

    Attributes:
        number: trial counter since the app started (1, 2, ...).
        config: the trial's configuration.
        schema: schema name. fixtures: its fixture names, in order.
        task_name: e.g. ``"trajectory/v3"``.
        points: (N, 3) POIs [m]. normals: (N, 3) or None. reach_radius: [m].
        start: (3,) tool start [m].
    """

    number: int
    config: TrialConfig
    schema: str
    fixtures: tuple[str, ...]
    task_name: str
    points: FloatArray
    normals: FloatArray | None
    reach_radius: float
    start: FloatArray


@dataclass(frozen=True, eq=False)
class Snapshot:
    """The hand-off between the threads: one trial's info and its latest frame."""

    info: TrialInfo
    frame: TrialFrame


class ViewerApp:
    """The viser server, its views, and the simulation and view threads.

    Args:
        host: interface to bind; ``127.0.0.1`` (default) admits only this machine.
        port: TCP port; 0 picks a free one. viser silently moves to the next free port when
            the requested one is busy: read ``port`` / ``url`` after ``start()``.
        schema: fixture schema of the demo trials (a name in ``protocols/schemas``).
        seed: operator seed of the first trial (incremented per trial).
        task: ``"trajectory"`` or ``"point"``.
        skill: scripted operator preset.
        variant: trajectory variant of the first trial.
        max_time: simulated time limit per trial [s].
        pause_s: wall time the final frame is held before the next trial starts [s].
        speed: simulated seconds per wall second (1 = real time).
        sim_hz, view_hz: loop rates of the simulation and view threads [Hz].
        max_catch_up_s: most simulated time one sim iteration may advance [s].

    Raises:
        ConfigError: for an unknown schema, task or skill, or a schema that does not fit
            the task (before any socket is opened).

    Example:
        >>> app = ViewerApp(port=0).start()         # doctest: +SKIP
        >>> print(app.url)                          # doctest: +SKIP
        http://127.0.0.1:40123/
        >>> app.request_schema("vg"); app.stop()    # doctest: +SKIP
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 8080,
        schema: str = "trajectory_following",
        seed: int = 0,
        task: TaskName = "trajectory",
        *,
        skill: Literal["novice", "intermediate", "expert"] = "intermediate",
        variant: int = 0,
        max_time: float = 180.0,
        pause_s: float = 1.5,
        speed: float = 1.0,
        sim_hz: float = 60.0,
        view_hz: float = 30.0,
        max_catch_up_s: float = 0.05,
    ):
        for name, v in (("pause_s", pause_s), ("speed", speed), ("sim_hz", sim_hz),
                        ("view_hz", view_hz), ("max_catch_up_s", max_catch_up_s)):
            if not (isinstance(v, int | float) and np.isfinite(v) and v >= 0):
                raise ConfigError(f"{name} must be a finite number >= 0, got {v!r}", field=name)
        if speed <= 0 or sim_hz <= 0 or view_hz <= 0 or max_catch_up_s <= 0:
            raise ConfigError("speed, sim_hz, view_hz and max_catch_up_s must be > 0, got "
                              f"{(speed, sim_hz, view_hz, max_catch_up_s)!r}")
        self.host = host
        self.requested_port = int(port)
        self.pause_s = float(pause_s)
        self.speed = float(speed)
        self.sim_period = 1.0 / sim_hz
        self.view_period = 1.0 / view_hz
        self.max_catch_up_s = float(max_catch_up_s)
        config = TrialConfig(task=task, variant=variant, schema=schema, seed=seed,
                             skill=skill, max_time=max_time)
        # Built here so that a bad schema/task fails before a socket is opened.
        self._runner = TrialRunner(config)
        self._trial_number = 0
        self._snapshot = self._publish_new_trial()
        self.commands: queue.SimpleQueue[Command] = queue.SimpleQueue()
        self.errors: list[str] = []
        """Messages of errors caught in callbacks and threads (newest last)."""
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._view_costs: collections.deque[float] = collections.deque(maxlen=600)
        self._view_updates = 0
        self._sim_cost = 0.0
        self._sim_time = 0.0
        self._sim_wall = 0.0
        self._local = threading.local()
        self._shown: TrialInfo | None = None
        self._shown_frame: TrialFrame | None = None
        self.server: viser.ViserServer | None = None
        self._stopped = False

    # -- lifecycle -----------------------------------------------------------------------
    def start(self) -> ViewerApp:
        """Binds the server, builds the scene and GUI, starts both threads; returns self."""
        if self.server is not None:
            raise RuntimeError("ViewerApp.start() was already called")
        check_bind_address(self.host, self.requested_port)
        self.server = viser.ViserServer(host=self.host, port=self.requested_port,
                                        verbose=False)
        try:
            self._build_scene()
            self._build_gui()
            self.server.on_client_connect(self._guard(self._on_connect))
            for target, name in ((self._sim_loop, "vasim-viewer-sim"),
                                 (self._view_loop, "vasim-viewer-view")):
                t = threading.Thread(target=target, name=name, daemon=True)
                t.start()
                self._threads.append(t)
        except BaseException:
            self.stop()
            raise
        return self

    def stop(self, timeout: float = 5.0) -> None:
        """Stops both threads (joined) and the server. Idempotent."""
        if self._stopped:
            return
        self._stopped = True
        self._stop.set()
        for t in self._threads:
            t.join(timeout=timeout)
            if t.is_alive():
                log.error("viewer thread %s did not stop within %.1f s", t.name, timeout)
        if self.server is not None:
            self.server.stop()

    def __enter__(self) -> ViewerApp:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def alive(self) -> bool:
        """True while both threads run."""
        return bool(self._threads) and all(t.is_alive() for t in self._threads)

    @property
    def threads(self) -> tuple[threading.Thread, ...]:
        return tuple(self._threads)

    @property
    def port(self) -> int:
        """The port actually bound (after ``start()``)."""
        if self.server is None:
            raise RuntimeError("ViewerApp.start() has not been called")
        return self.server.get_port()

    @property
    def url(self) -> str:
        """Address to open in a browser (the wildcard hosts are shown as 127.0.0.1)."""
        host = self.host
        if host in ("0.0.0.0", "::", ""):
            host = "127.0.0.1"
        elif ":" in host and not host.startswith("["):
            host = f"[{host}]"
        return f"http://{host}:{self.port}/"

    # -- API for callers (and tests): all go through the command queue -------------------
    @property
    def snapshot(self) -> Snapshot:
        """The latest published snapshot (immutable)."""
        return self._snapshot

    def request_schema(self, name: str) -> None:
        """Asks the sim thread to restart the trial with schema ``name``."""
        self.commands.put(Command("schema", str(name)))

    def request_task(self, task: str) -> None:
        """Asks the sim thread to switch to task ``task`` (restarts the trial)."""
        self.commands.put(Command("task", str(task)))

    def request_restart(self) -> None:
        """Asks the sim thread to restart the current trial."""
        self.commands.put(Command("restart"))

    def scene_nodes(self) -> list[str]:
        """Names of the scene nodes the views own (sorted)."""
        names: list[str] = []
        for v in (*self.organs, self.tool, self.trajectory, self.arrows, self.ghost):
            names.extend(v.node_names())
        return sorted(names)

    def stats(self) -> dict[str, float]:
        """Timing of both loops: CPU cost of one view update [ms] (mean, p95, max over the
        last 600 updates; thread CPU time, so preemption by other processes is not
        counted), number of view updates, simulated/wall time ratio, and the sim thread's
        CPU share (CPU seconds spent in ``advance`` per wall second)."""
        costs = np.array(self._view_costs) * 1e3
        return {
            "view_updates": float(self._view_updates),
            "view_ms_mean": float(costs.mean()) if len(costs) else float("nan"),
            "view_ms_p95": float(np.percentile(costs, 95)) if len(costs) else float("nan"),
            "view_ms_max": float(costs.max()) if len(costs) else float("nan"),
            "sim_realtime_factor": self._sim_time / self._sim_wall if self._sim_wall else 0.0,
            "sim_load": self._sim_cost / self._sim_wall if self._sim_wall else 0.0,
        }

    # -- scene and GUI -------------------------------------------------------------------
    def _build_scene(self) -> None:
        s = self.server
        assert s is not None
        s.scene.set_up_direction("+z")
        self.organs = [OrganView(s, o) for o in self._organs()]
        self._shown_physics = -1
        self.trocars = trocar_points()
        # The instrument ports (the camera port is where the default view looks through).
        ports = self.trocars[[i for i, n in enumerate(TROCAR_NAMES) if n != "camera"]]
        s.scene.add_point_cloud("/trocars", ports.astype(np.float32), (40, 40, 40),
                                point_size=0.004, point_shape="circle", precision="float32")
        trocar = self._tool_trocar(self._snapshot.info)
        self.tool = ToolView(s, trocar)
        self.trajectory = TrajectoryView(s)
        self.arrows = ArrowView(s)
        self.ghost = GhostView(s, trocar)
        self.camera = CameraController(s, endoscope_pose())
        self.camera.apply_initial()

    def _organs(self) -> list[Organ]:
        """The organs to draw: the abdomen's surfaces as the trial's physics has them (the
        vertex order of each model is its mesh's), or the static anatomy without a scene."""
        abdomen = self._runner.abdomen
        if abdomen is None:
            return default_anatomy()
        snap = abdomen.latest
        return [Organ(name=m.name,
                      mesh=trimesh.Trimesh(np.array(snap.organ(m.name).surface), m.faces,
                                           process=False),
                      color=m.color, delicate=m.delicate, kind=m.kind)  # type: ignore[arg-type]
                for m in abdomen.models]

    def _show_physics(self, frame: TrialFrame) -> None:
        """Deforming, breathing organs and the POIs riding on them (one physics step)."""
        snap = frame.abdomen
        if snap is None or snap.seq == self._shown_physics:
            return
        self._shown_physics = snap.seq
        for view in self.organs:
            try:
                view.update(snap.organ(view.organ.name).surface)
            except KeyError:  # an organ the scene does not simulate stays where it is
                continue
        if len(snap.targets) == len(self.trajectory.points):
            self.trajectory.move(snap.targets, snap.target_normals
                                 if frame.n_points == 1 else None)

    def _build_gui(self) -> None:
        s = self.server
        assert s is not None
        gui = s.gui
        info = self._snapshot.info
        with gui.add_folder("Demo trial"):
            names = available_schemas()
            if info.schema not in names:  # a schema given as a file path
                names = (*names, info.schema)
            self.schema_menu = gui.add_dropdown("Fixture schema", names,
                                                initial_value=info.schema)
            self.task_menu = gui.add_dropdown("Task", ("trajectory", "point"),
                                              initial_value=info.config.task)
            self.restart_button = gui.add_button("Restart trial")
            self.follow_camera = gui.add_checkbox(
                "Mag drives the camera", initial_value=True,
                hint="Off: orbit freely even when the schema has Mag")
        self.hud = HudView(s)

        self.schema_menu.on_update(self._guard(self._on_schema_menu))
        self.task_menu.on_update(self._guard(self._on_task_menu))
        self.restart_button.on_click(self._guard(lambda ev: self.request_restart()))
        self.follow_camera.on_update(self._guard(
            lambda ev: setattr(self.camera, "follow", bool(ev.target.value))))

    def _on_schema_menu(self, event: viser.GuiEvent) -> None:
        if not getattr(self._local, "syncing_menus", False):
            self.request_schema(event.target.value)

    def _on_task_menu(self, event: viser.GuiEvent) -> None:
        if not getattr(self._local, "syncing_menus", False):
            self.request_task(event.target.value)

    def _on_connect(self, client: viser.ClientHandle) -> None:
        self.camera.on_connect(client)

    def _tool_trocar(self, info: TrialInfo) -> FloatArray:
        """The port the instrument enters through (the trial's, see ``tool_trocar``)."""
        return tool_trocar(info.config.task, info.start)

    # -- errors --------------------------------------------------------------------------
    def _report(self, message: str) -> None:
        self.errors.append(message)
        server = self.server
        if server is None:
            return
        for client in server.get_clients().values():
            try:
                client.add_notification("vasim", message, color="red",
                                        auto_close_seconds=8.0)
            except Exception:  # a closing connection must not mask the original error
                log.debug("notification to client %s failed", client.client_id,
                          exc_info=True)

    def _guard(self, fn: Callable[..., Any]) -> Callable[..., Any]:
        """Wraps a callback: an exception is logged and notified, never raised."""

        @functools.wraps(fn)
        def wrapped(*args: Any, **kwargs: Any) -> Any:
            try:
                return fn(*args, **kwargs)
            except VasimError as exc:
                log.warning("viewer: %s", exc)
                self._report(str(exc))
            except Exception as exc:
                log.exception("viewer callback %s failed", getattr(fn, "__name__", fn))
                self._report(f"internal error: {type(exc).__name__}: {exc}")
            return None

        return wrapped

    # -- simulation thread ---------------------------------------------------------------
    def _publish_new_trial(self) -> Snapshot:
        runner = self._runner
        self._trial_number += 1
        task = runner.task
        info = TrialInfo(
            number=self._trial_number, config=runner.config, schema=runner.schema.name,
            fixtures=tuple(runner.schema.fixture_names), task_name=task.name,
            points=np.array(task.points, dtype=np.float64),
            normals=None if task.normals is None else np.array(task.normals),
            reach_radius=float(task.reach_radius), start=np.array(task.start),
        )
        snap = Snapshot(info, runner.frame)
        self._snapshot = snap
        return snap

    def _start_trial(self, config: TrialConfig) -> None:
        self._runner = TrialRunner(config)  # raises ConfigError: the old trial goes on
        self._publish_new_trial()

    def _handle(self, cmd: Command) -> None:
        cfg = self._runner.config
        if cmd.kind == "restart":
            self._start_trial(cfg)
        elif cmd.kind == "schema":
            if cmd.value == cfg.schema:
                return
            schema = load_schema(cmd.value)
            task = cfg.task if schema.task in ("any", cfg.task) else schema.task
            variant = cfg.variant if task == cfg.task else 0
            self._start_trial(replace(cfg, schema=cmd.value, task=task, variant=variant))
        elif cmd.kind == "task":
            if cmd.value == cfg.task:
                return
            if cmd.value not in DEFAULT_SCHEMA_FOR_TASK:
                raise ConfigError(f"unknown task {cmd.value!r} (trajectory, point)",
                                  field="task")
            schema = cfg.schema
            if self._runner.schema.task not in ("any", cmd.value):
                schema = DEFAULT_SCHEMA_FOR_TASK[cmd.value]
            self._start_trial(replace(cfg, task=cmd.value, schema=schema, variant=0))  # type: ignore[arg-type]
        else:
            raise ConfigError(f"unknown command {cmd.kind!r}")

    def _next_trial(self) -> None:
        cfg = self._runner.config
        variant = (cfg.variant + 1) % TRAJECTORY_VARIANTS if cfg.task == "trajectory" else 0
        self._start_trial(replace(cfg, variant=variant, seed=cfg.seed + 1))

    def _sim_loop(self) -> None:
        guarded_handle = self._guard(self._handle)
        last = time.perf_counter()
        debt = 0.0  # simulated time owed to the runner [s], < one control step
        done_since: float | None = None
        while not self._stop.is_set():
            tick = time.perf_counter()
            try:
                trial_before = self._snapshot.info
                while True:
                    try:
                        cmd = self.commands.get_nowait()
                    except queue.Empty:
                        break
                    guarded_handle(cmd)
                if self._snapshot.info is not trial_before:
                    debt, done_since = 0.0, None
                now = time.perf_counter()
                cpu0 = time.thread_time()
                elapsed = min(now - last, self.max_catch_up_s)
                last = now
                runner = self._runner
                if not runner.done:
                    dt = runner.config.dt
                    debt += elapsed * self.speed
                    n = int(debt / dt + 1e-9)
                    if n > 0:
                        debt -= n * dt
                        frame = runner.advance(n * dt)
                        self._snapshot = Snapshot(self._snapshot.info, frame)
                        self._sim_time += n * dt
                    self._sim_cost += time.thread_time() - cpu0
                    self._sim_wall += elapsed
                elif done_since is None:
                    done_since = now
                elif now - done_since >= self.pause_s:
                    self._next_trial()
                    debt, done_since = 0.0, None
            except Exception as exc:  # never let the thread die silently
                log.exception("viewer simulation step failed")
                self._report(f"simulation error: {type(exc).__name__}: {exc}")
                self._stop.wait(0.5)
            self._stop.wait(max(0.0, self.sim_period - (time.perf_counter() - tick)))

    # -- view thread ---------------------------------------------------------------------
    def _view_loop(self) -> None:
        while not self._stop.is_set():
            tick = time.perf_counter()
            try:
                self.render()
            except Exception as exc:
                log.exception("viewer update failed")
                self._report(f"viewer error: {type(exc).__name__}: {exc}")
                self._stop.wait(0.5)
            self._stop.wait(max(0.0, self.view_period - (time.perf_counter() - tick)))

    def render(self) -> bool:
        """Updates every view from the latest snapshot; returns False if nothing was new."""
        server = self.server
        snap = self._snapshot
        if server is None or (snap.info is self._shown and snap.frame is self._shown_frame):
            return False
        t0 = time.thread_time()  # CPU time of this thread: robust to preemption
        info, frame = snap.info, snap.frame
        out = frame.outputs
        new_trial = info is not self._shown
        with server.atomic():
            if new_trial:
                self._show_trial(info)
            self._show_physics(frame)
            self.tool.update(frame.tcp)
            self.trajectory.update(frame.goal_index)
            self.arrows.update(out.arrows)
            self.ghost.update(out.ghost)
            self.hud.update(self._hud_info(info, frame), force=new_trial or frame.done)
        self.camera.update(out.camera)
        self._shown, self._shown_frame = info, frame
        self._view_costs.append(time.thread_time() - t0)
        self._view_updates += 1
        return True

    def _show_trial(self, info: TrialInfo) -> None:
        self.trajectory.set_task(info.points, info.reach_radius, info.normals)
        trocar = self._tool_trocar(info)
        self.tool.set_trocar(trocar)
        self.ghost.trocar = trocar
        # Keep the menus in step with what runs (e.g. a point schema switched the task).
        # Assigning a value runs the menu's callbacks synchronously in this thread: the
        # thread-local flag keeps them from queueing a command, which could otherwise land
        # after (and undo) a choice the user made a moment ago.
        self._local.syncing_menus = True
        try:
            if self.schema_menu.value != info.schema:
                self.schema_menu.value = info.schema
            if self.task_menu.value != info.config.task:
                self.task_menu.value = info.config.task
        finally:
            self._local.syncing_menus = False

    @staticmethod
    def _hud_info(info: TrialInfo, frame: TrialFrame) -> HudInfo:
        out = frame.outputs
        return HudInfo(
            schema=info.schema, fixtures=info.fixtures,
            task=f"{info.task_name}", trial=info.number, t=frame.t,
            error_m=float(np.linalg.norm(frame.tcp - frame.goal)), error_l1=frame.error_l1,
            goal_index=frame.goal_index, n_points=frame.n_points,
            last_latency=frame.last_latency, audio=out.audio,
            force_n=None if out.force is None else float(np.linalg.norm(out.force.force)),
            zoom=None if out.camera is None else float(out.camera.zoom),
            # The runtime reports a ghost exactly when the schema has MS.
            ms=None if out.ghost is None else tuple(float(m) for m in out.ms_factors),  # type: ignore[arg-type]
            done=frame.done,
        )


__all__ = [
    "DEFAULT_SCHEMA_FOR_TASK",
    "Command",
    "Snapshot",
    "TrialInfo",
    "ViewerApp",
    "endoscope_pose",
    "is_loopback",
]
