"""Simulated cohorts: synthetic subjects run a protocol through the real session code.

``simulate_cohort`` creates, for subjects ``SIM001``, ``SIM002``, ... one session each
(``vasim.study.session.start_session``: the same protocol text, seed, stored schedule and
store as a real subject), records their pre-questionnaire, runs every scheduled trial with
the scripted operator, and records their post-questionnaire once their session completes.
Trials run in parallel worker processes (``spawn``); the parent process is the **one writer**
of the SQLite file: it begins each trial row ('running') when it hands the trial to a worker
and makes it durable (``finish_trial``, one transaction) when the result comes back, so
SQLite never sees concurrent writers. Re-running the same command continues where it
stopped: trials left 'running' by a killed run are marked 'interrupted' when the store opens
and run again as new attempts (same trial seed: the same trial).

Models (**decisions**): a cohort is a declared scenario (``vasim.operator.scenario``,
``protocols/scenarios/*.toml``; default ``seed_plausible``): its groups (learning rate and
asymptote, experience and skill), fixture effects, effect scale and questionnaire model are
assumptions with sources, not fits to the seed. Each session stores the scenario's text,
sha256 and the effect scale (``settings.extra["scenario"]``) and the operator label
"scripted (declared scenario, synthetic)".

* Subjects: ``n_surgeons`` surgeons and ``n_subjects - n_surgeons`` residents, assigned to
  the codes by a seeded permutation (codes do not reveal the group). Subject j draws from
  its own stream ``SeedSequence([seed, 5, j])``: the laparoscopy experience and, from it,
  the operator profile (``Scenario.sample_subject``: demographics and skill drawn
  together), then the other demographics; its session seed is
  ``SeedSequence([seed, 6, j])``, and its pre / post answers draw from
  ``SeedSequence([session seed, 7])`` / ``[session seed, 8]``. Same command, same cohort.
* Demographics: laparoscopy_experience from the scenario's group (with the skill); the
  others (``DEMOGRAPHIC_MODEL``, assumed, categorical, per group surgeon | resident):

  - specialisation: general surgery .6, gynaecology .15, urology .15, other .1 (both);
  - simulator_experience: none .4, occasional .5, regular .1 | none .3, occasional .5,
    regular .2;
  - robotic_experience: none .6, observed .2, assisted .1, performed .1 | none .7,
    observed .25, assisted .05.

* Post-questionnaire answers from what the subject experienced
  (``vasim.operator.questionnaire``, the scenario's ``[questionnaire]`` noise model): for
  each assisted condition c the measured benefit ``b_c = ln(E_probe / E_c)``, E the mean
  path deviation (``path_dev_mean_mm``, accuracy independent of speed;
  ``total_error_l1`` for trials stored without it) of the subject's completed trials of c
  and of its fixture-free probe trials (b > 0: the fixture reduced the error); "best" and
  "worst" are logit choices in b, the 0-10 rating linear in b plus noise (an unlabelled
  condition choice: uniform). No seed share or rating enters: with no fixture effect
  there is no preference. Proposed schemas: 0, 1 or 2 proposals with probabilities
  0.2, 0.5, 0.3 (``PROPOSALS_P``, capped by ``max_entries``), proposal m (1-based) = the
  ``min_size + m - 1`` conditions of largest best-utility. Likert items:
  ``clip(round(N(3.5, 1)), 1, 5)`` (no performance model); choice and integer items:
  uniform; free text: left unanswered (empty if required).

Performance: a worker runs the 1 kHz trial loop at ~20x real time per core; the parent's
writes (one transaction per trial) overlap the workers' computing. ``bench/study_simulate``
measures the cohort's real-time ratio.

Example:
    >>> import numpy as np
    >>> d = draw_demographics(np.random.default_rng(0), "resident")
    >>> d.group, d.laparoscopy_experience in ("none", "1-10", "11-50", "51-200")
    ('resident', True)
"""

from __future__ import annotations

import math
import multiprocessing
import os
import time
from collections import Counter
from collections.abc import Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from typing import Any

import pandas as pd

