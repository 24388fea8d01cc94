"""Study sessions: one subject running one protocol, durable trial by trial, resumable.

A session is created with its seed and its realised schedule in one transaction
(``start_session``); ``run_session`` then runs the scheduled trials that have no completed
trial yet, in schedule order, each through ``run_trial`` (one transaction per trial: a
completed trial is durable before the next one starts). A session killed mid-trial leaves
that trial's row 'running'; the next open of the store marks it 'interrupted' (its writer is
gone) and ``run_session`` re-runs the scheduled trial as a new trial row (``attempt`` + 1),
linked to the same schedule index. Resuming reads everything from the store -- the protocol
text as run, the seed, the schedule and the run settings -- and never the protocol file.

**Decisions**:

* Trial seeds: the operator seed of scheduled trial i is ``trial_seed(session seed, i)``,
  independent of the attempt, so a re-run after a crash repeats the trial the crash
  interrupted and a simulated session's data do not depend on its crash history.
* Practice and fixture effects: the scripted operator of scheduled trial i runs with the
  adjustment ``vasim.operator.learning.trial_adjustment`` of the conditions of trials
  0..i-1 and its own condition: the practice P is the rounded effective practice (a trial
  under a fixture may count more), and the profile's learnable noise and Fitts constants
  carry the fixture's effect while assisted, and its carry-over and guidance dependence in
  VF-free trials; a faded or adaptive trial carries its gain (``vasim.study.gain_plan``:
  the benefit scales with it). The effects are a declared scenario's
  (``vasim.operator.scenario``): the one stored in ``settings.extra["scenario"]`` (its
  text, sha256 and ``effect_scale``, written by ``vasim study simulate``), else the shipped
  default; the scenario's ``mechanism(scale)`` multiplies every trial's fixture gain
  (0: the fixtures do nothing, ``--effect-scale 0`` or the null scenario).
  A session run by the
  scripted operator stores its operator as ``learning.OPERATOR_LABEL`` ("scripted
  (declared scenario, synthetic)"); its trials keep ``operator = "scripted"``.
  A teleoperation trial also gets ``mode_practice``, the number of earlier trials of its
  mode in the schedule (the mode-specific learning of ``vasim.operator.teleop_profile``),
  and ``mode_effects``, the stored teleoperation scenario's mode penalties at the effect
  scale (``Scenario.teleop_effects``; None without a ``[teleop]`` scenario: the mechanism
  alone).
* Run settings (``SessionSettings``) are stored with the session (``sessions.config_json``),
  the operator profile resolved (not just the preset name), so a resumed session runs with
  the same person even if the presets change.
* A session is 'completed' once every scheduled trial has a completed trial; questionnaires
  are recorded separately (``record_answers``) and do not gate completion.
* Timed-out trials (protocol ``repeat_timed_out = true``): a scheduled trial whose attempt
  ran into the time limit (outcome ``'timed_out'``) is released (``TrialStore
  .release_scheduled``: the attempt stays stored with a ``'repeated'`` event) and run again,
  at most ``MAX_TIMED_OUT_REPEATS`` times; the last attempt then counts, timed out or not,
  so that a trial the operator cannot finish never blocks the session. A repeat's operator
  seed is ``trial_seed`` of the session seed, the index and the repeat number (the scripted
  operator would otherwise time out identically); a crash re-run keeps the seed of the
  attempt it replaces. ``run_session`` first releases any timed-out trial a crash left
  linked between its finish and its release.

Example:
    >>> import tempfile, pathlib
    >>> from vasim.study.protocol import load_protocol
    >>> from vasim.study.store import TrialStore
    >>> with tempfile.TemporaryDirectory() as d, TrialStore(pathlib.Path(d) / "s.db") as st:
    ...     sid = start_session(st, load_protocol("vf_learning_curve"), "S01", seed=7,
    ...                         settings=SessionSettings(max_trial_time=0.01))
    ...     n = run_session(st, sid, progress=False, max_trials=2)
    ...     st.sessions()[["n_trials", "n_completed", "next_index", "status"]].values.tolist()
    [[38, 2, 2, 'running']]
"""

from __future__ import annotations

import secrets
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd

