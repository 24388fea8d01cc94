"""The MRCP panel: a scripted slave-station scenario served live (``vasim serve --scene
mrcp:<scenario>``; issue 6, MRCP bullet; the seed's Figs. 4.23-4.26).

Threads (guides/architecture.md):

* the **scenario thread** (:class:`LiveScenario`, owned by the app) builds the scenario and
  runs it through :func:`vasim.mrcp.scenarios.runner.run_setup` — the same runner as
  ``vasim mrcp run`` — paced to real time by the runner's per-cycle ``progress`` hook
  (``speed`` simulated seconds per wall second; a cycle that costs more than its period
  makes the run fall behind, shown as the real-time factor over the last 2 s; more than
  0.25 s behind, it drops the debt rather than sprint to catch up). After each cycle it publishes
  an immutable :class:`MrcpFrame` (the runner's sample and the station's poses) and appends
  NTT, ``texec`` and ``tus`` per robot to a bounded history. A finished run starts again
  (the scenario loops); a safety stop ends that run, its cause stays in the status line
  and the station stays frozen for ``STOP_PAUSE_S`` before the next run (issue #26 §4); a
  failing cycle ends that run, is logged and reported (a
  notification in every page), and the scenario restarts after a pause.
* the **view thread** (:class:`MrcpViewerApp`) reads the latest frame, poses the station
  (:class:`~vasim.viewer.mrcp_view.StationView`) inside one ``server.atomic()`` block and
  refreshes the panel's text, plots and event log at a lower rate. It never blocks on the
  scenario thread (one lock, held only to copy the history).

**Decision** (the abdomen tabs): an MRCP scene is served by :class:`MrcpViewerApp`, not by
:class:`~vasim.viewer.app.ViewerApp`: it has no trainee trial, so the Trainee and
Experimenter tabs (and their training controller, which would run demo trials in the
background) are not built at all; the page shows the station and one "MRCP" tab.

**Decision** (operator input, issue #7 §3): the tab's "Operator" control switches the
target the runner's operator steers the task toward between the scenario's script
(``scripted``, the default: the run is the one ``vasim mrcp run`` makes) and a transform
gizmo on the task (``browser``; :class:`~vasim.mrcp.scenarios.runner.OperatorSwitch`).
Switching to browser places the gizmo at the task's current pose, so nothing moves until it
is dragged; the task then follows the gizmo at most 0.2 m/s and 120 deg/s, the kernel still
chooses the robot that holds it (and hands it over) and the invariants are checked every
cycle; a released gizmo holds its last pose. Switching back, the task returns to the
script at the same rate. The mode and the gizmo's pose survive a scenario's loop.

**Decision** (what a robot's ``texec`` / ``tus`` is): the runner's choice — RSel at CuTP, a
candidate at its best grasp point (largest ``tus``); ``texec`` is the minimum over the
indices. Transfer-phase (TT) cycles are not evaluated: gaps in the plots, as in the seed's.
"""

from __future__ import annotations

import collections
import html
import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import viser
from numpy.typing import NDArray

from vasim.core.config import check_array, check_number, expect
from vasim.core.errors import ConfigError
from vasim.core.geometry import matrix_from_quat
from vasim.viewer.access import viewer_url
from vasim.viewer.lighting import third_person_lighting
from vasim.viewer.mrcp_view import (
    StationFrame,
    StationGeometry,
    StationView,
    SubtaskView,
    station_frame,
    subtask_text,
    task_pose,
)
from vasim.viewer.notify import ErrorReporter
from vasim.viewer.views import set_gui_value

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
#: NTT drawn at this height when infinite (RSel has no useful time left), as in mrcp.plots.
NTT_TOP = 1.5
SCENE_PREFIX = "mrcp:"
#: ``tus`` below this [s] (down to -inf: no way to the grasp point) is drawn at it.
TUS_BOTTOM = -1.0
#: The real-time factor shown is measured over this much simulated time [s].
REALTIME_WINDOW_S = 2.0
#: A run more than this behind real time [s] drops the rest (no sprint to catch up).
MAX_DEBT_S = 0.25
#: After a safety stop the station stays frozen this long [s] before the scenario restarts.
STOP_PAUSE_S = 5.0
ROBOT_STROKES = ("#7048e8", "#0ca678", "#d6336c", "#1098ad", "#495057")  # not role colours