from vasim.core.config import check_int, check_number, expect
from vasim.core.errors import ConfigError, StoreError
from vasim.core.progress import progress_bar
from vasim.fixtures.schema import Schema, load_schema
from vasim.operator.scenario import (
    Scenario,
    default_scenario,
    load_scenario,
)
from vasim.records.point_metrics import POINT_COLUMNS
from vasim.records.samples import SampleBuffer
from vasim.records.trial_meta import TrialMeta
from vasim.records.trial_metrics import MetricParams
from vasim.study.gates import apply_gates, expert_groups
from vasim.study.protocol import Protocol, ScheduledTrial, gated_blocks
from vasim.study.session import (
    Session,
    SessionSettings,
    after_simulated_trial,
    load_session,
    record_answers,
    start_session,
)
from vasim.study.simulated_subjects import (
    DEMOGRAPHIC_MODEL,
    SimulatedSubject,
    cohort_subjects,
    draw_demographics,
    measured_benefits,
    simulated_answers,
    subject_stream,
)
from vasim.study.store import TrialStore
from vasim.trials.configs import AnyTrialConfig, VfTrialConfig
from vasim.trials.kinds import TELEOPERATION_MODES
from vasim.trials.lifecycle import (
    StoredTrial,
    begin_stored_trial,
    interruption_reason,
    stored_trial,
)
from vasim.trials.registry import TRIAL_KINDS


@dataclass(frozen=True)
class CohortReport:
    """What a ``simulate_cohort`` call did.

    Attributes:
        subjects: subjects in the cohort. sessions_completed: sessions now completed.
        trials_run: trials completed by this call. sim_seconds: simulated time of those
        trials [s]. wall_seconds: wall-clock time of the call [s]. workers: processes used
        (0 = in-process).
    """

    subjects: int
    sessions_completed: int
    trials_run: int
    sim_seconds: float
    wall_seconds: float
    workers: int

    @property
    def realtime_ratio(self) -> float:
        """Simulated seconds per wall-clock second."""
        return self.sim_seconds / self.wall_seconds if self.wall_seconds > 0 else math.nan


def _record_post(store: TrialStore, session: Session, subject: SimulatedSubject) -> None:
    """Draws and stores the post-questionnaire of a completed simulated session."""
    if session.protocol.post.empty:
        return
    sched = store.schedule(session.id)
    ids = [int(t) for t in sched["trial_id"].dropna()]
    tm = store.trial_metrics()
    tm = tm[tm["trial_id"].isin(ids)]
    metric = "path_dev_mean_mm"
    if tm.loc[tm["metric"] == metric, "value"].notna().sum() == 0:
        metric = "total_error_l1"   # trials stored before the path-deviation measures
    tm = tm[tm["metric"] == metric]
    errors = dict(zip(tm["trial_id"].astype(int), tm["value"].astype(float), strict=True))
    b = measured_benefits(sched, errors)
    rng = subject_stream(subject.session_seed, 8)
    scenario = session.scenario[0] or default_scenario()
    answers = simulated_answers(session.protocol, "post", rng, measured=b,
                                model=scenario.questionnaire)
    record_answers(store, session.id, "post", answers, source=f"simulated {subject.code}")


# ------------------------------------------------------------------------------ workers
def simulate_trial(config: AnyTrialConfig, params: MetricParams) -> dict[str, Any]:
    """Runs one trial without a store (a worker's job; its kind's ``simulate``,
    ``vasim.trials.registry``); returns what the writer stores.

    Returns:
        dict with ``columns`` (flat sample columns, copies), ``active_fixtures``,
        ``metrics`` (per-point frame), ``summary``, ``events``, ``trial_metrics``,
        ``wall_time`` [s], ``sim_time`` [s].
    """
    return TRIAL_KINDS.of(config).simulate(config, params)


@dataclass(frozen=True, eq=False)
class _Outcome:
    """A worker's dict as the ``ResultLike`` the life cycle stores."""

    samples: SampleBuffer
    metrics: pd.DataFrame
    summary: Mapping[str, Any]
    events: list[Any]
    trial_metrics: Mapping[str, float]


