"""Export a study database to tidy tables (CSV and/or Parquet) for analysis elsewhere.

``export_study(db, out)`` writes one file per table and format, plus ``manifest.json``
(vasim version, source database and its schema version, each table's row count, columns,
dtypes and units). ``read_export(out, table, fmt)`` reads a table back with the manifest's
dtypes, so CSV and Parquet give equal frames.

Tables (one row per ...):

``samples``
    logged step of every trial (completed and interrupted): ``trial_id`` then the flat
    sample columns of ``vasim.records.samples.FRAME_COLUMNS`` (``k``, ``t`` [s], ``x_*`` [m],
    ``g_*`` [m], ``goal_index``, ``f_*`` [N], ``ms_*``, ``zoom``, ``audio_*``, ``contact``,
    ``fc_*`` [N], ``tc_*`` [N m], ``delicate``, ``clutch``, ``in_view``, ``gain`` (the
    fixture gain in force, 1 = the schema as written)). Written trial by
    trial (a cohort's samples do not fit in memory at once).
``trials``
    trial row, every status (the audit table): ``trial_id, subject`` (NULL for a trial
    without a subject), ``label`` (its free-practice label, if any), ``session_id, protocol,
    trial_index`` (schedule index, NULL outside sessions), ``attempt, status, outcome``
    (how the trial ended: ``vasim.study.store.TRIAL_OUTCOMES``; NULL while running or
    unknown), ``task, variant, schema, active_fixtures, operator, seed, dt`` [s],
    ``n_samples, started_at, ended_at, vasim_version``.
``trial_metrics``
    **completed** trial of a subject: the context ``trial_id, subject, group, session_id,
    protocol, trial_index, block, block_index, trial_in_block, phase, sitting, day,
    condition, schema, task, variant, probe, probe_index`` (the VF-free trial number 1..8 of
    the learning curve, NULL for assisted trials), ``repetition, attempt, outcome`` and one
    column per metric of ``vasim.records.trial_metrics.TRIAL_METRICS`` (units there).
    Trials outside sessions have NULL session columns and ``condition`` = their schema.
``point_metrics``
    trajectory point of a completed trial of a subject: ``trial_id, subject, session_id,
    trial_index,
    condition, probe, probe_index`` and the columns of ``metrics.POINT_COLUMNS``.
``questionnaires``
    answer value: ``session_id, subject, protocol, questionnaire`` (pre/post), ``item,
    key`` (condition of a rating, entry number of a proposal, empty otherwise), ``value``
    (text as given), ``value_num`` (numeric items).
``subjects``
    subject: ``subject, created_at, group, specialisation, laparoscopy_experience,
    simulator_experience, robotic_experience`` (NULL when no pre-questionnaire).
``sessions``
    session: ``session_id, subject, protocol, protocol_sha256, seed, status, operator,
    n_trials, n_completed, n_interrupted, created_at, ended_at, notes``.
``schedule``
    scheduled trial: ``session_id, trial_index, block, block_index, trial_in_block,
    phase, sitting, day, condition, schema, task, variant, probe, probe_index, repetition,
    trial_id, attempts``.

``phase`` is the trial's block's phase (``acquisition``, ``retention``, ``transfer``),
``sitting`` the 1-based sitting (a new one at each block with ``delay_days``) and ``day``
the nominal day of that sitting after the first [d] (the protocol's delays, not the
calendar; the real elapsed time is in the ``'sitting'`` events), from the stored protocol
and schedule (``_phases``).

Trials without a subject (free practice) are in ``samples`` and ``trials`` (the audit
tables) but left out of the subject analyses (``trial_metrics``, ``point_metrics``);
``manifest.json`` says how many (``trials_without_subject``: completed ones left out).

CSV conventions (**decision**): UTF-8, comma-separated, a header row, floats written with
the shortest repr that reads back to the same double, a missing value written ``\\N`` (so
that an empty string, e.g. a VF-free trial's ``active_fixtures`` or an empty comment, stays
an empty string), booleans ``True``/``False``. (A text value that is exactly ``\\N`` would
read back from CSV as missing; Parquet keeps it.)

Example:
    >>> import tempfile, pathlib
    >>> from vasim.study.store import TrialStore
    >>> with tempfile.TemporaryDirectory() as d:
    ...     TrialStore(pathlib.Path(d) / "s.db").close()
    ...     out = export_study(pathlib.Path(d) / "s.db", pathlib.Path(d) / "out",
    ...                        formats=("csv",), tables=("sessions",))
    ...     sorted(p.name for p in out.iterdir())
    ['manifest.json', 'sessions.csv']
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from vasim import __version__
from vasim.core.atomic import atomic_folder
from vasim.core.config import check_choice, check_dir_path, check_file, expect
from vasim.core.errors import ConfigError
from vasim.core.extras import require
from vasim.core.progress import progress_bar
from vasim.records.samples import FRAME_COLUMNS, FRAME_DTYPES
from vasim.records.trial_metrics import TRIAL_METRICS
from vasim.study.protocol import (
    ScheduledTrial,
    block_of,
    day_offsets,
    parse_protocol,
    sitting_numbers,
)
from vasim.study.store import TrialStore

EXPORT_TABLES: tuple[str, ...] = ("samples", "trials", "trial_metrics", "point_metrics",
                                  "questionnaires", "subjects", "sessions", "schedule")
"""Every table ``export_study`` can write (the module docstring describes each)."""
FORMATS: tuple[str, ...] = ("csv", "parquet")
CSV_NA = "\\N"
"""How a missing value is written in the CSV files."""

_CONTEXT: dict[str, str] = {
    "trial_id": "int64", "subject": "str", "group": "str", "session_id": "Int64",
    "protocol": "str", "trial_index": "Int64", "block": "str", "block_index": "Int64",
    "trial_in_block": "Int64", "phase": "str", "sitting": "Int64", "day": "float64",
    "condition": "str", "schema": "str", "task": "str",
    "variant": "Int64", "probe": "boolean", "probe_index": "Int64", "repetition": "Int64",
    "attempt": "Int64", "outcome": "str",
}

_SPECS: dict[str, dict[str, str]] = {
    "samples": {"trial_id": "int64",
                **{c: ("float64" if FRAME_DTYPES[c] is np.float64 else "int64")
                   for c in FRAME_COLUMNS}},
    "trials": {"trial_id": "int64", "subject": "str", "label": "str", "session_id": "Int64",
               "protocol": "str", "trial_index": "Int64", "attempt": "Int64", "status": "str",
               "outcome": "str", "task": "str", "variant": "Int64", "schema": "str",
               "active_fixtures": "str", "operator": "str", "seed": "Int64", "dt": "float64",
               "n_samples": "Int64",
               "started_at": "str", "ended_at": "str", "vasim_version": "str"},
    "trial_metrics": {**_CONTEXT, **dict.fromkeys(TRIAL_METRICS, "float64")},
    "point_metrics": {**{k: _CONTEXT[k] for k in ("trial_id", "subject", "session_id",
                                                  "trial_index", "phase", "sitting",
                                                  "condition", "probe", "probe_index")},
                      "point": "int64", "reached": "bool", "t_reached": "float64",
                      "error_l1": "float64", "latency": "float64", "path_l1": "float64",
                      "path_l2": "float64", "n_samples": "int64"},
    "questionnaires": {"session_id": "int64", "subject": "str", "protocol": "str",
                       "questionnaire": "str", "item": "str", "key": "str", "value": "str",
                       "value_num": "float64"},
    "subjects": {"subject": "str", "created_at": "str", "group": "str",
                 "specialisation": "str", "laparoscopy_experience": "str",
                 "simulator_experience": "str", "robotic_experience": "str"},
    "sessions": {"session_id": "int64", "subject": "str", "protocol": "str",
                 "protocol_sha256": "str", "seed": "int64", "status": "str",
                 "operator": "str", "n_trials": "int64", "n_completed": "int64",
                 "n_interrupted": "int64", "created_at": "str", "ended_at": "str",
                 "notes": "str"},
    "schedule": {"session_id": "int64", "trial_index": "int64", "block": "str",
                 "block_index": "int64", "trial_in_block": "int64", "phase": "str",
                 "sitting": "Int64", "day": "float64", "condition": "str",
                 "schema": "str", "task": "str", "variant": "int64", "probe": "bool",
                 "probe_index": "Int64", "repetition": "int64", "trial_id": "Int64",
                 "attempts": "int64"},
}
"""Column -> dtype of every table (what ``read_export`` restores)."""

_UNITS: dict[str, str] = {"t": "s", "dt": "s", "day": "d", "t_reached": "s", "latency": "s",
                          "error_l1": "m", "path_l1": "m", "path_l2": "m",
                          **{f"{p}_{a}": u for p, u in (("x", "m"), ("g", "m"), ("f", "N"),
                                                        ("fc", "N"), ("tc", "N m"))
                             for a in "xyz"},
                          "audio_period": "s", "audio_pitch": "Hz"}


def table_columns(table: str) -> dict[str, str]:
    """Column -> dtype of an export table.

    Raises:
        ConfigError: unknown table.
    """
    check_choice(table, "tables", EXPORT_TABLES)
    return dict(_SPECS[table])


def _typed(df: pd.DataFrame, table: str) -> pd.DataFrame:
    """``df`` with exactly the table's columns, in order, cast to their dtypes."""
    spec = _SPECS[table]
    missing = [c for c in spec if c not in df.columns]
    if missing:
        raise ValueError(f"table {table}: missing columns {missing}")
    out = {}
    for c, dtype in spec.items():
        col = df[c]
        if dtype == "str":
            col = col.astype(pd.StringDtype())   # missing stays missing on pandas 2 and 3
        elif dtype == "boolean":
            col = col.astype("boolean")
        else:
            col = col.astype(dtype)
        out[c] = col
    return pd.DataFrame(out, columns=list(spec))


