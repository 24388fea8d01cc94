"""The viewer's server-side training state: modes, sessions, the live trial, the store.

One :class:`TrainingController` per server; **only the controller thread calls it** (the
app's loop: ``handle`` for each queued :class:`Command`, then ``poll``), so the SQLite store
(which belongs to the thread that opened it) and the running trial have one owner. GUI
callbacks, from any browser tab, only queue commands; what the pages show is rebuilt from
the immutable :class:`TrialInfo` / :class:`PanelState` the controller publishes. A reload or
a second tab is just another reader: it cannot start a second trial or write one twice.

Modes (**decisions**):

* ``demo`` — the scripted operator plays trials by itself, looping over the trajectory
  variants (what ``vasim serve`` shows at start). Demo trials are not stored: they are an
  attract loop, not a subject's data.
* ``free`` — free training: the experimenter picks the schema (and edits its f5PL
  parameters), the trainee (or the scripted operator) runs one trial per "Start". Stored
  like a headless ``vasim trial`` (no session, protocol None).
* ``protocol`` — a study session: subject code + protocol; "Start" resumes the subject's
  running session of that protocol or creates one (``vasim.study.session``), then runs the
  first pending scheduled trial with the session's ``trial_config`` and stores it linked to
  its schedule index (``TrialStore.begin_trial`` refuses a second running attempt, so a
  double start from two tabs cannot duplicate a trial). The session completes when no
  scheduled trial is pending. A pending trial that begins a later sitting (a block with
  ``delay_days``) is refused before its delay has passed since the previous trial ended,
  on Start (before any countdown) and on auto-advance alike: the status line and the
  notification name the sitting and when it is due (``history.refuse_early_sitting``, the
  rule of ``vasim study resume``; no simulated delay in the browser).
  A subject who *completed* the protocol gets no second session silently (issue #30
  item 3): Start is refused, on the status line and in a notification, until the
  experimenter gives the reason ("Again, because", the ``again`` command), which is stored
  with the new session as ``vasim study run --again`` stores it; a reason while the
  subject's session is open is refused (Start resumes that session). The rule is
  ``history.session_rule``. A session is marked completed as soon as its last scheduled
  trial is stored. A scheduled trial of a teleoperation mode (``stdt``, ``mrcp``,
  ``mrcp_cam``: ``mrcp_suture_dynamic``, ``mrcp_vs_stdt``) runs the station's needle task
  with the session's input as the master (``teleop_live``, issue #28) and is stored with
  ``teleop_meta`` as ``vasim study simulate`` stores it. The experimenter records the
  protocol's questionnaires on the page (the ``answers`` command, ``questionnaire_form``).

Storage is ``run_trial``'s: the trial row is begun as 'running' before the first step, and
on completion the samples, per-point metrics, summary, events and trial metrics are
written in one transaction; a stopped trial (Stop, a mode/schema change, the server
shutting down) is marked 'interrupted' with what it recorded and the reason, and a
scheduled trial stays pending.

The scene of every trial is the server's ``--scene`` (also for protocol trials, whose
``trial_config`` leaves the scene at its default); it is stored in the trial's config.
Browser- or device-driven trials store ``operator = "browser"`` / the device name in the
trial row and config (``TrialConfig.operator`` only admits ``"scripted"`` in this release:
the config is run with it and the stored record is corrected).
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from vasim.core.config import check_choice, check_not_dir
from vasim.core.errors import ConfigError, StoreError, VasimError
from vasim.fixtures.schema import Schema, load_schema
from vasim.haptics.device import Device
from vasim.haptics.devices.browser import BrowserDevice
from vasim.haptics.devices.laparoscopic import LaparoscopicDevice
from vasim.haptics.laparoscopic import InputMapping
from vasim.tasks import TRAJECTORY_VARIANTS
from vasim.trials.configs import AnyTrialConfig, TeleopTrialConfig
from vasim.trials.lifecycle import StoredTrial, begin_stored_trial
from vasim.trials.teleop_run import teleop_meta
from vasim.trials.vf import TrialConfig, TrialFrame, make_profile, make_task, tool_trocar
from vasim.trials.vf_run import trial_meta
from vasim.viewer.app_options import TrialOptions
from vasim.viewer.condition import viewer_condition
from vasim.viewer.condition_commands import DEFAULT_SCHEMA_FOR_TASK, ConditionCommands
from vasim.viewer.history import (
    CURVE_METRICS,
    completed_note,
    learning_curve,
    open_session,
    record_browser_sitting,
    refuse_early_sitting,
    session_progress,
    trial_score_card,
)
from vasim.viewer.instrument_input import instrument_device
from vasim.viewer.live import LiveTrial, make_live_trial
from vasim.viewer.session_commands import INPUTS, SessionCommands
from vasim.viewer.state import (
    Command,
    PanelState,
    TrialInfo,
    demo_config,
    f5pl_fields,
    gain_plan,
    plain,
    plain_dict,
    schema_choices,
    with_f5pl,
)
from vasim.viewer.teleop_live import (
    is_teleop,
    make_live_teleop_trial,
    person_config,
    teleop_task,
)
from vasim.viewer.trainee import ScoreCard, frame_outcome

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
Mode = Literal["demo", "free", "protocol"]
InputKind = Literal["scripted", "browser", "laparoscopic"]
MODES: tuple[str, ...] = ("demo", "free", "protocol")



NO_START_CUE = TrialOptions(countdown_s=0.0)
"""A controller's trials by default: the viewer's, without the start cue (a controller
driven by a program, not a person at a page)."""


@dataclass(frozen=True)
class TrainingSettings:
    """What a ``TrainingController`` runs (``ViewerApp`` builds it from its options).

    Attributes:
        scene: the abdomen scene of every trial (``"none"``: a static task).
        db: the study store's path (opened on first use), or None (nothing is stored;
            free training and protocols are then refused).
        trials: the first demo trial, the time limit of demo and free trials, the pause
            after a finished trial (demo, auto-advance), the start cue of a trial a person
            drives (free and protocol modes, input not scripted: Start counts down this
            long before the trial begins) and the endoscope's optics stored with every
            trial (:class:`~vasim.viewer.app_options.TrialOptions`; default
            :data:`NO_START_CUE`).
        speed: simulated seconds per wall second (1 = real time).
        trial_factory: builds the live trial (default ``make_live_trial``).
    """

    scene: str = "default"
    db: str | Path | None = None
    trials: TrialOptions = NO_START_CUE
    speed: float = 1.0
    trial_factory: Callable[..., LiveTrial] | None = None


class TrainingController(ConditionCommands, SessionCommands):
    """Server-side state of the viewer (module docstring). Not thread-safe by design: one
    controller thread calls ``handle``/``poll``/``close``; other threads read the published
    ``info``, ``frame()`` and ``panel``.

    Args:
        settings: the scene, store, first demo trial, time limits and pace
            (``TrainingSettings``).

    Raises:
        ConfigError: for a bad first trial, or a ``db`` that is a directory (before
            anything runs).
    """

    def __init__(self, settings: TrainingSettings = TrainingSettings()):
        st, t = settings, settings.trials
        scene, db, schema, task, skill = st.scene, st.db, t.schema, t.task, t.skill
        seed, variant, max_time, pause_s = t.seed, t.variant, t.max_time, t.pause_s
        speed, trial_factory, countdown_s = st.speed, st.trial_factory, t.countdown_s
        optics_deg = t.optics
        self.scene = scene
        self.countdown_s = float(countdown_s)
        self.optics_deg = float(optics_deg)
        self.countdown_until: float | None = None
        """Monotonic time the pending trial starts at (the start cue), or None."""
        self._pending: Callable[[], None] | None = None
        self.outcome: tuple[int, str | None] = (0, None)
        """(trial number, how it ended) of the current trial; None while it runs."""
        self.db = None if db is None else Path(db)
        # a directory was only refused when Free mode first opened the store;
        # refuse it at start-up (vasim serve prints this as one line and exits 2).
        if self.db is not None:
            check_not_dir(self.db, "db", what="a database file (--db is a directory)",
                          error=ConfigError)
        self.pause_s = float(pause_s)
        self.speed = float(speed)
        self.max_time = float(max_time)
        self._factory = trial_factory or make_live_trial
        self.teleop_factory: Callable[..., LiveTrial] = make_live_teleop_trial
        """Builds the live trial of a teleoperation mode (``teleop_live``)."""
        self._store: Any = None
        self._number = 0
        self._trial: LiveTrial | None = None
        self._schema_obj: Schema | None = None  # an edited schema (f5PL editor), if any
        self._done_since: float | None = None
        self._stored_done = False
        self._stored = StoredTrial(None, None)  # the running trial's row (lifecycle)
        self._closed = True
        self.instrument: LaparoscopicDevice | None = None
        """The trainee's instrument of a laparoscopic-input trial (replaced per trial)."""
        self.input_mapping = InputMapping()
        """Fulcrum effect and sensitivity of the trainee's instrument (experimenter's page)."""
        self.screen: tuple[FloatArray, FloatArray] | None = None
        """The trainee view's (right, up) axes the instrument's screen motion follows."""
        self.view_axes: Callable[[FloatArray, FloatArray], tuple[FloatArray, FloatArray]] | \
            None = None
        """The trainee view's (right, up) axes for a task's points and start (the app's
        endoscope aims per task); None: ``screen`` for every trial."""
        self.viewer_timing: Callable[[], dict[str, float]] | None = None
        """The viewer's figures stored in a trial's ``timing_json["viewer"]`` (page update
        rates beside the loop's: issue #26.2); None: none."""
        self.browser: BrowserDevice | None = None
        """The device the page's drag input feeds (replaced per browser-driven trial)."""
        self._base = TrialConfig(task=task, variant=variant, schema=schema, seed=seed,
                                 skill=skill, max_time=max_time, scene=scene)
        self.panel = PanelState(schema=schema, task=task,
                                f5pl=f5pl_fields(load_schema(schema)))
        self.info: TrialInfo = self._launch(self._base, mode="demo")
        self._publish(status="demo: the scripted operator plays trials by itself")

    # -- reading (any thread) -------------------------------------------------------------
    def frame(self) -> TrialFrame:
        """The running trial's latest frame."""
        return self._pair[1].frame()

    def current(self) -> tuple[TrialInfo, TrialFrame]:
        """The current trial's info and latest frame, consistent with each other (one
        reference is swapped when a trial starts: safe to call from any thread)."""
        info, trial = self._pair
        return info, trial.frame()

    @property
    def trial(self) -> LiveTrial | None:
        return self._trial

    def active(self) -> bool:
        """True while a trial runs (started, not stopped, not finished)."""
        return self._trial is not None and not self._closed and not self._trial.done

    # -- publishing ---------------------------------------------------------------------
    def _publish(self, **changes: Any) -> None:
        p = self.panel
        self.panel = replace(p, version=p.version + 1, **changes)

    # -- the store ---------------------------------------------------------------------
    def store(self) -> Any:
        """The study store (opened on first use, on the controller thread).

        Raises:
            ConfigError: the server runs without ``--db``.
        """
        if self._store is None:
            if self.db is None:
                raise ConfigError("this server runs without a study database (start it with "
                                  "--db FILE to store trials)", field="db")
            from vasim.study.store import TrialStore

            self._store = TrialStore(self.db)
        return self._store

    # -- trials ------------------------------------------------------------------------
    def _launch(self, config: AnyTrialConfig, *, mode: str, schema: Schema | None = None,
                input_kind: str = "scripted", session: Any = None,
                scheduled: Any = None) -> TrialInfo:
        """Builds, registers (stored modes) and starts a trial; returns its info.

        The old trial must already be closed. On failure nothing runs and the error is
        raised (the caller reports it).
        """
        device: Device | None = None
        # A teleoperation mode (a protocol's stdt / mrcp / mrcp_cam trial) runs the station's
        # needle task: vasim.viewer.teleop_live (issue #28).
        teleop = is_teleop(config)
        if isinstance(config, TeleopTrialConfig):
            if input_kind != "scripted":
                config = person_config(config)
            task = teleop_task(config)
        else:
            task = make_task(config)
        if input_kind == "browser":
            device = BrowserDevice()
        elif input_kind == "laparoscopic":
            screen = (self.view_axes(np.asarray(task.points), np.asarray(task.start))
                      if self.view_axes is not None else self.screen)
            device = instrument_device(tool_trocar(config.task, np.asarray(task.start)),
                                       np.asarray(task.start), self.input_mapping, screen)
            self.screen = screen
        trial = (self._factory(config, device, schema=schema, speed=self.speed)
                 if isinstance(config, TrialConfig)
                 else self.teleop_factory(config, device, schema=schema, speed=self.speed))
        sch = schema if schema is not None else load_schema(
            config.schema if isinstance(config, TrialConfig) else "none")
        self._stored = StoredTrial(None, None)  # a demo is not stored
        if mode != "demo":
            where = {"session_id": None if session is None else session.id,
                     "schedule_index": None if scheduled is None else scheduled.index,
                     "protocol": None if session is None else session.protocol.name}
            meta = (teleop_meta(config, **where) if isinstance(config, TeleopTrialConfig)
                    else trial_meta(config, sch, make_profile(config), **where))
            if input_kind != "scripted":
                cfg = dict(meta.config or {})
                # What was in force, stored with the trial (condition.viewer_condition).
                # **Decision**: only for trials a person drives through the viewer: a
                # scripted trial saw nothing of it and is stored exactly like a headless run.
                cfg["viewer"] = viewer_condition(
                    input_kind=input_kind,
                    mapping=self.input_mapping if input_kind == "laparoscopic" else None,
                    optics_deg=self.optics_deg,
                    mag_camera=any(f.channel == "camera" for f in sch.fixtures))
                cfg["operator"] = input_kind
                if not teleop:  # no simulated person behind a device ...
                    cfg.pop("profile", None)
                # ... but a teleoperation trial keeps it: its reaction delay times the
                # gripper and the safety-stop acknowledgement (teleop_live, decisions).
                if input_kind == "laparoscopic":
                    cfg["input_mapping"] = cfg["viewer"]["input_mapping"]
                meta = replace(meta, operator=input_kind, config=cfg)
            self._stored = begin_stored_trial(self.store(), meta)
        trial_id = self._stored.trial_id
        self._number += 1
        self.outcome = (self._number, None)
        self.info = TrialInfo(
            number=self._number, config=config, schema=sch.name,
            fixtures=tuple(sch.fixture_names), task_name=task.name,
            points=np.array(task.points, dtype=np.float64),
            normals=None if task.normals is None else np.array(task.normals),
            reach_radius=float(task.reach_radius), start=np.array(task.start), mode=mode,
            input=input_kind, trial_id=trial_id,
            schedule_index=None if scheduled is None else scheduled.index,
            condition=None if scheduled is None else scheduled.condition,
            gain_plan=self._gain_plan(config, session, scheduled),
            schedule_total=None if scheduled is None else len(session.schedule),
        )
        self.browser = device if isinstance(device, BrowserDevice) else None
        self.instrument = device if isinstance(device, LaparoscopicDevice) else None
        self._trial = trial
        self._done_since = None
        self._stored_done = False
        self._closed = False
        trial.start()
        self._pair = (self.info, trial)
        return self.info

    @staticmethod
    def _gain_plan(config: AnyTrialConfig, session: Any, scheduled: Any) -> str:
        """How the trial's fixture gain is set (``state.gain_plan``): a protocol trial's
        from its block (``vasim.study.gain_plan.gain_text``), any other's from its config."""
        text = ""
        if session is not None and scheduled is not None:
            from vasim.study.gain_plan import gain_text

            text = gain_text(session.protocol, scheduled)
        # a teleoperation trial has no fixtures, so no gain
        return gain_plan(1.0 if isinstance(config, TeleopTrialConfig) else config.gain, text)

    def _close_trial(self, reason: str, *, failed: bool = False) -> None:
        """Stops the running trial; a stored one that is not done (or whose loop ``failed``)
        is marked interrupted."""
        trial, info = self._trial, self.info
        if trial is None or self._closed:
            return
        trial.stop()
        self._closed = True
        if self.outcome[1] is None:  # how it ended, for every page (trainee.OUTCOME_TEXT)
            from vasim.study.store.vocabulary import outcome_of_reason

            last = trial.frame()
            self.outcome = (info.number, "failed" if failed else
                            frame_outcome(True, last.goal_index, last.n_points)
                            if trial.done else outcome_of_reason(reason))
        if info.trial_id is not None and not self._stored_done:
            if trial.done and not failed:
                self._store_result()
            else:
                res = trial.result()
                timing = self._timing(info.trial_id)  # writes the recording
                # ... and names it in a 'recording' event, as run_realtime_trial does, so
                # the interrupted trial replays (replay_trial needs the trial to name it).
                files = (timing or {}).get("recording")
                events = [(None, "recording", json.dumps(files))] if files else []
                self._stored.interrupt(reason, res, summary=plain_dict(res.summary),
                                       events=events)
                self._stored_done = True
                # The trainee's score card of what the trial recorded before it ended.
                try:
                    self._publish(scorecard=self._score_card(res.trial_metrics))
                except (VasimError, StoreError, KeyError, ValueError):
                    log.exception("the score card of %s failed", info.title)
                self._publish(running=False, status=f"{info.title} stopped "
                              f"({reason}); it stays pending" if info.schedule_index
                              is not None else f"{info.title} stopped ({reason})")
        self.browser = None

    def _store_result(self) -> None:
        """Stores the finished trial (one transaction) and publishes its summary."""
        trial, info = self._trial, self.info
        assert trial is not None
        kw: dict[str, Any] = {}
        if info.schedule_index is not None and self.panel.session_id is not None:
            from vasim.study.session import load_session

            kw["metric_params"] = load_session(self.store(), self.panel.session_id
                                               ).metric_params
        res = trial.result(**kw)
        summary = plain_dict(res.summary)
        self.outcome = (info.number, summary.get("outcome"))
        if info.trial_id is not None:
            self._stored.finish(res, timing=self._timing(info.trial_id))
        self._stored_done = True
        changes: dict[str, Any] = {"running": False, "summary": summary}
        if info.schedule_index is not None and self.panel.session_id is not None:
            from vasim.study.gates import apply_gates  # a gated block's decision (#18 §4)

            try:
                record_browser_sitting(self.store(), self.panel.session_id,
                                       info.schedule_index)
                apply_gates(self.store(), self.panel.session_id)
            except VasimError as exc:
                log.warning("the proficiency gate of %s: %s", info.title, exc)
                changes["status"] = f"proficiency gate not decided: {exc}"
        if info.trial_id is not None:
            changes["curve"] = self._curve()
            changes["scorecard"] = self._score_card(res.trial_metrics)
            changes.setdefault("status", f"{info.title} stored "
                                 f"({summary.get('points_reached')}/{summary.get('n_points')}"
                                 f" points, {summary.get('duration', 0.0):.1f} s)")
        if info.schedule_index is not None:
            changes.update(self._progress())
            if changes.get("position") is None and self.panel.session_id is not None:
                self._complete_session(self.panel.session_id, changes)
        self._publish(**changes)

    def _complete_session(self, session_id: int, changes: dict[str, Any]) -> None:
        """Marks a session whose scheduled trials are all completed as 'completed' (as
        ``run_session`` does at its end), so that the subject's next Start meets the rule of
        a second session at once, not one trial later."""
        st = self.store()
        if st.session(session_id)["status"] != "running":
            return
        try:
            st.set_session_status(session_id, "completed")
        except StoreError as exc:   # trials left after all (a gate): the next Start decides
            log.warning("session %s not completed: %s", session_id, exc)
            return
        changes["status"] = (f"{changes.get('status', '')}; session {session_id} is complete"
                             ).lstrip("; ")

    def _timing(self, trial_id: int) -> dict[str, Any] | None:
        """The live trial's timing for ``timing_json``; a real-time trial's recording (the
        device stream and the physics log) is written next to the database and named
        there, as ``run_realtime_trial`` does, so viewer trials replay like CLI ones."""
        trial = self._trial
        assert trial is not None
        timing = trial.timing()
        out: dict[str, Any] | None = timing.to_dict() if hasattr(timing, "to_dict") else None
        if out is not None and self.viewer_timing is not None:
            try:  # the pages' update rates beside the loop's (issue #26.2)
                out["viewer"] = self.viewer_timing()
            except Exception:
                log.exception("the viewer's timing of trial %s failed", trial_id)
        recording = getattr(trial, "recording", None)
        if callable(recording) and out is not None:
            try:
                p_dev, p_rt = recording().save(self.store().path, trial_id)
                out["recording"] = {"device_stream": p_dev.name, "realtime": p_rt.name}
            except Exception:  # the trial's data matter more than its replay files
                log.exception("saving the recording of trial %s failed", trial_id)
        return out

    def _score_card(self, metrics: dict[str, float]) -> ScoreCard:
        """The score card of the stored trial just finished (``history.trial_score_card``)."""
        return trial_score_card(self.store(), self.info, metrics, self.outcome[1])

    def _curve(self) -> tuple[tuple[int, float, float], ...]:
        """The learning curve so far (``history.learning_curve``)."""
        p = self.panel
        return learning_curve(self.store(), p.session_id if p.mode == "protocol" else None,
                              p.subject or self._base.subject, p.label)

    # -- protocol sessions ---------------------------------------------------------------
    def _session(self) -> Any:
        """The subject's running session of the chosen protocol, created if none (with the
        input and the instrument's mapping in force now: every trial of it keeps them)."""
        p = self.panel
        m = self.input_mapping
        try:
            session = open_session(self.store(), p.subject, p.protocol, {
                "ui": "vasim serve", "input": p.input, "scene": self.scene,
                "input_mapping": {"fulcrum_effect": m.fulcrum_effect,
                                  "sensitivity": m.sensitivity}}, again=p.again)
        except ConfigError as exc:   # the refusal on the page's status line too
            self._publish(running=False, status=str(exc))
            raise
        if p.again is not None:      # the reason is stored with this session: used up
            self._publish(again=None)
        return session

    def _progress(self) -> dict[str, Any]:
        """Progress fields of the panel for the chosen subject and protocol."""
        p = self.panel
        if p.session_id is None:
            return {}
        running = self.active() and self.info.schedule_index is not None
        return session_progress(self.store(), p.session_id,
                                self.info.schedule_index if running else None)

    def _start_protocol_trial(self) -> None:
        session = self._session()
        self._publish(session_id=session.id)
        pending = session.pending
        if not pending:
            from vasim.study.store import TrialStore

            st: TrialStore = self.store()
            if session.status == "running":
                st.set_session_status(session.id, "completed")
            self._publish(status=f"session {session.id} is complete", **self._progress())
            return
        nxt = pending[0]
        try:  # a later sitting before its delay: refused, as vasim study resume does
            refuse_early_sitting(self.store(), session, nxt)
        except StoreError as exc:
            self._publish(running=False, status=str(exc), **self._progress())
            raise
        # A VF trial's config, or a teleoperation mode's own (issue #29): teleop_live runs it.
        cfg: AnyTrialConfig = replace(session.trial_config(nxt), scene=self.scene)
        # The session's input (stored with it when it was created) drives all its trials.
        kind = str(session.settings.extra.get("input", self.panel.input))
        mapping = session.settings.extra.get("input_mapping")
        if isinstance(mapping, dict):
            self.input_mapping = InputMapping(**mapping)
        self._launch(cfg, mode="protocol", input_kind=kind, session=session, scheduled=nxt)
        # The greyed f5PL editor shows the running trial's condition (issue #26 §5), not
        # the free-training schema: the trial's own schema, as _launch loaded it.
        self._publish(running=True, summary=None, scorecard=None, input=kind,
                      f5pl=f5pl_fields(load_schema(self.info.schema)),
                      status=f"{self.info.title} running ({nxt.condition}; store id "
                      f"{self.info.trial_id})", **self._progress())

    def _free_config(self) -> TrialConfig:
        p = self.panel
        base = self._base
        subject = p.subject or base.subject
        return replace(base, schema=p.schema, task=p.task,  # type: ignore[arg-type]  # panel strs
                       variant=base.variant if p.task == "trajectory" else 0,
                       subject=subject, label=None if subject else p.label,
                       seed=base.seed + self._number)

    # -- commands ---------------------------------------------------------------------
    def handle(self, cmd: Command) -> None:
        """Applies one command (controller thread). Raises ``VasimError`` for a bad one
        (the caller reports it); the running trial is unaffected then."""
        handler = {
            "mode": self._on_mode,
            "schema": self._on_schema,
            "task": self._on_task,
            "input_mapping": self._on_input_mapping,
            "input": self._on_input,
            "label": self._on_label,
            "again": self._on_again,
            "subject": self._on_subject,
            "protocol": self._on_protocol,
            "start": self._on_start,
            "stop": self._on_stop,
            "restart": self._on_restart,
            "f5pl": self._on_f5pl,
            "auto_advance": self._on_auto_advance,
            "answers": self._record_answers,
        }.get(cmd.kind)
        if handler is None:
            raise ConfigError(f"unknown command {cmd.kind!r}")
        handler(cmd.value)

    def _on_mode(self, value: Any) -> None:
        p = self.panel
        check_choice(value, "mode", MODES)
        if value == p.mode:
            return
        if value != "demo":
            self.store()  # refuse early without a database
        self._close_trial(f"switched to {value} mode")
        if value != "protocol":   # back from a protocol trial's f5PL (shown greyed)
            self._publish(f5pl=f5pl_fields(self._schema_obj if self._schema_obj
                                           is not None else load_schema(p.schema)))
        self._publish(mode=value, summary=None, running=False,
                      status={"demo": "demo: the scripted operator plays trials by itself",
                              "free": "free training: pick a schema, then Start",
                              "protocol": "protocol: enter the subject code and pick a "
                                          "protocol, then Start"}[value])
        if value == "demo":
            self._start_demo(replace(self._base, schema=p.schema, task=p.task))  # type: ignore[arg-type]  # panel
        elif value == "protocol" and p.subject and p.protocol:
            self._publish(curve=(), **self._select_session())

    def _on_schema(self, value: Any) -> None:
        self._set_schema(str(value))

    def _on_task(self, value: Any) -> None:
        self._set_task(str(value))

    def _on_label(self, value: Any) -> None:
        self._set_label(value)

    def _on_start(self, value: Any) -> None:
        self._start()

    def _on_stop(self, value: Any) -> None:
        if self._pending is not None:
            self._pending = self.countdown_until = None
            self._publish(running=False, status="start cancelled")
            return
        if not self.active():
            raise ConfigError("no trial is running", field="stop")
        self._close_trial("stopped by the experimenter")
        if self.info.trial_id is None:
            self._publish(running=False, status=f"{self.info.title} stopped")
        elif self.info.schedule_index is not None:
            self._publish(**self._progress())

    def _on_restart(self, value: Any) -> None:
        p = self.panel
        if p.mode == "demo":
            self._close_trial("restarted")
            self._start_demo(demo_config(self.info))
        else:
            raise ConfigError("use Stop, then Start (a stored trial is not restarted)",
                              field="restart")

    def _on_f5pl(self, value: Any) -> None:
        instance, params = value
        self._apply_f5pl(str(instance), params)

    def _on_auto_advance(self, value: Any) -> None:
        self._publish(auto_advance=bool(value))

    def _running_stored(self) -> bool:
        return self.active() and self.info.trial_id is not None

    def _select_session(self) -> dict[str, Any]:
        """Progress of the subject's running session of the chosen protocol (if any)."""
        p = self.panel
        st = self.store()
        df = st.sessions(subject=p.subject, protocol=p.protocol)
        running = df[df["status"] == "running"]
        if not len(running):
            from vasim.study.protocol import load_protocol

            n = load_protocol(str(p.protocol)).n_trials
            note = completed_note(st, str(p.subject), str(p.protocol))
            return {"session_id": None, "position": 1, "total": n, "completed": 0,
                    "condition": None, "status": note or f"new session of {p.protocol} for "
                    f"{p.subject}: Start runs trial 1 of {n}"}
        self.panel = replace(p, session_id=int(running["id"].iloc[-1]))
        prog = self._progress()
        return {"session_id": self.panel.session_id, **prog,
                "curve": self._curve(),
                "status": f"session {self.panel.session_id} of {p.subject}: "
                          f"{prog['completed']} of {prog['total']} done"}

    def _start(self) -> None:
        p = self.panel
        if (self.active() or self._pending is not None) and p.mode != "demo":
            raise ConfigError("a trial is already running (Stop it first)", field="start")
        if p.mode == "protocol":   # refuse an early sitting before any countdown
            session = self._session()
            self._publish(session_id=session.id)
            if session.pending:
                try:
                    refuse_early_sitting(self.store(), session, session.pending[0])
                except StoreError as exc:
                    self._publish(running=False, status=str(exc), **self._progress())
                    raise
        if p.mode != "demo" and p.input != "scripted" and self.countdown_s > 0:
            # The start cue (**decision**: a countdown, not the first move, because the
            # trial's clock must not depend on when a page's first batch arrives): the
            # trainee page counts down, the trial and its clock begin at 0.
            self._close_trial("replaced")
            self.countdown_until = time.monotonic() + self.countdown_s
            self._pending = self._begin
            self._publish(running=True, summary=None, scorecard=None,
                          status=f"the trial starts in {self.countdown_s:g} s")
            return
        self._begin()

    def _begin(self) -> None:
        """Starts the trial of the current mode (after the countdown, if any)."""
        p = self.panel
        self._pending = self.countdown_until = None
        if p.mode == "demo":
            self._close_trial("restarted")
            self._start_demo(demo_config(self.info))
        elif p.mode == "free":
            self._close_trial("replaced")
            self._launch(self._free_config(), mode="free", schema=self._schema_obj,
                         input_kind=p.input)
            self._publish(running=True, summary=None, scorecard=None,
                          status=f"{self.info.title} running ({self.info.schema})")
        else:
            self._close_trial("replaced")
            self._start_protocol_trial()

    def _start_demo(self, config: TrialConfig) -> None:
        self._launch(replace(config, subject=self._base.subject), mode="demo",
                     schema=self._schema_obj)
        self._publish(running=True)

    # -- the loop ------------------------------------------------------------------------
    def poll(self, now: float | None = None) -> None:
        """Stores a finished trial; loops the demo; auto-advances a protocol."""
        now = time.monotonic() if now is None else now
        if self._pending is not None and self.countdown_until is not None:
            if time.monotonic() >= self.countdown_until:
                self._begin()
            return
        trial = self._trial
        if trial is None or not trial.done or (self._closed and self._stored_done):
            return
        error = getattr(trial, "error", None)
        if error is not None and not self._stored_done:
            # **decision**: a trial whose loop failed is stored as interrupted (with what it
            # recorded and the error as the reason), never as completed; the scheduled trial
            # stays pending. The error goes on to the app, which notifies the page.
            reason = f"the trial loop failed: {type(error).__name__}: {error}"
            self._close_trial(reason, failed=True)
            self._stored_done = True
            self._done_since = math.inf
            self._publish(running=False, status=reason)
            raise VasimError(f"trial {self.info.number}: {reason}")
        if not self._stored_done:
            trial.stop()
            if self.info.mode == "demo":
                self._stored_done = True
            else:
                self._store_result()
        if self._done_since is None:
            self._done_since = now
            return
        if now - self._done_since < self.pause_s:
            return
        p = self.panel
        if p.mode == "demo" and self.info.mode == "demo":
            cfg = demo_config(self.info)
            variant = (cfg.variant + 1) % TRAJECTORY_VARIANTS if cfg.task == "trajectory" else 0
            self._start_demo(replace(cfg, variant=variant, seed=cfg.seed + 1))
        elif (p.mode == "protocol" and p.auto_advance and self.info.schedule_index is not None
              and p.position is not None):
            self._done_since = math.inf  # once: a refused next sitting is not retried
            self._start_protocol_trial()
        else:
            self._done_since = math.inf  # hold the final frame until the next command

    def close(self) -> None:
        """Stops the trial (a stored one is marked interrupted) and closes the store."""
        try:
            self._close_trial("viewer stopped")
        except (VasimError, StoreError):
            log.exception("closing the running trial failed")
        finally:
            if self._store is not None:
                self._store.close()
                self._store = None


__all__ = [
    "CURVE_METRICS",
    "DEFAULT_SCHEMA_FOR_TASK",
    "INPUTS",
    "MODES",
    "Command",
    "PanelState",
    "TrainingController",
    "TrainingSettings",
    "TrialInfo",
    "f5pl_fields",
    "plain",
    "schema_choices",
    "with_f5pl",
]
