"""The experimenter's panel: mode, subject, protocol, progress, trial control, the fixture
schema with live f5PL editing, live metrics, the end-of-trial summary and learning curve;
the live metrics include the running trial's fixture gain (its current value and whether
it is constant, scheduled or adaptive).

The panel only reads and queues: every control's callback turns into a controller
``Command`` passed to ``submit`` (the app queues it for the controller thread), and
:meth:`ExperimenterPanel.show` redraws the panel from the controller's immutable
``PanelState`` when its version changes. Writing a control's value from the server runs
that control's callbacks in the writing thread; a thread-local flag keeps those from
queueing commands (they would echo the state back).

Subject-entered text (the subject code) and every other string reaches markdown through
:func:`md_escape`: viser does not sanitise markdown or HTML.
"""

from __future__ import annotations

import html
import math
import re
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import viser
from numpy.typing import NDArray

from vasim.fixtures.logistic import Logistic5
from vasim.records.path_deviation import path_distances
from vasim.trials.vf import TrialFrame, make_task
from vasim.viewer.condition import shipped_name
from vasim.viewer.controller import INPUTS, MODES, Command, PanelState, TrialInfo
from vasim.viewer.f5pl_view import (
    F5PL_LABELS,
    F5PL_MEANING,
    FixtureAxes,
    editor_data,
    fixture_axes,
    operating_distance,
    parameter_lines,
)
from vasim.viewer.history import AGAIN_FIELD
from vasim.viewer.state import demo_config
from vasim.viewer.trainee import OUTCOME_TEXT, frame_outcome, score_card_markdown
from vasim.viewer.views import set_gui_value

FloatArray = NDArray[np.float64]

NO_PROTOCOL = "(choose)"
"""The protocol menu's entry before a protocol is picked."""

F5PL_FIELDS: tuple[str, ...] = ("a", "b", "c", "d", "g")

_MD_SPECIAL = re.compile(r"([\\`*_{}\[\]()#+\-.!|~>])")


def md_escape(text: object) -> str:
    """``text`` safe inside viser markdown: HTML-escaped, markdown punctuation backslashed.

    **Decision**: an apostrophe is left as it is (viser's markdown shows an entity as
    typed: every quoted name in a status line read ``&#x27;D9&#x27;``); in text, outside
    any tag (``<`` is escaped), it cannot start markup. ``"`` stays escaped.

    >>> md_escape("<img src=x onerror=alert(1)>*S01*")
    '&lt;img src=x onerror=alert\\\\(1\\\\)&gt;\\\\*S01\\\\*'
    >>> md_escape("subject 'D9'")
    "subject 'D9'"
    """
    return _MD_SPECIAL.sub(r"\\\1", html.escape(str(text), quote=False).replace('"', "&quot;"))


def f5pl_curve(p: Logistic5, n: int = 80) -> tuple[FloatArray, FloatArray]:
    """The modulation curve to plot: x in [0, 3c] (the transition is centred on c), y = f5PL.

    >>> x, y = f5pl_curve(Logistic5(a=0.0, b=4.0, c=0.02, d=1.0))
    >>> round(float(x[-1]), 3), float(y[0]), round(float(y[-1]), 2)
    (0.06, 0.0, 0.99)
    """
    x = np.linspace(0.0, 3.0 * p.c, n)
    return x, np.asarray(p(x), dtype=np.float64)


CURVE_SERIES = (
    viser.uplot.Series(label="distance [mm]"),
    viser.uplot.Series(label="edited", stroke="#d9480f", width=2),
    viser.uplot.Series(label="shipped", stroke="#495057", width=1.5, dash=(6.0, 4.0)),
    viser.uplot.Series(label="now", stroke="#1971c2", width=0,
                       points=viser.uplot.Series_Points(show=True, size=10, fill="#1971c2")),
)
"""The editor's curves: the edited f5PL, the shipped schema's (reference) and the current
operating point, all in the fixture's output unit over the distance in mm."""


