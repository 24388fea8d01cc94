"""The training viewer: ``vasim serve`` starts :class:`ViewerApp` (issue 6).

Threads and hand-offs (guides/architecture.md):

* The **controller thread** (``control_hz``, 50 Hz) owns the :class:`TrainingController`
  (modes, sessions, the study store, the live trial): it drains the command queue and
  polls the controller (storing a finished trial, looping the demo, auto-advancing a
  protocol). The live trial runs on its own thread (the 1 kHz servo loop of
  ``vasim.trials.realtime`` when present, else the viewer's ``SimThreadTrial``): the viewer
  never slows the physics or the haptic loop, it only reads their latest frame.
* The **view thread** (``view_hz``, 40 Hz: the issue asks for >= 30 scene updates/s in
  the browser, and a loaded host loses a few) reads ``controller.current()`` (the trial's
  immutable info and latest frame) and, if new, updates every view inside one
  ``server.atomic()`` block, streams the AG cue to the pages' synths (:mod:`audio`) and
  redraws the experimenter panel when its ``PanelState`` version changed.
* **GUI callbacks** (viser's thread pool, any browser tab) only put a ``Command`` on the
  queue — except the tool-tip gizmo, which feeds its samples straight into the
  ``BrowserDevice`` of a browser-driven trial (the device is thread-safe and interpolates
  between the ~20 Hz browser samples for the 1 kHz loop). Every callback is wrapped: an
  exception is logged and shown as a notification, never raised into viser (which would
  print and swallow it), so a failing callback never kills the server.

A page reload or a second tab is just another client: it gets the scene, the panel and
its own audio synth; the trial and the store are untouched (one owner, the controller).

The MRCP panel (the robots, which one holds the task, NTT, texec/tus per robot) belongs to
scenes with a slave station; none of the shipped abdomen scenes has robots, so no panel is
built: :meth:`ViewerApp._build_mrcp_panel` is the hook where it goes. The scripted MRCP
scenarios (``--scene mrcp:<scenario>``) are served by
:class:`vasim.viewer.mrcp_panel.MrcpViewerApp`: the station and an MRCP tab, without the
abdomen's trainee and experimenter tabs.
"""

from __future__ import annotations

import collections
import logging
import math
import queue
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
import trimesh
import viser
from numpy.typing import NDArray

from vasim.abdomen.anatomy import TROCAR_NAMES, Organ, default_anatomy, trocar_points
from vasim.core.bounds import PORT
from vasim.core.config import check_choice, check_int, check_number, expect
from vasim.core.errors import ConfigError
from vasim.fixtures.schema import load_schema
from vasim.haptics.laparoscopic import InputMapping
from vasim.records.path_deviation import path_distances
from vasim.study.protocol import available_protocols
from vasim.trials.vf import TrialFrame, tool_trocar
from vasim.viewer.access import (
    access_policy,
    guarded_server,
    new_token,
    same_token,
    viewer_url,
)
from vasim.viewer.app_options import PageAccess, TrialOptions, ViewerPace
from vasim.viewer.audio import AudioStream
from vasim.viewer.chrome import experimenter_chrome, lock_trainee_chrome
from vasim.viewer.controller import (
    DEFAULT_SCHEMA_FOR_TASK,
    Command,
    TrainingController,
    TrainingSettings,
    TrialInfo,
    schema_choices,
)
from vasim.viewer.endoscope import Scope, ScopeLight, scope_from_mag, scope_pose, task_target
from vasim.viewer.flow import (
    MIN_SCENE_HZ,
    PageAcks,
    RateMeter,
    ScenePacer,
    page_stats,
    registry,
    slowest_page_hz,
)
from vasim.viewer.instrument_input import CONTROLS_TEXT, InstrumentInput, screen_axes
from vasim.viewer.lighting import third_person_lighting
from vasim.viewer.notify import ErrorReporter
from vasim.viewer.page_notices import PageNotices
from vasim.viewer.panel import ExperimenterPanel
from vasim.viewer.questionnaire_form import QuestionnaireForm
from vasim.viewer.scene_views import DragInput, SceneViews, endoscope_pose, third_person_pose
from vasim.viewer.trainee import (
    HudInfo,
    HudView,
    frame_outcome,
    instruction,
    score_card_markdown,
)
from vasim.viewer.views import (
    ArrowView,
    CameraController,
    CameraPose,
    GhostView,
    OrganView,
    ToolView,
    TrajectoryView,
)

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
DEFAULT_TRIALS, DEFAULT_PACE, DEFAULT_ACCESS = TrialOptions(), ViewerPace(), PageAccess()