# ----------------------------------------------------------------------------- tables
def _phases(store: TrialStore, session_id: int, sched: pd.DataFrame) -> pd.DataFrame:
    """``sched`` with the phase, sitting and nominal day of each scheduled trial, from the
    protocol text stored with the session (``vasim.study.protocol.phases``).

    **Decision**: derived on export, not stored per trial: the stored protocol and the
    stored schedule determine them (``sitting_numbers``, ``day_offsets``, the same
    functions the session runner uses), so old databases export them too. A stored
    protocol this release can no longer parse leaves the three columns missing rather
    than failing the export.
    """
    out = sched.copy()
    try:
        protocol = parse_protocol(store.session(session_id)["protocol_toml"],
                                  source=f"{store.path} session {session_id}")
        schedule = [ScheduledTrial.from_row(r) for r in sched.to_dict("records")]
        out["phase"] = [block_of(protocol, t.block).phase for t in schedule]
        out["sitting"] = sitting_numbers(protocol, schedule)
        out["day"] = day_offsets(protocol, schedule)
    except (ConfigError, KeyError):
        out["phase"], out["sitting"], out["day"] = None, pd.NA, np.nan
    return out


def _schedule_all(store: TrialStore) -> pd.DataFrame:
    frames = [_phases(store, int(i), store.schedule(int(i))) for i in store.sessions()["id"]]
    if not frames:
        return _typed(pd.DataFrame({c: [] for c in _SPECS["schedule"]}), "schedule")
    return _typed(pd.concat(frames, ignore_index=True), "schedule")


