"""The study report: ``vasim report --db study.sqlite --out report/ [--protocol NAME]``.

:func:`build_report` reads a study store (read-only) and writes

* ``report/index.html``: one self-contained page (figures embedded as PNG, no script;
  :mod:`vasim.study.report_html`), and
* ``report/tables/*.csv``: every table of the page at full precision, ``provenance.csv`` and
  ``manifest.json`` (the tables written, their rows and columns).

Sections (spec/study.md §3-4): cohort; learning curves over the VF-free probe trials;
effect of fixture (subject-level RM-ANOVA, post hoc tests, the seed's per-sample ANOVA as a
labelled replication); box plots; questionnaires; the MRCP vs standard-teleoperation
comparison; traceability. A section whose data are missing says what is missing and which
subjects or trials it leaves out; it never fails the report.

What is read: sessions, the realised schedules, trial rows, per-point metrics, per-trial
metrics, demographics and answers. The ``samples`` table is never read (the per-point and
per-trial metrics are computed from the samples when a trial closes and stored with it).

**Decisions** (the seed leaves them open; each is also stated in the report's text):

* One report covers one protocol: ``--protocol NAME``, or the only protocol of the store's
  sessions (several protocols without ``--protocol`` is a ``ConfigError`` naming them).
  The protocol text stored with the latest session gives the questionnaire items.
* Analysed trials: the completed attempt of each scheduled trial
  (``scheduled_trials.trial_id``). Interrupted attempts and trials outside sessions are
  counted in the cohort section but not analysed.
* Per-trial outcomes of the VF study, from the per-point metrics (eq. 6.5):
  cumulative error ``E = Σ_i e_i`` [m] over the trial's points, and latency
  ``L = Σ_i l_i`` [s] over its *reached* points, i.e. the reach time of the last reached
  point (the trial's completion time when every point is reached). A trial with no
  reached point has no latency and is excluded (listed).
* Fixture factor (6 levels none, VG, AG, MS, Mag, FF): the cell of a subject and fixture is
  the mean of E (or L) over the subject's analysed trials of that condition (6 assisted
  trials; "none" = the 8 VF-free probe trials, baseline included). Trial factor (8 levels):
  the probe trials 1..8, one trial per cell. The two factors are not crossed (assisted
  trials have no probe number), so each gets its own one-way subject-level RM-ANOVA
  (spec §3 decision: the primary result) over the subjects with every cell (the others
  are listed as excluded).
* The seed's per-sample ANOVA (replication only, ``stats.seed_per_sample_anova``): one row
  per trajectory point of every analysed trial (e_i or l_i), factors fixture and "trial";
  an assisted trial's "trial" level is the probe number of the VF-free trial that closes
  its block (the stage of the session it belongs to), a probe trial's its own number.
* MRCP (spec §4) per trial: ET = ``completion_time`` [s], EM = ``path_l2`` (Euclidean
  tool path length) [m], Q = ``target_displacement_max`` [m] (when stored),
  ``contact_time`` [s], ``accumulated_force`` [N s], ``accumulated_torque`` [N m s].
  Per subject and mode the cell is the mean over the mode's trials; means, sds, paired
  t-tests and gains use the subjects with every mode; gain = mean(StdT) / mean(mode) of
  those cell means (``stats.gain``); the learning curve's trial number is the trial's
  position among the session's trials of that mode (1..6).
* Traceability: every CSV has a ``trial_id``/``trial_ids`` (or, for questionnaire tables,
  ``session_ids``) column, or rows in ``provenance.csv`` (``table, group, subject,
  session_ids, trial_ids``) listing per table cell the stored trial ids it was computed
  from.

Example:
    >>> import tempfile, pathlib
    >>> from vasim.study.store import TrialStore
    >>> with tempfile.TemporaryDirectory() as d:
    ...     TrialStore(pathlib.Path(d) / "s.sqlite").close()
    ...     res = build_report(pathlib.Path(d) / "s.sqlite", pathlib.Path(d) / "rep")
    ...     res.index.name, "no sessions" in res.index.read_text()
    ('index.html', True)
"""

from __future__ import annotations

import json
import math
import os
import time
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import pandas as pd

from vasim import __version__
from vasim.core.errors import ConfigError
from vasim.core.progress import progress_bar
from vasim.study import stats
from vasim.study.protocol import Protocol, QuestionItem, parse_protocol
from vasim.study.report_html import (
    Block,
    FigureBlock,
    Notes,
    Paragraph,
    ReportDoc,
    Section,
    TableBlock,
    TextList,
    render_html,
)
from vasim.study.report_plots import (
    PALETTE,
    box_figure,
    choice_rating_figure,
    counts_figure,
    demographics_figure,
    figure_png,
    learning_curve_figure,
)
from vasim.study.store import (
    DEMOGRAPHIC_COLUMNS,
    GROUPS,
    LAPAROSCOPY_LEVELS,
    ROBOTIC_LEVELS,
    SCHEDULE_COLUMNS,
    SIMULATOR_LEVELS,
    SPECIALISATIONS,
    TrialStore,
)
from vasim.trials.kinds import TELEOPERATION_MODES

T = TypeVar("T")

FIXTURE_ORDER: tuple[str, ...] = ("none", "vg", "ag", "ms", "mag", "ff")
"""Conditions of the VF study in report order (none first, then the seed's order)."""
FIXTURE_LABELS: dict[str, str] = {"none": "none", "vg": "VG", "ag": "AG", "ms": "MS",
                                  "mag": "Mag", "ff": "FF"}
"""Display names of the fixture conditions (other conditions show their own name)."""
MODE_ORDER: tuple[str, ...] = ("stdt", "mrcp", "mrcp_cam")
"""Teleoperation modes in report order; StdT is the reference of the gains."""
MODE_LABELS: dict[str, str] = {"stdt": "StdT", "mrcp": "MRCP", "mrcp_cam": "MRCP+Cam"}
"""Display names of the teleoperation modes."""

VF_DVS: tuple[tuple[str, str, str], ...] = (
    ("cum_error", "cumulative error Σe_i", "m"),
    ("latency", "latency Σl_i", "s"),
)
"""Per-trial outcomes of the VF study: (column, name, unit)."""
_PLOT_NAMES: dict[str, str] = {"cum_error": r"cumulative error $\Sigma_i\, e_i$",
                               "latency": r"latency $\Sigma_i\, l_i$"}
"""The outcomes' names in figures (matplotlib mathtext)."""
FIXTURE_COLORS: dict[str, str] = {FIXTURE_LABELS[c]: PALETTE[i]
                                  for i, c in enumerate(FIXTURE_ORDER)}
"""One colour per fixture in every figure (keyed by display name)."""
MODE_COLORS: dict[str, str] = {"StdT": PALETTE[0], "MRCP": PALETTE[1], "MRCP+Cam": PALETTE[2]}
"""One colour per teleoperation mode (keyed by display name)."""

SEED_REPORTED: dict[tuple[str, str], str] = {
    ("cum_error", "fixture"): "F(5, 98131) = 35.030", ("cum_error", "trial"):
    "F(7, 98131) = 22.871", ("latency", "fixture"): "F(5, 98131) = 44.099",
    ("latency", "trial"): "F(7, 98131) = 87.344",
}
"""The seed's per-sample ANOVA results (section 6.4.4), shown beside the replication."""


@dataclass(frozen=True)
class MrcpMetric:
    """One per-trial metric of the MRCP comparison (spec §4).

    Attributes:
        key: column name in the report tables. metric: name in ``trial_metrics``.
        family: ``"ET"``, ``"EM"`` (economy of movement) or ``"Q"`` (quality).
        label: what it measures. unit: its unit.
    """

    key: str
    metric: str
    family: str
    label: str
    unit: str


MRCP_METRICS: tuple[MrcpMetric, ...] = (
    MrcpMetric("ET", "completion_time", "ET", "execution time", "s"),
    MrcpMetric("EM", "path_l2", "EM", "tool path length", "m"),
    MrcpMetric("Q_target_displacement", "target_displacement_max", "Q",
               "largest target displacement", "m"),
    MrcpMetric("Q_contact_time", "contact_time", "Q", "accumulated contact time", "s"),
    MrcpMetric("Q_force", "accumulated_force", "Q", "accumulated force on tissue", "N s"),
    MrcpMetric("Q_torque", "accumulated_torque", "Q", "accumulated torque on tissue", "N m s"),
)
"""The MRCP metrics, in report order (those with no stored value are left out)."""

PROVENANCE_COLUMNS: tuple[str, ...] = ("table", "group", "subject", "session_ids", "trial_ids")
"""Columns of ``tables/provenance.csv``: per table cell/group, the ids it comes from."""

LABEL_TUKEY = "Tukey HSD with the RM-ANOVA error term, as in the seed (assumes sphericity)"
LABEL_PAIRED = "paired t-tests, Holm-corrected: the within-subject-correct alternative"

_DEMOGRAPHIC_PANELS: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("specialisation", "specialisation", SPECIALISATIONS),
    ("laparoscopy_experience", "laparoscopy (procedures as first surgeon)",
     LAPAROSCOPY_LEVELS),
    ("simulator_experience", "surgical simulators", SIMULATOR_LEVELS),
    ("robotic_experience", "robotic surgery", ROBOTIC_LEVELS),
)


# ---------------------------------------------------------------------------- helpers
def ids_text(values: Iterable[Any]) -> str:
    """Sorted distinct integer ids joined by spaces (the CSV form of an id list).

    >>> ids_text([12, 3, 3, 7])
    '3 7 12'
    """
    return " ".join(str(v) for v in sorted({int(v) for v in values if not pd.isna(v)}))


