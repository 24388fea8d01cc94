"""What the report reads from a study store (:func:`load_study` -> :class:`StudyData`)."""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from vasim.core.config import check_file
from vasim.core.errors import ConfigError
from vasim.study.protocol import Protocol, parse_protocol
from vasim.study.store import (
    DEMOGRAPHIC_COLUMNS,
    SCHEDULE_COLUMNS,
    TrialStore,
)

# ------------------------------------------------------------------------------ data
SCRIPTED_OPERATOR = "scripted"
"""``sessions.operator`` of a simulated session (:mod:`vasim.study.cohort`)."""
SYNTHETIC_LABEL = ("synthetic data: simulated operator (a declared scenario, not people); "
                   "not evidence")
"""The label of every figure and table of a simulated cohort. Its numbers follow from the
simulation's assumptions (issue #25): they are never a reproduction of the seed."""


@dataclass(frozen=True)
class StudyData:
    """What the report reads from a store, for one protocol (pure data, no connection).

    Attributes:
        db: the database file. protocol_name: the protocol reported (None: no session).
        protocol: the stored protocol parsed (None if there is none or it does not parse).
        notes: remarks on reading (protocol versions, a protocol that does not parse).
        sessions: ``TrialStore.sessions()`` rows of the protocol.
        schedule: the scheduled trials of those sessions (``SCHEDULE_COLUMNS``) plus
            ``subject`` and ``stage`` (probe number of the VF-free trial closing the block).
        trials: the trial rows of those sessions, every status (``TRIAL_COLUMNS``).
        n_outside: trial rows of the store outside any session (not analysed).
        points: per-point metrics (``trial_id, point, reached, t_reached, error_l1``
            [m·sample], ``error_l1_mm_s`` [mm·s], ``latency`` [s]) of the analysed trials.
        metrics: per-trial metrics of the analysed trials, wide (index ``trial_id``); read
            only when the schedule has teleoperation-mode trials (the MRCP section).
        demographics: demographics of the protocol's subjects (``DEMOGRAPHIC_COLUMNS``).
        answers: questionnaire answers of the protocol's sessions (``ANSWER_COLUMNS``).
        protocols_present: every protocol with a session in the store.
        schema_version: the store's schema version (None for an empty file).
        gates: the stored proficiency-gate decisions of the sessions
            (``vasim.study.gates.gate_frame``).
        sittings: the stored later-sitting records (``session_id, trial_id, record``).
    """

    db: Path
    protocol_name: str | None
    protocol: Protocol | None
    notes: tuple[str, ...]
    sessions: pd.DataFrame = field(repr=False)
    schedule: pd.DataFrame = field(repr=False)
    trials: pd.DataFrame = field(repr=False)
    n_outside: int
    points: pd.DataFrame = field(repr=False)
    metrics: pd.DataFrame = field(repr=False)
    demographics: pd.DataFrame = field(repr=False)
    answers: pd.DataFrame = field(repr=False)
    protocols_present: tuple[str, ...]
    schema_version: int | None
    gates: pd.DataFrame = field(default_factory=pd.DataFrame, repr=False)
    sittings: pd.DataFrame = field(default_factory=pd.DataFrame, repr=False)

    @property
    def synthetic(self) -> bool:
        """Whether the cohort is simulated: a session's stored ``operator`` is the scripted
        operator (``vasim study simulate``; stored as ``scripted`` or, calibrated,
        ``scripted (calibrated to the seed, synthetic)``).

        **Decision**: one scripted session makes the whole report synthetic because its
        numbers then mix simulated trials into every pooled statistic.
        """
        ops = self.sessions["operator"].astype(str)
        # "scripted" (older stores) or "scripted (calibrated to the seed, synthetic)"
        return bool(len(self.sessions)) and bool(
            ((ops == SCRIPTED_OPERATOR) | ops.str.startswith(SCRIPTED_OPERATOR + " ")).any())

    @property
    def data_label(self) -> str:
        """The label every figure and table carries: :data:`SYNTHETIC_LABEL` for a simulated
        cohort, ``""`` otherwise (the only use of :attr:`synthetic` in the report)."""
        return SYNTHETIC_LABEL if self.synthetic else ""

    @property
    def analysed(self) -> pd.DataFrame:
        """Scheduled trials with a completed trial: the trials the report analyses."""
        done = self.schedule[self.schedule["trial_id"].notna()].copy()
        done["trial_id"] = done["trial_id"].astype(np.int64)
        return done.reset_index(drop=True)