def scenario_from_scene(scene: str) -> str | None:
    """``"mrcp:cube_rotation"`` -> ``"cube_rotation"``; None for an abdomen scene."""
    return scene[len(SCENE_PREFIX):] if scene.startswith(SCENE_PREFIX) else None


def scenario_help() -> str:
    """The MRCP scenes ``vasim serve --scene`` accepts, for ``--help``."""
    from vasim.mrcp.scenarios import SCENARIOS

    return ", ".join(f"{SCENE_PREFIX}{n}" for n in sorted(SCENARIOS))


def resolve_scenario(scenario: Any) -> Any:
    """A registered scenario by name (``"cube_rotation"`` or ``"mrcp:cube_rotation"``), or
    a scenario object (``name``, ``duration``, ``build``) as given.

    Raises:
        ConfigError: for an unknown name; the message lists the known MRCP scenes.
    """
    if not isinstance(scenario, str):
        expect(callable(getattr(scenario, "build", None)) and hasattr(scenario, "name"),
               scenario, "an MRCP scenario (a name, or an object with build and name)",
               field="scene")
        return scenario
    from vasim.mrcp.scenarios import SCENARIOS

    name = scenario_from_scene(scenario) or scenario
    expect(name in SCENARIOS, name, f"an MRCP scenario: one of {scenario_help()}",
           field="scene")
    return SCENARIOS[name]


def plot_value(v: float, top: float | None = None, bottom: float | None = None) -> float:
    """A value as drawn: NaN stays a gap; a value is clipped into ``[bottom, top]`` (an
    infinite one beyond an open end is a gap).

    Example:
        >>> plot_value(math.inf, NTT_TOP), plot_value(0.4), math.isnan(plot_value(math.inf))
        (1.5, 0.4, True)
        >>> plot_value(-math.inf, bottom=TUS_BOTTOM), plot_value(-3.0, bottom=TUS_BOTTOM)
        (-1.0, -1.0)
    """
    v = float(v)
    if math.isnan(v):
        return v
    if math.isinf(v) and (top if v > 0 else bottom) is None:
        return math.nan
    if top is not None:
        v = min(v, top)
    if bottom is not None:
        v = max(v, bottom)
    return v


# --------------------------------------------------------------------------- frames
@dataclass(frozen=True, eq=False)
class MrcpFrame:
    """One published cycle.

    Attributes:
        seq: frame counter over all runs.
        run: run number (1 = the first; a loop or a restart after an error increments it).
        sample: the runner's :class:`~vasim.mrcp.scenarios.runner.Sample`.
        station: the poses to draw.
        realtime: simulated seconds per wall second over the last ``REALTIME_WINDOW_S``.
    """

    seq: int
    run: int
    sample: Any
    station: StationFrame
    realtime: float


@dataclass(frozen=True)
class History:
    """The plotted window: time ``(m,)`` [s], NTT ``(m,)``, per robot ``texec`` and ``tus``
    ``(m,)`` [s]; ``events``: ``(t, event)`` of the current run; ``transfers``: the
    runner's transfer dicts (start, from, to, point, ntt, cause, done); ``tt``: ``(m,)``
    the transfer-phase band (``NTT_TOP`` in TT cycles, else 0).

    TT cycles are not evaluated (NaN). uPlot gaps only at ``null``, which a numeric array
    cannot carry, so its lines bridge them: the shaded TT band in the NTT plot shows
    where a line is such a bridge (**decision**)."""

    run: int
    t: FloatArray
    ntt: FloatArray
    texec: dict[str, FloatArray]
    tus: dict[str, FloatArray]
    events: tuple[tuple[float, str], ...]
    transfers: tuple[dict[str, Any], ...]
    tt: FloatArray | None = None


class _Stopped(Exception):
    """Raised from the progress hook to end a run when the app stops."""