def fixture_label(condition: str) -> str:
    """Display name of a condition: ``"mag"`` -> ``"Mag"``, modes ``"mrcp_cam"`` ->
    ``"MRCP+Cam"``; unknown names are returned unchanged.

    >>> fixture_label("mag"), fixture_label("mrcp_cam"), fixture_label("custom")
    ('Mag', 'MRCP+Cam', 'custom')
    """
    return FIXTURE_LABELS.get(condition, MODE_LABELS.get(condition, condition))


def ordered_conditions(present: Iterable[str], order: Sequence[str]) -> list[str]:
    """The present conditions in ``order``, unknown ones after it, sorted.

    >>> ordered_conditions(["ff", "x", "none", "vg"], FIXTURE_ORDER)
    ['none', 'vg', 'ff', 'x']
    """
    seen = set(present)
    return [c for c in order if c in seen] + sorted(seen - set(order))


def _subjects_text(subjects: Iterable[str], limit: int = 40) -> str:
    s = sorted(set(subjects))
    shown = ", ".join(s[:limit])
    return shown + (f" and {len(s) - limit} more" if len(s) > limit else "")


def _captured(fn: Callable[..., T], *args: Any, **kwargs: Any) -> tuple[T, list[str]]:
    """Calls ``fn`` and returns its result with the messages of the warnings it issued."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = fn(*args, **kwargs)
    msgs = []
    for w in caught:
        text = str(w.message)
        if text not in msgs:
            msgs.append(text)
    return out, msgs


def _prov(table: str, group: str, subject: str | None = None, *,
          session_ids: Iterable[Any] = (), trial_ids: Iterable[Any] = ()) -> dict[str, str]:
    return {"table": table, "group": group, "subject": subject or "",
            "session_ids": ids_text(session_ids), "trial_ids": ids_text(trial_ids)}


# ------------------------------------------------------------------------------ data
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
        points: per-point metrics (``trial_id, point, reached, t_reached, error_l1,
            latency``) of the analysed trials.
        metrics: per-trial metrics of the analysed trials, wide (index ``trial_id``); read
            only when the schedule has teleoperation-mode trials (the MRCP section).
        demographics: demographics of the protocol's subjects (``DEMOGRAPHIC_COLUMNS``).
        answers: questionnaire answers of the protocol's sessions (``ANSWER_COLUMNS``).
        protocols_present: every protocol with a session in the store.
        schema_version: the store's schema version (None for an empty file).
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

    @property
    def analysed(self) -> pd.DataFrame:
        """Scheduled trials with a completed trial: the trials the report analyses."""
        done = self.schedule[self.schedule["trial_id"].notna()].copy()
        done["trial_id"] = done["trial_id"].astype(np.int64)
        return done.reset_index(drop=True)


_POINT_COLS = ("trial_id", "point", "reached", "t_reached", "error_l1", "latency")
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
    if not path.exists():
        raise ConfigError("study database not found", file=path, field="--db")
    if path.is_dir():
        raise ConfigError("is a directory, expected the study database (SQLite file)",
                          file=path, field="--db")
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
        "SELECT p.trial_id, p.point, p.reached, p.t_reached, p.error_l1, p.latency "
        "FROM point_metrics p WHERE p.trial_id IN (SELECT q.trial_id FROM scheduled_trials q "
        "JOIN sessions s ON s.id = q.session_id WHERE s.protocol = ? AND q.trial_id IS NOT "
        "NULL) ORDER BY p.trial_id, p.point", (name,)).fetchall()
    points = pd.DataFrame(rows, columns=list(_POINT_COLS))
    points = points.astype({"trial_id": np.int64, "point": np.int64, "t_reached": np.float64,
                            "error_l1": np.float64, "latency": np.float64})
    points["reached"] = points["reached"].astype(bool)
    done_ids = set(int(t) for t in sched["trial_id"].dropna())
    if sched["condition"].isin(TELEOPERATION_MODES).any():  # only the MRCP section uses them
        metrics = store.trial_metrics(wide=True)
        metrics = metrics[metrics.index.isin(done_ids)]
    else:
        metrics = pd.DataFrame(index=pd.Index([], name="trial_id", dtype=np.int64))
    demo = store.demographics()
    demo = demo[demo["subject"].isin(set(sessions["subject"]))].reset_index(drop=True)
    answers = store.answers()
    answers = answers[answers["session_id"].isin(sids)].reset_index(drop=True)
    return StudyData(db=path, protocol_name=name, protocol=parsed, notes=tuple(notes),
                     sessions=sessions, schedule=sched, trials=trials, n_outside=n_outside,
                     points=points, metrics=metrics, demographics=demo, answers=answers,
                     protocols_present=present, schema_version=version)


# ---------------------------------------------------------------------------- results
@dataclass
class _Out:
    """A section under construction: its blocks and its notes (what is missing)."""

    blocks: list[Block] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def section(self, key: str, title: str, intro: Sequence[Block] = ()) -> Section:
        head: list[Block] = list(intro)
        if self.notes:
            head.append(Notes(tuple(dict.fromkeys(self.notes))))  # each note once
        return Section(key, title, tuple(head + self.blocks))


@dataclass(frozen=True)
class ReportResult:
    """What :func:`build_report` wrote.

    Attributes:
        out: the output folder. index: ``out/index.html``.
        tables: CSV stems written under ``out/tables/`` (``provenance`` included).
        n_figures: figures embedded in the page. seconds: wall time of the build [s].
        protocol: the protocol reported (None: the store has no session).
    """

    out: Path
    index: Path
    tables: tuple[str, ...]
    n_figures: int
    seconds: float
    protocol: str | None


# ----------------------------------------------------------------------------- cohort
def cohort_section(data: StudyData) -> tuple[Section, list[dict[str, str]]]:
    """Cohort description: subjects, groups, specialisations, experience, sessions.

    Returns:
        The section and its provenance rows.
    """
    out = _Out()
    out.notes.extend(data.notes)
    if data.n_outside:
        out.notes.append(f"{data.n_outside} trial row(s) of the store were run outside any "
                         "session (stand-alone `vasim trial`): not analysed")
    s = data.sessions
    if s.empty:
        out.notes.append("no sessions stored" + (f" for protocol {data.protocol_name!r}"
                                                 if data.protocol_name else "")
                         + ": the store holds no study data to describe or analyse")
        return out.section("cohort", "Cohort"), []
    subjects = sorted(set(s["subject"]))
    demo = data.demographics
    with_demo = set(demo["subject"])
    no_demo = [x for x in subjects if x not in with_demo]
    if no_demo:
        out.notes.append(f"no demographics (pre-questionnaire) for {len(no_demo)} subject(s): "
                         f"{_subjects_text(no_demo)}; they count as group 'unknown'")
    group_of = dict(zip(demo["subject"], demo["subject_group"], strict=True))
    sched = data.schedule
    tr = data.trials
    interrupted = tr[tr["status"] == "interrupted"]
    reruns = sched[sched["attempts"] > 1]
    completed_s = s[s["status"] == "completed"]
    running_s = s[s["status"] == "running"]
    aborted_s = s[s["status"] == "aborted"]
    n_done = int(sched["trial_id"].notna().sum())

    def subj_of(frame: pd.DataFrame) -> str:
        return " ".join(sorted(set(frame["subject"])))

    rows = [
        ("subjects", len(subjects), " ".join(subjects), ""),
        ("surgeons", sum(group_of.get(x) == "surgeon" for x in subjects),
         " ".join(x for x in subjects if group_of.get(x) == "surgeon"), ""),
        ("residents", sum(group_of.get(x) == "resident" for x in subjects),
         " ".join(x for x in subjects if group_of.get(x) == "resident"), ""),
        ("group unknown (no demographics)", len(no_demo), " ".join(no_demo), ""),
        ("sessions", len(s), subj_of(s), ids_text(s["id"])),
        ("sessions completed", len(completed_s), subj_of(completed_s),
         ids_text(completed_s["id"])),
        ("sessions incomplete (running)", len(running_s), subj_of(running_s),
         ids_text(running_s["id"])),
        ("sessions aborted", len(aborted_s), subj_of(aborted_s), ids_text(aborted_s["id"])),
        ("scheduled trials", len(sched), subj_of(s), ids_text(s["id"])),
        ("scheduled trials completed (analysed)", n_done, subj_of(sched[sched["trial_id"]
                                                                       .notna()]), ""),
        ("interrupted trial rows", len(interrupted), subj_of(interrupted),
         ids_text(interrupted["session_id"])),
        ("scheduled trials re-run after an interruption", len(reruns), subj_of(reruns),
         ids_text(reruns["session_id"])),
    ]
    summary = pd.DataFrame(rows, columns=["quantity", "value", "subjects", "session_ids"])
    out.blocks.append(TableBlock(
        "cohort_summary", "Cohort and sessions", summary,
        "Counts over the sessions of this protocol; 'subjects' and 'session_ids' list whom "
        "each count covers.", columns=("quantity", "value")))
    # demographics by group
    drows = []
    for fld, _, levels in _DEMOGRAPHIC_PANELS:
        for lev in levels:
            who = demo[demo[fld] == lev]
            sur = who[who["subject_group"] == "surgeon"]
            res = who[who["subject_group"] == "resident"]
            drows.append({"field": fld, "value": lev, "surgeon": len(sur), "resident": len(res),
                          "total": len(who),
                          "percent": 100.0 * len(who) / len(demo) if len(demo) else math.nan,
                          "subjects": " ".join(sorted(who["subject"])),
                          "session_ids": ids_text(who["session_id"])})
    dtab = pd.DataFrame(drows)
    out.blocks.append(TableBlock(
        "cohort_demographics", "Specialisation and experience (pre-questionnaire)", dtab,
        f"Subjects per answer and group; percent of the {len(demo)} subject(s) with "
        "demographics; session_ids: the sessions whose pre-questionnaire gave them.",
        columns=("field", "value", "surgeon", "resident", "total", "percent")))
    if len(demo):
        counts = pd.DataFrame(
            [{"field": r["field"], "value": r["value"], "group": g, "n": r[g]}
             for r in drows for g in GROUPS])
        fig = demographics_figure(counts, fields=[(f, t) for f, t, _ in _DEMOGRAPHIC_PANELS],
                                  groups=GROUPS,
                                  levels={f: lv for f, _, lv in _DEMOGRAPHIC_PANELS})
        out.blocks.append(FigureBlock(
            "demographics", "Composition of the cohort (as the seed's Fig. 6.16)", figure_png(fig),
            "Subjects per specialisation and experience level, stacked by group; numbers "
            "in tables/cohort_demographics.csv."))
    sess = s[["id", "subject", "status", "n_trials", "n_completed", "n_interrupted", "seed",
              "created_at", "ended_at", "notes"]].rename(columns={"id": "session_id"})
    out.blocks.append(TableBlock(
        "cohort_sessions", "Sessions", sess,
        "One row per session: progress, randomisation seed and notes (e.g. why a session "
        "was aborted).", display="details"))
    if len(reruns):
        rr = []
        for r in reruns.itertuples(index=False):
            att = tr[(tr["session_id"] == r.session_id)
                     & (tr["schedule_index"] == r.trial_index)]
            rr.append({"session_id": int(r.session_id), "subject": r.subject,
                       "trial_index": int(r.trial_index), "condition": r.condition,
                       "attempts": int(r.attempts),
                       "trial_id": None if pd.isna(r.trial_id) else int(r.trial_id),
                       "interrupted_trial_ids": ids_text(
                           att.loc[att["status"] == "interrupted", "id"])})
        out.blocks.append(TableBlock(
            "cohort_reruns", "Scheduled trials re-run after an interruption",
            pd.DataFrame(rr), "The completed attempt (trial_id) is the one analysed; the "
            "interrupted attempts are kept in the store but not analysed."))
    return out.section("cohort", "Cohort"), []


# --------------------------------------------------------------------------- VF study
@dataclass(frozen=True)
class VfAnalysis:
    """The per-trial and per-cell data of the VF learning-curve study.

    Attributes:
        trials: one row per analysed trial of a fixture condition or a probe (columns
            ``trial_id, subject, session_id, trial_index, block, condition, fixture, probe,
            probe_index, stage, n_points, points_reached, completed, cum_error, latency``).
        excluded: trials left out (``trial_id, subject, condition, reason``).
        fixture_cells: ``subject, fixture, n_trials, cum_error, latency, trial_ids``: per
            subject and fixture the mean over its trials (every subject).
        trial_cells: ``subject, trial, trial_id, cum_error, latency``: the probe trials.
        fixture_levels: fixture labels present, in report order.
        trial_levels: probe numbers present.
        n_baseline: probe trials before the first assisted trial (3 in the VF protocol).
    """

    trials: pd.DataFrame
    excluded: pd.DataFrame
    fixture_cells: pd.DataFrame
    trial_cells: pd.DataFrame
    fixture_levels: tuple[str, ...]
    trial_levels: tuple[int, ...]
    n_baseline: int


def vf_trial_outcomes(analysed: pd.DataFrame, points: pd.DataFrame) -> pd.DataFrame:
    """Per-trial cumulative error and latency from the per-point metrics (eq. 6.5).

    Args:
        analysed: analysed scheduled trials (``StudyData.analysed``), any conditions.
        points: per-point metrics with ``trial_id, reached, error_l1`` [m], ``latency`` [s].

    Returns:
        ``analysed``'s rows of fixture conditions and probes (teleoperation modes left out)
        with ``fixture`` (display label), ``n_points``, ``points_reached``, ``completed``,
        ``cum_error`` = Σ e_i [m] and ``latency`` = Σ l_i over reached points [s] (NaN when
        the trial has no per-point row, resp. no reached point).

    Example:
        >>> a = pd.DataFrame({"trial_id": [1], "condition": ["vg"], "probe": [False]})
        >>> p = pd.DataFrame({"trial_id": [1, 1], "reached": [True, False],
        ...                   "error_l1": [0.5, 0.25], "latency": [2.0, float("nan")]})
        >>> r = vf_trial_outcomes(a, p).iloc[0]
        >>> float(r.cum_error), float(r.latency), bool(r.completed)
        (0.75, 2.0, False)
    """
    vf = analysed[~analysed["condition"].isin(TELEOPERATION_MODES)].copy()
    pts = points[points["trial_id"].isin(set(vf["trial_id"]))]
    g = pts.groupby("trial_id")
    reached = pts.loc[pts["reached"].astype(bool).to_numpy()]
    agg = pd.DataFrame({
        "n_points": g.size(),
        "points_reached": g["reached"].sum(),
        "cum_error": g["error_l1"].sum(min_count=1),
    })
    agg["latency"] = reached.groupby("trial_id")["latency"].sum(min_count=1)
    vf = vf.merge(agg, how="left", left_on="trial_id", right_index=True)
    vf["n_points"] = vf["n_points"].astype("Int64")
    vf["points_reached"] = vf["points_reached"].astype("Int64")
    vf["completed"] = (vf["n_points"] == vf["points_reached"]).fillna(False).astype(bool)
    vf["fixture"] = vf["condition"].map(fixture_label)
    return vf.reset_index(drop=True)


def analyse_vf(data: StudyData) -> VfAnalysis:
    """Builds :class:`VfAnalysis` from the store's data (see the module decisions)."""
    vf = vf_trial_outcomes(data.analysed, data.points)
    bad = vf["cum_error"].isna() | vf["latency"].isna()
    reasons = np.where(vf["n_points"].isna(), "no per-point metrics stored",
                       np.where(vf["latency"].isna(), "no trajectory point reached",
                                "no cumulative error"))
    excluded = vf.loc[bad, ["trial_id", "subject", "condition"]].assign(
        reason=reasons[bad.to_numpy()]).reset_index(drop=True)
    ok = vf[~bad]
    cond_order = ordered_conditions(ok["condition"], FIXTURE_ORDER)
    fixture_levels = tuple(fixture_label(c) for c in cond_order)
    cells = (ok.groupby(["subject", "condition"], sort=False)
             .agg(n_trials=("trial_id", "size"), cum_error=("cum_error", "mean"),
                  latency=("latency", "mean"), trial_ids=("trial_id", ids_text))
             .reset_index())
    cells["fixture"] = pd.Categorical(cells["condition"].map(fixture_label),
                                      categories=list(fixture_levels))
    cells = cells.sort_values(["subject", "fixture"]).reset_index(drop=True)
    cells = cells[["subject", "fixture", "condition", "n_trials", "cum_error", "latency",
                   "trial_ids"]]
    probes = ok[ok["probe"].astype(bool) & ok["probe_index"].notna()]
    tcells = probes[["subject", "probe_index", "trial_id", "cum_error", "latency"]].rename(
        columns={"probe_index": "trial"})
    tcells["trial"] = tcells["trial"].astype(np.int64)
    tcells = tcells.sort_values(["subject", "trial"]).reset_index(drop=True)
    trial_levels = tuple(int(t) for t in sorted(tcells["trial"].unique()))
    # baseline: probe trials before the first assisted trial of a session (the mode)
    sched = data.schedule
    n_base = 0
    if len(sched):
        firsts = []
        for _, g in sched.groupby("session_id"):
            assisted = g[~g["probe"].astype(bool)]
            first = int(assisted["trial_index"].min()) if len(assisted) else None
            firsts.append(int(g["probe"].astype(bool).sum()) if first is None
                          else int((g["probe"].astype(bool) & (g["trial_index"] < first)).sum()))
        n_base = int(pd.Series(firsts).mode().iloc[0])
    cols = ["trial_id", "subject", "session_id", "trial_index", "block", "condition",
            "fixture", "probe", "probe_index", "stage", "n_points", "points_reached",
            "completed", "cum_error", "latency"]
    return VfAnalysis(trials=vf[cols], excluded=excluded, fixture_cells=cells,
                      trial_cells=tcells, fixture_levels=fixture_levels,
                      trial_levels=trial_levels, n_baseline=n_base)