def store_outcome(rec: StoredTrial, out: Mapping[str, Any]) -> None:
    """Finishes the stored trial ``rec`` with a worker's dict ``out`` (``simulate_trial``'s):
    its sample columns as a ``SampleBuffer``, its point metrics (``StoreError`` if their
    columns are not ``POINT_COLUMNS``), summary, events and trial metrics. The one way a
    simulated trial is stored (``simulate_cohort`` and the power study's kept cohorts)."""
    buf = SampleBuffer.from_columns(out["columns"], active_fixtures=out["active_fixtures"])
    metrics = out["metrics"]
    if list(metrics.columns) != list(POINT_COLUMNS):
        raise StoreError(f"worker returned point metrics with columns {list(metrics.columns)}")
    rec.finish(_Outcome(buf, metrics, out["summary"], out["events"], out["trial_metrics"]))


@dataclass(frozen=True)
class _Job:
    session: Session
    subject: SimulatedSubject
    scheduled: ScheduledTrial
    config: AnyTrialConfig


# ------------------------------------------------------------------------------ cohort
def scenario_record(scenario: Scenario, effect_scale: float) -> dict[str, Any]:
    """What a simulated session stores of its scenario (``settings.extra["scenario"]``):
    name, text, sha256 and the effect scale."""
    return {"name": scenario.name, "sha256": scenario.sha256, "effect_scale": effect_scale,
            "text": scenario.text}


TELEOP_DEFAULT_SCENARIO = "teleop_mechanism_only"
"""The scenario of a protocol of teleoperation modes without ``--scenario``: the mechanism
alone (issue #25 item 6: a comparison of the modes is first reported without penalties)."""


def is_teleop_protocol(protocol: Protocol) -> bool:
    """Whether the protocol's conditions are teleoperation modes (the MRCP study)."""
    return any(b.condition in TELEOPERATION_MODES for b in protocol.blocks)


def default_scenario_for(protocol: Protocol) -> Scenario:
    """``teleop_mechanism_only`` for a protocol of teleoperation modes, else the default
    VF scenario (``seed_plausible``)."""
    if is_teleop_protocol(protocol):
        return load_scenario(TELEOP_DEFAULT_SCENARIO)
    return default_scenario()


def check_scenario_kind(protocol: Protocol, scenario: Scenario,
                        file: str | os.PathLike[str] | None = None) -> None:
    """Refuses a VF scenario for a protocol of teleoperation modes and vice versa.

    Raises:
        ConfigError: (field ``--scenario``) naming the file (or the scenario), its kind and
            the protocol's.
    """
    want = "teleop" if is_teleop_protocol(protocol) else "vf"
    what = {"teleop": "a teleoperation scenario (with [teleop]: teleop_mechanism_only, "
                      "teleop_assumed)",
            "vf": "a VF scenario (no [teleop]: seed_plausible, null)"}
    expect(scenario.kind == want, scenario.name, f"{what[want]} for protocol "
           f"{protocol.name!r}, not {what[scenario.kind].split(' (')[0]} {scenario.name!r}",
           file=None if file is None else str(file), field="--scenario")