from vasim.core.config import (
    check_choice,
    check_file,
    check_table,
    check_type,
    expect,
    parse_toml,
)
from vasim.core.errors import ConfigError, InputError, StoreError
from vasim.core.progress import progress_bar
from vasim.operator.learning import OPERATOR_LABEL, VF_FREE, trial_adjustment
from vasim.operator.retention import practice_weights, weighted_adjustment
from vasim.operator.scenario import Scenario, scenario_from_text
from vasim.operator.scripted import OperatorProfile
from vasim.records.trial_meta import validate_subject_code
from vasim.records.trial_metrics import MetricParams
from vasim.study.gain_plan import (
    condition_effects,
    learning_gain,
    scale_gain,
    schedule_gains,
    trial_gain,
)
from vasim.study.gates import apply_gates
from vasim.study.protocol import (
    Protocol,
    ScheduledTrial,
    block_of,
    day_offsets,
    generate_schedule,
    sitting_numbers,
    validate_answers,
)
from vasim.study.sitting_rule import early_sitting
from vasim.study.store import SessionMeta, TrialStore
from vasim.study.stored_session import read_session
from vasim.trials.configs import AnyTrialConfig, TeleopTrialConfig
from vasim.trials.kinds import TELEOPERATION_MODES, check_trial_time
from vasim.trials.registry import run_trial
from vasim.trials.vf import TrialConfig, make_profile

OPERATORS: tuple[str, ...] = ("scripted",)
"""Input devices a session can be run with from the command line."""

BROWSER_HINT = ("browser sessions run from `vasim serve` (the viewer issue), where the "
                "person at the browser is the operator; `vasim study run` drives the "
                "scripted operator only")


def new_seed() -> int:
    """A fresh randomisation seed in [0, 2**63) from the OS's entropy."""
    return secrets.randbelow(2**63)


MAX_TIMED_OUT_REPEATS = 2
"""A timed-out scheduled trial is repeated at most this often (``repeat_timed_out``)."""


def trial_seed(session_seed: int, index: int, repeat: int = 0) -> int:
    """The operator seed of scheduled trial ``index`` (see the module's decisions);
    ``repeat`` > 0: of its repeat after that many timed-out attempts.

    Example:
        >>> trial_seed(7, 0) == trial_seed(7, 0) != trial_seed(7, 1)
        True
        >>> trial_seed(7, 0, 1) != trial_seed(7, 0)
        True
    """
    key = [int(session_seed), 3, int(index)] + ([int(repeat)] if repeat else [])
    a, b = np.random.SeedSequence(key).generate_state(2)
    return ((int(a) << 32) | int(b)) & (2**63 - 1)


@dataclass(frozen=True)
class SessionSettings:
    """How a session's trials are run (stored with the session).

    Attributes:
        operator: input device (``OPERATORS``).
        skill: scripted operator preset, used when ``profile`` is None.
        profile: the scripted operator (a simulated person), overrides ``skill``.
        max_trial_time: trial time limit [s]; None: the protocol's ``max_trial_time_s``.
        dt: control step [s].
        extra: further JSON-able facts to keep with the session (e.g. cohort parameters).

    Raises:
        ConfigError: an unknown operator (``"browser"`` gets its own explanation) or a bad
            value.
    """

    operator: str = "scripted"
    skill: Literal["novice", "intermediate", "expert"] = "intermediate"
    profile: OperatorProfile | None = None
    max_trial_time: float | None = None
    dt: float = 1e-3
    extra: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.operator == "browser":
            raise ConfigError(BROWSER_HINT, field="operator")
        expect(self.operator in OPERATORS, self.operator, f"a known operator: "
                f"{', '.join(OPERATORS)} (browser sessions run from `vasim serve`)",
                field="operator")
        check_choice(self.skill, "skill", ("novice", "intermediate", "expert"))
        if self.profile is not None:
            check_type(self.profile, "profile", OperatorProfile, "an OperatorProfile")
        if self.max_trial_time is not None:
            check_trial_time(self.max_trial_time, "max_trial_time")
        check_type(self.extra, "extra", Mapping, "a mapping")

    def resolved_profile(self) -> OperatorProfile:
        """The operator profile: ``profile``, or the ``skill`` preset."""
        if self.profile is not None:
            return self.profile
        return make_profile(TrialConfig(skill=self.skill))

    def to_record(self) -> dict[str, Any]:
        """JSON-able record (the profile resolved to its fields)."""
        p = self.resolved_profile()
        return {"operator": self.operator, "skill": self.skill,
                "profile": {f.name: getattr(p, f.name) for f in fields(p)},
                "max_trial_time": self.max_trial_time, "dt": self.dt,
                "extra": dict(self.extra)}

    @classmethod
    def from_record(cls, rec: Mapping[str, Any]) -> SessionSettings:
        """Inverse of ``to_record``."""
        prof = rec.get("profile")
        return cls(operator=rec.get("operator", "scripted"),
                   skill=rec.get("skill", "intermediate"),
                   profile=None if prof is None else OperatorProfile(**prof),
                   max_trial_time=rec.get("max_trial_time"), dt=rec.get("dt", 1e-3),
                   extra=rec.get("extra") or {})