def _curve_axes(x_label: str, y_label: str) -> tuple[viser.uplot.Axis, ...]:
    return (viser.uplot.Axis(label=x_label), viser.uplot.Axis(label=y_label, size=60))


def plot_data(data: Sequence[FloatArray]) -> tuple[tuple[FloatArray, ...], dict[str, Any]]:
    """``data`` for a viser uPlot chart without NaN, and the chart's scales.

    **Decision**: viser's uPlot draws nothing at all -- no curve, no y ticks -- when any
    series holds a NaN (seen in headless Chromium: the f5PL editor's curve never showed,
    its "now" series is NaN but at one distance). So the y scale is fixed to the finite
    values' range (5 % margin; 0-1 without any) and each NaN is put far above it, where
    uPlot clips it away: a missing value stays invisible. The x values are kept as given.

    >>> d, scales = plot_data((np.array([0.0, 1.0]), np.array([1.0, math.nan])))
    >>> scales["y"]["range"], bool(d[1][1] > 1e3)
    ((0.95, 1.05), True)
    """
    ys = [np.asarray(v, dtype=np.float64) for v in data[1:]]
    finite = np.concatenate([v[np.isfinite(v)] for v in ys]) if ys else np.zeros(0)
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    pad = 0.05 * (hi - lo) if hi > lo else max(0.05 * abs(hi), 0.05)
    lo, hi = lo - pad, hi + pad
    away = hi + 1e4 * (hi - lo)
    out = (np.asarray(data[0], dtype=np.float64),
           *(np.where(np.isfinite(v), v, away) for v in ys))
    return out, {"x": {"time": False}, "y": {"auto": False, "range": (lo, hi)}}


def _set_plot(handle: Any, data: Sequence[FloatArray]) -> None:
    """Sets a uPlot chart's data through :func:`plot_data` (its y scale with it)."""
    values, scales = plot_data(data)
    if handle.scales != scales:
        handle.scales = scales
    handle.data = values


DEFAULT_TASK_SCALE = 0.03
"""D [m] of the editor's distance axis before the first trial (``Task.scale``'s default)."""

EDITOR_INTERVAL_S = 0.5
"""The f5PL editor's operating point is redrawn at most this often [s]."""


def fixture_goal(info: TrialInfo, frame: TrialFrame) -> NDArray[np.float64]:
    """The point a fixture measures its error to (as ``trials.vf`` does): the nearest point
    of the current segment of the path (trajectory), or the current target (point)."""
    tcp = np.asarray(frame.tcp, dtype=np.float64).reshape(3)
    pts = np.asarray(info.points, dtype=np.float64).reshape(-1, 3)
    i = min(int(frame.goal_index), len(pts) - 1)
    if info.config.task != "trajectory":
        return pts[i]
    a = np.asarray(info.start, dtype=np.float64).reshape(3) if i == 0 else pts[i - 1]
    ab = pts[i] - a
    den = float(ab @ ab)
    u = 0.0 if den <= 0 else min(1.0, max(0.0, float((tcp - a) @ ab) / den))
    return a + u * ab


def progress_text(p: PanelState) -> str:
    """The progress line: ``trial k of N`` and the current condition (markdown, escaped)."""
    who = f"subject **{md_escape(p.subject)}**" if p.subject else "no subject yet"
    if p.mode != "protocol":
        return f"**{md_escape(p.mode)}** mode, {who}"
    proto = md_escape(p.protocol) if p.protocol else "no protocol yet"
    if p.total is None:
        return f"protocol {proto}, {who}"
    pos = "—" if p.position is None else str(p.position)
    cond = f", condition **{md_escape(p.condition)}**" if p.condition else ""
    return (f"protocol {proto}, {who}: trial **{pos} of {p.total}**{cond} "
            f"({p.completed or 0} completed)")