def _trials_table(store: TrialStore) -> pd.DataFrame:
    t = store.trials().rename(columns={"id": "trial_id", "schedule_index": "trial_index"})
    return _typed(t, "trials")


def _context(store: TrialStore, trials: pd.DataFrame) -> pd.DataFrame:
    """Completed trials of a subject with their schedule context and the subject's group
    (trials without a subject are no subject's data: left out, counted in the manifest)."""
    done = trials[(trials["status"] == "completed") & trials["subject"].notna()][
        ["trial_id", "subject", "session_id", "protocol", "trial_index", "attempt", "schema",
         "task", "variant", "outcome"]]
    sched = _schedule_all(store).drop(columns=["trial_id", "attempts", "schema", "task",
                                               "variant"])
    ctx = done.merge(sched, how="left", on=["session_id", "trial_index"])
    ctx["condition"] = ctx["condition"].astype(object).where(ctx["condition"].notna(),
                                                             ctx["schema"].astype(object))
    demo = store.demographics()[["subject", "subject_group"]].rename(
        columns={"subject_group": "group"})
    ctx = ctx.merge(demo, how="left", on="subject")
    return ctx.sort_values("trial_id", kind="stable").reset_index(drop=True)


def _trial_metrics_table(store: TrialStore, ctx: pd.DataFrame) -> pd.DataFrame:
    wide = store.trial_metrics(wide=True)
    for m in TRIAL_METRICS:
        if m not in wide.columns:
            wide[m] = np.nan
    wide = wide[list(TRIAL_METRICS)].reset_index()
    df = ctx.merge(wide, how="left", on="trial_id")
    return _typed(df, "trial_metrics")