@dataclass(frozen=True)
class Session:
    """A session as stored (what ``run_session`` replays).

    Attributes:
        id: session id. subject: subject code. protocol: the protocol parsed from the text
        stored with the session. seed: randomisation seed. status: running | completed |
        aborted. settings: how its trials run. schedule: the stored schedule.
        completed: trial id of the completed trial of each scheduled index (None if none).
    """

    id: int
    subject: str
    protocol: Protocol
    seed: int
    status: str
    settings: SessionSettings
    schedule: tuple[ScheduledTrial, ...]
    completed: tuple[int | None, ...]

    @property
    def pending(self) -> list[ScheduledTrial]:
        """Scheduled trials without a completed trial, in schedule order."""
        return [t for t, tid in zip(self.schedule, self.completed, strict=True) if tid is None]

    def trial_config(self, scheduled: ScheduledTrial, repeat: int = 0) -> AnyTrialConfig:
        """The trial configuration of one scheduled trial (see the module's decisions);
        ``repeat``: how many timed-out attempts it had before."""
        if scheduled.schema is None:
            self.protocol.check_runnable()
        s = self.settings
        profile = s.resolved_profile()
        practice = scheduled.index
        gain = trial_gain(self.protocol, scheduled)  # faded/adaptive fixtures (issue #18)
        scenario, scale = self.scenario
        if s.operator == "scripted":
            history = self.schedule[:scheduled.index]
            labels = [t.condition for t in history]
            g = learning_gain(gain)
            if self.spans_days_or_paths:
                # Forgetting and transfer (vasim.operator.retention) weight the practice;
                # the gain hook's rule (learning.trial_adjustment) is applied on top.
                # **Decision**: in a protocol with later sittings the guidance dependence
                # after a faded trial is not scaled by that trial's gain (the retention
                # model counts each earlier trial by its forgetting weight only).
                adj = weighted_adjustment(labels, scheduled.condition,
                                          self.practice_weights(scheduled),
                                          condition_effects(self.protocol, scenario, scale))
                if g != 1.0 and scheduled.condition != VF_FREE:
                    adj = replace(adj, noise_factor=1.0 - g * (1.0 - adj.noise_factor),
                                  time_factor=1.0 + g * (adj.time_factor - 1.0))
            else:
                adj = trial_adjustment(labels, scheduled.condition,
                                       condition_effects(self.protocol, scenario, scale),
                                       gain=g,
                                       history_gains=schedule_gains(self.protocol, history))
            profile, practice = adj.apply(profile), round(adj.practice)
        if scenario is not None and scenario.mechanism(scale) != 1.0 \
                and scheduled.condition != VF_FREE \
                and scheduled.condition not in TELEOPERATION_MODES:
            gain = scale_gain(gain, scenario.mechanism(scale))
        max_time = (s.max_trial_time if s.max_trial_time is not None
                    else self.protocol.max_trial_time)
        seed = trial_seed(self.seed, scheduled.index, repeat)
        if scheduled.condition in TELEOPERATION_MODES:
            # A teleoperation mode runs the MRCP station's needle task (vasim.trials.teleop).
            mode = scheduled.condition
            return TeleopTrialConfig(
                mode=mode, operator=s.operator, skill=s.skill, seed=seed, practice=practice,
                max_time=max_time, subject=self.subject, profile=profile,
                reach_radius=self.protocol.reach_radius,
                mode_practice=sum(t.condition == mode
                                  for t in self.schedule[:scheduled.index]),
                mode_effects=None if scenario is None or scenario.teleop is None
                else scenario.teleop_effects(scale))
        return TrialConfig(
            task=scheduled.task,  # type: ignore[arg-type]  # protocol task names are checked
            variant=scheduled.variant, schema=str(scheduled.schema), operator=s.operator,
            skill=s.skill, seed=seed, practice=practice, dt=s.dt, max_time=max_time,
            subject=self.subject, profile=profile,
            reach_radius=self.protocol.reach_radius, poi_spacing=self.protocol.poi_spacing,
            gain=gain,
        )

    @property
    def scenario(self) -> tuple[Scenario | None, float]:
        """The session's stored scenario and effect scale (None, 1: the shipped default;
        module decisions)."""
        rec = self.settings.extra.get("scenario")
        if not isinstance(rec, Mapping) or "text" not in rec:
            return None, 1.0
        return scenario_from_text(str(rec["text"])), float(rec.get("effect_scale", 1.0))

    @property
    def spans_days_or_paths(self) -> bool:
        """The protocol has later sittings or transfer blocks (retention and transfer of
        the simulated operator apply, ``vasim.operator.retention``)."""
        return any(b.delay_days > 0 or b.phase == "transfer" for b in self.protocol.blocks)

    def practice_weights(self, scheduled: ScheduledTrial) -> list[float]:
        """The weight of each earlier trial's practice at ``scheduled``
        (``retention.practice_weights``).

        **Decision**: the simulated operator forgets over the protocol's nominal delays
        (the simulated date of each sitting, ``day_offsets``), whether or not a real
        delay passed; a transfer block's trials are on an untrained trajectory.
        """
        days = day_offsets(self.protocol, self.schedule)
        earlier = self.schedule[:scheduled.index]
        untrained = block_of(self.protocol, scheduled.block).phase == "transfer"
        return practice_weights([days[scheduled.index] - days[t.index] for t in earlier],
                                [t.variant == scheduled.variant for t in earlier],
                                untrained=untrained)

    @property
    def metric_params(self) -> MetricParams:
        """The trial-metric constants of the protocol."""
        return MetricParams(excessive_force_n=self.protocol.excessive_force_n,
                            path_tolerance_m=self.protocol.path_tolerance_m)