SUMMARY_UNITS: dict[str, str] = {
    "duration": "s", "sim_time": "s", "completion_time": "s", "mean_latency": "s",
    "total_latency": "s", "max_latency": "s",
    "total_error_l1": "m summed over samples (not a length)",
    "mean_error_l1": "m summed over samples (not a length)",
}
"""Units of the end-of-trial summary's values (the rest are counts, flags or names).
**Decision**: the thesis's e_i is a sum of per-sample Manhattan errors; its unit says so,
so that it is never read as a length."""


def summary_text(summary: dict[str, Any] | None) -> str:
    """The end-of-trial summary as a markdown table with names and units (escaped), or a
    line saying that no trial has finished yet."""
    if not summary:
        return "*no finished trial yet*"
    rows = []
    for k, v in summary.items():
        if isinstance(v, float):
            v = "—" if not math.isfinite(v) else f"{v:.4g}"
        elif v is None:
            v = "—"
        unit = SUMMARY_UNITS.get(k, "")
        rows.append(f"| {md_escape(k)} | {md_escape(v)} | {md_escape(unit)} |")
    return "| metric | value | unit |\n|---|---|---|\n" + "\n".join(rows)


def gain_text(info: TrialInfo, frame: TrialFrame) -> str:
    """The experimenter's gain cell: the current gain and how it is set, e.g. ``"0.63
    (adaptive 25-100 %)"``; ``"— (no fixtures)"`` for a fixture-free trial.

    **Decision**: only the experimenter page shows it; the trainee page does not (what
    the trainee is told about the assistance is the protocol's business, not the
    viewer's).
    """
    if not info.fixtures:
        return "— (no fixtures)"
    return f"{float(frame.gain):.2f} ({md_escape(info.gain_plan)})"


def metrics_text(info: TrialInfo, frame: TrialFrame, latencies: Sequence[float],
                 outcome: str | None = None) -> str:
    """Live metrics (markdown): the trial (its store id, how it ended), time in trial and
    its limit, current distance of the tool tip to the planned path and to the goal [mm],
    points reached, latency per reached point [s].

    The distance to the path is ``vasim.records.path_deviation.path_distances`` (the segment
    of the current goal and the one before it); "—" once every point is reached. No sum of
    samples (e_i) is shown here: it is not a length.
    """
    tcp = np.asarray(frame.tcp, dtype=np.float64).reshape(3)
    goal_mm = float(np.linalg.norm(tcp - np.asarray(frame.goal))) * 1e3
    n_pts = int(np.asarray(info.points).reshape(-1, 3).shape[0])
    if frame.goal_index < n_pts:
        path_mm = float(path_distances(tcp[None, :], [int(frame.goal_index)], info.points,
                                       info.start)[0]) * 1e3
        path_txt = f"{path_mm:.1f} mm"
    else:
        path_txt = "—"
    lat = ", ".join(f"{x:.2f}" for x in latencies[-8:]) or "—"
    more = f" (last 8 of {len(latencies)})" if len(latencies) > 8 else ""
    outcome = outcome or frame_outcome(frame.done, frame.goal_index, frame.n_points)
    state = ("running" if outcome is None and not frame.done
             else f"ended: {OUTCOME_TEXT.get(outcome or '', outcome or 'ended')}")
    limit = float(info.config.max_time)
    return (f"| | |\n|---|---|\n"
            f"| Trial | {md_escape(info.title)} ({md_escape(info.mode)}, {md_escape(state)}) |\n"
            f"| Time | {frame.t:.2f} s of {limit:.0f} s |\n"
            f"| Fixture gain | {gain_text(info, frame)} |\n"
            f"| Distance to path | {path_txt} |\n"
            f"| Distance to goal | {goal_mm:.1f} mm |\n"
            f"| Points | {min(frame.goal_index, frame.n_points)} / {frame.n_points} |\n"
            f"| Latency per point [s] | {lat}{more} |")