def _point_metrics_table(store: TrialStore, ctx: pd.DataFrame) -> pd.DataFrame:
    frames = []
    keys = ["trial_id", "subject", "session_id", "trial_index", "phase", "sitting",
            "condition", "probe", "probe_index"]
    for row in ctx[keys].itertuples(index=False):
        pm = store.point_metrics(int(row.trial_id))
        if pm.empty:
            continue
        for k in keys:
            pm[k] = getattr(row, k)
        frames.append(pm)
    df = (pd.concat(frames, ignore_index=True) if frames
          else pd.DataFrame({c: [] for c in _SPECS["point_metrics"]}))
    return _typed(df, "point_metrics")


def _questionnaires_table(store: TrialStore) -> pd.DataFrame:
    a = store.answers()
    s = store.sessions()[["id", "protocol"]].rename(columns={"id": "session_id"})
    df = a.merge(s, how="left", on="session_id")
    return _typed(df, "questionnaires")


def _subjects_table(store: TrialStore) -> pd.DataFrame:
    subj = store.subjects().rename(columns={"code": "subject"})
    demo = store.demographics().rename(columns={"subject_group": "group"})
    df = subj.merge(demo.drop(columns=["session_id", "updated_at"]), how="left",
                    on="subject")
    return _typed(df, "subjects")


def _sessions_table(store: TrialStore) -> pd.DataFrame:
    return _typed(store.sessions().rename(columns={"id": "session_id"}), "sessions")


# ---------------------------------------------------------------------------- writing
class _Writer:
    """Writes one table in the requested formats, whole or chunk by chunk."""

    def __init__(self, out: Path, table: str, formats: Sequence[str]):
        self.paths = {fmt: out / f"{table}.{fmt}" for fmt in formats}
        self.table = table
        self.rows = 0
        self._pq: Any = None
        self._csv_started = False
        for p in self.paths.values():
            if p.exists():
                p.unlink()

    def write(self, df: pd.DataFrame) -> None:
        if "csv" in self.paths:
            df.to_csv(self.paths["csv"], mode="a" if self._csv_started else "w",
                      header=not self._csv_started, index=False, na_rep=CSV_NA,
                      encoding="utf-8", lineterminator="\n")
            self._csv_started = True
        if "parquet" in self.paths:
            pa = require("pyarrow", "Parquet export")
            pq = require("pyarrow.parquet", "Parquet export")
            tab = pa.Table.from_pandas(df, preserve_index=False)
            if self._pq is None:
                self._pq = pq.ParquetWriter(self.paths["parquet"], tab.schema)
            self._pq.write_table(tab.cast(self._pq.schema))
        self.rows += len(df)

    def close(self, empty: pd.DataFrame) -> None:
        if not self._csv_started and self._pq is None:
            self.write(empty)  # an empty table still gets its header / schema
        if self._pq is not None:
            self._pq.close()


def export_study(
    db: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    formats: Iterable[str] = ("csv",),
    tables: Iterable[str] = EXPORT_TABLES,
    progress: bool = False,
) -> Path:
    """Writes the study's tidy tables (module docstring) into the folder ``out``.

    Args:
        db: the study database (opened read-only; a version-1 store must be opened
            writable once, e.g. by ``vasim study list``, to migrate it).
        out: output folder, written atomically (``vasim.core.atomic.atomic_folder``): the
            new set of files replaces a previous export as a whole, so a killed export
            leaves the old complete set or the new one, never a truncated table beside an
            old manifest; a folder holding files no export writes is refused, not deleted.
        formats: ``"csv"`` and/or ``"parquet"``.
        tables: a subset of ``EXPORT_TABLES``.
        progress: progress output over the trials while writing samples
            (``vasim.core.progress``).

    Returns:
        The output folder.

    Raises:
        ConfigError: unknown format or table. StoreError: unreadable database.
    """
    fmts = list(dict.fromkeys(formats))
    bad = [f for f in fmts if f not in FORMATS]
    expect(fmts and not bad, bad or fmts, f"export formats of {', '.join(FORMATS)} "
            "(unknown export format)", field="format")
    if "parquet" in fmts:  # before any work: one line naming the extra (issue #27 item 1)
        require("pyarrow.parquet", "Parquet export")
    names = list(dict.fromkeys(tables))
    # issue #30 item 6: `--tables ''` wrote only a manifest and exited 0
    expect(names, names, f"one or more of {', '.join(EXPORT_TABLES)}", field="--tables")
    for t in names:
        table_columns(t)
    out_dir = check_dir_path(Path(out), "out", what="an export folder", error=ConfigError)
    with atomic_folder(out_dir, owned=_export_file, what="export") as tmp:
        _export_into(db, tmp, fmts, names, progress)
    return out_dir