# ------------------------------------------------------------------------ lifecycle
MAX_REASON_CHARS = 500
"""Longest ``--again`` reason (one line)."""


def check_again(store: TrialStore, protocol: str, subject: str, again: str | None,
                *, option: str = "--again", ask: str = "give the reason with --again 'REASON'",
                ) -> str | None:
    """The rule of a second session (issue #30 item 3): a subject who *completed* a session
    of ``protocol`` gets another only with a reason (``again``, ``vasim study run --again
    REASON``), which is stored with the new session; ``again`` without such a session is
    refused too (the reason would be false).

    **Decision**: only a *completed* session of the same protocol (by name) counts: an
    aborted one frees the subject (as before), a running one is refused by the store
    ("resume it"), and another protocol is another study. The rule is the command line's;
    library callers (the cohort simulator, which resumes its own subjects) decide for
    themselves; the viewer's experimenter page applies it with its own field's words
    (``option``: the field named in the errors; ``ask``: how to give the reason).

    Returns:
        The note to store with the new session (None: no ``again``).

    Raises:
        ConfigError: (field ``option``) naming the subject, the protocol, the completed
            session(s) and what to do; or an empty, multi-line or over-long reason.
    """
    done = store.sessions(subject=subject, protocol=protocol, status="completed")
    ids = ", ".join(str(int(i)) for i in done["id"])
    if again is None:
        if done.empty:
            return None
        ended = str(done["ended_at"].iloc[-1] or "")[:19]
        raise ConfigError(
            f"subject {subject!r} already completed protocol {protocol!r} in {store.path} "
            f"(session{'s' if len(done) > 1 else ''} {ids}{', ended ' + ended if ended else ''}"
            f"); to run it again {ask} (stored with the new session), or use another "
            "subject code", field=option)
    expect(isinstance(again, str) and again.strip() and "\n" not in again
           and len(again) <= MAX_REASON_CHARS, again,
           f"a one-line reason of 1-{MAX_REASON_CHARS} characters", field=option)
    if done.empty:
        raise ConfigError(f"subject {subject!r} has no completed session of protocol "
                          f"{protocol!r} in {store.path}; a reason ({option}) is only for "
                          "running a completed protocol again (leave it out)", field=option)
    return (f"again after completed session{'s' if len(done) > 1 else ''} {ids}: "
            f"{again.strip()}")