def complete_subjects(cells: pd.DataFrame, factor: str, levels: Sequence[Any],
                      subject: str = "subject") -> tuple[pd.DataFrame, dict[str, list[str]]]:
    """Keeps the subjects that have every level of ``factor``.

    Args:
        cells: one row per subject and level. factor: the level column.
        levels: the levels every subject must have.

    Returns:
        (the cells of the complete subjects, {excluded subject: its missing levels}).

    Example:
        >>> c = pd.DataFrame({"subject": ["a", "a", "b"], "f": ["x", "y", "x"]})
        >>> kept, gone = complete_subjects(c, "f", ["x", "y"])
        >>> sorted(kept["subject"].unique()), gone
        (['a'], {'b': ['y']})
    """
    have = cells.groupby(subject)[factor].agg(lambda s: set(s.astype(str)))
    want = [str(v) for v in levels]
    missing = {str(s): [v for v in want if v not in got] for s, got in have.items()}
    missing = {s: m for s, m in missing.items() if m}
    kept = cells[~cells[subject].astype(str).isin(set(missing))].reset_index(drop=True)
    return kept, missing


def _excluded_text(factor: str, missing: dict[str, list[str]],
                   what: str = "RM-ANOVA and its post hoc tests") -> str:
    parts = [f"{s} (no {', '.join(m)})" for s, m in sorted(missing.items())]
    shown = "; ".join(parts[:30]) + (f"; and {len(parts) - 30} more" if len(parts) > 30 else "")
    return (f"{len(missing)} subject(s) without every {factor} cell are excluded from the "
            f"{factor} {what}: {shown}")