class LiveScenario:
    """Runs a scenario in real time on its own thread, looping (see the module docstring).

    Args:
        scenario: a scenario object (``name``, ``build(options)``).
        options: the runner's options (``coarse``, ``seed``, ``duration``).
        speed: simulated seconds per wall second (1: the real 18 ms cycle).
        history_s: plotted window [s].
        on_error: called with a message when a run fails (from the scenario thread).
        retry_s: pause before a failed scenario restarts [s].
        stop_pause_s: pause after a run ended by a safety stop [s] (the station stays as
            it stopped, the panel names the cause).
    """

    def __init__(self, scenario: Any, options: Any, *, speed: float = 1.0,
                 history_s: float = 20.0, on_error: Callable[[str], None] | None = None,
                 retry_s: float = 1.0, stop_pause_s: float = STOP_PAUSE_S):
        self.scenario = scenario
        self.options = options
        self.speed = float(speed)
        self.retry_s = float(retry_s)
        self._on_error = on_error or (lambda msg: None)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._pending: Any = None
        self._setup: Any = None
        self.geometry: StationGeometry | None = None
        self._frame: MrcpFrame | None = None
        self._seq = 0
        self.run = 0
        self.failures = 0
        self.cycles = 0
        self._history_s = float(history_s)
        self._reset_history([])
        self.operator: Any = None
        """The run's :class:`~vasim.mrcp.scenarios.runner.OperatorSwitch` (after prepare)."""
        self.stop_pause_s = float(stop_pause_s)
        self.stopped: tuple[str, int, str] | None = None
        """The last safety stop: (scenario, run, ``RunResult.stop``), or None."""

    # -- lifecycle ---------------------------------------------------------------------
    def prepare(self) -> StationGeometry:
        """Builds the first run's station and returns what to draw (call before start)."""
        from vasim.mrcp.scenarios.runner import OperatorSwitch
        from vasim.viewer.mrcp_view import station_geometry

        setup = self.scenario.build(self.options)
        self.operator = OperatorSwitch(setup.operator)
        try:
            self.geometry = station_geometry(self.scenario.name, setup)
        except BaseException:
            setup.close()
            raise
        self._pending = setup
        self.robots = list(setup.arms)
        self.ntt_threshold = float(setup.config.ntt_threshold)
        self.t_max = float(setup.config.t_max)
        self.dt = float(setup.config.dt)
        self._reset_history(self.robots)
        return self.geometry

    def start(self) -> None:
        if self.geometry is None:
            self.prepare()
        self._thread = threading.Thread(target=self._loop, name="vasim-viewer-mrcp",
                                        daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 60.0) -> None:
        # A generous join: a scenario's build (not interruptible) took over 5 s at load 25.
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=timeout)
            if self._thread.is_alive():
                log.error("MRCP scenario thread did not stop within %.1f s", timeout)
        if self._pending is not None:
            self._pending.close()
            self._pending = None

    def alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def latest(self) -> MrcpFrame | None:
        """The newest frame (None before the first cycle)."""
        return self._frame

    # -- the thread --------------------------------------------------------------------
    def _loop(self) -> None:
        from vasim.mrcp.scenarios.runner import run_setup

        while not self._stop.is_set():
            try:
                setup = self._pending if self._pending is not None else \
                    self.scenario.build(self.options)
                self._pending = None
                self._setup = setup
                self.operator.script = setup.operator
                with self._lock:
                    self.run += 1
                    self._reset_history(self.robots)
                self._t_wall0 = time.perf_counter()
                self._clock: collections.deque[tuple[float, float]] = collections.deque(
                    maxlen=max(2, int(REALTIME_WINDOW_S / self.dt)))
                res = run_setup(self.scenario.name, setup, self.options.duration,
                                self._on_sample, operator=self.operator)
                if res.stop is not None:
                    # The cause stays on the panel (status line and event log); the station
                    # stays frozen for stop_pause_s before the scenario starts again.
                    self.stopped = (res.scenario, self.run, res.stop)
                    log.warning("MRCP scenario %s run %d: safety stop %s",
                                self.scenario.name, self.run, res.stop)
                    if self._stop.wait(self.stop_pause_s):
                        break
            except _Stopped:
                break
            except Exception as exc:
                self.failures += 1
                t = self._frame.sample.t if self._frame is not None else 0.0
                log.exception("MRCP scenario %s failed (run %d, t=%.3f s)",
                              self.scenario.name, self.run, t)
                self._on_error(f"MRCP scenario {self.scenario.name} failed at t={t:.3f} s "
                               f"(run {self.run}): {type(exc).__name__}: {exc}; restarting")
                self._stop.wait(self.retry_s)

    def _on_sample(self, s: Any) -> None:
        if self._stop.is_set():
            raise _Stopped
        assert self.geometry is not None
        station = station_frame(self.geometry, self._setup.world, s)
        now = time.perf_counter()
        self._clock.append((now, s.t))
        (w0, t0), (w1, t1) = self._clock[0], self._clock[-1]
        self._seq += 1
        self.cycles += 1
        self._frame = MrcpFrame(self._seq, self.run, s, station,
                                (t1 - t0) / (w1 - w0) if w1 > w0 else math.inf)
        with self._lock:
            self._t.append(s.t)
            self._ntt.append(plot_value(s.ntt, NTT_TOP))
            self._tt.append(NTT_TOP if str(s.state).startswith("TT") else 0.0)
            for r in self.robots:
                rs = s.robots.get(r)
                self._texec[r].append(math.nan if rs is None else plot_value(rs.texec_min))
                self._tus[r].append(math.nan if rs is None else
                                    plot_value(rs.tus, bottom=TUS_BOTTOM))
            if s.events:
                self._event_samples.append(s)
        ahead = s.t / self.speed - (time.perf_counter() - self._t_wall0)
        if ahead > 0 and self._stop.wait(ahead):
            raise _Stopped
        if ahead < -MAX_DEBT_S:  # a stall: drop the debt rather than sprint to catch up
            self._t_wall0 -= -ahead - MAX_DEBT_S

    def _reset_history(self, robots: list[str]) -> None:
        n = max(2, int(self._history_s / getattr(self, "dt", 0.018)))
        self._t: collections.deque[float] = collections.deque(maxlen=n)
        self._ntt: collections.deque[float] = collections.deque(maxlen=n)
        self._tt: collections.deque[float] = collections.deque(maxlen=n)
        self._texec = {r: collections.deque[float](maxlen=n) for r in robots}
        self._tus = {r: collections.deque[float](maxlen=n) for r in robots}
        self._event_samples: list[Any] = []

    def history(self) -> History:
        """A copy of the plotted window and the current run's events and transfers."""
        from vasim.mrcp.scenarios.runner import RunResult

        with self._lock:
            t = np.array(self._t)
            ntt = np.array(self._ntt)
            tt = np.array(self._tt)
            texec = {r: np.array(v) for r, v in self._texec.items()}
            tus = {r: np.array(v) for r, v in self._tus.items()}
            samples = list(self._event_samples)
            run = self.run
        res = RunResult(self.scenario.name, list(self.robots), samples, [])
        return History(run, t, ntt, texec, tus, tuple(res.events()),
                       tuple(res.transfers()), tt)