def start_session(store: TrialStore, protocol: Protocol, subject: str, *,
                  seed: int | None = None, settings: SessionSettings | None = None,
                  notes: str | None = None) -> int:
    """Creates a session: seed, protocol text and realised schedule, in one transaction.

    Args:
        store: the study store. protocol: the protocol (its ``text`` is stored).
        subject: subject code. seed: randomisation seed (None: a fresh one, ``new_seed``).
        settings: how the trials run (default ``SessionSettings()``).
        notes: stored with the session (``sessions.notes``; e.g. :func:`check_again`'s).

    Returns:
        The session id.

    Raises:
        ConfigError: the protocol cannot run in this release (``check_runnable``), a bad
            subject code or seed.
        StoreError: the subject already has a running session of this protocol.
    """
    validate_subject_code(subject)
    protocol.check_runnable()
    settings = settings if settings is not None else SessionSettings()
    seed = new_seed() if seed is None else seed
    schedule = generate_schedule(protocol, seed)
    text = protocol.text
    if text is None:
        raise ConfigError(f"protocol {protocol.name!r} has no source text to store; load it "
                          "with load_protocol or parse_protocol")
    return store.create_session(
        SessionMeta(subject=subject, protocol=protocol.name, protocol_toml=text, seed=seed,
                    operator=OPERATOR_LABEL if settings.operator == "scripted"
                    else settings.operator, config=settings.to_record(), notes=notes),
        [t.as_row() for t in schedule])


def load_session(store: TrialStore, session_id: int) -> Session:
    """Reads a session back from the store (protocol from its stored text,
    :func:`vasim.study.stored_session.read_session`).

    Raises:
        StoreError: unknown session.
    """
    rec = read_session(store, session_id)
    return Session(id=rec.id, subject=rec.subject, protocol=rec.protocol, seed=rec.seed,
                   status=rec.status, settings=SessionSettings.from_record(rec.config),
                   schedule=rec.schedule, completed=rec.completed)


def find_session(store: TrialStore, *, subject: str | None = None,
                 session_id: int | None = None, protocol: str | None = None) -> int:
    """The id of the session to resume: ``session_id``, or the subject's running session
    (of ``protocol``, when given).

    Raises:
        ConfigError: neither given, or the subject has no running session, or several.
        StoreError: unknown session id.
    """
    if session_id is not None:
        return int(store.session(session_id)["id"])
    expect(subject is not None, subject, "a subject code (or a session id)", field="subject")
    validate_subject_code(subject)
    df = store.sessions(subject=subject, protocol=protocol)
    running = df[df["status"] == "running"]
    if running.empty:
        what = f" of protocol {protocol!r}" if protocol else ""
        if df.empty:
            raise ConfigError(f"no session{what} for subject {subject!r} in {store.path}",
                              field="subject")
        listed = ", ".join(f"{i} {s}" for i, s in zip(df["id"], df["status"], strict=True))
        raise ConfigError(f"subject {subject!r} has no running session{what} in {store.path} "
                          f"(sessions: {listed})", field="subject")
    if len(running) > 1:
        raise ConfigError(f"subject {subject!r} has {len(running)} running sessions "
                          f"({', '.join(map(str, running['id']))}); name the protocol or the "
                          "session", field="subject")
    return int(running["id"].iloc[0])