def prepare_sessions(store: TrialStore, protocol: Protocol,
                     subjects: Sequence[SimulatedSubject], *, cohort_seed: int,
                     max_trial_time: float | None = None,
                     scenario: Scenario | None = None,
                     effect_scale: float = 1.0) -> list[tuple[SimulatedSubject, int]]:
    """Finds or creates each subject's session of ``protocol`` (with its pre answers).

    An existing session must come from the same cohort (seed and subject number, stored
    with it) and the same scenario and effect scale; an aborted one is left alone.

    Raises:
        ConfigError: a subject code already used by another cohort or a real subject, or
            by this cohort under another scenario or effect scale.
    """
    sc = scenario or default_scenario()
    rec = scenario_record(sc, effect_scale)
    out = []
    for subj in subjects:
        df = store.sessions(subject=subj.code, protocol=protocol.name)
        live = df[df["status"] != "aborted"]
        if not live.empty:
            sid = int(live["id"].iloc[-1])
            extra = (store.session(sid)["config"] or {}).get("extra", {})
            cohort = extra.get("cohort", {})
            if cohort.get("seed") != cohort_seed or cohort.get("subject") != subj.number:
                raise ConfigError(
                    f"subject {subj.code} of {store.path} already has session {sid} of "
                    f"{protocol.name!r} from another cohort ({cohort or 'not simulated'}); "
                    f"use another database or the cohort seed {cohort.get('seed')!r}",
                    field="seed")
            if cohort.get("group", subj.group) != subj.group:
                # Which subjects are surgeons depends on the cohort size: the same seed with
                # another --subjects/--surgeons would mix two cohorts' groups and profiles.
                raise ConfigError(
                    f"subject {subj.code} of {store.path} was simulated as a "
                    f"{cohort['group']} in a cohort of another size or surgeon count (now a "
                    f"{subj.group}); use the same --subjects and --surgeons as before, or "
                    f"another database", field="subjects")
            had = extra.get("scenario") or {}
            if (had.get("sha256"), had.get("effect_scale", 1.0)) != (sc.sha256, effect_scale):
                raise ConfigError(
                    f"subject {subj.code} of {store.path} was simulated under scenario "
                    f"{had.get('name', 'seed calibration (before issue #25)')!r} at effect "
                    f"scale {had.get('effect_scale', 1.0)!r} (now {sc.name!r} at "
                    f"{effect_scale!r}); use the same --scenario and --effect-scale, or "
                    "another database", field="scenario")
            out.append((subj, sid))
            continue
        settings = SessionSettings(
            operator="scripted", profile=subj.profile, max_trial_time=max_trial_time,
            extra={"cohort": {"seed": cohort_seed, "subject": subj.number,
                              "group": subj.group}, "scenario": rec})
        sid = start_session(store, protocol, subj.code, seed=subj.session_seed,
                            settings=settings)
        if not protocol.pre.empty:
            answers = simulated_answers(protocol, "pre", subject_stream(subj.session_seed, 7),
                                        demographics=subj.demographics)
            record_answers(store, sid, "pre", answers, source=f"simulated {subj.code}")
        out.append((subj, sid))
    return out


def _jobs(store: TrialStore, sessions: Sequence[tuple[SimulatedSubject, int]]) -> list[_Job]:
    """Each running session's pending trials, up to and including its first pending trial
    of a gated block (the trials after it wait for the gate's decision)."""
    jobs = []
    for subj, sid in sessions:
        session = load_session(store, sid)
        if session.status != "running":
            continue
        gated = {b.name for b in gated_blocks(session.protocol)}
        for st in session.pending:
            jobs.append(_Job(session, subj, st, session.trial_config(st)))
            if st.block in gated and not st.probe:
                break
    return jobs


def _finish_sessions(store: TrialStore, sessions: Sequence[tuple[SimulatedSubject, int]],
                     only: set[int] | None = None) -> int:
    """Completes the sessions with no pending trial and records their post answers."""
    n = 0
    for subj, sid in sessions:
        if only is not None and sid not in only:
            continue
        session = load_session(store, sid)
        if session.status == "running" and not session.pending:
            store.set_session_status(sid, "completed")
            session = load_session(store, sid)
        if session.status == "completed":
            n += 1
            if store.answers(sid).query("questionnaire == 'post'").empty:
                _record_post(store, session, subj)
    return n


@dataclass(frozen=True)
class CohortPlan:
    """What a simulated cohort is (``simulate_cohort``): the same plan and seed give the
    same stored trials.

    Attributes:
        n_subjects, n_surgeons: cohort size and surgeons among it (the rest residents).
        seed: cohort seed (subjects, profiles, schedules, answers).
        scenario: the declared scenario (None: ``default_scenario_for(protocol)``); its
            kind must be the protocol's (``check_scenario_kind``).
        effect_scale: x the scenario's fixture effects and mechanism gain (0: no fixture
            effect at all; ``Scenario.effects``, ``Scenario.mechanism``); in a
            teleoperation scenario x its mode penalties (``Scenario.teleop_effects``; 0: the
            mechanism alone).
        max_trial_time: trial time limit [s] (None: the protocol's).
    """

    n_subjects: int = 46
    n_surgeons: int = 31
    seed: int = 7
    scenario: Scenario | None = None
    effect_scale: float = 1.0
    max_trial_time: float | None = None


@dataclass(frozen=True)
class CohortRun:
    """How a cohort is run (``simulate_cohort``): none of it changes a stored trial.

    Attributes:
        workers: worker processes (None: ``os.cpu_count()``; 0: run in this process).
        progress: progress output over the cohort's trials (:mod:`vasim.core.progress`).
        max_trials_per_subject: run at most this many (the first pending) trials of each
            subject (None: all); for tests and benchmarks.
    """

    workers: int | None = None
    progress: bool = True
    max_trials_per_subject: int | None = None