def check_bind_address(host: str, port: int) -> None:
    """Raises ``ConfigError`` unless ``port`` is a valid TCP port and ``host`` an address of
    this machine (viser would otherwise fail in a background thread and hang the server).
    A busy port is fine: viser moves to the next free one."""
    check_int(port, "port", bound=PORT)
    try:
        infos = socket.getaddrinfo(host, 0, type=socket.SOCK_STREAM)
        family, _, _, _, addr = infos[0]
        with socket.socket(family, socket.SOCK_STREAM) as probe:
            probe.bind(addr)
    except OSError as exc:
        raise ConfigError(f"cannot bind to host {host!r}: {exc.strerror or exc}",
                          field="host") from None


@dataclass(frozen=True, eq=False)
class Snapshot:
    """One trial's info and a frame of it (what the views were last fed)."""

    info: TrialInfo
    frame: TrialFrame


class ViewerApp(ErrorReporter):
    """The viser server, its views and panels, and the controller and view threads.

    Args:
        host: interface to bind; ``127.0.0.1`` (default) admits only this machine.
        port: TCP port; 0 picks a free one. viser silently moves to the next free port when
            the requested one is busy: read ``port`` / ``url`` after ``start()``.
        scene: the abdomen scene of every trial (``"none"``: a static task).
        db: the study store (SQLite path) trials are stored in; None: demo only.
        trials: the first demo trial, time limit, pause, start cue and optics
            (``TrialOptions``).
        pace: the trials' speed and the threads' and pages' rates (``ViewerPace``).
        access: the pages' tokens and the experimenter page's port (``PageAccess``).
        trial_factory: builds live trials (default ``make_live_trial``).

    Raises:
        ConfigError: for an unknown schema, task, skill or scene, a schema that does not
            fit the task, or a ``db`` that is a directory (before any socket is opened).

    Example:
        >>> app = ViewerApp(port=0, trials=TrialOptions(schema="vg")).start()  # doctest: +SKIP
        >>> print(app.url)                                                     # doctest: +SKIP
        http://127.0.0.1:40123/
        >>> app.request_schema("mag"); app.stop()                              # doctest: +SKIP
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 8080,
        *,
        scene: str = "default",
        db: str | None = None,
        trials: TrialOptions = DEFAULT_TRIALS,
        pace: ViewerPace = DEFAULT_PACE,
        access: PageAccess = DEFAULT_ACCESS,
        trial_factory: Callable[..., Any] | None = None,
    ):
        # Two pages, two tokens (issue #30.1): the trainee's token never opens the
        # experimenter's page. Given only the trainee's, the experimenter's is drawn here.
        token, experimenter_token = access.token, access.experimenter_token
        if token and experimenter_token is None:
            experimenter_token = new_token()
        expect(not (token and experimenter_token and same_token(experimenter_token, token)),
               "the trainee's token", "a token that must differ from the trainee's (one "
               "token per page)", field="experimenter_token")
        self.access = access_policy(host, token, role="trainee")
        self.exp_access = access_policy(host, experimenter_token, role="experimenter")
        self.scope = Scope(trocar_points()[TROCAR_NAMES.index("camera")],
                           optics_deg=trials.optics)
        self._check_pace(trials, pace)
        expect(not scene.startswith("mrcp:"), scene, "an abdomen scene (an MRCP slave "
               "station is served by vasim.viewer.mrcp_panel.MrcpViewerApp: vasim serve "
               "--scene mrcp:<scenario> starts it)", field="scene")
        self.host = host
        self.requested_port = int(port)
        self.requested_experimenter_port = (
            int(access.experimenter_port) if access.experimenter_port is not None
            else (0 if int(port) == 0 else int(port) + 1))
        self.control_period = 1.0 / pace.control_hz
        self.view_period = 1.0 / pace.view_hz
        self.audio_hz = float(pace.audio_hz)
        # Built here so that a bad schema/task/scene fails before a socket is opened.
        self.controller = TrainingController(TrainingSettings(
            scene=scene, db=db, trials=trials, speed=pace.speed, trial_factory=trial_factory))
        self.scene_name = scene
        # The instrument's screen motion follows the scope's image of each trial's task.
        self.controller.view_axes = self._view_axes
        eye = self._scope_view(self.controller.info)
        self.controller.screen = screen_axes(eye.position, eye.look_at, eye.up)
        self._init_loop_state()
        self.view_hz = float(pace.view_hz)
        self.speed = float(pace.speed)
        if pace.scene_hz is not None:
            check_number(pace.scene_hz, "scene_hz", gt=0)
        self._init_pacing(pace.scene_hz)
        self.controller.viewer_timing = self.viewer_timing

    @staticmethod
    def _check_pace(trials: TrialOptions, pace: ViewerPace) -> None:
        """The pause and the rates: a number, >= 0, and (but the pause) > 0."""
        speed, control_hz, view_hz, audio_hz = (pace.speed, pace.control_hz, pace.view_hz,
                                                pace.audio_hz)
        for name, v in (("pause_s", trials.pause_s), ("speed", speed),
                        ("control_hz", control_hz), ("view_hz", view_hz),
                        ("audio_hz", audio_hz)):
            check_number(v, name, ge=0)
        for name, v in (("speed", speed), ("control_hz", control_hz), ("view_hz", view_hz),
                        ("audio_hz", audio_hz)):
            check_number(v, name, gt=0)

    def _init_loop_state(self) -> None:
        """The command queue, the threads' state, what the pages show and the servers
        (None until ``start``)."""
        self.commands: queue.SimpleQueue[Command] = queue.SimpleQueue()
        self.errors: list[str] = []
        """Messages of errors caught in callbacks and threads (newest last)."""
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._view_costs: collections.deque[float] = collections.deque(maxlen=600)
        self._view_updates = 0
        self._t_started = 0.0
        self._shown: TrialInfo | None = None
        self._shown_frame: TrialFrame | None = None
        self._shown_extra: tuple[Any, ...] = ()
        self._snapshot = Snapshot(*self.controller.current())
        self.server: viser.ViserServer | None = None
        """The trainee's page: the endoscope's view, the instrument, the fixtures' cues."""
        self.exp_server: viser.ViserServer | None = None
        """The experimenter's page (a second address): the controls, a third-person view
        and the live metrics; nothing of it is reachable from the trainee's page."""
        self.mrcp_panel: Any = None
        """The MRCP panel (None: the scene has no slave station)."""
        self._stopped = False

    def _init_pacing(self, scene_hz: float | None) -> None:
        """When the pages' frames carry the organs, the realtime meter, the notices and
        the trial's flow."""
        every = float("inf")
        self.scene_pacer = (ScenePacer(every, every) if scene_hz is None
                            else ScenePacer(scene_hz, min(MIN_SCENE_HZ, scene_hz)))
        self.exp_scene_pacer = (ScenePacer(every, every) if scene_hz is None
                                else ScenePacer(scene_hz, min(MIN_SCENE_HZ, scene_hz)))
        """When each page's frame carries the organs (flow.py, "Less per frame")."""
        self._light_t = -math.inf
        self.rate = RateMeter()
        """The loop's recent realtime factor as the pages see it (frame.t per wall s)."""
        self._trial_flow: tuple[float, int, dict[tuple[int, int], int]] = (0.0, 0, {})

    # -- lifecycle -----------------------------------------------------------------------
    def start(self) -> ViewerApp:
        """Binds the server, builds the scene and GUI, starts both threads; returns self."""
        if self.server is not None:
            raise RuntimeError("ViewerApp.start() was already called")
        try:
            check_bind_address(self.host, self.requested_port)
            self.server = guarded_server(self.host, self.requested_port, self.access)
            exp_port = self.requested_experimenter_port
            if exp_port != 0 and exp_port == self.server.get_port():
                exp_port += 1
            self.exp_server = guarded_server(self.host, exp_port, self.exp_access)
            lock_trainee_chrome(self.server)  # before any other GUI (chrome.py)
            experimenter_chrome(self.exp_server)
            third_person_lighting(self.exp_server)
            self.acks = PageAcks(self.server)
            self.exp_acks = PageAcks(self.exp_server)
            self.notices = PageNotices(self.acks, self.exp_acks)
            self._build_scene()
            self._build_gui()
            self.mrcp_panel = self._build_mrcp_panel()
            self.server.on_client_connect(self._guard(self._on_connect))
            self.exp_server.on_client_connect(self._guard(self._on_exp_connect))
            self._t_started = time.perf_counter()
            for target, name in ((self._control_loop, "vasim-viewer-control"),
                                 (self._view_loop, "vasim-viewer-view")):
                t = threading.Thread(target=target, name=name, daemon=True)
                t.start()
                self._threads.append(t)
        except BaseException:
            self.stop()
            raise
        return self

    def stop(self, timeout: float = 5.0) -> None:
        """Stops both threads (joined), the trial (a stored one is marked interrupted), the
        store and the server. Idempotent."""
        if self._stopped:
            return
        self._stopped = True
        self._stop.set()
        for t in self._threads:
            t.join(timeout=timeout)
            if t.is_alive():
                log.error("viewer thread %s did not stop within %.1f s", t.name, timeout)
        if not self._threads:  # never started: close here (the store was never opened)
            self.controller.close()
        for server in (self.server, self.exp_server):
            if server is not None:
                server.stop()

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
    def experimenter_port(self) -> int:
        """The experimenter page's port (after ``start()``)."""
        if self.exp_server is None:
            raise RuntimeError("ViewerApp.start() has not been called")
        return self.exp_server.get_port()

    @property
    def experimenter_url(self) -> str:
        """Address of the experimenter's page (with the token of an exposed viewer)."""
        return viewer_url(self.host, self.experimenter_port, self.exp_access.token)

    @property
    def url(self) -> str:
        """Address of the trainee's page (wildcard hosts shown as 127.0.0.1; the token of an
        exposed viewer included)."""
        return viewer_url(self.host, self.port, self.access.token)

    # -- API for callers (and tests): all go through the command queue -------------------
    @property
    def snapshot(self) -> Snapshot:
        """The current trial's info and latest frame."""
        return Snapshot(*self.controller.current())

    @property
    def panel(self) -> Any:
        """The experimenter panel's state (``controller.PanelState``)."""
        return self.controller.panel

    def submit(self, command: Command) -> None:
        """Queues a command for the controller thread."""
        self.commands.put(command)

    def request(self, kind: str, value: Any = None) -> None:
        """Queues ``Command(kind, value)`` (see ``controller.Command``)."""
        self.submit(Command(kind, value))

    def request_schema(self, name: str) -> None:
        """Asks for schema ``name`` (the demo restarts with it)."""
        self.request("schema", str(name))

    def request_task(self, task: str) -> None:
        """Asks for task ``task`` (the demo restarts with it)."""
        self.request("task", str(task))

    def request_restart(self) -> None:
        """Asks to restart the demo trial."""
        self.request("restart")

    def scene_nodes(self) -> list[str]:
        """Names of the scene nodes the views own (sorted)."""
        return self.views.node_names()

    # The trainee page's views (what tests and benchmarks inspect).
    @property
    def organs(self) -> list[OrganView]:
        return self.views.organs

    @property
    def tool(self) -> ToolView:
        return self.views.tool

    @property
    def trajectory(self) -> TrajectoryView:
        return self.views.trajectory

    @property
    def arrows(self) -> ArrowView:
        return self.views.arrows

    @property
    def ghost(self) -> GhostView:
        return self.views.ghost

    def stats(self) -> dict[str, float]:
        """Timing: CPU cost of one view update [ms] (mean, p95, max over the last 600;
        thread CPU time, so preemption is not counted), view updates and their rate per
        wall second, AG parameter updates sent, and the live trial's loop figures
        (``control_hz``, ``realtime_factor``, ... as its ``timing()`` reports them)."""
        costs = np.array(self._view_costs) * 1e3
        wall = time.perf_counter() - self._t_started if self._t_started else 0.0
        out = {
            "view_updates": float(self._view_updates),
            "view_rate_hz": self._view_updates / wall if wall > 0 else 0.0,
            "view_ms_mean": float(costs.mean()) if len(costs) else float("nan"),
            "view_ms_p95": float(np.percentile(costs, 95)) if len(costs) else float("nan"),
            "view_ms_max": float(costs.max()) if len(costs) else float("nan"),
            "audio_updates": float(self.audio.sent) if self.server is not None else 0.0,
        }
        trial = self.controller.trial
        timing = trial.timing() if trial is not None else None
        d = timing.to_dict() if timing is not None and hasattr(timing, "to_dict") else {}
        for k, v in d.items():
            if isinstance(v, dict):  # RealtimeTiming's physics thread figures
                for k2, v2 in v.items():
                    if isinstance(v2, int | float) and not isinstance(v2, bool):
                        out[f"trial_{k}_{k2}"] = float(v2)
            elif isinstance(v, int | float) and not isinstance(v, bool):
                out[f"trial_{k}"] = float(v)
        return out

    # -- scene and GUI -------------------------------------------------------------------
    def _build_scene(self) -> None:
        s, e = self.server, self.exp_server
        assert s is not None and e is not None
        organs = self._organs()
        self.trocars = trocar_points()
        info = self._snapshot.info
        trocar = tool_trocar(info.config.task, info.start)
        self.views = SceneViews(s, organs, self.trocars, trocar, tones=True)
        self.exp_views = SceneViews(e, organs, self.trocars, trocar)
        # The trainee sees through the endoscope (Mag moves it along its port when the
        # condition has Mag); the experimenter orbits freely from a third-person view.
        eye = self._scope_view(info)
        self.camera = CameraController(s, eye, mapper=partial(scope_from_mag, self.scope))
        self.camera.apply_initial()
        self.light = ScopeLight(s)
        self.light.follow(eye)
        self.exp_camera = CameraController(e, third_person_pose())
        self.exp_camera.apply_initial()
        self.exp_camera.follow = False
        self.drag = DragInput(s, lambda: self.controller.browser, self._guard)
        self.instrument_input = InstrumentInput(s, lambda: self.controller.instrument,
                                                self._guard)
        self.audio = AudioStream(s, rate_hz=self.audio_hz)

    def _scope_view(self, info: TrialInfo) -> CameraPose:
        """The scope's pose without Mag for a trial: aimed at its task from 1 cm inside the
        camera port (every task is in view from there: tests/viewer/test_endoscope.py)."""
        return scope_pose(self.scope, task_target(info.points, info.start), 0.01)[0]

    def _view_axes(self, points: FloatArray, start: FloatArray) -> tuple[FloatArray, FloatArray]:
        pose = scope_pose(self.scope, task_target(points, start), 0.01)[0]
        return screen_axes(pose.position, pose.look_at, pose.up)

    def _organs(self) -> list[Organ]:
        """The organs to draw: the scene's surfaces as the trial's physics has them (the
        vertex order of each model is its mesh's), or the static anatomy without a scene."""
        frame = self._snapshot.frame
        snap = frame.abdomen
        if snap is None:
            return default_anatomy()
        runner = getattr(self.controller.trial, "runner", None)
        abdomen = getattr(runner, "abdomen", None)
        if abdomen is not None:
            models = list(abdomen.models)
        else:
            from vasim.abdomen.scene import load_scene

            models = list(load_scene(self.scene_name).build())
        return [Organ(name=m.name,
                      mesh=trimesh.Trimesh(np.array(snap.organ(m.name).surface), m.faces,
                                           process=False),
                      color=m.color, delicate=m.delicate, kind=m.kind)
                for m in models]

    def _build_gui(self) -> None:
        s, e = self.server, self.exp_server
        assert s is not None and e is not None
        p = self.controller.panel
        # The trainee's page: the view, the cues, a minimal status; no controls of the
        # experimenter's (**decision**: not even the Mag camera switch — Mag is part of the
        # condition, and the experimenter's page has its own free camera).
        self.hud = HudView(s)
        self.score = s.gui.add_markdown("", visible=False)
        s.gui.add_markdown(CONTROLS_TEXT)
        # The experimenter's page: today's controls beside a third-person view.
        self.panel_view = ExperimenterPanel(
            e, self.submit, self._guard, p, schema_choices(p.schema), available_protocols())
        self.questionnaire = QuestionnaireForm(e, self.submit, self._guard)
        with e.gui.add_folder("Trainee's instrument (input laparoscopic)"):
            fulcrum = e.gui.add_checkbox(
                "Fulcrum effect", initial_value=True,
                hint="on: the tip moves opposite to the hand, as through a real port")
            sensitivity = e.gui.add_slider("Sensitivity", min=0.1, max=5.0, step=0.1,
                                           initial_value=1.0)

        def mapping(_: Any) -> None:
            self.submit(Command("input_mapping", InputMapping(
                fulcrum_effect=bool(fulcrum.value), sensitivity=float(sensitivity.value))))

        fulcrum.on_update(self._guard(mapping))
        sensitivity.on_update(self._guard(mapping))

    def _build_mrcp_panel(self) -> Any:
        """Abdomen scenes carry no robots: slave stations are served as ``mrcp:<scenario>``
        scenes by :class:`vasim.viewer.mrcp_panel.MrcpViewerApp` (robots, task holder, live
        NTT / texec / tus plots). A scene file that declares robots is refused here with a
        pointer to those scenes rather than shown without its robots."""
        from vasim.abdomen.scene import load_scene

        if self.scene_name == "none":
            return None
        robots = getattr(load_scene(self.scene_name), "robots", ())
        if robots:
            raise ConfigError(f"scene {self.scene_name!r} declares robots: slave stations are "
                              "served as --scene mrcp:<scenario> (vasim mrcp list)",
                              field="scene")
        return None

    def _on_exp_connect(self, client: viser.ClientHandle) -> None:
        self.exp_camera.on_connect(client)
        self._install_flow(client, self.exp_acks)

    def _install_flow(self, client: viser.ClientHandle, acks: PageAcks) -> None:
        """The page's acknowledgement script and its notice line (page_notices.py)."""
        self.notices.install(client, acks)

    def _on_connect(self, client: viser.ClientHandle) -> None:
        self._install_flow(client, self.acks)
        self.camera.on_connect(client)
        self.audio.install(client)
        self.instrument_input.install(client)
        enabled = [False]
        button = client.gui.add_button("Enable audio", icon=viser.Icon.VOLUME,
                                       hint="browsers play sound only after a click")

        def toggle(event: Any) -> None:
            enabled[0] = not enabled[0]
            self.audio.enable(client, enabled[0])
            button.label = "Mute audio" if enabled[0] else "Enable audio"

        button.on_click(self._guard(toggle))


    # -- controller thread ---------------------------------------------------------------
    def _control_loop(self) -> None:
        ctl = self.controller
        handle = self._guard(ctl.handle)
        try:
            while not self._stop.is_set():
                tick = time.perf_counter()
                try:
                    while True:
                        try:
                            cmd = self.commands.get_nowait()
                        except queue.Empty:
                            break
                        handle(cmd)
                    ctl.poll()
                except Exception as exc:  # never let the thread die silently
                    log.exception("viewer controller step failed")
                    self._report(f"controller error: {type(exc).__name__}: {exc}")
                    self._stop.wait(0.5)
                self._stop.wait(max(0.0, self.control_period - (time.perf_counter() - tick)))
        finally:
            try:
                ctl.close()  # on this thread: the store belongs to it
            except Exception:
                log.exception("closing the training controller failed")

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
        """Updates every view from the current frame; returns False if nothing was new."""
        server = self.server
        if server is None:
            return False
        self.panel_view.show(self.controller.panel)
        self.questionnaire.show(self.controller.panel)
        info, frame = self.controller.current()
        ctl = self.controller
        # The trial ends (Stop, time out), a countdown ticks, a score card arrives: the
        # trainee page says so even when no new frame comes.
        extra = (ctl.outcome, None if ctl.countdown_until is None
                 else int(ctl.countdown_until - time.monotonic()), ctl.panel.scorecard)
        if info is self._shown and frame is self._shown_frame and extra == self._shown_extra:
            return False
        self._shown_extra = extra
        t0 = time.thread_time()  # CPU time of this thread: robust to preemption
        out = frame.outputs
        new_trial = info is not self._shown
        self._snapshot = Snapshot(info, frame)
        now = time.monotonic()
        with server.atomic():
            self.views.update(info, frame, new_trial=new_trial,
                              scene=self.scene_pacer.due(now, slowest_page_hz(self.acks)))
            self.hud.update(self._hud_info(info, frame), force=True if new_trial
                            or frame.done or ctl.outcome[1] is not None else False)
            card = score_card_markdown(ctl.panel.scorecard
                                       if not ctl.panel.running else None)
            if card != self.score.content:
                self.score.content = card
                self.score.visible = bool(card)
            self.drag.update(frame.tcp, info.input == "browser" and not frame.done)
            self.acks.marks.mark(frame.t)
        assert self.exp_server is not None
        with self.exp_server.atomic():
            self.exp_views.update(info, frame, new_trial=new_trial,
                                  scene=self.exp_scene_pacer.due(
                                      now, slowest_page_hz(self.exp_acks)))
            self.exp_acks.marks.mark(frame.t)
            self.panel_view.show_live(info, frame, force=True if new_trial or frame.done
                                     or ctl.outcome[1] is not None else False,
                                     outcome=ctl.outcome[1]
                                     if ctl.outcome[0] == info.number else None)
        if new_trial:
            self.camera.retarget(self._scope_view(info))
        self.camera.update(out.camera)
        # The light moves with the scope's pose as the pages are given it (a camera write
        # is skipped for a pose within 0.2 mm / 2 mrad of the last: so is the light's).
        # At most at the camera's own write rate (10 Hz): the pages' cameras ease toward
        # each pose anyway.
        target = self.camera.target
        if self.light.pose is None or new_trial or (
                self.light.pose is not target and not self.light.pose.close_to(target)
                and now - self._light_t >= self.camera.min_interval):
            self.light.follow(target)
            self._light_t = now
        self.audio.update(out.audio)
        if new_trial:
            self.rate.reset()
            self.notices.scales.restart(self.acks.port)
            self._trial_flow = (time.monotonic(), self._view_updates, {
                k: f.total_acks for k, f in registry.pages.copy().items()})
        if frame is not self._shown_frame and not frame.done and ctl.countdown_until is None:
            self.rate.add(frame.t)
        self._shown, self._shown_frame = info, frame
        self.notices.show(frame.t, self.rate.factor(), self.speed, self.view_hz,
                          self._view_updates)
        self._view_costs.append(time.thread_time() - t0)
        self._view_updates += 1
        return True

    def flow_stats(self) -> dict[str, float]:
        """The pages' stream figures (flow.py): per page kind, the slowest page's update
        rate, frames in flight, queued messages, displayed-clock lag, stalls; and the loop's
        recent realtime factor."""
        t = self._snapshot.frame.t
        out = {f"trainee_{k}": v for k, v in page_stats(self.acks, t).items()}
        out.update({f"experimenter_{k}": v for k, v in page_stats(self.exp_acks, t).items()})
        factor = self.rate.factor()
        out["realtime_factor_recent"] = float("nan") if factor is None else factor
        return out

    def viewer_timing(self) -> dict[str, float]:
        """What the trial record stores about the viewer (``timing_json["viewer"]``): view
        updates per wall second during the trial, the trainee pages' update rates (mean
        over the trial; the slowest page), the loop's recent realtime factor."""
        t0, n0, acks0 = self._trial_flow
        wall = time.monotonic() - t0 if t0 else 0.0
        rates = [(f.total_acks - acks0.get((self.acks.port, cid), 0)) / wall
                 for cid, f in self.acks.pages().items() if f.acking and wall > 0]
        factor = self.rate.factor()
        return {"view_update_hz": (self._view_updates - n0) / wall if wall > 0 else 0.0,
                "trainee_page_update_hz": min(rates) if rates else float("nan"),
                "trainee_pages": float(len(rates)),
                "trainee_render_scale_min": self.notices.scales.coarsest.get(
                    self.acks.port, 1.0),
                "realtime_factor_recent": float("nan") if factor is None else factor}

    def _hud_info(self, info: TrialInfo, frame: TrialFrame) -> HudInfo:
        out = frame.outputs
        ctl = self.controller
        number, outcome = ctl.outcome
        until = ctl.countdown_until
        limit = float(info.config.max_time)
        return HudInfo(
            schema=info.schema, fixtures=info.fixtures,
            task=f"{info.task_name}", t=frame.t,
            # Counting down: the trial to come (its store id is given when it begins).
            title=info.title if until is None else "the next trial",
            time_left=limit - frame.t if np.isfinite(limit) else None,
            outcome=(outcome if number == info.number and outcome is not None
                     else frame_outcome(frame.done, frame.goal_index, frame.n_points)),
            instruction=(instruction(info.task_name, len(info.points), info.input)
                         if until is None else instruction(
                             ctl.panel.task, len(info.points) if ctl.panel.task == info.config.task
                             else 1, ctl.panel.input)),
            countdown_s=None if until is None else until - time.monotonic(),
            error_m=float(np.linalg.norm(frame.tcp - frame.goal)),
            path_m=(float(path_distances(np.asarray(frame.tcp, dtype=np.float64)[None, :],
                                         [int(frame.goal_index)], info.points,
                                         info.start)[0])
                    if 0 <= frame.goal_index < len(info.points) else None),
            goal_index=frame.goal_index, n_points=frame.n_points,
            last_latency=frame.last_latency, audio=out.audio,
            force_n=None if out.force is None else float(np.linalg.norm(out.force.force)),
            zoom=None if out.camera is None else float(out.camera.zoom),
            # The runtime reports a ghost exactly when the schema has MS.
            ms=None if out.ghost is None else tuple(float(m) for m in out.ms_factors),  # type: ignore[arg-type]  # 3 MS factors
            done=frame.done or outcome is not None,
        )


def default_schema(task: str) -> str:
    """The schema ``vasim serve`` starts with for ``task``."""
    check_choice(task, "task", tuple(DEFAULT_SCHEMA_FOR_TASK))
    load_schema(DEFAULT_SCHEMA_FOR_TASK[task])
    return DEFAULT_SCHEMA_FOR_TASK[task]


__all__ = [
    "DEFAULT_SCHEMA_FOR_TASK",
    "Command",
    "DragInput",
    "PageAccess",
    "Snapshot",
    "TrialInfo",
    "TrialOptions",
    "ViewerApp",
    "ViewerPace",
    "check_bind_address",
    "default_schema",
    "endoscope_pose",
]