_POINT_COLS = ("trial_id", "point", "reached", "t_reached", "error_l1", "error_l1_mm_s",
               "latency")
_SESSION_COLS = ("id", "subject", "protocol", "protocol_sha256", "seed", "status",
                 "created_at", "ended_at", "operator", "n_trials", "notes", "vasim_version",
                 "n_completed", "n_interrupted", "next_index")


def _empty_data(path: Path, protocol: str | None, notes: tuple[str, ...],
                schema_version: int | None) -> StudyData:
    sched = pd.DataFrame({c: [] for c in (*SCHEDULE_COLUMNS, "subject", "stage")})
    return StudyData(
        db=path, protocol_name=protocol, protocol=None, notes=notes,
        sessions=pd.DataFrame({c: [] for c in _SESSION_COLS}), schedule=sched,
        trials=pd.DataFrame({c: [] for c in ("id", "subject", "session_id", "status",
                                             "schedule_index", "attempt")}),
        n_outside=0, points=pd.DataFrame({c: np.array([], dtype=bool if c == "reached" else
                                                      np.int64 if c in ("trial_id", "point")
                                                      else np.float64) for c in _POINT_COLS}),
        metrics=pd.DataFrame(index=pd.Index([], name="trial_id", dtype=np.int64)),
        demographics=pd.DataFrame({c: [] for c in DEMOGRAPHIC_COLUMNS}),
        answers=pd.DataFrame({c: [] for c in ("session_id", "subject", "questionnaire",
                                              "item", "key", "value", "value_num")}),
        protocols_present=(), schema_version=schema_version)


def load_study(db: str | os.PathLike[str], protocol: str | None = None) -> StudyData:
    """Reads what the report needs from a study store, read-only.

    Args:
        db: the SQLite study store.
        protocol: the protocol to report (a ``sessions.protocol`` name), or None for the
            store's only protocol.

    Returns:
        :class:`StudyData` (empty frames when the store has no session).

    Raises:
        ConfigError: ``db`` does not exist or is a directory; the store holds several
            protocols and none is chosen; the chosen protocol has no session.
        StoreError: the file is not a vasim store (or a newer or unmigrated one).
    """
    path = Path(db)
    check_file(path, "--db", what="the study database (SQLite file)", error=ConfigError)
    if path.stat().st_size == 0:
        return _empty_data(path, protocol, ("the database file is empty (0 bytes): no "
                                            "sessions, nothing to analyse",), None)
    with TrialStore(path, readonly=True) as store:
        return _read_store(store, protocol)