# --------------------------------------------------------------------------- the panel
def status_text(scenario: str, frame: MrcpFrame | None, speed: float,
                stopped: tuple[str, int, str] | None = None) -> str:
    """The panel's status lines (markdown; only kernel-made strings, escaped); ``stopped``
    (:attr:`LiveScenario.stopped`) adds the last safety stop and its cause."""
    stop = ""
    if stopped is not None:
        _, run, cause = stopped
        stop = f"  \n**safety stop** (run {run}) {html.escape(cause)}"
        if frame is not None and frame.run == run:
            stop += " — the run ended there; restarting shortly"
    if frame is None:
        return f"**{html.escape(scenario)}**: building the station…{stop}"
    s = frame.sample
    ntt = "∞" if math.isinf(s.ntt) else ("—" if math.isnan(s.ntt) else f"{s.ntt:.2f}")
    rcnt = f" → **{html.escape(str(s.rcnt))}**" if s.rcnt and s.rcnt != s.rsel else ""
    lag = "" if frame.realtime >= 0.9 * speed else \
        f" (behind: {frame.realtime:.2f}× real time)"
    text = (f"**{html.escape(scenario)}** · run {frame.run} · t = {s.t:5.2f} s{lag}  \n"
            f"holds the task: **{html.escape(s.rsel)}** @ point {s.cutp}{rcnt} · "
            f"mode {html.escape(str(s.state))} · NTT {ntt}{stop}")
    sub = subtask_text(s)
    if sub is not None:       # a scenario with a state graph of subtasks (the suture)
        text += f"  \nsubtask: **{html.escape(sub)}**"
    return text


