"""One Monte Carlo cohort of a power run: simulated in memory, analysed as the report does.

:func:`cohort_tests` is the unit of work a Ray task runs (:mod:`vasim.study.power.driver`):
it draws the cohort's subjects exactly as ``vasim study simulate`` does
(``vasim.study.cohort.cohort_subjects``: groups, operator profiles, session seeds, the
latin-square seeds), realises each subject's schedule (``generate_schedule``) and trial
configurations through the session code (``Session.trial_config``: the same trial seeds,
practice and operator adjustments as a stored session), runs every trial with its kind's
headless job (``simulate_trial``) and keeps only what the analysis reads: the per-point
metrics and the per-trial metrics. Those become a
:class:`~vasim.study.report.data.StudyData` like the one ``load_study`` reads from a store,
and the report's own functions analyse it (``analyse_vf``, then the PRIMARY probe
model's fixture test, :func:`~vasim.study.report.primary.probe_model_tests`, and the
seed's RM-ANOVAs, :func:`~vasim.study.report.primary.primary_tests`).

**Decisions**:

* No store, no ``TrialSink``: the analyses need per-trial measures, not the 1 kHz samples,
  so each trial's samples are dropped in the worker as soon as its metrics are computed
  (``bench/power.py`` measures what the SQLite writes would have cost).
  ``keep_dir`` (``--keep-cohorts DIR``) writes the cohort as a real study database instead
  (``DIR/power_N{N}_c{k}.sqlite``, samples included), one writer per file, and analyses it
  through ``load_study``: the store path and the in-memory path give the same tests
  (``tests/study/power/test_cohort.py``).
* The sessions carry the design's scenario at its effect scale (subjects, groups, the
  fixture mechanisms' gain, ``Session.trial_config``); each trial's operator adjustment is
  then re-derived with the design's effects (the scenario's, with the protocol's
  ``[power.effects]`` and ``--effects`` over them, scaled: ``trial_adjustment(...,
  effects)``); every other field of the configuration is the session's.
* Power cohorts have no questionnaires (no test of the power run reads them).
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from vasim.operator.learning import FixtureEffect, trial_adjustment
from vasim.operator.scenario import Scenario, default_scenario
from vasim.study.cohort import (
    SimulatedSubject,
    cohort_subjects,
    scenario_record,
    simulate_trial,
    store_outcome,
)
from vasim.study.power.design import PowerDesign, cohort_seed, surgeons_for
from vasim.study.power.estimate import COHORT_COLUMNS
from vasim.study.protocol import Protocol, ScheduledTrial
from vasim.study.protocol.schedule import generate_schedule
from vasim.study.report.analysis import analyse_vf
from vasim.study.report.data import StudyData, load_study
from vasim.study.report.primary import primary_tests, probe_model_tests
from vasim.study.session import Session, SessionSettings, start_session
from vasim.study.store import SCHEDULE_COLUMNS, TrialStore
from vasim.trials.configs import AnyTrialConfig
from vasim.trials.lifecycle import stored_trial
from vasim.trials.registry import TRIAL_KINDS

POINT_READ = ("point", "reached", "t_reached", "error_l1", "error_l1_mm_s", "latency")
"""The per-point columns the report reads (``load_study``)."""


def subject_session(protocol: Protocol, subject: SimulatedSubject, *, dt: float,
                    max_trial_time: float | None,
                    extra: Mapping[str, Any] | None = None) -> Session:
    """The session a stored simulated subject would get, in memory (id = subject number);
    ``extra``: its ``settings.extra`` (e.g. the scenario record).

    Its ``trial_config`` gives the very configurations ``vasim study simulate`` runs.
    """
    settings = SessionSettings(operator="scripted", profile=subject.profile,
                               max_trial_time=max_trial_time, dt=dt, extra=dict(extra or {}))
    schedule = tuple(generate_schedule(protocol, subject.session_seed))
    return Session(id=subject.number, subject=subject.code, protocol=protocol,
                   seed=subject.session_seed, status="running", settings=settings,
                   schedule=schedule, completed=(None,) * len(schedule))


def trial_configs(session: Session, profile: Any,
                  effects: Mapping[str, FixtureEffect] | None = None
                  ) -> list[tuple[ScheduledTrial, AnyTrialConfig]]:
    """Each scheduled trial with its configuration under ``effects`` (module decisions).

    Args:
        session: the subject's session (:func:`subject_session`).
        profile: the subject's own operator profile (before any trial adjustment).
        effects: fixture effects re-derived over the session's configuration (None: the
            session's own, i.e. its stored scenario at its effect scale).
    """
    out = []
    for st in session.schedule:
        cfg = session.trial_config(st)
        if effects is not None and cfg.kind == "vf":
            history = [t.condition for t in session.schedule[:st.index]]
            adj = trial_adjustment(history, st.condition, effects)
            cfg = replace(cfg, profile=adj.apply(profile), practice=round(adj.practice))
        out.append((st, cfg))
    return out


@dataclass(frozen=True)
class CohortTrials:
    """What a cohort's analysis needs, in the frames ``load_study`` returns.

    Attributes:
        schedule: ``SCHEDULE_COLUMNS`` + ``subject``, ``stage``. points: ``trial_id`` +
        :data:`POINT_READ`. metrics: per-trial metrics, wide, index ``trial_id``.
        sim_seconds: simulated time [s]. n_trials: trials run.
    """

    schedule: pd.DataFrame
    points: pd.DataFrame
    metrics: pd.DataFrame
    sim_seconds: float
    n_trials: int


def schedule_frame(rows: list[dict[str, Any]]) -> pd.DataFrame:
    """The schedule frame ``load_study`` reads from a store, from scheduled-trial rows
    (``ScheduledTrial.as_row()`` + ``session_id, trial_id, attempts, subject``): store
    dtypes, ordered by session and trial index, with ``stage``."""
    df = pd.DataFrame(rows, columns=[*SCHEDULE_COLUMNS, "subject"])
    for c in ("session_id", "trial_index", "block_index", "trial_in_block", "variant",
              "repetition", "attempts"):
        df[c] = df[c].astype(np.int64)
    df["probe"] = df["probe"].astype(bool)
    for c in ("probe_index", "trial_id"):
        df[c] = df[c].astype("Int64")
    df = df.sort_values(["session_id", "trial_index"]).reset_index(drop=True)
    # as load_study: the probe number of the next VF-free trial (own number for a probe)
    df["stage"] = df.groupby("session_id")["probe_index"].bfill().astype("Int64")
    return df


def simulate_in_memory(protocol: Protocol, subjects: Sequence[SimulatedSubject], *,
                       dt: float, max_trial_time: float | None,
                       effects: Mapping[str, FixtureEffect] | None = None,
                       extra: Mapping[str, Any] | None = None) -> CohortTrials:
    """Runs every scheduled trial of ``subjects`` in this process, keeping metrics only.

    Trial ids are 1, 2, ... in subject then schedule order (the order a fresh store
    written by :func:`simulate_to_store` numbers them).
    """
    sched_rows: list[dict[str, Any]] = []
    point_frames: list[pd.DataFrame] = []
    metric_rows: dict[int, Mapping[str, float]] = {}
    sim, tid = 0.0, 0
    for subj in subjects:
        session = subject_session(protocol, subj, dt=dt, max_trial_time=max_trial_time,
                                  extra=extra)
        for st, cfg in trial_configs(session, subj.profile, effects):
            out = simulate_trial(cfg, session.metric_params)
            tid += 1
            sim += float(out["sim_time"])
            pts = out["metrics"].loc[:, list(POINT_READ)].copy()
            pts.insert(0, "trial_id", tid)
            point_frames.append(pts)
            metric_rows[tid] = dict(out["trial_metrics"])
            sched_rows.append({**st.as_row(), "session_id": session.id, "trial_id": tid,
                               "attempts": 1, "subject": subj.code})
    points = pd.concat(point_frames, ignore_index=True) if point_frames else \
        pd.DataFrame(columns=["trial_id", *POINT_READ])
    points = points.astype({"trial_id": np.int64, "point": np.int64, "t_reached": np.float64,
                            "error_l1": np.float64, "error_l1_mm_s": np.float64,
                            "latency": np.float64})
    points["reached"] = points["reached"].astype(bool)
    metrics = pd.DataFrame.from_dict(metric_rows, orient="index").astype(float)
    metrics.index = pd.Index(metrics.index.astype(np.int64), name="trial_id")
    return CohortTrials(schedule=schedule_frame(sched_rows), points=points, metrics=metrics,
                        sim_seconds=sim, n_trials=tid)


def study_data(protocol: Protocol, trials: CohortTrials) -> StudyData:
    """The cohort as the report's :class:`StudyData` (only the frames the VF analysis
    reads are filled; the others are empty)."""
    empty = pd.DataFrame()
    return StudyData(db=Path(":memory:"), protocol_name=protocol.name, protocol=protocol,
                     notes=(), sessions=empty, schedule=trials.schedule, trials=empty,
                     n_outside=0, points=trials.points, metrics=trials.metrics,
                     demographics=empty, answers=empty, protocols_present=(protocol.name,),
                     schema_version=None)



def simulate_to_store(db: Path, protocol: Protocol, subjects: Sequence[SimulatedSubject], *,
                      dt: float, max_trial_time: float | None,
                      effects: Mapping[str, FixtureEffect] | None = None,
                      extra: Mapping[str, Any] | None = None) -> float:
    """Runs the cohort into a new study database ``db`` (``--keep-cohorts``): one session
    per subject (``start_session``, with ``extra`` kept in its settings), every trial
    stored whole (``stored_trial``), the session then completed.

    Returns:
        Simulated time [s].
    """
    sim = 0.0
    with TrialStore(db) as store:
        for subj in subjects:
            session = subject_session(protocol, subj, dt=dt, max_trial_time=max_trial_time,
                                      extra=extra)
            settings = replace(session.settings, extra={
                "cohort": {"subject": subj.number, "group": subj.group},
                **dict(extra or {})})
            sid = start_session(store, protocol, subj.code, seed=subj.session_seed,
                                settings=settings)
            for st, cfg in trial_configs(session, subj.profile, effects):
                meta = TRIAL_KINDS.of(cfg).meta(cfg, session_id=sid, schedule_index=st.index,
                                                protocol=protocol.name)
                with stored_trial(store, meta) as rec:
                    out = simulate_trial(cfg, session.metric_params)
                    store_outcome(rec, out)
                sim += float(out["sim_time"])
            store.set_session_status(sid, "completed")
    return sim


def cohort_subjects_of(protocol: Protocol, n_subjects: int, seed: int,
                       scenario: Scenario | None = None) -> list[SimulatedSubject]:
    """The cohort's subjects as ``vasim study simulate`` draws them."""
    return cohort_subjects(n_subjects, surgeons_for(n_subjects), seed,
                           latin_square=protocol.block_order == "latin_square",
                           scenario=scenario)