def _read_store(store: TrialStore, protocol: str | None) -> StudyData:
    path = store.path
    sessions_all = store.sessions()
    present = tuple(sorted(str(p) for p in sessions_all["protocol"].unique()))
    if protocol is None:
        if len(present) > 1:
            raise ConfigError(f"the store holds sessions of {len(present)} protocols "
                              f"({', '.join(present)}); choose one with --protocol",
                              file=path, field="--protocol")
        name = present[0] if present else None
    else:
        if present and protocol not in present:
            raise ConfigError(f"no session of protocol {protocol!r} in the store (protocols "
                              f"with sessions: {', '.join(present)})", file=path,
                              field="--protocol")
        name = protocol
    n_outside = int(store.con.execute(
        "SELECT count(*) FROM trials WHERE session_id IS NULL").fetchone()[0])
    version = store.schema_version
    if name is None or sessions_all.empty:
        return replace(_empty_data(path, name, (), version), n_outside=n_outside)
    sessions = sessions_all[sessions_all["protocol"] == name].reset_index(drop=True)
    notes: list[str] = []
    n_free = len(store.trials().query("subject.isna()"))
    if n_free:  # no subject's data (free practice): never in a subject analysis
        notes.append(f"{n_free} trial(s) without a subject left out of the subject analyses")
    latest = int(sessions["id"].max())
    text = store.session(latest)["protocol_toml"]
    parsed: Protocol | None
    try:
        parsed = parse_protocol(text, source=f"{path} session {latest} (stored protocol)")
    except ConfigError as exc:
        parsed = None
        notes.append(f"the protocol text stored with session {latest} does not parse with "
                     f"this vasim ({exc}); questionnaire items cannot be interpreted")
    n_versions = int(sessions["protocol_sha256"].nunique())
    if n_versions > 1:
        notes.append(f"the sessions ran {n_versions} different versions of protocol {name!r} "
                     f"(protocol_sha256); questionnaire items are read from the latest "
                     f"(session {latest})")
    frames = [store.schedule(int(sid)) for sid in sessions["id"]]
    sched = pd.concat(frames, ignore_index=True)
    subj = dict(zip(sessions["id"].astype(int), sessions["subject"], strict=True))
    sched["subject"] = sched["session_id"].map(subj)
    sched = sched.sort_values(["session_id", "trial_index"]).reset_index(drop=True)
    # stage: the probe number of the next VF-free trial in the session (own number for a
    # probe) -- the seed replication's "trial" level of an assisted trial
    sched["stage"] = sched.groupby("session_id")["probe_index"].bfill().astype("Int64")
    trials = store.trials()
    sids = set(sessions["id"].astype(int))
    trials = trials[trials["session_id"].isin(sids)].reset_index(drop=True)
    # No bulk reader of point metrics in TrialStore: one read-only query (the IN form lets
    # SQLite use the point_metrics primary key; a plain JOIN can scan it per session).
    rows = store.con.execute(
        "SELECT p.trial_id, p.point, p.reached, p.t_reached, p.error_l1, p.error_l1_mm_s, "
        "p.latency "
        "FROM point_metrics p WHERE p.trial_id IN (SELECT q.trial_id FROM scheduled_trials q "
        "JOIN sessions s ON s.id = q.session_id WHERE s.protocol = ? AND q.trial_id IS NOT "
        "NULL) ORDER BY p.trial_id, p.point", (name,)).fetchall()
    points = pd.DataFrame(rows, columns=list(_POINT_COLS))
    points = points.astype({"trial_id": np.int64, "point": np.int64, "t_reached": np.float64,
                            "error_l1": np.float64, "error_l1_mm_s": np.float64,
                            "latency": np.float64})
    points["reached"] = points["reached"].astype(bool)
    done_ids = set(int(t) for t in sched["trial_id"].dropna())
    # the MRCP section and the VF study's path deviation (``PATH_DEV_METRIC``) read them
    metrics = store.trial_metrics(wide=True)
    metrics = metrics[metrics.index.isin(done_ids)]
    demo = store.demographics()
    demo = demo[demo["subject"].isin(set(sessions["subject"]))].reset_index(drop=True)
    answers = store.answers()
    answers = answers[answers["session_id"].isin(sids)].reset_index(drop=True)
    from vasim.study.gates import gate_frame
    from vasim.study.session import SITTING_EVENT

    sittings = pd.DataFrame(store.con.execute(
        "SELECT q.session_id, e.trial_id, e.detail FROM events e JOIN scheduled_trials q ON "
        "q.trial_id = e.trial_id JOIN sessions s ON s.id = q.session_id WHERE s.protocol = ? "
        "AND e.kind = ? ORDER BY q.session_id, q.trial_index", (name, SITTING_EVENT)
    ).fetchall(), columns=["session_id", "trial_id", "record"])
    return StudyData(db=path, protocol_name=name, protocol=parsed, notes=tuple(notes),
                     sessions=sessions, schedule=sched, trials=trials, n_outside=n_outside,
                     points=points, metrics=metrics, demographics=demo, answers=answers,
                     protocols_present=present, schema_version=version,
                     gates=gate_frame(store, [int(i) for i in sessions["id"]]),
                     sittings=sittings)