def event_log_text(h: History, limit: int = 8) -> str:
    """Markdown: the run's transfers (start, from -> to @ point, cause, NTT, completion)
    and its latest events, newest first."""
    lines = []
    if h.transfers:
        lines += ["| start [s] | from → to | cause | NTT | done [s] |", "|---|---|---|---|---|"]
        for tr in reversed(h.transfers[-limit:]):
            done = "—" if tr["t_done"] is None else f"{tr['t_done']:.2f}"
            lines.append(f"| {tr['t_start']:.2f} | {html.escape(str(tr['from']))} → "
                         f"{html.escape(str(tr['to']))} @ {tr['point']} | "
                         f"{html.escape(str(tr['cause']))} | {tr['ntt']:.2f} | {done} |")
    else:
        lines.append("*no transfer yet in this run*")
    if h.events:
        lines.append("")
        lines += [f"`{t:6.2f}` {html.escape(e)}  " for t, e in reversed(h.events[-limit:])]
    return "\n".join(lines)


class MrcpPanel:
    """The "MRCP" tab: status, live NTT / ``texec`` / ``tus`` plots per robot (uPlot) and
    the event log of transfers with their cause."""

    def __init__(self, server: viser.ViserServer, scenario: str, robots: list[str],
                 ntt_threshold: float, t_max: float = 5.0):
        gui = server.gui
        self.scenario = scenario
        self.robots = list(robots)
        self.ntt_threshold = float(ntt_threshold)
        self.updates = 0
        tabs = gui.add_tab_group()
        x = np.array([0.0, 1.0])
        nan = np.full(2, math.nan)
        axes: dict[str, viser.uplot.Scale] = {"x": {"time": False}}
        with tabs.add_tab("MRCP", icon=viser.Icon.ROBOT):
            self.status = gui.add_markdown(status_text(scenario, None, 1.0))
            self.ntt = gui.add_uplot(
                (x, nan, np.full(2, self.ntt_threshold), np.zeros(2)),
                (viser.uplot.Series(label="t [s]"),
                 viser.uplot.Series(label="NTT", stroke="#212529", width=2),
                 viser.uplot.Series(label="threshold", stroke="#e03131", width=1,
                                    dash=(6.0, 4.0)),
                 viser.uplot.Series(label="TT (not evaluated)", stroke="#f0a0a0",
                                    width=0, fill="rgba(240, 80, 80, 0.12)")),
                title="NTT (∞ drawn at 1.5)",
                scales={**axes, "y": {"auto": False, "range": [0.0, NTT_TOP + 0.05]}},
                aspect=2.2)
            per_robot = tuple(viser.uplot.Series(label=r, stroke=ROBOT_STROKES[i % 5], width=2)
                              for i, r in enumerate(self.robots))
            # Fixed y ranges: uPlot's auto range breaks on a series that starts with a gap.
            top = float(t_max) + 0.25
            self.texec = gui.add_uplot(
                (x, *[nan] * len(self.robots)),
                (viser.uplot.Series(label="t [s]"), *per_robot),
                title="texec per robot [s] (min over indices)",
                scales={**axes, "y": {"auto": False, "range": [-0.25, top]}}, aspect=2.2)
            self.tus = gui.add_uplot(
                (x, *[nan] * len(self.robots)),
                (viser.uplot.Series(label="t [s]"), *per_robot),
                title=f"tus per robot [s] (< {TUS_BOTTOM:g} drawn at {TUS_BOTTOM:g})",
                scales={**axes, "y": {"auto": False, "range": [TUS_BOTTOM - 0.25, top]}},
                aspect=2.2)
            self.operator = gui.add_dropdown(
                "Operator", ("scripted", "browser"), initial_value="scripted",
                hint="scripted: the scenario's script moves the task; browser: drag the "
                     "gizmo on the task (followed at <= 0.2 m/s, 120 deg/s)")
            with gui.add_folder("Transfers and events"):
                self.log = gui.add_markdown("*no transfer yet in this run*")
            gui.add_markdown("Robots: orange holds the task (RSel), light orange grasps "
                             "during a hand-over, blue receives (RCnt), grey waits; red "
                             "dot: the held grasp point (CuTP); yellow: a sensing body.")
        self._log_key: tuple[int, int] = (-1, -1)

    def show_status(self, frame: MrcpFrame | None, speed: float,
                    stopped: tuple[str, int, str] | None = None) -> None:
        text = status_text(self.scenario, frame, speed, stopped)
        if self.status.content != text:
            self.status.content = text

    def show_history(self, h: History) -> None:
        """Redraws the plots and, when it changed, the event log."""
        if len(h.t) >= 2:
            tt = h.tt if h.tt is not None else np.zeros(len(h.t))
            self.ntt.data = (h.t, h.ntt, np.full(len(h.t), self.ntt_threshold), tt)
            self.texec.data = (h.t, *[h.texec[r] for r in self.robots])
            self.tus.data = (h.t, *[h.tus[r] for r in self.robots])
        key = (h.run, len(h.events))
        if key != self._log_key:
            self._log_key = key
            self.log.content = event_log_text(h)
        self.updates += 1