def learning_curve_section(data: StudyData, vf: VfAnalysis
                           ) -> tuple[Section, list[dict[str, str]]]:
    """Learning curves over the VF-free probe trials (seed Figs. 6.17-6.18)."""
    out = _Out()
    intro: list[Block] = [Paragraph(
        "VF-free (probe) trials only, all on the original trajectory: per probe number, the "
        "mean over subjects and the interquartile range of the trial's cumulative error "
        "E = Σ_i e_i (eq. 6.5, Manhattan error summed over the logged samples of each "
        "point, summed over the points) and latency L = Σ_i l_i (time from the trial start "
        "to the last reached point: the completion time when every point is reached). "
        "Fit: power law of practice y = a·n^(-b) by least squares on the subject-level "
        "points, with the 95 % pointwise confidence band of the fitted mean curve (delta "
        "method).")]
    tc = vf.trial_cells
    if tc.empty:
        out.notes.append("no VF-free probe trial with per-point metrics in the sessions of "
                         "this protocol: no learning curve")
        return out.section("learning", "Learning curves (VF-free trials)", intro), []
    incomplete = vf.trials[vf.trials["probe"].astype(bool) & ~vf.trials["completed"]]
    if len(incomplete):
        out.notes.append(f"{len(incomplete)} probe trial(s) did not reach every point within "
                         f"the time limit (their L covers the reached points only): trial "
                         f"ids {ids_text(incomplete['trial_id'])}")
    _note_excluded(out, vf.excluded, probe_only=True, trials=vf.trials)
    summaries, fits = [], []
    prov: list[dict[str, str]] = []
    for dv, name, unit in VF_DVS:
        summ, msgs = _captured(stats.learning_curve_summary, tc, dv=dv, subject="subject",
                               trial="trial")
        out.notes.extend(msgs)
        ids = tc.groupby("trial")["trial_id"].agg(ids_text)
        summ["trial_ids"] = summ["trial"].map(ids)
        summ.insert(0, "dv", dv)
        summ.insert(1, "unit", unit)
        summaries.append(summ)
        band, fit_label = None, None
        try:
            fitrow, msgs = _captured(stats.fit_learning_curves, tc, dv=dv, subject="subject",
                                     trial="trial")
            out.notes.extend(msgs)
            pf, _ = _captured(stats.fit_power_law, tc["trial"].to_numpy(dtype=float),
                              tc[dv].to_numpy(dtype=float))
            grid = np.linspace(min(vf.trial_levels), max(vf.trial_levels), 60)
            band = pf.band(grid)
            r = fitrow.iloc[0]
            fit_label = f"fit ${r['a']:.3g}\\, n^{{-{r['b']:.3g}}}$"
            fitrow.insert(0, "dv", dv)
            fitrow.insert(1, "model", "a*n^(-b)")
            fits.append(fitrow)
        except ConfigError as exc:
            out.notes.append(f"{name}: power-law fit not computed: {exc.reason}")
        pname = _PLOT_NAMES[dv]
        fig = learning_curve_figure(
            summ, ylabel=f"{pname} [{unit}]", title=f"{pname[0].upper()}{pname[1:]} over the "
            "VF-free trials", band=band, fit_label=fit_label,
            split_after=vf.n_baseline + 0.5 if vf.n_baseline else None)
        out.blocks.append(FigureBlock(
            f"learning_{dv}", f"Learning curve: {name} (as the seed's Fig. "
            f"{'6.17' if dv == 'cum_error' else '6.18'})", figure_png(fig),
            f"Mean (line) and interquartile range (shaded) over subjects per VF-free trial; "
            f"dashed: power-law fit with its 95 % confidence band (hatched). Numbers: "
            f"tables/vf_learning_curve.csv (dv = {dv}) and tables/vf_learning_fit.csv."))
    table = pd.concat(summaries, ignore_index=True)
    out.blocks.append(TableBlock(
        "vf_learning_curve", "Learning curve per VF-free trial", table,
        "n subjects per trial; mean, 25th and 75th percentiles over subjects; trial_ids: the "
        "probe trials of that number.", columns=("dv", "unit", "trial", "n", "mean", "q25",
                                                 "q75")))
    if fits:
        ftab = pd.concat(fits, ignore_index=True)
        out.blocks.append(TableBlock(
            "vf_learning_fit", "Power-law fits y = a·n^(-b)", ftab,
            "a in the unit of the dv; b dimensionless (> 0: improvement with practice); "
            "standard errors from the least-squares covariance; provenance.csv lists the "
            "probe trials fitted.", columns=("dv", "model", "n_obs", "a", "b", "se_a", "se_b",
                                             "rss", "dof")))
        for r in tc.itertuples(index=False):
            prov.append(_prov("vf_learning_fit", f"trial={r.trial}", r.subject,
                              trial_ids=[r.trial_id]))
    out.blocks.append(TableBlock(
        "vf_trials", "Analysed trials of the VF study", vf.trials,
        "One row per analysed trial (the completed attempt of each scheduled trial): "
        "cum_error = Σ e_i [m], latency = Σ l_i over reached points [s]; stage = probe "
        "number closing the trial's block (the seed replication's trial level).",
        display="csv"))
    return out.section("learning", "Learning curves (VF-free trials)", intro), prov


def _note_excluded(out: _Out, excluded: pd.DataFrame, *, probe_only: bool,
                   trials: pd.DataFrame) -> None:
    ex = excluded
    if probe_only:
        probe_ids = set(trials.loc[trials["probe"].astype(bool), "trial_id"])
        ex = ex[ex["trial_id"].isin(probe_ids)]
    for reason, g in ex.groupby("reason"):
        out.notes.append(f"{len(g)} trial(s) excluded ({reason}): trial ids "
                         f"{ids_text(g['trial_id'])} of subject(s) "
                         f"{_subjects_text(g['subject'])}")


def _rm_block(cells: pd.DataFrame, factor: str, levels: Sequence[Any], out: _Out,
              cells_text: str, table_names: Sequence[str], trial_col: str
              ) -> tuple[list[pd.DataFrame], list[pd.DataFrame], list[pd.DataFrame],
                         list[dict[str, str]]]:
    """RM-ANOVA and both post hoc families of one factor, for every VF dv."""
    anovas: list[pd.DataFrame] = []
    tukeys: list[pd.DataFrame] = []
    paireds: list[pd.DataFrame] = []
    prov: list[dict[str, str]] = []
    if len(levels) < 2:
        out.notes.append(f"factor {factor}: {len(levels)} level(s) with data "
                         f"({', '.join(map(str, levels)) or 'none'}); an RM-ANOVA needs 2")
        return anovas, tukeys, paireds, prov
    kept, missing = complete_subjects(cells, factor, levels)
    if missing:
        out.notes.append(_excluded_text(factor, {
            s: [f"{factor} {v}" if v.isdigit() else v for v in m]
            for s, m in missing.items()}))
    n = kept["subject"].nunique()
    if n < 2:
        out.notes.append(f"factor {factor}: {n} subject(s) with every cell; an RM-ANOVA "
                         "needs at least 2: not computed")
        return anovas, tukeys, paireds, prov
    data = kept.copy()
    data[factor] = pd.Categorical(data[factor].astype(str), categories=[str(v) for v in levels])
    for r in kept.itertuples(index=False):
        ids = getattr(r, trial_col)
        ids = ids.split() if isinstance(ids, str) else [ids]
        for t in table_names:
            prov.append(_prov(t, f"{factor}={getattr(r, factor)}", r.subject, trial_ids=ids))
    for dv, _name, unit in VF_DVS:
        head = {"dv": dv, "unit": unit, "factor": factor}
        try:
            aov, msgs = _captured(stats.rm_anova, data, dv=dv, subject="subject",
                                  within=factor)
            out.notes.extend(f"{dv}, {factor}: {m}" for m in msgs)
            aov.insert(0, "dv", dv)
            aov.insert(1, "unit", unit)
            aov.insert(2, "factor", factor)
            aov.insert(3, "n_subjects", n)
            aov.insert(4, "levels", ", ".join(str(v) for v in levels))
            aov.insert(5, "cells", cells_text)
            aov.insert(6, "excluded_subjects", " ".join(sorted(missing)))
            anovas.append(aov)
        except ConfigError as exc:
            out.notes.append(f"RM-ANOVA of {dv} by {factor} not computed: {exc.reason}")
        try:
            tk, msgs = _captured(stats.tukey_hsd_rm, data, dv=dv, subject="subject",
                                 within=factor)
            out.notes.extend(f"{dv}, {factor}: {m}" for m in msgs)
            c = tk.comparisons.copy()
            for i, (k, v) in enumerate({**head, "label": LABEL_TUKEY}.items()):
                c.insert(i, k, v)
            c["ms_error"], c["df_error"], c["q_crit"] = tk.ms_error, tk.df_error, tk.q_crit
            tukeys.append(c)
        except ConfigError as exc:
            out.notes.append(f"Tukey HSD of {dv} by {factor} not computed: {exc.reason}")
        try:
            pp, msgs = _captured(stats.pairwise_paired, data, dv=dv, subject="subject",
                                 within=factor)
            out.notes.extend(f"{dv}, {factor}: {m}" for m in msgs)
            for i, (k, v) in enumerate({**head, "label": LABEL_PAIRED}.items()):
                pp.insert(i, k, v)
            paireds.append(pp)
        except ConfigError as exc:
            out.notes.append(f"paired t-tests of {dv} by {factor} not computed: {exc.reason}")
    return anovas, tukeys, paireds, prov


def _p_text(p: float) -> str:
    """A p-value as reported: ``p < 0.001`` below 0.001, else three decimals.

    >>> _p_text(3e-45), _p_text(0.0123), _p_text(float("nan"))
    ('p < 0.001', 'p = 0.012', 'p undefined')
    """
    if math.isnan(p):
        return "p undefined"
    return "p < 0.001" if p < 0.001 else f"p = {p:.3f}"