def _scenario_extra(design: PowerDesign) -> dict[str, Any]:
    """The sessions' ``extra``: the design's scenario (or the default) at its scale."""
    return {"scenario": scenario_record(design.scenario or default_scenario(),
                                        design.effect_scale)}


@dataclass(frozen=True)
class CohortOutcome:
    """What one cohort task returns (small: no samples, no per-trial rows).

    Attributes:
        tests: :data:`~vasim.study.power.estimate.COHORT_COLUMNS` rows, one per primary
            test. wall_seconds: the task's wall-clock time [s]. sim_seconds: simulated
            time [s]. n_trials: trials run. cpu_seconds: the task's process CPU time [s]
            (below ``wall_seconds`` when the task waited for a core).
    """

    tests: pd.DataFrame
    wall_seconds: float
    sim_seconds: float
    n_trials: int
    cpu_seconds: float = 0.0


def cohort_tests(protocol: Protocol, design: PowerDesign, n_subjects: int, k: int,
                 keep_dir: str | None = None) -> CohortOutcome:
    """Simulates cohort ``k`` of size ``n_subjects`` and returns its primary tests.

    Args:
        protocol: the protocol every subject runs. design: the power run.
        n_subjects: N. k: 0-based cohort number (``cohort_seed``).
        keep_dir: a folder to write the cohort's study database into (None: in memory).

    Returns:
        A :class:`CohortOutcome`.
    """
    t0, c0 = time.perf_counter(), time.process_time()
    seed = cohort_seed(design.seed, n_subjects, k)
    subjects = cohort_subjects_of(protocol, n_subjects, seed, design.scenario)
    scen = _scenario_extra(design)
    if keep_dir is None:
        trials = simulate_in_memory(protocol, subjects, dt=design.dt,
                                    max_trial_time=design.max_trial_time,
                                    effects=design.effects, extra=scen)
        data = study_data(protocol, trials)
        sim, n_trials = trials.sim_seconds, trials.n_trials
    else:
        db = Path(keep_dir) / f"power_N{n_subjects}_c{k}.sqlite"
        if db.exists():
            db.unlink()   # a cohort is a pure function of its seed: rewrite, never mix
        sim = simulate_to_store(db, protocol, subjects, dt=design.dt,
                                max_trial_time=design.max_trial_time, effects=design.effects,
                                extra={**scen,
                                       "power": {"seed": seed, "n_subjects": n_subjects,
                                                 "cohort": k,
                                                 "effect_scale": design.effect_scale}})
        data = load_study(db, protocol.name)
        n_trials = int(data.analysed.shape[0])
    vf = analyse_vf(data)
    # the PRIMARY analysis (post-block probe model) first, then the seed's RM-ANOVAs
    tests = pd.concat([probe_model_tests(vf), primary_tests(vf)], ignore_index=True)
    out = pd.DataFrame({"n_subjects": n_subjects, "cohort": k, "seed": seed,
                        "dv": tests["dv"], "factor": tests["factor"],
                        "n_complete": tests["n_subjects"], "F": tests["F"],
                        "p_unc": tests["p_unc"], "p_gg": tests["p_gg"], "np2": tests["np2"],
                        "reason": tests["reason"]}, columns=list(COHORT_COLUMNS))
    return CohortOutcome(out, wall_seconds=time.perf_counter() - t0, sim_seconds=sim,
                         n_trials=n_trials, cpu_seconds=time.process_time() - c0)


__all__ = ["CohortOutcome", "CohortTrials", "cohort_subjects_of", "cohort_tests",
           "schedule_frame", "simulate_in_memory", "simulate_to_store", "study_data",
           "subject_session",
           "trial_configs"]