def simulate_cohort(
    db: str | os.PathLike[str],
    protocol: Protocol,
    plan: CohortPlan = CohortPlan(),
    run: CohortRun = CohortRun(),
) -> CohortReport:
    """Simulates (or continues simulating) a cohort into the study database ``db``.

    Args:
        db: the SQLite study store (created if missing).
        protocol: the protocol every subject runs (``check_runnable``).
        plan: the cohort (``CohortPlan``: size, seed, scenario, effect scale, time limit).
        run: how it is run (``CohortRun``: workers, progress, a per-subject trial cap).

    Returns:
        A ``CohortReport``.

    Raises:
        ConfigError: bad counts, a protocol that cannot run, a clash with another cohort.
        KeyboardInterrupt: after marking the trials in flight 'interrupted'.
    """
    protocol.check_runnable()
    sc = plan.scenario or default_scenario_for(protocol)
    check_scenario_kind(protocol, sc)
    effect_scale, workers = plan.effect_scale, run.workers
    check_number(effect_scale, "effect_scale", ge=0)
    subjects = cohort_subjects(plan.n_subjects, plan.n_surgeons, plan.seed,
                               latin_square=protocol.block_order == "latin_square",
                               scenario=sc)
    n_workers = (os.cpu_count() or 1) if workers is None else int(workers)
    check_int(n_workers, "workers", lo=0)
    t0 = time.perf_counter()
    with TrialStore(db) as store:
        sessions = prepare_sessions(store, protocol, subjects, cohort_seed=plan.seed,
                                    max_trial_time=plan.max_trial_time, scenario=sc,
                                    effect_scale=effect_scale)
        _finish_sessions(store, sessions)
        total = sum(len(load_session(store, sid).schedule) for _, sid in sessions)
        initial = total - sum(len(load_session(store, sid).pending) for _, sid in sessions)
        bar = progress_bar(total, f"cohort {protocol.name}", "trial", initial=initial,
                           enabled=run.progress)
        tally = _Tally(store, sessions, bar, initial)
        try:
            runner = _run_in_process if n_workers == 0 else _run_in_pool
            done_first: list[tuple[SimulatedSubject, int]] = []
            for phase in _phases(protocol, sessions):
                if any(load_session(store, sid).status == "running" for _, sid in done_first):
                    break   # the benchmark's experts are not done (max_trials_per_subject)
                while True:   # rounds: a gated trial's decision comes before what follows
                    for _, sid in phase:   # decisions a killed run left undone
                        apply_gates(store, sid)
                    jobs = _capped(_jobs(store, phase), run.max_trials_per_subject,
                                   tally.taken)
                    if not jobs:
                        break
                    remaining = Counter(job.session.id for job in jobs)
                    for job, out in runner(store, jobs, n_workers):
                        tally.count(job, out, remaining)
                done_first = phase
            done = _finish_sessions(store, sessions)
        finally:
            bar.close()
    return CohortReport(subjects=len(subjects), sessions_completed=done,
                        trials_run=tally.trials, sim_seconds=tally.sim,
                        wall_seconds=time.perf_counter() - t0, workers=n_workers)


def _capped(jobs: list[_Job], cap: int | None, taken: Counter[int]) -> list[_Job]:
    """The first jobs of each session up to ``cap`` trials per session over the whole run
    (``taken``: trials already run per session id); all of them when ``cap`` is None."""
    if cap is None:
        return jobs
    left = {j.session.id: cap - taken[j.session.id] for j in jobs}
    kept = []
    for j in jobs:
        if left[j.session.id] > 0:
            left[j.session.id] -= 1
            kept.append(j)
    return kept