def _anova_sentence(r: dict[str, Any]) -> str:
    """One RM-ANOVA row in the usual reporting form."""
    name = dict((dv, n) for dv, n, _ in VF_DVS).get(r["dv"], r["dv"])
    gg = (f"; Greenhouse-Geisser eps = {r['eps_gg']:.3f}, {_p_text(r['p_gg'])}"
          if r["df1"] > 1 and not math.isnan(r["eps_gg"]) else "")
    return (f"{name} by {r['factor']} (n = {r['n_subjects']} subjects): "
            f"F({r['df1']}, {r['df2']}) = {r['F']:.3f}, {_p_text(r['p_unc'])}{gg}; "
            f"partial eta squared = {r['np2']:.3f}")


def fixture_effect_section(data: StudyData, vf: VfAnalysis
                           ) -> tuple[Section, list[dict[str, str]]]:
    """Effect of fixture: subject-level RM-ANOVAs, post hoc tests, seed replication."""
    out = _Out()
    cells_fix = ("per subject: mean of the trial outcome over the subject's analysed trials "
                 "of that condition (the assisted trials of a fixture, 6 in the VF protocol; "
                 "'none' = the VF-free probe trials, baseline included)")
    cells_trial = "per subject: the probe trial of that number (one trial per cell)"
    intro: list[Block] = [Paragraph(
        "Primary analysis (spec §3 decision): one-way repeated-measures ANOVAs on "
        "subject-level cell means, one for the factor fixture (" + cells_fix + ") and one "
        "for the factor trial (" + cells_trial + "); the two factors are not crossed "
        "(assisted trials have no VF-free trial number), so no interaction is tested. "
        "Mauchly's test, Greenhouse-Geisser (p_gg) and Huynh-Feldt (p_hf) corrections and "
        "partial eta squared (np2) are given. Post hoc: " + LABEL_TUKEY + "; and "
        + LABEL_PAIRED + ". Only subjects with every cell of a factor enter its tests.")]
    if vf.trials.empty:
        out.notes.append("no analysed trial of a fixture condition or a VF-free probe in the "
                         "sessions of this protocol: no fixture analysis")
        return out.section("fixture", "Effect of fixture", intro), []
    if "none" not in set(vf.fixture_cells["condition"]):
        out.notes.append("no VF-free (probe) trial: the fixture factor lacks the level "
                         "'none' and compares the fixtures only")
    _note_excluded(out, vf.excluded, probe_only=False, trials=vf.trials)
    prov: list[dict[str, str]] = []
    names = ("vf_rm_anova", "vf_posthoc_tukey", "vf_posthoc_paired")
    a1, t1, p1, pr1 = _rm_block(vf.fixture_cells, "fixture", vf.fixture_levels, out,
                                cells_fix, names, "trial_ids")
    tc = vf.trial_cells
    a2, t2, p2, pr2 = _rm_block(tc, "trial", vf.trial_levels, out, cells_trial, names,
                                "trial_id") if len(tc) else ([], [], [], [])
    if not len(tc):
        out.notes.append("no VF-free probe trial: the trial factor is not analysed")
    prov += pr1 + pr2
    anova = pd.concat(a1 + a2, ignore_index=True) if a1 + a2 else pd.DataFrame()
    if len(anova):
        out.blocks.append(TableBlock(
            "vf_rm_anova", "Subject-level RM-ANOVA (primary result)", anova,
            "df1, df2: degrees of freedom (p and p(n-1)); F and uncorrected p_unc; eps_gg, "
            "p_gg: Greenhouse-Geisser; mauchly_p: Mauchly's test of sphericity; np2: "
            "partial eta squared. Cells: see the 'cells' column; provenance.csv lists the "
            "trial ids of every subject x level cell.",
            columns=("dv", "factor", "n_subjects", "df1", "df2", "F", "p_unc", "eps_gg",
                     "p_gg", "p_hf", "np2", "mauchly_W", "mauchly_p")))
        out.blocks.append(TextList("In words", tuple(_anova_sentence(r) for r in
                                                     anova.to_dict("records"))))
    if t1 + t2:
        out.blocks.append(TableBlock(
            "vf_posthoc_tukey", "Post hoc: " + LABEL_TUKEY, pd.concat(t1 + t2,
                                                                      ignore_index=True),
            "diff = mean2 - mean1 (unit of the dv); p_adj: studentized range; lwr/upr: "
            "simultaneous 95 % interval; both factors (fixture, trial).", display="details",
            columns=("dv", "factor", "group1", "group2", "mean1", "mean2", "diff", "lwr",
                     "upr", "p_adj")))
    if p1 + p2:
        out.blocks.append(TableBlock(
            "vf_posthoc_paired", "Post hoc: " + LABEL_PAIRED, pd.concat(p1 + p2,
                                                                       ignore_index=True),
            "mean_diff = mean(group1 - group2); p_holm: Holm-adjusted within each dv x "
            "factor family; cohen_dz; power_observed at this n; n_power90_ceil: minimum n "
            "for power 0.9.", display="details",
            columns=("dv", "factor", "group1", "group2", "n", "mean_diff", "t", "p", "p_holm",
                     "cohen_dz")))
    rep, rprov = _seed_replication(data, vf, out)
    prov += rprov
    if rep is not None:
        out.blocks.append(TableBlock(
            "vf_seed_replication", "Replication of the seed's per-sample ANOVA (not the "
            "primary result)", rep,
            stats.SEED_LABEL + ". One row per trajectory point of every analysed trial "
            "(e_i [m] or l_i [s]); factors fixture and trial (an assisted trial's trial "
            "level = the VF-free trial closing its block); additive OLS model, type II SS. "
            "df2 counts points, not subjects: the p-values are not valid inference. "
            "'seed_reported' is the seed's published figure.",
            columns=("dv", "effect", "df1", "df2", "F", "p", "seed_reported", "n_rows")))
    return out.section("fixture", "Effect of fixture", intro), prov


def _seed_replication(data: StudyData, vf: VfAnalysis, out: _Out
                      ) -> tuple[pd.DataFrame | None, list[dict[str, str]]]:
    ok = vf.trials[vf.trials["cum_error"].notna() & vf.trials["latency"].notna()
                   & vf.trials["stage"].notna()]
    if ok.empty:
        out.notes.append("seed replication not computed: no analysed trial with a stage")
        return None, []
    rows = data.points.merge(ok[["trial_id", "subject", "fixture", "stage"]], on="trial_id")
    rows["trial"] = rows["stage"].astype(np.int64)
    rows["fixture"] = pd.Categorical(rows["fixture"], categories=list(vf.fixture_levels))
    parts = []
    for dv, col in (("cum_error", "error_l1"), ("latency", "latency")):
        d = rows[rows[col].notna()]
        try:
            r, msgs = _captured(stats.seed_per_sample_anova, d, dv=col,
                                factors=("fixture", "trial"))
        except ConfigError as exc:
            out.notes.append(f"seed replication of {dv} not computed: {exc.reason}")
            continue
        out.notes.extend(msgs)
        r.insert(0, "dv", dv)
        r.insert(1, "label", stats.SEED_LABEL)
        r["n_rows"] = len(d)
        r["seed_reported"] = [SEED_REPORTED.get((dv, e), "") for e in r["effect"]]
        parts.append(r)
    if not parts:
        return None, []
    prov = [_prov("vf_seed_replication", "all points of the subject's analysed trials", s,
                  trial_ids=g["trial_id"]) for s, g in ok.groupby("subject")]
    return pd.concat(parts, ignore_index=True), prov


def box_plot_section(vf: VfAnalysis) -> tuple[Section, list[dict[str, str]]]:
    """Box plots of the subject-level cells per fixture and per VF-free trial."""
    out = _Out()
    values = [(dv, f"{_PLOT_NAMES[dv]} [{unit}]") for dv, _, unit in VF_DVS]
    fc = vf.fixture_cells
    if fc.empty:
        out.notes.append("no analysed VF trial: no box plots")
        return out.section("boxplots", "Box plots"), []
    fig = box_figure(fc, group="fixture", values=values, order=list(vf.fixture_levels),
                     colors=FIXTURE_COLORS,
                     xlabel="fixture", title="Per fixture: subject means")
    out.blocks.append(FigureBlock(
        "box_fixture", "Per fixture", figure_png(fig),
        "One dot per subject: the subject's mean over its trials of the fixture ('none' = "
        "its VF-free trials); box = quartiles, line = median, diamond = mean, whiskers = "
        "1.5 IQR. Numbers: tables/vf_cells_fixture.csv (every subject; the RM-ANOVA uses "
        "the subjects with every cell)."))
    out.blocks.append(TableBlock(
        "vf_cells_fixture", "Subject x fixture cells", fc,
        "Mean cumulative error [m] and latency [s] per subject and fixture; trial_ids: the "
        "trials averaged.", display="csv"))
    tc = vf.trial_cells
    if tc.empty:
        out.notes.append("no VF-free probe trial: no box plot per trial")
    else:
        fig = box_figure(tc, group="trial", values=values, order=list(vf.trial_levels),
                         colors=False,
                         xlabel="VF-free trial number", title="Per VF-free trial")
        out.blocks.append(FigureBlock(
            "box_trial", "Per VF-free trial", figure_png(fig),
            "One dot per subject and probe trial. Numbers: tables/vf_cells_trial.csv."))
        out.blocks.append(TableBlock(
            "vf_cells_trial", "Subject x VF-free trial cells", tc,
            "One probe trial per subject and number.", display="csv"))
    return out.section("boxplots", "Box plots"), []


# ------------------------------------------------------------------------ questionnaires
def _items(protocol: Protocol | None) -> list[tuple[str, QuestionItem]]:
    if protocol is None:
        return []
    return [(q, it) for q in ("pre", "post") for it in getattr(protocol, q).items]