def run_session(store: TrialStore, session_id: int, *, progress: bool = True,
                max_trials: int | None = None, simulate_delay: bool = False) -> int:
    """Runs a session's pending scheduled trials in order; completes it when none is left.

    A protocol with later sittings (blocks with ``delay_days``) runs one sitting per call:
    the call stops before the first trial of the next sitting; the call that begins a
    later sitting (``vasim study resume``) checks that its delay has passed since the
    previous trial ended, or with ``simulate_delay`` records a simulated delay and does
    not wait. Either way the first trial of the sitting gets a ``'sitting'`` event saying
    which (``record_sitting``). After each trial of a gated block the gate decides
    (``vasim.study.gates.apply_gates``); a decision that adds a trial extends the stored
    schedule.

    Args:
        store: the study store (the only writer of this session).
        session_id: the session. progress: progress output over the session's trials.
        max_trials: stop after this many trials (None: run to the end).
        simulate_delay: begin a later sitting at once, recording a simulated delay.

    Returns:
        The number of trials run (completed).

    Raises:
        StoreError: the session is not running, or one of its trials is being run by a
            live process.
        ConfigError: the protocol cannot run in this release.
        KeyboardInterrupt: after marking the current trial interrupted.
    """
    session = load_session(store, session_id)
    if session.status != "running":
        raise StoreError(f"session {session_id} of subject {session.subject!r} is "
                         f"{session.status!r}; nothing to run")
    session.protocol.check_runnable()
    busy = store.trials("running")
    busy = busy[busy["session_id"] == session.id]
    if not busy.empty:
        raise StoreError(f"session {session.id} is being run: trial {int(busy['id'].iloc[0])} "
                         f"is 'running' (process {busy['pid'].iloc[0]} on "
                         f"{busy['host'].iloc[0]})")

    if _release_timed_out(store, session):
        session = load_session(store, session.id)
    apply_gates(store, session.id)          # a decision a crash left undone
    session = load_session(store, session.id)
    n_total = len(session.schedule)
    bar = progress_bar(n_total, f"{session.subject} {session.protocol.name}", "trial",
                       initial=n_total - len(session.pending), enabled=progress)
    done = 0
    n_run = 0
    try:
        while session.pending and (max_trials is None or n_run < max_trials):
            st = session.pending[0]
            begins = sitting_begins(session, st)
            note: dict[str, Any] = {}
            if begins is not None:
                if n_run:
                    break                       # this sitting is over: resume later
                note = _check_delay(store, session, st, begins, simulate_delay)
            bar.set_postfix_str(f"trial {st.index + 1}/{len(session.schedule)} {st.condition}"
                                f"{' (VF-free)' if st.probe else ''} v{st.variant}")
            while True:
                repeat = _timed_out_attempts(store, session.id, st.index)
                run_trial(session.trial_config(st, repeat), store, session_id=session.id,
                          schedule_index=st.index, protocol=session.protocol.name,
                          metric_params=session.metric_params)
                done += 1
                if not _release_timed_out(store, session, st.index):
                    break
            if begins is not None:
                record_sitting(store, session, st, note)
            n_run += 1
            bar.update(1)
            if apply_gates(store, session.id):
                bar.total += 1
            session = load_session(store, session.id)
    finally:
        bar.close()
    if not load_session(store, session.id).pending:
        store.set_session_status(session.id, "completed")
    return done


SITTING_EVENT = "sitting"
"""``events.kind`` on the first trial of a later sitting (its delay, simulated or real)."""


def sitting_begins(session: Session, st: ScheduledTrial) -> float | None:
    """The delay [d] before ``st`` when it begins a later sitting, else None."""
    if st.index == 0:
        return None
    numbers = sitting_numbers(session.protocol, session.schedule)
    if numbers[st.index] == numbers[st.index - 1]:
        return None
    days = day_offsets(session.protocol, session.schedule)
    return days[st.index] - days[st.index - 1]