class ExperimenterPanel:
    """The experimenter's controls (module docstring); build inside a tab or folder.

    Args:
        server: the viser server.
        submit: queues a controller command.
        guard: wraps a callback so that an exception is logged and notified.
        panel: the first state to show.
        schemas: schema menu entries. protocols: protocol menu entries.
        metrics_hz: maximum rewrites per second of the live metrics.
    """

    def __init__(self, server: viser.ViserServer, submit: Callable[[Command], None],
                 guard: Callable[[Callable[..., Any]], Callable[..., Any]],
                 panel: PanelState, schemas: Sequence[str], protocols: Sequence[str], *,
                 metrics_hz: float = 5.0):
        gui = server.gui
        self.submit = submit
        self._local = threading.local()
        self.min_interval = 1.0 / metrics_hz
        self._last_metrics = -math.inf
        self.shown_version = -1
        self.f5pl: dict[str, Logistic5] = {}
        self.metrics_md = ""
        self.latencies: list[float] = []
        self._lat_trial: int | None = None
        self._lat_goal = 0
        self._shown_subject: str | None = None
        self._shown_again: str | None = None
        self._schemas: dict[str, Any] = {}      # schema name -> loaded Schema (cache)
        self._mode = panel.mode
        self._free_schema = panel.schema
        self._task = panel.task
        self._trial_schema: str | None = None   # the running trial's schema (protocol)
        self._trial_key: int | None = None
        self._task_scale = DEFAULT_TASK_SCALE
        self._operating: float | None = None
        self._last_editor = -math.inf

        self._guard = guard
        self._add_controls(gui, panel, protocols)
        self._add_folders(gui, panel, schemas)
        self._wire(submit, guard)
        self.show(panel)

    def _on(self, handle: Any, fn: Callable[[Any], None]) -> None:
        """Calls ``fn`` on the user's updates of ``handle`` (not on ``show``'s own)."""
        def cb(event: Any) -> None:
            if not getattr(self._local, "syncing", False):
                fn(event)
        handle.on_update(self._guard(cb))

    def _add_controls(self, gui: Any, panel: PanelState, protocols: Sequence[str]) -> None:
        """The status lines and the session's controls (mode, input, subject, label,
        protocol, start/stop)."""
        self.status = gui.add_markdown("")
        self.progress = gui.add_markdown(progress_text(panel))
        self.progress_bar = gui.add_progress_bar(0.0, visible=False)
        self.mode = gui.add_dropdown("Mode", MODES, initial_value=panel.mode,
                                     hint="demo: the scripted operator plays by itself; "
                                          "free: free training; protocol: a study session")
        self.input = gui.add_dropdown("Input", INPUTS, initial_value=panel.input,
                                      hint="scripted operator; browser: drag the tool tip's gizmo; "
                                           "laparoscopic: the trainee's instrument")
        self.subject = gui.add_text("Subject code", panel.subject or "",
                                    hint="a pseudonymous code (letters, digits, _ or -)")
        self.set_subject = gui.add_button("Set subject")
        self.label = gui.add_text("Practice label", panel.label or "",
                                  hint="free practice without a subject, e.g. 'free: warm-up' "
                                       "(a space or ':' in it); empty clears it")
        self.set_label = gui.add_button("Set label")
        self.protocol = gui.add_dropdown("Protocol", (NO_PROTOCOL, *protocols),
                                         initial_value=panel.protocol or NO_PROTOCOL)
        self.again = gui.add_text(AGAIN_FIELD, panel.again or "",
                                  hint="only to run a protocol the subject completed again: "
                                       "why (one line, stored with the new session)")
        self.set_again = gui.add_button("Set reason")
        self.start = gui.add_button("Start trial", color="green")
        self.stop = gui.add_button("Stop trial", color="red")
        self.advance = gui.add_button("Next trial",
                                      hint="start the next scheduled trial (protocol)")
        self.auto_advance = gui.add_checkbox("Auto-advance", panel.auto_advance,
                                             hint="start the next scheduled trial by itself")

    def _add_folders(self, gui: Any, panel: PanelState, schemas: Sequence[str]) -> None:
        """The free-training schema and f5PL editor, the live metrics and the last trial
        with its learning curve."""
        with gui.add_folder("Fixture schema (free training)"):
            self.schema = gui.add_dropdown("Schema", tuple(schemas), initial_value=panel.schema)
            self.task = gui.add_dropdown("Task", ("trajectory", "point"),
                                         initial_value=panel.task)
            self.restart = gui.add_button("Restart demo trial")
            self.fixture = gui.add_dropdown("f5PL of", ("—",), initial_value="—",
                                            hint="the fixture whose modulation curve "
                                                 "(f5PL) is shown and edited")
            self.numbers = {k: gui.add_number(F5PL_LABELS[k], 1.0, step=1e-4,
                                              hint=F5PL_MEANING[k]) for k in F5PL_FIELDS}
            self.apply = gui.add_button("Apply f5PL", hint="restarts the trial with the edit")
            x, y = np.array([0.0, 1.0]), np.array([0.0, 0.0])
            nan = np.full(2, math.nan)
            data, scales = plot_data((x, y, nan, nan))
            self.curve = gui.add_uplot(
                data, CURVE_SERIES, title="modulation curve (f5PL)",
                scales=scales, axes=_curve_axes("distance [mm]", "output"),
                aspect=1.4)
            self.f5pl_text = gui.add_markdown("")
        with gui.add_folder("Live metrics"):
            self.metrics = gui.add_markdown("*no trial yet*")
        with gui.add_folder("Last trial and learning curve"):
            self.card = gui.add_markdown("")
            self.summary = gui.add_markdown(summary_text(None))
            data, scales = plot_data((np.array([1.0]), np.array([math.nan]),
                                      np.array([math.nan])))
            self.learning = gui.add_uplot(
                data,
                (viser.uplot.Series(label="trial"),
                 viser.uplot.Series(label="completion time [s]", stroke="#1971c2", width=2),
                 viser.uplot.Series(label="mean latency [s]", stroke="#2f9e44", width=2)),
                title="learning curve", scales=scales, aspect=1.6)

    def _wire(self, submit: Callable[[Command], None],
              guard: Callable[[Callable[..., Any]], Callable[..., Any]]) -> None:
        """Each control's callback: a command to the controller, or a local f5PL view."""
        on = self._on
        on(self.mode, lambda e: submit(Command("mode", e.target.value)))
        on(self.input, lambda e: submit(Command("input", e.target.value)))
        self.set_subject.on_click(guard(
            lambda e: submit(Command("subject", self.subject.value.strip()))))
        self.set_label.on_click(guard(
            lambda e: submit(Command("label", self.label.value.strip()))))

        def submit_again(e: Any) -> None:
            # The page shows what was submitted: once the controller takes the reason and a
            # session uses it up (again -> None), show() clears the field. Without this the
            # view could miss the short-lived state and keep the used reason on the page.
            self._shown_again = self.again.value
            submit(Command("again", self.again.value))

        self.set_again.on_click(guard(submit_again))

        def pick_protocol(e: Any) -> None:
            if e.target.value != NO_PROTOCOL:
                submit(Command("protocol", e.target.value))

        on(self.protocol, pick_protocol)
        self.start.on_click(guard(lambda e: submit(Command("start"))))
        self.stop.on_click(guard(lambda e: submit(Command("stop"))))
        self.advance.on_click(guard(lambda e: submit(Command("start"))))
        on(self.auto_advance, lambda e: submit(Command("auto_advance", bool(e.target.value))))
        on(self.schema, lambda e: submit(Command("schema", e.target.value)))
        on(self.task, lambda e: submit(Command("task", e.target.value)))
        self.restart.on_click(guard(lambda e: submit(Command("restart"))))
        on(self.fixture, lambda e: self._show_f5pl(e.target.value))
        for h in self.numbers.values():
            on(h, lambda e: self._preview())
        self.apply.on_click(guard(lambda e: self._apply()))

    # -- f5PL editor --------------------------------------------------------------------
    def edited_params(self) -> Logistic5:
        """The f5PL parameters in the number fields (ConfigError if invalid)."""
        return Logistic5(**{k: float(self.numbers[k].value) for k in F5PL_FIELDS})

    def _apply(self) -> None:
        inst = self.fixture.value
        if inst not in self.f5pl:
            return
        self.submit(Command("f5pl", (inst, self.edited_params())))

    def _preview(self) -> None:
        try:
            p = self.edited_params()
        except ValueError:
            return  # an invalid value is refused on Apply, with its message
        self._draw(self.fixture.value, p)

    def _schema(self, name: str) -> Any:
        if name not in self._schemas:
            from vasim.fixtures.schema import load_schema

            self._schemas[name] = load_schema(name)
        return self._schemas[name]

    def shown_schema(self) -> str:
        """The (shipped) schema whose f5PL the editor shows: the running trial's in
        protocol mode (its condition, greyed), else the free-training choice."""
        if self._mode == "protocol" and self._trial_schema is not None:
            return shipped_name(self._trial_schema)
        return shipped_name(self._free_schema)

    def fixture_view(self, instance: str) -> tuple[FixtureAxes, Logistic5 | None] | None:
        """The axes of fixture ``instance`` of the shown schema and its shipped f5PL (the
        reference); None when the schema has no such fixture."""
        try:
            schema = self._schema(self.shown_schema())
        except Exception:  # a schema that cannot be read: no axes (the curve stays)
            return None
        for fx in schema.fixtures:
            if fx.name == instance:
                ref = getattr(fx.params, "f5pl", None)
                axes = fixture_axes(fx.kind, fx.params, schema.task if schema.task != "any"
                                    else self._task, self._task_scale)
                return axes, ref if isinstance(ref, Logistic5) else None
        return None

    def _draw(self, instance: str, p: Logistic5) -> None:
        view = self.fixture_view(instance)
        if view is None:
            x, y = f5pl_curve(p)
            nan = np.full(x.shape, math.nan)
            _set_plot(self.curve, (x, y, nan, nan))
            return
        axes, ref = view
        _set_plot(self.curve, editor_data(p, ref, axes, self._operating))
        labels = _curve_axes(axes.x_label, axes.y_label)
        if self.curve.axes != labels:
            self.curve.axes = labels
        text = parameter_lines(p, ref, axes, self._operating)
        if self.f5pl_text.content != text:
            self.f5pl_text.content = text

    def _show_f5pl(self, instance: str) -> None:
        p = self.f5pl.get(instance)
        if p is None:
            return
        self._local.syncing = True
        try:
            for k in F5PL_FIELDS:
                set_gui_value(self.numbers[k], float(getattr(p, k)))
        finally:
            self._local.syncing = False
        self._draw(instance, p)

    # -- redraw ---------------------------------------------------------------------------
    def show(self, p: PanelState) -> None:
        """Redraws the panel from ``p`` (skipped when its version was shown already)."""
        if p.version == self.shown_version:
            return
        self.shown_version = p.version
        self._mode, self._free_schema, self._task = p.mode, p.schema, p.task
        self._local.syncing = True
        try:
            self.status.content = md_escape(p.status) if p.status else ""
            self.progress.content = progress_text(p)
            if p.total:
                set_gui_value(self.progress_bar, 100.0 * (p.completed or 0) / p.total)
                self.progress_bar.visible = True
            else:
                self.progress_bar.visible = False
            choices: tuple[tuple[Any, str | bool], ...] = (
                (self.mode, p.mode), (self.input, p.input), (self.schema, p.schema),
                (self.task, p.task), (self.protocol, p.protocol or NO_PROTOCOL),
                (self.auto_advance, p.auto_advance))
            for handle, value in choices:
                if handle.value != value:
                    if isinstance(handle, viser.GuiDropdownHandle) and \
                            value not in handle.options:
                        handle.options = (*handle.options, value)
                    set_gui_value(handle, value)
            if p.subject != self._shown_subject:  # only on a change: never clobber typing
                self._shown_subject = p.subject
                if self.subject.value != (p.subject or ""):
                    set_gui_value(self.subject, p.subject or "")
            if p.again != self._shown_again:      # e.g. cleared once a session stored it
                self._shown_again = p.again
                if self.again.value != (p.again or ""):
                    set_gui_value(self.again, p.again or "")
            self.again.visible = self.set_again.visible = p.mode == "protocol"
            free = p.mode != "protocol"
            for h in (self.schema, self.task, self.fixture, self.apply,
                      *self.numbers.values()):
                h.disabled = not free
            self.restart.visible = p.mode == "demo"
            self.advance.visible = self.auto_advance.visible = p.mode == "protocol"
            self.start.disabled = p.running and p.mode != "demo"
            self.stop.disabled = not p.running
            self.f5pl = dict(p.f5pl)
            names = tuple(self.f5pl) or ("—",)
            keep = self.fixture.value if self.fixture.value in names else names[0]
            if tuple(self.fixture.options) != names:
                self.fixture.options = names
            if self.fixture.value != keep:
                set_gui_value(self.fixture, keep)
            self.summary.content = summary_text(p.summary)
            self.card.content = score_card_markdown(p.scorecard)
            self.label.visible = self.set_label.visible = p.mode == "free"
            if p.label is not None and self.label.value != p.label:
                set_gui_value(self.label, p.label)
            if p.curve:
                c = np.array(p.curve, dtype=np.float64)
                _set_plot(self.learning, (c[:, 0], c[:, 1], c[:, 2]))
        finally:
            self._local.syncing = False
        self._show_f5pl(self.fixture.value)

    def show_live(self, info: TrialInfo, frame: TrialFrame, now: float | None = None,
                  *, force: bool = False, outcome: str | None = None) -> None:
        """Collects the per-point latencies and rewrites the live metrics (rate-limited);
        keeps the f5PL editor's operating point (and, for a new trial, its schema and
        scale) current."""
        self._follow_trial(info, frame)
        if self._lat_trial != info.number:
            self._lat_trial, self._lat_goal, self.latencies = info.number, 0, []
        if frame.goal_index > self._lat_goal:
            if frame.last_latency is not None:
                self.latencies.append(float(frame.last_latency))
            self._lat_goal = frame.goal_index
        now = time.perf_counter() if now is None else now
        if not force and now - self._last_metrics < self.min_interval:
            return
        self._last_metrics = now
        text = metrics_text(info, frame, self.latencies, outcome)
        if text != self.metrics_md:
            self.metrics_md = text
            self.metrics.content = text
        if now - self._last_editor >= EDITOR_INTERVAL_S:
            self._last_editor = now
            current = self.f5pl.get(self.fixture.value)
            if current is not None:
                try:   # the fields (an edit being typed) if valid, else the current curve
                    current = self.edited_params()
                except ValueError:
                    pass
                self._draw(self.fixture.value, current)

    def _follow_trial(self, info: TrialInfo, frame: TrialFrame) -> None:
        if self._trial_key != info.number:
            self._trial_key = info.number
            self._trial_schema = info.schema
            try:
                self._task_scale = float(make_task(demo_config(info)).scale)
            except Exception:   # the editor keeps the last scale; the trial is unaffected
                self._task_scale = DEFAULT_TASK_SCALE
        view = self.fixture_view(self.fixture.value)
        if frame.done or view is None:
            self._operating = None
            return
        goal = fixture_goal(info, frame)
        self._operating = operating_distance(frame.tcp, goal, view[0].per_axis)


__all__ = [
    "F5PL_FIELDS",
    "NO_PROTOCOL",
    "ExperimenterPanel",
    "f5pl_curve",
    "fixture_goal",
    "gain_text",
    "md_escape",
    "metrics_text",
    "progress_text",
    "summary_text",
]