def questionnaire_section(data: StudyData) -> tuple[Section, list[dict[str, str]]]:
    """Subjective results: best/worst choices, ratings, proposed schemas, Likert items,
    Spearman correlations and free comments (seed Figs. 6.19, 6.24-6.25; spec §4)."""
    out = _Out()
    prov: list[dict[str, str]] = []
    a = data.answers
    s = data.sessions
    if s.empty:
        out.notes.append("no sessions: no questionnaire answers")
        return out.section("questionnaires", "Questionnaires"), prov
    items = _items(data.protocol)
    if data.protocol is None:
        out.notes.append("the protocol's questionnaire items are unknown (see the cohort "
                         "notes): answers cannot be interpreted")
        return out.section("questionnaires", "Questionnaires"), prov
    if not items:
        out.notes.append(f"protocol {data.protocol_name!r} asks no questionnaire item beyond "
                         "the demographics")
        return out.section("questionnaires", "Questionnaires"), prov
    for qname in ("post", "pre"):
        if not any(q == qname for q, _ in items):
            continue
        answered = set(a.loc[a["questionnaire"] == qname, "session_id"])
        missing = s[~s["id"].isin(answered)]
        if len(missing) == len(s):
            out.notes.append(f"no {qname}-questionnaire answers stored for any of the "
                             f"{len(s)} session(s)")
        elif len(missing):
            out.notes.append(f"{len(missing)} session(s) have no {qname}-questionnaire "
                             f"answers (left out of its tables): subject(s) "
                             f"{_subjects_text(missing['subject'])}")
    subject_of = dict(zip(s["id"].astype(int), s["subject"], strict=True))
    choice_rows, rating_rows, set_rows, fix_rows, num_rows, text_items = [], [], [], [], [], []
    best = worst = rating = None
    numeric_long = []
    for qname, it in items:
        rows = a[(a["questionnaire"] == qname) & (a["item"] == it.id)]
        resp = sorted(set(int(v) for v in rows["session_id"]))
        if it.type in ("condition_choice", "choice"):
            opts = list(it.conditions) if it.type == "condition_choice" else list(it.options)
            tab = []
            for o in opts:
                who = rows[rows["value"] == o]
                tab.append({"item": it.id, "questionnaire": qname, "select": it.select or "",
                            "condition": fixture_label(o) if it.type == "condition_choice"
                            else o, "value": o, "count": len(who), "n_respondents": len(resp),
                            "percent": 100.0 * len(who) / len(resp) if resp else math.nan,
                            "session_ids": ids_text(who["session_id"])})
            choice_rows += tab
            if it.type == "condition_choice" and resp:
                frame = pd.DataFrame(tab)[["value", "percent"]].rename(
                    columns={"value": "condition"})
                if it.select == "best" and best is None:
                    best = frame
                elif it.select == "worst" and worst is None:
                    worst = frame
        elif it.type == "condition_rating":
            tab = []
            for c in it.conditions:
                v = rows.loc[rows["key"] == c, "value_num"].astype(float)
                tab.append({"item": it.id, "questionnaire": qname, "condition": c,
                            "label": fixture_label(c), "n": int(v.notna().sum()),
                            "mean": float(v.mean()) if v.notna().any() else math.nan,
                            "sd": float(v.std(ddof=1)) if v.notna().sum() > 1 else math.nan,
                            "median": float(v.median()) if v.notna().any() else math.nan,
                            "min": float(v.min()) if v.notna().any() else math.nan,
                            "max": float(v.max()) if v.notna().any() else math.nan,
                            "scale": f"{it.min}-{it.max}",
                            "session_ids": ids_text(rows.loc[rows["key"] == c, "session_id"])})
            rating_rows += tab
            if rating is None and resp:
                rating = (pd.DataFrame(tab), (float(it.min), float(it.max)))
        elif it.type == "condition_sets":
            counts: dict[str, list[int]] = {}
            for r in rows.itertuples(index=False):
                counts.setdefault(str(r.value), []).append(int(r.session_id))
            for schema, sids in sorted(counts.items(), key=lambda kv: (-len(kv[1]), kv[0])):
                set_rows.append({"item": it.id, "questionnaire": qname, "schema": "+".join(
                    fixture_label(c) for c in schema.split("+")), "value": schema,
                    "count": len(sids), "session_ids": ids_text(sids)})
            for c in it.conditions:
                sids = [sid for schema, ss in counts.items() if c in schema.split("+")
                        for sid in ss]
                fix_rows.append({"item": it.id, "questionnaire": qname, "condition": c,
                                 "label": fixture_label(c), "count": len(sids),
                                 "session_ids": ids_text(sids)})
        elif it.type in ("likert", "integer"):
            v = rows["value_num"].astype(float)
            num_rows.append({"item": it.id, "questionnaire": qname, "type": it.type,
                             "prompt": it.prompt, "n": int(v.notna().sum()),
                             "mean": float(v.mean()) if v.notna().any() else math.nan,
                             "sd": float(v.std(ddof=1)) if v.notna().sum() > 1 else math.nan,
                             "median": float(v.median()) if v.notna().any() else math.nan,
                             "session_ids": ids_text(rows["session_id"])})
            numeric_long.append(pd.DataFrame({"subject": rows["session_id"].map(subject_of),
                                              "item": it.id, "value": v.to_numpy()}))
        elif it.type == "text":
            texts = [(int(r.session_id), str(r.value)) for r in rows.itertuples(index=False)
                     if str(r.value).strip()]
            text_items.append((qname, it, texts))
    if best is not None or worst is not None or rating is not None:
        cond = [c for c in ordered_conditions(
            (list(best["condition"]) if best is not None else [])
            + (list(worst["condition"]) if worst is not None else [])
            + (list(rating[0]["condition"]) if rating is not None else []),
            FIXTURE_ORDER + MODE_ORDER)]
        known = FIXTURE_COLORS | MODE_COLORS
        fig = choice_rating_figure(best, worst, None if rating is None else rating[0],
                                   order=cond, labels={c: fixture_label(c) for c in cond},
                                   colors={c: known[fixture_label(c)]
                                           for c in FIXTURE_ORDER + MODE_ORDER},
                                   rating_range=(0.0, 10.0) if rating is None else rating[1],
                                   noun="mode" if set(cond) & set(MODE_ORDER) else "VF")
        out.blocks.append(FigureBlock(
            "subjective", "Choices and ratings (as the seed's Fig. 6.19)", figure_png(fig),
            "Percent of the respondents choosing each condition as best / worst, and the "
            "mean rating with ± 1 sd (the panels of the items the protocol asks). Numbers: "
            "tables/questionnaire_choices.csv and tables/questionnaire_ratings.csv."))
    if choice_rows:
        out.blocks.append(TableBlock(
            "questionnaire_choices", "Choices (best / worst and other single choices)",
            pd.DataFrame(choice_rows), "percent of the respondents of the item; session_ids: "
            "the sessions whose answer it is.",
            columns=("item", "select", "condition", "count", "n_respondents", "percent")))
    if rating_rows:
        out.blocks.append(TableBlock(
            "questionnaire_ratings", "Ratings per condition", pd.DataFrame(rating_rows),
            "Mean, sd (n-1), median, range of the ratings.",
            columns=("item", "label", "n", "mean", "sd", "median", "min", "max", "scale")))
    if set_rows or fix_rows:
        st = pd.DataFrame(set_rows, columns=["item", "questionnaire", "schema", "value",
                                             "count", "session_ids"])
        ft = pd.DataFrame(fix_rows)
        n_prop = int(st["count"].sum()) if len(st) else 0
        fig = counts_figure(st, label="schema", title=f"proposed schemas ({n_prop} proposals, "
                            f"{len(st)} distinct)", second=ft.sort_values(
                                "count", ascending=False, kind="stable"),
                            second_label="label",
                            second_title="fixtures within the proposals",
                            xlabel="proposals")
        out.blocks.append(FigureBlock(
            "schemas", "Proposed schemas (as the seed's Figs. 6.24-6.25)", figure_png(fig),
            "Left: how often each set of fixtures was proposed; right: in how many proposals "
            "each fixture appears. Numbers: tables/questionnaire_schemas.csv and "
            "tables/questionnaire_schema_fixtures.csv."))
        out.blocks.append(TableBlock("questionnaire_schemas", "Proposed schemas", st,
                                     columns=("item", "schema", "count")))
        out.blocks.append(TableBlock("questionnaire_schema_fixtures",
                                     "Fixtures within the proposed schemas", ft,
                                     columns=("item", "label", "count")))
    if num_rows:
        out.blocks.append(TableBlock(
            "questionnaire_numeric", "Likert and numeric items", pd.DataFrame(num_rows),
            "Five-point Likert items (1 = strongly disagree ... 5 = strongly agree) and "
            "integer items: n, mean, sd (n-1), median.",
            columns=("item", "prompt", "n", "mean", "sd", "median")))
        likert = [d for d in numeric_long if len(d)]
        if len(likert) >= 2:
            long = pd.concat(likert, ignore_index=True)
            try:
                sp, msgs = _captured(stats.spearman_items, long, subject="subject",
                                     item="item", value="value")
                out.notes.extend(msgs)
                out.blocks.append(TableBlock(
                    "questionnaire_spearman", "Spearman correlations between items", sp,
                    "rho over the respondents answering both items (n); p: two-sided (t "
                    "approximation). provenance.csv lists the sessions."))
                for r in sp.itertuples(index=False):
                    both = long[long["item"].isin([r.var1, r.var2])].dropna()
                    ss = [sid for sid, subj in subject_of.items()
                          if subj in set(both["subject"])]
                    prov.append(_prov("questionnaire_spearman", f"{r.var1} ~ {r.var2}",
                                      session_ids=ss))
            except ConfigError as exc:
                out.notes.append(f"Spearman correlations not computed: {exc.reason}")
        elif numeric_long:
            out.notes.append("fewer than 2 Likert/numeric items answered: no Spearman "
                             "correlations")
    comment_rows = []
    for qname, it, texts in text_items:
        out.blocks.append(TextList(
            f"Free text: {it.id} ({qname}-questionnaire, {len(texts)} answer(s))",
            tuple(f"{subject_of.get(sid, '?')}: {t}" for sid, t in texts),
            empty="no answer"))
        comment_rows += [{"item": it.id, "questionnaire": qname, "session_id": sid,
                          "subject": subject_of.get(sid, ""), "text": t} for sid, t in texts]
    if comment_rows:
        out.blocks.append(TableBlock(
            "questionnaire_comments", "Free-text answers", pd.DataFrame(
                comment_rows, columns=["item", "questionnaire", "session_id", "subject",
                                       "text"]),
            "As entered (the CSV keeps the text verbatim).", display="csv"))
    return out.section("questionnaires", "Questionnaires"), prov