# --------------------------------------------------------------------------- the app
def station_camera(geometry: StationGeometry) -> tuple[FloatArray, FloatArray]:
    """Initial camera ``(position, look_at)``: from the front (-y) and above, aimed between
    the robots' bases and the task's start, framing the bases."""
    bases = np.array([r.base[:3, 3] for r in geometry.robots])
    centre = 0.5 * (bases.mean(axis=0) + geometry.task_start) + np.array([0.0, 0.0, 0.1])
    span = float(np.ptp(bases[:, 0])) if len(bases) > 1 else 1.0
    d = max(1.0, 1.3 * span)
    return centre + d * np.array([0.25, -0.85, 0.5]), centre


@dataclass(frozen=True)
class MrcpPace:
    """How fast an ``MrcpViewerApp`` runs its scenario and updates its page.

    Attributes:
        speed: simulated seconds per wall second (1: real time).
        view_hz: rate of the station's pose updates [Hz].
        plot_hz: rate of the plots and event log [Hz].
        history_s: plotted window [s].
        retry_s: pause before a failed run restarts [s]. stop_pause_s: pause after a run
            ended by a safety stop [s].
    """

    speed: float = 1.0
    view_hz: float = 30.0
    plot_hz: float = 4.0
    history_s: float = 20.0
    retry_s: float = 1.0
    stop_pause_s: float = STOP_PAUSE_S