@dataclass
class _Tally:
    """The run's counts as trials come back: progress, and each session's answers once its
    last trial of the round is in."""

    store: TrialStore
    sessions: Sequence[tuple[SimulatedSubject, int]]
    bar: Any
    initial: int
    trials: int = 0
    sim: float = 0.0
    taken: Counter[int] = field(default_factory=Counter)

    def count(self, job: _Job, out: Mapping[str, Any], remaining: Counter[int]) -> None:
        self.trials += 1
        self.taken[job.session.id] += 1
        self.sim += out["sim_time"]
        after_simulated_trial(self.store, job.session, job.scheduled)
        self.bar.total = max(self.bar.total, self.initial + self.trials)
        self.bar.update(1)
        self.bar.set_postfix_str(f"{job.subject.code} trial "
                                 f"{job.scheduled.index + 1} "
                                 f"{job.scheduled.condition}")
        remaining[job.session.id] -= 1
        if remaining[job.session.id] == 0:  # answers once it is complete
            _finish_sessions(self.store, self.sessions, only={job.session.id})


def _phases(protocol: Protocol, sessions: Sequence[tuple[SimulatedSubject, int]],
            ) -> list[list[tuple[SimulatedSubject, int]]]:
    """All sessions at once, or the gates' expert groups first (``gates.expert_groups``)."""
    first = expert_groups(protocol)
    return [list(sessions)] if not first else [
        [x for x in sessions if x[0].group in first],
        [x for x in sessions if x[0].group not in first]]


_SCHEMAS: dict[str, Schema] = {}


def _meta(job: _Job) -> TrialMeta:
    """The trial row of ``job``, built by its kind (schemas loaded once per process)."""
    cfg = job.config
    schema = None
    if isinstance(cfg, VfTrialConfig):
        schema = _SCHEMAS.get(cfg.schema)
        if schema is None:
            schema = _SCHEMAS[cfg.schema] = load_schema(cfg.schema)
        assert cfg.profile is not None
    return TRIAL_KINDS.of(cfg).meta(cfg, schema=schema, session_id=job.session.id,
                                    schedule_index=job.scheduled.index,
                                    protocol=job.session.protocol.name)


def _run_in_process(store: TrialStore, jobs: Sequence[_Job],
                    n_workers: int) -> Iterator[tuple[_Job, dict[str, Any]]]:
    for job in jobs:
        with stored_trial(store, _meta(job)) as rec:
            out = simulate_trial(job.config, job.session.metric_params)
            store_outcome(rec, out)
        yield job, out


def _run_in_pool(store: TrialStore, jobs: Sequence[_Job],
                 n_workers: int) -> Iterator[tuple[_Job, dict[str, Any]]]:
    """Workers compute, this process writes; at most 2 trials in flight per worker."""
    ctx = multiprocessing.get_context("spawn")
    pending: dict[Future[dict[str, Any]], tuple[_Job, StoredTrial]] = {}
    queue = list(jobs)
    window = 2 * n_workers
    pool = ProcessPoolExecutor(max_workers=n_workers, mp_context=ctx)
    try:
        while queue or pending:
            while queue and len(pending) < window:
                job = queue.pop(0)
                rec = begin_stored_trial(store, _meta(job))  # finished when its worker is
                try:
                    fut = pool.submit(simulate_trial, job.config, job.session.metric_params)
                except BaseException as exc:
                    rec.interrupt(interruption_reason(exc))
                    raise
                pending[fut] = (job, rec)
            done, _ = wait(list(pending), return_when=FIRST_COMPLETED)
            # store in submission order among the finished ones (deterministic ids per run)
            for fut in [f for f in pending if f in done]:
                job, rec = pending.pop(fut)
                try:
                    out = fut.result()
                except BaseException as exc:
                    rec.interrupt(f"worker failed: {interruption_reason(exc)}")
                    raise
                store_outcome(rec, out)
                yield job, out
    except BaseException as exc:
        for _, rec in pending.values():
            rec.interrupt(f"cohort run stopped: {type(exc).__name__}")
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


__all__ = [
    "DEMOGRAPHIC_MODEL",
    "TELEOP_DEFAULT_SCENARIO",
    "CohortPlan",
    "CohortReport",
    "CohortRun",
    "SimulatedSubject",
    "check_scenario_kind",
    "cohort_subjects",
    "default_scenario_for",
    "draw_demographics",
    "is_teleop_protocol",
    "measured_benefits",
    "prepare_sessions",
    "scenario_record",
    "simulate_cohort",
    "simulate_trial",
    "simulated_answers",
    "store_outcome",
]