# ---------------------------------------------------------------------------------- MRCP
def mrcp_section(data: StudyData) -> tuple[Section, list[dict[str, str]]]:
    """MRCP vs standard teleoperation (spec §4; seed Tables 5.1-5.5)."""
    out = _Out()
    prov: list[dict[str, str]] = []
    intro: list[Block] = [Paragraph(
        "Per trial: ET = execution time (completion_time) [s]; EM = economy of movement, "
        "the Euclidean length of the tool path (path_l2) [m]; Q = quality: target "
        "displacement [m] (when stored), accumulated contact time [s], force [N s] and "
        "torque [N m s] on tissue. Per subject and mode the cell is the mean over the "
        "mode's trials; mean and sd per mode, paired Student t-tests per pair of modes "
        "(with observed power and the minimum n for power 0.9) and the seed's gain "
        "mean(StdT)/mean(mode) use the subjects with every mode. Learning curves: mean and "
        "interquartile range per trial number within the mode (1..6). Likert items: see "
        "the Questionnaires section.")]
    done = data.analysed
    mt = done[done["condition"].isin(TELEOPERATION_MODES)].copy()
    if mt.empty:
        out.notes.append("no analysed trial of the teleoperation modes (stdt, mrcp, "
                         "mrcp_cam) in the sessions of this protocol: not an MRCP study, "
                         "section not applicable")
        return out.section("mrcp", "MRCP vs standard teleoperation", intro), prov
    modes = ordered_conditions(mt["condition"], MODE_ORDER)
    labels = [fixture_label(m) for m in modes]
    mt["mode"] = mt["condition"].map(fixture_label)
    mt["trial_number"] = (mt.groupby(["session_id", "condition"])["trial_index"]
                          .rank(method="first").astype(np.int64))
    metrics = [m for m in MRCP_METRICS if m.metric in data.metrics.columns
               and data.metrics.loc[data.metrics.index.isin(set(mt["trial_id"])),
                                    m.metric].notna().any()]
    absent = [m.metric for m in MRCP_METRICS if m not in metrics]
    if absent:
        out.notes.append(f"metrics not stored for these trials (left out): {', '.join(absent)}")
    if not metrics:
        out.notes.append("no MRCP metric is stored for the teleoperation trials")
        return out.section("mrcp", "MRCP vs standard teleoperation", intro), prov
    wide = mt.merge(data.metrics[[m.metric for m in metrics]], how="left",
                    left_on="trial_id", right_index=True)
    wide = wide.rename(columns={m.metric: m.key for m in metrics})
    trials_tab = wide[["trial_id", "subject", "session_id", "trial_index", "condition", "mode",
                       "trial_number", *[m.key for m in metrics]]]
    desc, paired, gains, curves, fits = [], [], [], [], []
    excl: dict[str, list[str]] = {}  # exclusion note -> the metrics it applies to
    curve_figs: list[FigureBlock] = []
    for m in metrics:
        d = wide[["trial_id", "subject", "condition", "mode", "trial_number", m.key]].rename(
            columns={m.key: "value"})
        bad = d[d["value"].isna()]
        if len(bad):
            out.notes.append(f"{m.key}: {len(bad)} trial(s) without a value (e.g. not "
                             f"completed) left out: trial ids {ids_text(bad['trial_id'])}")
        d = d[d["value"].notna()]
        cells = (d.groupby(["subject", "condition"]).agg(
            value=("value", "mean"), n_trials=("trial_id", "size"),
            trial_ids=("trial_id", ids_text)).reset_index())
        cells["mode"] = cells["condition"].map(fixture_label)
        kept, missing = complete_subjects(cells, "condition", modes)
        if missing:
            excl.setdefault(_excluded_text("mode", {
                s: [fixture_label(x) for x in v] for s, v in missing.items()},
                "means, sds, paired tests and gains"), []).append(m.key)
        n = kept["subject"].nunique()
        for cond in modes:
            part = kept[kept["condition"] == cond]
            desc.append({"metric": m.key, "family": m.family, "unit": m.unit, "mode":
                         fixture_label(cond), "n_subjects": len(part),
                         "n_trials": int(part["n_trials"].sum()),
                         "mean": float(part["value"].mean()) if len(part) else math.nan,
                         "sd": float(part["value"].std(ddof=1)) if len(part) > 1 else math.nan,
                         "trial_ids": ids_text(" ".join(part["trial_ids"]).split())})
        for r in kept.itertuples(index=False):
            for t in ("mrcp_paired", "mrcp_gains"):
                prov.append(_prov(t, f"{m.key}|mode={r.mode}", r.subject,
                                  trial_ids=str(r.trial_ids).split()))
        if n >= 2 and len(modes) >= 2:
            k = kept.copy()
            k["mode"] = pd.Categorical(k["mode"], categories=labels)
            try:
                pp, msgs = _captured(stats.pairwise_paired, k, dv="value", subject="subject",
                                     within="mode")
                out.notes.extend(f"{m.key}: {x}" for x in msgs)
                pp.insert(0, "metric", m.key)
                pp.insert(1, "unit", m.unit)
                paired.append(pp)
            except ConfigError as exc:
                out.notes.append(f"{m.key}: paired t-tests not computed: {exc.reason}")
            if "stdt" in modes:
                ref = kept[kept["condition"] == "stdt"].set_index("subject")["value"]
                for cond in modes:
                    if cond == "stdt":
                        continue
                    cmp_ = kept[kept["condition"] == cond].set_index("subject")["value"]
                    cmp_ = cmp_.reindex(ref.index)
                    try:
                        g = stats.gain(ref.to_numpy(), cmp_.to_numpy())
                    except ConfigError as exc:
                        out.notes.append(f"{m.key}: gain StdT/{fixture_label(cond)} not "
                                         f"computed: {exc.reason}")
                        continue
                    gains.append({"metric": m.key, "family": m.family, "unit": m.unit,
                                  "reference": "StdT", "mode": fixture_label(cond),
                                  "n_subjects": n, "mean_reference": float(ref.mean()),
                                  "mean_mode": float(cmp_.mean()), "gain": g})
        elif n < 2:
            out.notes.append(f"{m.key}: {n} subject(s) with every mode; paired tests and "
                             "gains need at least 2")
        summ, msgs = _captured(stats.learning_curve_summary, d, dv="value", subject="subject",
                               trial="trial_number", condition="mode")
        out.notes.extend(msgs)
        ids = d.groupby(["mode", "trial_number"])["trial_id"].agg(ids_text)
        summ["trial_ids"] = [ids.get((r["mode"], r["trial"]), "")
                             for r in summ.to_dict("records")]
        summ.insert(0, "metric", m.key)
        summ.insert(1, "unit", m.unit)
        curves.append(summ)
        bands = {}
        for lab in labels:
            part = d[d["mode"] == lab]
            try:
                pf, _ = _captured(stats.fit_power_law, part["trial_number"].to_numpy(float),
                                  part["value"].to_numpy(float))
            except ConfigError as exc:
                out.notes.append(f"{m.key}, {lab}: learning-curve fit not computed: "
                                 f"{exc.reason}")
                continue
            bands[lab] = pf.band(np.linspace(1, float(part["trial_number"].max()), 40))
            fits.append({"metric": m.key, "unit": m.unit, "mode": lab, "model": "a*n^(-b)",
                         "n_obs": pf.n_obs, "a": pf.a, "b": pf.b, "se_a": pf.se_a,
                         "se_b": pf.se_b, "rss": pf.rss, "dof": pf.dof})
            for r in part.itertuples(index=False):
                prov.append(_prov("mrcp_learning_fit", f"{m.key}|mode={lab}", r.subject,
                                  trial_ids=[r.trial_id]))
        fig = learning_curve_figure(
            summ, ylabel=f"{m.family}: {m.label} [{m.unit}]",
            title=f"Learning curve: {m.key} ({m.label})",
            xlabel="trial number within the mode", condition="mode", order=labels,
            labels=None, bands=bands, colors=MODE_COLORS)
        curve_figs.append(FigureBlock(
            f"mrcp_learning_{m.key}", f"Learning curve: {m.key} ({m.label})", figure_png(fig),
            "Mean (line) and interquartile range (shaded) over subjects per trial number, "
            "one colour per mode; dashed: power-law fit per mode. Numbers: "
            f"tables/mrcp_learning_curve.csv (metric = {m.key})."))
    out.notes.extend(f"{', '.join(keys)}: {text}" for text, keys in excl.items())
    fig = box_figure(wide, group="mode", colors=MODE_COLORS,
                     values=[(m.key, f"{m.family}: {m.label} [{m.unit}]") for m in metrics],
                     order=labels,
                     xlabel="mode", title="Per mode: every trial")
    out.blocks.append(TableBlock(
        "mrcp_descriptives", "Mean and sd per mode (as the seed's Tables 5.1-5.5)",
        pd.DataFrame(desc), "Over the subject means (subjects with every mode); trial_ids: "
        "the trials averaged.", columns=("metric", "unit", "mode", "n_subjects", "n_trials",
                                         "mean", "sd")))
    if gains:
        out.blocks.append(TableBlock(
            "mrcp_gains", "Gains mean(StdT) / mean(mode)", pd.DataFrame(gains),
            "gain > 1: the mode has the smaller mean (shorter, more economical, fewer "
            "contacts). provenance.csv lists the trials of every subject x mode cell."))
    if paired:
        out.blocks.append(TableBlock(
            "mrcp_paired", "Paired t-tests per pair of modes", pd.concat(paired,
                                                                     ignore_index=True),
            "mean_diff = mean(group1 - group2); p two-sided; p_holm over the pairs of a "
            "metric; power_observed: power at this n; n_power90_ceil: minimum n for power "
            "0.9 at the observed effect cohen_dz.",
            columns=("metric", "group1", "group2", "n", "mean_diff", "t", "p", "p_holm",
                     "cohen_dz", "power_observed", "n_power90_ceil")))
    out.blocks.append(FigureBlock(
        "mrcp_box", "Per mode", figure_png(fig),
        "Every trial of every subject (one dot per trial); box = quartiles, line = median, "
        "diamond = mean. Numbers: tables/mrcp_trials.csv."))
    out.blocks.extend(curve_figs)
    if curves:
        out.blocks.append(TableBlock(
            "mrcp_learning_curve", "Learning curves per mode", pd.concat(curves,
                                                                     ignore_index=True),
            "Per metric, mode and trial number: n subjects, mean, quartiles; trial_ids.",
            display="details",
            columns=("metric", "mode", "trial", "n", "mean", "q25", "q75")))
    if fits:
        out.blocks.append(TableBlock(
            "mrcp_learning_fit", "Power-law fits per mode", pd.DataFrame(fits),
            "y = a·n^(-b) on the trials of every subject.", display="details"))
    out.blocks.append(TableBlock(
        "mrcp_trials", "Analysed teleoperation trials", trials_tab,
        "One row per analysed trial with its metrics.", display="csv"))
    return out.section("mrcp", "MRCP vs standard teleoperation", intro), prov