class MrcpViewerApp(ErrorReporter):
    """``vasim serve --scene mrcp:<scenario>``: a slave-station scenario in the browser.

    Args:
        host: interface to bind (default loopback only).
        port: TCP port; 0 picks a free one (read ``port`` after ``start()``).
        scenario: a registered name (``"cube_rotation"`` or ``"mrcp:cube_rotation"``) or a
            scenario object.
        seed: the kernel's planner seed.
        coarse: the runner's cheaper 36 ms cycle (tests; a slow machine).
        duration: run length before the scenario loops [s] (None: the scenario's own).
        pace: the run's speed, the page's update rates and the pauses (``MrcpPace``).
        token: the page's access token (``vasim.viewer.access``).

    Raises:
        ConfigError: for an unknown scenario or a bad rate (before a socket is opened).

    Example:
        >>> app = MrcpViewerApp(port=0, scenario="cube_rotation").start()  # doctest: +SKIP
        >>> print(app.url); app.stop()                                     # doctest: +SKIP
    """

    notify_title = "vasim MRCP"

    def __init__(self, host: str = "127.0.0.1", port: int = 8080,
                 scenario: Any = "cube_rotation", *, seed: int = 0, coarse: bool = False,
                 duration: float | None = None, pace: MrcpPace = MrcpPace(),
                 token: str | None = None):
        from vasim.viewer.access import access_policy

        speed, view_hz, plot_hz, history_s = (pace.speed, pace.view_hz, pace.plot_hz,
                                              pace.history_s)
        retry_s, stop_pause_s = pace.retry_s, pace.stop_pause_s

        self.access = access_policy(host, token)
        for name, v in (("speed", speed), ("view_hz", view_hz), ("plot_hz", plot_hz),
                        ("history_s", history_s)):
            check_number(v, name, gt=0)
        from vasim.mrcp.scenarios import ScenarioOptions

        self.scenario = resolve_scenario(scenario)
        self.host = host
        self.requested_port = int(port)
        self.speed = float(speed)
        self.view_period = 1.0 / view_hz
        self.plot_period = 1.0 / plot_hz
        self.errors: list[str] = []
        """Messages of errors caught in callbacks and threads (newest last)."""
        self.live = LiveScenario(self.scenario, ScenarioOptions(seed=seed, duration=duration,
                                                                coarse=coarse),
                                 speed=speed, history_s=history_s, on_error=self._report,
                                 retry_s=retry_s, stop_pause_s=stop_pause_s)
        self.server: viser.ViserServer | None = None
        self.station: StationView | None = None
        self.subtasks: SubtaskView | None = None
        """The suture's thread and subtask label (created at the first sample with a
        subtask)."""
        self.panel: MrcpPanel | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.gizmo: Any = None
        self._shown_seq = -1
        self._shown_stop: tuple[str, int, str] | None = None
        self._t_plot = 0.0
        self._stopped = False
        self.view_updates = 0

    @property
    def scene_name(self) -> str:
        return f"{SCENE_PREFIX}{self.scenario.name}"

    # -- lifecycle -----------------------------------------------------------------------
    def start(self) -> MrcpViewerApp:
        """Builds the station, binds the server, builds the scene and the MRCP tab, starts
        the scenario and view threads; returns self."""
        from vasim.viewer.access import guarded_server
        from vasim.viewer.app import check_bind_address

        if self.server is not None:
            raise RuntimeError("MrcpViewerApp.start() was already called")
        try:
            check_bind_address(self.host, self.requested_port)
            geometry = self.live.prepare()
            self.server = guarded_server(self.host, self.requested_port, self.access)
            s = self.server
            s.gui.configure_theme(control_width="large")
            s.scene.set_up_direction("+z")
            third_person_lighting(s)
            position, look_at = station_camera(geometry)
            s.initial_camera.position = np.asarray(position, dtype=np.float64)
            s.initial_camera.look_at = np.asarray(look_at, dtype=np.float64)
            s.scene.add_grid("/mrcp/floor", width=2.0, height=2.0, cell_size=0.1,
                             position=(0.0, 0.0, float(min(r.base[2, 3] for r in
                                                           geometry.robots)) - 0.3))
            self.station = StationView(s, geometry)
            panel = self.panel = MrcpPanel(s, self.scenario.name, self.live.robots,
                                           self.live.ntt_threshold, self.live.t_max)
            start = task_pose(geometry.task_start, None)
            gizmo = self.gizmo = s.scene.add_transform_controls(
                "/mrcp/operator_gizmo", scale=0.25, position=tuple(start[:3]),
                wxyz=tuple(start[3:]), visible=False)
            panel.operator.on_update(self._guard(
                lambda _: self.set_operator_mode(str(panel.operator.value))))
            gizmo.on_update(self._guard(lambda _: self.set_operator_pose(
                np.asarray(gizmo.position, float), np.asarray(gizmo.wxyz, float))))
            self.live.start()
            self._thread = threading.Thread(target=self._view_loop, name="vasim-viewer-view",
                                            daemon=True)
            self._thread.start()
        except BaseException:
            self.stop()
            raise
        return self

    def stop(self, timeout: float = 5.0) -> None:
        """Stops the view and scenario threads (joined), the station and the server.
        Idempotent."""
        if self._stopped:
            return
        self._stopped = True
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=timeout)
        self.live.stop(timeout)
        if self.server is not None:
            self.server.stop()

    def __enter__(self) -> MrcpViewerApp:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def alive(self) -> bool:
        """True while the view and scenario threads run."""
        return self._thread is not None and self._thread.is_alive() and self.live.alive()

    @property
    def port(self) -> int:
        if self.server is None:
            raise RuntimeError("MrcpViewerApp.start() has not been called")
        return self.server.get_port()

    @property
    def url(self) -> str:
        """Address to open in a browser (with the token of an exposed viewer)."""
        return viewer_url(self.host, self.port, self.access.token)

    def scene_nodes(self) -> list[str]:
        """Names of the station's scene nodes (sorted; the suture's thread and subtask
        label once drawn)."""
        names = self.station.node_names() if self.station is not None else []
        if self.subtasks is not None:
            names = sorted([*names, *self.subtasks.node_names()])
        return names

    def stats(self) -> dict[str, float]:
        """Cycles run, runs, failures, view and panel updates, the run's real-time factor."""
        f = self.live.latest()
        return {"cycles": float(self.live.cycles), "runs": float(self.live.run),
                "failures": float(self.live.failures),
                "view_updates": float(self.view_updates),
                "panel_updates": float(self.panel.updates if self.panel else 0),
                "realtime_factor": f.realtime if f is not None else math.nan}

    # -- operator input ------------------------------------------------------------------
    @property
    def operator_mode(self) -> str:
        """``"scripted"`` or ``"browser"`` (see the module's decision)."""
        return str(self.live.operator.mode) if self.live.operator is not None else "scripted"

    def set_operator_mode(self, mode: str) -> None:
        """Switches the operator's target source (what the "Operator" control does).

        Switching to ``"browser"`` moves the gizmo to the task's current pose and makes it
        the target; ``"scripted"`` hides the gizmo and returns to the script.

        Raises:
            ConfigError: for an unknown mode or before ``start()``.
        """
        from vasim.mrcp.scenarios.runner import OPERATOR_MODES

        expect(mode in OPERATOR_MODES, mode, f"an operator mode of {OPERATOR_MODES}",
               field="operator")
        if self.live.operator is None or self.gizmo is None or self.panel is None:
            raise ConfigError("the MRCP viewer is not started", field="operator")
        if mode == self.live.operator.mode:
            return
        if mode == "browser":
            frame = self.live.latest()
            if frame is not None:
                pose = task_pose(frame.sample.task_position, frame.sample.task_rotation)
            else:
                p0, r0 = self.live.operator.script(0.0)
                pose = task_pose(p0, r0)
            self.gizmo.position = tuple(float(v) for v in pose[:3])
            self.gizmo.wxyz = tuple(float(v) for v in pose[3:])
            self.set_operator_pose(pose[:3], pose[3:])
        self.live.operator.set_mode(mode)
        self.gizmo.visible = mode == "browser"
        if self.panel.operator.value != mode:
            set_gui_value(self.panel.operator, mode)

    def set_operator_pose(self, position: FloatArray, wxyz: FloatArray) -> None:
        """The browser target (what dragging the gizmo does): position ``(3,)`` [m],
        quaternion ``wxyz``. Held until the next one; ignored by the scripted mode.

        Raises:
            ConfigError: for a non-finite pose or a zero quaternion.
        """
        what = "a non-zero quaternion wxyz (the gizmo's orientation)"
        q = check_array(wxyz, "operator", shape=(4,), what=what)
        expect(np.linalg.norm(q) >= 1e-9, q, what, field="operator")
        rot = matrix_from_quat(q)
        self.live.operator.set_pose(np.asarray(position, float), rot)


    # -- view thread ---------------------------------------------------------------------
    def _view_loop(self) -> None:
        render = self._guard(self.render)
        while not self._stop.is_set():
            tick = time.perf_counter()
            if render() is None:  # failed (logged and notified): do not spin on it
                self._stop.wait(0.5)
            self._stop.wait(max(0.0, self.view_period - (time.perf_counter() - tick)))

    def render(self, force_plots: bool = False) -> bool:
        """Poses the station from the newest frame and, at ``plot_hz`` (or when forced),
        refreshes the plots and the event log; returns False when nothing was new."""
        server, station, panel = self.server, self.station, self.panel
        if server is None or station is None or panel is None:
            return False
        frame = self.live.latest()
        new = frame is not None and frame.seq != self._shown_seq
        stopped = self.live.stopped
        if not new and not force_plots and stopped == self._shown_stop:
            return False
        now = time.perf_counter()
        with server.atomic():
            if new:
                assert frame is not None
                self._shown_seq = frame.seq
                station.update(frame.station)
                if getattr(frame.sample, "subtask", None) is not None:
                    if self.subtasks is None:
                        self.subtasks = SubtaskView(server)
                        # the needle is 36 mm across: grasp-point markers of 3 mm, not 12
                        station.points.point_size = 0.003
                    self.subtasks.update(frame.sample)
            if new or stopped != self._shown_stop:
                self._shown_stop = stopped
                panel.show_status(frame, self.speed, stopped)
            if force_plots or now - self._t_plot >= self.plot_period:
                self._t_plot = now
                panel.show_history(self.live.history())
        self.view_updates += new
        return new


__all__ = [
    "History",
    "LiveScenario",
    "MrcpFrame",
    "MrcpPace",
    "MrcpPanel",
    "MrcpViewerApp",
    "event_log_text",
    "plot_value",
    "resolve_scenario",
    "scenario_from_scene",
    "scenario_help",
    "station_camera",
    "status_text",
]