def sitting_record(store: TrialStore, session: Session, st: ScheduledTrial, delay: float,
                   simulate: bool, at: str | None = None) -> dict[str, Any]:
    """The record of a later sitting beginning at ``st`` (the ``'sitting'`` event):
    sitting number, block, nominal delay and day [d], simulated or not, and the real time
    elapsed [d] from the end of the previous trial to ``at`` (an ISO time, e.g. the
    trial's ``started_at``; None: now)."""
    rec: dict[str, Any] = {"sitting": sitting_numbers(session.protocol,
                                                      session.schedule)[st.index],
                           "block": st.block, "delay_days": delay,
                           "day": day_offsets(session.protocol, session.schedule)[st.index],
                           "simulated": bool(simulate), "elapsed_days": None}
    tid = session.completed[st.index - 1] if st.index else None
    if tid is not None:
        raw = store.trial(tid)["ended_at"]
        last = stored_time(raw)
        if last is None:
            # issue #30 item 5: a hand-edited ended_at ('not a date', NULL) was a traceback
            if not simulate:
                raise StoreError(
                    f"{store.path}: trial {tid} (session {session.id}, the trial before "
                    f"sitting {rec['sitting']}) has ended_at = {raw!r}, not an ISO 8601 time, "
                    "so the sitting's delay cannot be measured; repair trials.ended_at of "
                    "that trial, or pass --simulate-delay to record a simulated delay")
            rec["previous_ended_at_invalid"] = None if raw is None else str(raw)
            return rec
        then = pd.Timestamp.now(tz=last.tz) if at is None else pd.Timestamp(at)
        rec["elapsed_days"] = (then - last).total_seconds() / 86_400
        rec["previous_ended_at"] = last.isoformat()
    return rec


def stored_time(value: object) -> pd.Timestamp | None:
    """A stored ISO 8601 time (UTC when it has no offset), or None when it is missing or
    not a time (a hand-edited store).

    >>> stored_time("2026-11-20T10:00:00+00:00").isoformat(), stored_time("not a date")
    ('2026-11-20T10:00:00+00:00', None)
    """
    if not isinstance(value, str) or not value.strip():
        return None
    try:
        t = pd.Timestamp(value)
    except (ValueError, OverflowError, TypeError):
        return None
    if pd.isna(t):
        return None
    return t if t.tz is not None else t.tz_localize("UTC")


def _check_delay(store: TrialStore, session: Session, st: ScheduledTrial, delay: float,
                 simulate: bool) -> dict[str, Any]:
    """The sitting's record; refuses a real sitting whose delay has not passed."""
    rec = sitting_record(store, session, st, delay, simulate)
    if not simulate:
        check_sitting_due(session, rec, "resume then, or pass --simulate-delay to record "
                          "a simulated delay")
    return rec


def check_sitting_due(session: Session, rec: Mapping[str, Any], remedy: str,
                      now: str | pd.Timestamp | None = None) -> None:
    """Refuses the later sitting ``rec`` (:func:`sitting_record`) when its delay has not
    passed at ``now`` (None: the current time): the rule of
    :func:`vasim.study.sitting_rule.early_sitting`, shared by ``vasim study resume`` and the
    viewer, each with its own ``remedy``.

    Raises:
        StoreError: naming the session, subject, sitting, block, delay, when the previous
            trial ended, when the sitting is due and how long that is.
    """
    early = early_sitting(sitting=int(rec["sitting"]), block=str(rec["block"]),
                          delay_days=float(rec["delay_days"]),
                          previous_ended_at=rec.get("previous_ended_at"),
                          now=pd.Timestamp.now(tz="UTC") if now is None else now)
    if early is not None:
        raise StoreError(early.message(session.id, session.subject, remedy))


def record_sitting(store: TrialStore, session: Session, st: ScheduledTrial,
                   rec: Mapping[str, Any]) -> None:
    """Stores the ``'sitting'`` event on the trial that began a later sitting."""
    import json

    tid = store.schedule(session.id)["trial_id"].iloc[st.index]
    if not pd.isna(tid):
        store.add_event(int(tid), SITTING_EVENT, json.dumps(dict(rec), sort_keys=True))


def after_simulated_trial(store: TrialStore, session: Session, st: ScheduledTrial) -> int:
    """What follows a simulated trial (``vasim study simulate``): the record of a later
    sitting it began (a simulated delay: no real waiting) and the gates' decisions
    (``vasim.study.gates.apply_gates``); returns the trials the gates added."""

    delay = sitting_begins(session, st)
    if delay is not None:
        record_sitting(store, session, st, sitting_record(store, session, st, delay, True))
    return apply_gates(store, session.id)