# --------------------------------------------------------------------------- traceability
def traceability_section(tables: Sequence[TableBlock]) -> Section:
    """Where every number comes from: the CSV files and how each is traced."""
    rows = []
    for t in tables:
        cols = set(t.data.columns)
        if "trial_id" in cols or "trial_ids" in cols:
            how = "trial_id(s) column"
        elif "session_ids" in cols or "session_id" in cols:
            how = "session_id(s) column" + (" + provenance.csv" if t.name in {
                "questionnaire_spearman"} else "")
        else:
            how = "provenance.csv (rows with table = name)"
        if t.name in ("vf_rm_anova", "vf_posthoc_tukey", "vf_posthoc_paired",
                      "vf_seed_replication", "vf_learning_fit", "mrcp_paired", "mrcp_gains",
                      "mrcp_learning_fit", "questionnaire_spearman"):
            how = "provenance.csv (rows with table = name)"
        rows.append({"table": f"tables/{t.name}.csv", "title": t.title, "rows": len(t.data),
                     "traced_by": how})
    rows.append({"table": "tables/provenance.csv", "title": "provenance of the test tables",
                 "rows": "", "traced_by": "table, group (the cell), subject, session_ids, "
                                          "trial_ids"})
    return Section("traceability", "Traceability", (
        Paragraph(
            "Every number of this report traces back to stored trials. Tables with one row "
            "per trial carry its trial_id; tables of groups or cells carry the trial_ids "
            "(space-separated) they were computed from; questionnaire tables carry the "
            "session_ids of the answers; statistical-test tables (ANOVA, post hoc, fits, "
            "gains) are traced through tables/provenance.csv, which lists per table, cell "
            "(group) and subject the trial ids averaged into that cell. Trial ids are the "
            "store's trials.id (vasim study export writes the same ids). The samples table "
            "is not read: the per-point and per-trial metrics stored with each trial are."),
        TableBlock("", "Tables written", pd.DataFrame(rows)),
    ))


# ------------------------------------------------------------------------------- assembly
STEPS: tuple[str, ...] = ("read store", "cohort", "learning curves", "fixture effect",
                          "box plots", "questionnaires", "MRCP", "write")
"""The progress-bar steps of :func:`build_report`."""


def build_report(db: str | os.PathLike[str], out: str | os.PathLike[str], *,
                 protocol: str | None = None, progress: bool = False) -> ReportResult:
    """Writes the study report of ``db`` into the folder ``out``.

    Args:
        db: the SQLite study store (opened read-only).
        out: output folder (created; ``index.html`` and ``tables/`` inside are replaced,
            CSVs of an earlier report listed in its ``tables/manifest.json`` removed).
        protocol: the protocol to report, or None for the store's only protocol.
        progress: progress output over the report's steps on stderr (:mod:`vasim.core.progress`).

    Returns:
        :class:`ReportResult`.

    Raises:
        ConfigError: ``db`` missing, ``out`` is a file, protocol ambiguous or unknown.
        StoreError: ``db`` is not a vasim study store.
    """
    t0 = time.perf_counter()
    out_dir = Path(out)
    if out_dir.exists() and not out_dir.is_dir():
        raise ConfigError("exists and is not a folder", file=out_dir, field="--out")
    with progress_bar(len(STEPS), "vasim report", "step", enabled=progress,
                      leave=False) as bar:
        def step(name: str) -> None:
            bar.set_postfix_str(name)

        step(STEPS[0])
        data = load_study(db, protocol)
        bar.update()
        prov: list[dict[str, str]] = []
        sections: list[Section] = []

        def run(name: str, build: Callable[[], tuple[Section, list[dict[str, str]]]]
                ) -> None:
            step(name)  # shown while the section is built
            section, rows = build()
            sections.append(section)
            prov.extend(rows)
            bar.update()

        run(STEPS[1], lambda: cohort_section(data))
        vf = analyse_vf(data)
        run(STEPS[2], lambda: learning_curve_section(data, vf))
        run(STEPS[3], lambda: fixture_effect_section(data, vf))
        run(STEPS[4], lambda: box_plot_section(vf))
        run(STEPS[5], lambda: questionnaire_section(data))
        run(STEPS[6], lambda: mrcp_section(data))
        step(STEPS[7])
        tables = [b for s in sections for b in s.blocks
                  if isinstance(b, TableBlock) and b.name]
        sections.append(traceability_section(tables))
        n_fig = sum(isinstance(b, FigureBlock) for s in sections for b in s.blocks)
        doc = ReportDoc(title=f"vasim study report: {data.protocol_name or 'no sessions'}",
                        meta=_meta(data), sections=tuple(sections))
        names = _write(out_dir, data, tables, prov, render_html(doc))
        bar.update()
    return ReportResult(out=out_dir, index=out_dir / "index.html", tables=names,
                        n_figures=n_fig, seconds=time.perf_counter() - t0,
                        protocol=data.protocol_name)


def _meta(data: StudyData) -> tuple[tuple[str, str], ...]:
    s = data.sessions
    shas = sorted(set(s["protocol_sha256"])) if len(s) else []
    return (
        ("database", str(data.db)),
        ("store schema version", "–" if data.schema_version is None
         else str(data.schema_version)),
        ("protocol", data.protocol_name or "– (no sessions)"),
        ("protocol text sha256", ", ".join(x[:16] for x in shas) or "–"),
        ("subjects / sessions", f"{s['subject'].nunique() if len(s) else 0} / {len(s)}"),
        ("generated", datetime.now(UTC).isoformat(timespec="seconds")),
        ("vasim", __version__),
        ("tables", "tables/*.csv beside this file; tables/provenance.csv traces the tests"),
    )


def _write(out_dir: Path, data: StudyData, tables: Sequence[TableBlock],
           prov: Sequence[dict[str, str]], page: str) -> tuple[str, ...]:
    tdir = out_dir / "tables"
    tdir.mkdir(parents=True, exist_ok=True)
    manifest = tdir / "manifest.json"
    if manifest.is_file():
        try:
            old = json.loads(manifest.read_text(encoding="utf-8")).get("tables", {})
        except (OSError, ValueError):
            old = {}
        for name in old:
            p = tdir / f"{name}.csv"
            if isinstance(name, str) and "/" not in name and p.is_file():
                p.unlink()
    seen: set[str] = set()
    info: dict[str, Any] = {}
    for t in tables:
        if t.name in seen:
            raise RuntimeError(f"report table {t.name!r} written twice")  # a programming error
        seen.add(t.name)
        t.data.to_csv(tdir / f"{t.name}.csv", index=False)
        info[t.name] = {"title": t.title, "rows": len(t.data),
                        "columns": [str(c) for c in t.data.columns]}
    pv = pd.DataFrame(list(prov), columns=list(PROVENANCE_COLUMNS))
    pv.to_csv(tdir / "provenance.csv", index=False)
    info["provenance"] = {"title": "provenance", "rows": len(pv),
                          "columns": list(PROVENANCE_COLUMNS)}
    manifest.write_text(json.dumps({
        "vasim_version": __version__, "database": str(data.db),
        "protocol": data.protocol_name, "tables": info}, indent=1), encoding="utf-8")
    (out_dir / "index.html").write_text(page, encoding="utf-8")
    return tuple(info)


__all__ = [
    "FIXTURE_LABELS",
    "FIXTURE_ORDER",
    "LABEL_PAIRED",
    "LABEL_TUKEY",
    "MODE_LABELS",
    "MODE_ORDER",
    "MRCP_METRICS",
    "PROVENANCE_COLUMNS",
    "STEPS",
    "MrcpMetric",
    "ReportResult",
    "StudyData",
    "VfAnalysis",
    "analyse_vf",
    "build_report",
    "complete_subjects",
    "fixture_label",
    "ids_text",
    "load_study",
    "ordered_conditions",
    "vf_trial_outcomes",
]