def _export_file(rel: Path) -> bool:
    """True for a file an export writes (``manifest.json``, ``<table>.<format>``)."""
    if len(rel.parts) != 1:
        return False
    return rel.name == "manifest.json" or (
        rel.suffix[1:] in FORMATS and rel.stem in EXPORT_TABLES)


def _export_into(db: str | os.PathLike[str], out_dir: Path, fmts: list[str], names: list[str],
                 progress: bool) -> None:
    manifest: dict[str, Any] = {
        "vasim_version": __version__, "exported_at": datetime.now(UTC).isoformat(),
        "database": str(Path(db).resolve()),
        "csv": {"encoding": "utf-8", "separator": ",", "na": CSV_NA},
        "tables": {},
    }
    with TrialStore(db, readonly=True) as store:
        manifest["schema_version"] = store.schema_version
        trials = _trials_table(store)
        ctx = _context(store, trials)
        manifest["trials_without_subject"] = int(
            ((trials["status"] == "completed") & trials["subject"].isna()).sum())
        builders = {
            "trials": lambda: trials,
            "trial_metrics": lambda: _trial_metrics_table(store, ctx),
            "point_metrics": lambda: _point_metrics_table(store, ctx),
            "questionnaires": lambda: _questionnaires_table(store),
            "subjects": lambda: _subjects_table(store),
            "sessions": lambda: _sessions_table(store),
            "schedule": lambda: _schedule_all(store),
        }
        for t in names:
            w = _Writer(out_dir, t, fmts)
            empty = _typed(pd.DataFrame({c: [] for c in _SPECS[t]}), t)
            try:
                if t == "samples":
                    _write_samples(store, trials, w, progress)
                else:
                    w.write(builders[t]())
            finally:
                w.close(empty)
            manifest["tables"][t] = {
                "rows": w.rows,
                "files": {f: p.name for f, p in w.paths.items()},
                "columns": [{"name": c, "dtype": d, **({"unit": _UNITS[c]} if c in _UNITS
                                                        else {})}
                            for c, d in _SPECS[t].items()],
            }
    (out_dir / "manifest.json").write_text(json.dumps(manifest, indent=2) + "\n",
                                           encoding="utf-8")


def _write_samples(store: TrialStore, trials: pd.DataFrame, w: _Writer,
                   progress: bool) -> None:
    ids = trials["trial_id"].tolist()
    for tid in progress_bar(None, "samples", "trial", enabled=progress, leave=False,
                            iterable=ids):
        s = store.samples(int(tid))
        if s.empty:
            continue
        s.insert(0, "trial_id", np.full(len(s), int(tid), dtype=np.int64))
        w.write(_typed(s, "samples"))


def read_export(out: str | os.PathLike[str], table: str, fmt: str = "csv") -> pd.DataFrame:
    """Reads an exported table back with its declared dtypes (CSV and Parquet agree).

    Raises:
        ConfigError: unknown table or format, or the file is missing.
    """
    spec = table_columns(table)
    check_choice(fmt, "format", FORMATS)
    path = check_file(Path(out) / f"{table}.{fmt}", "table",
                      what=f"an exported table {table!r} in {fmt} format")
    if fmt == "parquet":
        require("pyarrow.parquet", "reading a Parquet export")
        df = pd.read_parquet(path)
    else:
        dtypes = {c: ("str" if d == "str" else d) for c, d in spec.items()}
        df = pd.read_csv(path, dtype=dtypes, keep_default_na=False, na_values=[CSV_NA],
                         encoding="utf-8")
    return _typed(df, table)


__all__ = ["CSV_NA", "EXPORT_TABLES", "FORMATS", "export_study", "read_export",
           "table_columns"]