def _timed_out_attempts(store: TrialStore, session_id: int, index: int) -> int:
    """Completed attempts at a scheduled trial whose outcome was 'timed_out'."""
    t = store.trials("completed", outcome="timed_out")
    return int(((t["session_id"] == session_id) & (t["schedule_index"] == index)).sum())


def _release_timed_out(store: TrialStore, session: Session, index: int | None = None,
                       ) -> list[int]:
    """Releases the scheduled trials (one ``index``, or all) whose linked trial timed out,
    when the protocol repeats timed-out trials and repeats are left; returns their indices.
    """
    if not session.protocol.repeat_timed_out:
        return []
    sched = store.schedule(session.id)
    linked = sched[sched["trial_id"].notna()]
    if index is not None:
        linked = linked[linked["trial_index"] == index]
    if linked.empty:
        return []
    timed_out = store.trials("completed", outcome="timed_out")
    timed_out = timed_out[timed_out["session_id"] == session.id]
    released = []
    for idx, tid in zip(linked["trial_index"], linked["trial_id"], strict=True):
        n = int((timed_out["schedule_index"] == idx).sum())
        if int(tid) in set(timed_out["id"]) and n <= MAX_TIMED_OUT_REPEATS:
            store.release_scheduled(session.id, int(idx), reason=(
                f"timed out; repeated (protocol repeat_timed_out, repeat {n} of at most "
                f"{MAX_TIMED_OUT_REPEATS})"))
            released.append(int(idx))
    return released


def abort_session(store: TrialStore, session_id: int, reason: str) -> None:
    """Closes a running session for good ('aborted'), keeping its trials.

    Raises:
        StoreError: unknown session or not running. ConfigError: empty reason.
    """
    expect(isinstance(reason, str) and reason.strip(), reason,
            "the reason for aborting the session", field="reason")
    store.set_session_status(session_id, "aborted", notes=reason)


# ---------------------------------------------------------------------- questionnaires
def record_answers(store: TrialStore, session_id: int, questionnaire: Literal["pre", "post"],
                   answers: Mapping[str, Any], *, source: str | None = None) -> int:
    """Validates one questionnaire's answers against the session's protocol and stores
    them (and, for ``pre``, the demographics) in one transaction.

    Args:
        store: the study store. session_id: the session. questionnaire: "pre" / "post".
        answers: item id -> answer (see ``protocol.validate_answers``).
        source: where the answers came from (named in errors).

    Returns:
        The number of answer rows stored.

    Raises:
        ConfigError: answers that do not fit the protocol. StoreError: already answered.
    """
    session = load_session(store, session_id)
    rows, demo = validate_answers(session.protocol, questionnaire, answers, source=source)
    return store.add_answers(session.id, questionnaire, rows, demographics=demo)


def load_answers_file(path: str | Path) -> dict[str, dict[str, Any]]:
    """Reads an answers file: TOML with a ``[pre]`` and/or ``[post]`` table of item ->
    answer, e.g.::

        [pre]
        group = "resident"
        specialisation = "general_surgery"
        laparoscopy_experience = "11-50"
        simulator_experience = "occasional"
        robotic_experience = "none"

        [post]
        best_vf = "ff"
        worst_vf = "ag"
        rating = { vg = 6, ag = 3, ms = 7, mag = 5, ff = 9 }
        proposed_schemas = [["ff", "mag"]]
        comments = "FF felt natural."

    Raises:
        ConfigError: unreadable file, invalid TOML, or other top-level tables.
    """
    p = check_file(path, what="an answers file")
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read answers file: {exc}", file=p) from exc
    data = parse_toml(text, file=p, kind="answers file")   # the one TOML reader
    for key, value in data.items():
        check_choice(key, key, ("pre", "post"), file=p)
        check_table(value, key, file=p, what="a [pre] or [post] table of item -> answer")
    return data


__all__ = [
    "BROWSER_HINT",
    "OPERATORS",
    "SITTING_EVENT",
    "Session",
    "SessionSettings",
    "abort_session",
    "after_simulated_trial",
    "check_again",
    "check_sitting_due",
    "find_session",
    "load_answers_file",
    "load_session",
    "new_seed",
    "record_answers",
    "record_sitting",
    "run_session",
    "sitting_begins",
    "sitting_record",
    "start_session",
    "stored_time",
    "trial_seed",
]
