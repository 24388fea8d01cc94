"""The durable trial store: one SQLite file per study (spec/study.md §2).

``TrialStore`` is the only code that talks to SQLite. A trial's life in the store:

1. ``begin_trial(meta)`` commits a ``trials`` row with status ``'running'`` at once, so a
   run that dies is visible afterwards;
2. ``finish_trial(...)`` writes every sample, the per-point metrics, the events, the summary
   and status ``'completed'`` in **one transaction**: a trial's data are either all in the
   store or not at all, never half-written;
3. ``mark_interrupted(...)`` closes a trial that stopped early (Ctrl-C, error), optionally
   with the samples gathered so far (again in one transaction).

Opening a store marks as ``'interrupted'`` every trial left ``'running'`` by a process that
no longer exists on this host (``os.kill(pid, 0)``, plus the process start time from
``/proc`` so that a recycled pid is not mistaken for the writer). Running trials of other
hosts are left alone (their liveness cannot be checked from here).

Durability (**decision**: durability over speed). ``journal_mode=WAL`` (readers never block
the writer; a killed writer leaves only an uncommitted WAL tail, which SQLite ignores) and
``synchronous=FULL`` (each commit is fsync'ed: a trial ``finish_trial`` returned for
survives a process kill *and* an OS crash or power cut; ``NORMAL`` would survive only the
former). The cost is one fsync per trial, not per sample. ``foreign_keys=ON``;
``busy_timeout`` = 10 s for concurrent writers (e.g. two stations sharing one file).

Identification: ``PRAGMA application_id`` = ``APPLICATION_ID`` marks a vasim store and
``PRAGMA user_version`` = ``SCHEMA_VERSION`` its schema; the ``schema_version`` table logs
when each version was applied. A store from a newer vasim is refused (``StoreError``); an
older one is migrated in one transaction by the steps in ``_MIGRATIONS`` (version 1 -> 2
adds tables and columns; no row is rewritten). Versions add tables and nullable or
defaulted columns; they never rename.

Schema, version 2 (units in brackets; times of day are ISO 8601 UTC text; "v2" marks what
version 2 added to version 1):

``schema_version``
    ``version`` INTEGER PK, ``applied_at`` TEXT.
``subjects`` — pseudonymous: codes only, never names.
    ``code`` TEXT PK (``^[A-Za-z0-9_-]{1,32}$``, also a CHECK), ``created_at`` TEXT,
    ``notes`` TEXT NULL (free text; must not identify the person).
``trials``
    ``id`` INTEGER PK; ``subject`` TEXT -> subjects.code; ``session_id`` INTEGER NULL (the
    session, -> sessions.id; NULL for a stand-alone ``vasim trial``); ``protocol`` TEXT NULL
    (protocol name); ``task`` TEXT (``'trajectory'``/``'point'``); ``variant`` INTEGER NULL
    (trajectory variant, 0 = original); ``schema`` TEXT NULL (fixture schema name);
    ``operator`` TEXT NULL (input device); ``seed`` INTEGER NULL; ``status`` TEXT in
    ``'running'``, ``'completed'``, ``'interrupted'``; ``started_at``, ``ended_at`` TEXT
    (ended NULL while running); ``dt`` REAL NULL [s] (control step); ``n_samples`` INTEGER
    NULL (rows in ``samples``, set when the trial closes); ``active_fixtures`` TEXT (``''`` =
    VF-free); ``summary_json`` TEXT NULL (``metrics.trial_summary`` + runner extras, JSON,
    NaN -> null); ``timing_json`` TEXT NULL (servo-loop timing statistics, JSON); ``pid``
    INTEGER, ``host`` TEXT, ``proc_token`` TEXT NULL (boot id + process start time) of the
    writing process; ``config_json`` TEXT NULL (the full trial configuration, operator
    profile included, as JSON: with the seed it re-runs the trial); ``schema_toml`` TEXT NULL
    (the resolved fixture schema as TOML, so a trial stays interpretable when the schema
    file changes); ``vasim_version`` TEXT NULL; v2: ``schedule_index`` INTEGER NULL (the
    scheduled trial of the session this row is an attempt at, -> scheduled_trials
    .trial_index), ``attempt`` INTEGER NULL (1 for the first attempt at that scheduled trial,
    2 after one interruption, ...).
``samples`` — one row per logged step, WITHOUT ROWID, PK (trial_id, k).
    ``trial_id`` -> trials.id; ``k`` INTEGER (step); ``t`` REAL [s] since trial start;
    ``x_x, x_y, x_z`` REAL [m] TCP; ``g_x, g_y, g_z`` REAL [m] goal; ``goal_index`` INTEGER;
    ``f_x, f_y, f_z`` REAL [N] rendered force; ``ms_x, ms_y, ms_z`` REAL MS factors;
    ``zoom`` REAL Mag magnification; ``audio_pitch`` REAL, ``audio_period`` REAL [s],
    ``audio_volume`` REAL AG outputs; ``contact`` INTEGER (0/1); v2: ``fc_x, fc_y, fc_z``
    REAL [N] tissue contact force (default 0), ``tc_x, tc_y, tc_z`` REAL [N m] tissue contact
    torque (default 0), ``delicate`` INTEGER (0/1, contact with a delicate structure),
    ``clutch`` INTEGER (0/1), ``in_view`` INTEGER (1 tool tip in the camera's field of
    view, 0 outside, -1 not determined: the value every version-1 row reads). See
    ``vasim.records.samples``.
``point_metrics`` — WITHOUT ROWID, PK (trial_id, point); columns of
    ``metrics.POINT_COLUMNS``: ``point`` INTEGER, ``reached`` INTEGER (0/1), ``t_reached``
    REAL [s] NULL, ``error_l1`` REAL [m] NULL, ``latency`` REAL [s] NULL, ``path_l1``,
    ``path_l2`` REAL [m] NULL, ``n_samples`` INTEGER; v4: ``error_l1_mm_s`` REAL [mm s]
    NULL (rate-independent e_i), ``path_dev_mean_mm``, ``path_dev_rms_mm``,
    ``path_dev_max_mm`` REAL [mm] NULL (distance to the planned path), ``path_dev_out_frac``
    REAL NULL (fraction of time outside the tolerance tube). ``error_l1`` is eq. 6.5, a sum
    of per-sample distances [m·sample], not a length.
``events`` — things that happened during a trial (device NaN, interruption, ...).
    ``id`` INTEGER PK, ``trial_id`` -> trials.id, ``t`` REAL NULL [s] since trial start,
    ``kind`` TEXT, ``detail`` TEXT, ``created_at`` TEXT.
``sessions`` (v2) — one subject running one protocol.
    ``id`` INTEGER PK; ``subject`` TEXT -> subjects.code; ``protocol`` TEXT (protocol name);
    ``protocol_toml`` TEXT (the protocol file's text as run: a session never depends on the
    file staying unchanged); ``protocol_sha256`` TEXT (of that text); ``seed`` INTEGER (the
    randomisation seed of the schedule); ``status`` TEXT in ``'running'``, ``'completed'``
    (every scheduled trial has a completed trial), ``'aborted'`` (stopped for good, reason in
    ``notes``); ``created_at``, ``ended_at`` TEXT; ``operator`` TEXT (``'scripted'``, ...);
    ``n_trials`` INTEGER (scheduled trials); ``config_json`` TEXT NULL (how the session's
    trials are run: operator skill or profile, time limit, cohort parameters of a simulated
    subject); ``notes`` TEXT NULL; ``vasim_version`` TEXT. At most one running session per
    (subject, protocol) (a partial UNIQUE index).
``scheduled_trials`` (v2) — the realised schedule, WITHOUT ROWID, PK (session_id,
    trial_index); written once with the session and replayed on resume, never recomputed.
    ``session_id`` -> sessions.id; ``trial_index`` INTEGER (0-based position in the session);
    ``block`` TEXT (block name); ``block_index`` INTEGER (0-based position of the block in
    this subject's order); ``trial_in_block`` INTEGER (0-based); ``condition`` TEXT (the
    protocol's condition label: a schema name, ``'none'``, or a teleoperation mode);
    ``schema`` TEXT NULL (fixture schema run, NULL for a teleoperation mode); ``task`` TEXT;
    ``variant`` INTEGER; ``probe`` INTEGER (0/1: a fixture-free probe trial, the learning
    curve's trials); ``probe_index`` INTEGER NULL (1-based number of the probe trial within
    the session: the VF study's "trial" factor 1..8); ``repetition`` INTEGER (0-based);
    ``trial_id`` INTEGER NULL (-> trials.id: the completed attempt, set in the transaction that
    completes it); ``attempts`` INTEGER (trial rows begun for this index).
``demographics`` (v2) — one row per subject (the latest pre-questionnaire), values checked.
    ``subject`` TEXT PK -> subjects.code; ``subject_group`` TEXT in ``GROUPS``;
    ``specialisation`` TEXT in ``SPECIALISATIONS``; ``laparoscopy_experience`` in
    ``LAPAROSCOPY_LEVELS``; ``simulator_experience`` in ``SIMULATOR_LEVELS``;
    ``robotic_experience`` in ``ROBOTIC_LEVELS`` (all TEXT); ``session_id`` INTEGER NULL (the
    session whose questionnaire gave them); ``updated_at`` TEXT.
``answers`` (v2) — questionnaire answers, tidy: one row per value, WITHOUT ROWID, PK
    (session_id, questionnaire, item, key). ``session_id`` -> sessions.id; ``subject`` TEXT;
    ``questionnaire`` TEXT ``'pre'``/``'post'``; ``item`` TEXT (the protocol's item id);
    ``key`` TEXT (the condition of a per-condition item such as a 0-10 rating, the 1-based
    entry number of a multi-entry item such as proposed schemas, ``''`` otherwise);
    ``value`` TEXT (as given: free text is stored verbatim, unescaped); ``value_num`` REAL
    NULL (the number, for numeric items); ``answered_at`` TEXT.
``trial_metrics`` (v2) — per-trial metrics, long format, WITHOUT ROWID, PK (trial_id,
    metric). ``trial_id`` -> trials.id; ``metric`` TEXT (a name of
    ``trial_metrics.TRIAL_METRICS``, which gives unit and meaning); ``value`` REAL NULL (NaN
    -> NULL). **decision**: long rather than wide, so that a new metric needs no schema
    change; ``TrialStore.trial_metrics(wide=True)`` pivots it. Written in the transaction
    that closes the trial; version-1 trials have none.

Floats round-trip exactly (SQLite REAL is an IEEE double) with two SQLite caveats: NaN is
stored as NULL (read back as NaN in float columns) and -0.0 is read back as 0.0.

Example:
    >>> import tempfile, pathlib
    >>> from vasim.records.samples import SampleBuffer
    >>> with tempfile.TemporaryDirectory() as d, TrialStore(pathlib.Path(d) / "s.db") as st:
    ...     tid = st.begin_trial(TrialMeta(subject="S01", task="trajectory"))
    ...     buf = SampleBuffer()
    ...     buf.append(0, 0.001, (0, 0, 0), (0, 0, 0.01), 0)
    ...     st.finish_trial(tid, buf)
    ...     st.trial(tid)["status"], len(st.samples(tid))
    ('completed', 1)
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import socket
import sqlite3
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd

from vasim import __version__
from vasim.core.errors import ConfigError, StoreError
from vasim.core.jsonio import dumps
from vasim.records.path_deviation import PATH_POINT_COLUMNS
from vasim.records.point_metrics import POINT_COLUMNS
from vasim.records.samples import FRAME_COLUMNS, FRAME_DTYPES, SampleBuffer
from vasim.records.trial_meta import SUBJECT_CODE_PATTERN, TrialMeta, validate_subject_code

log = logging.getLogger(__name__)

SCHEMA_VERSION = 4
"""Schema version written to ``PRAGMA user_version``."""

APPLICATION_ID = 0x76534D31  # b"vSM1"
"""``PRAGMA application_id`` of a vasim trial store."""


TrialStatus = Literal["running", "completed", "interrupted"]
TRIAL_STATUSES: tuple[str, ...] = ("running", "completed", "interrupted")

TRIAL_COLUMNS: tuple[str, ...] = (
    "id", "subject", "session_id", "protocol", "task", "variant", "schema", "operator", "seed",
    "status", "started_at", "ended_at", "dt", "n_samples", "active_fixtures", "summary_json",
    "timing_json", "pid", "host", "proc_token", "config_json", "schema_toml", "vasim_version",
    "schedule_index", "attempt",
)
"""Columns of the ``trials`` table (and of ``TrialStore.trials()``), in order."""

SessionStatus = Literal["running", "completed", "aborted"]
SESSION_STATUSES: tuple[str, ...] = ("running", "completed", "aborted")

SESSION_COLUMNS: tuple[str, ...] = (
    "id", "subject", "protocol", "protocol_toml", "protocol_sha256", "seed", "status",
    "created_at", "ended_at", "operator", "n_trials", "config_json", "notes", "vasim_version",
)
"""Columns of the ``sessions`` table, in order."""

SCHEDULE_COLUMNS: tuple[str, ...] = (
    "session_id", "trial_index", "block", "block_index", "trial_in_block", "condition",
    "schema", "task", "variant", "probe", "probe_index", "repetition", "trial_id", "attempts",
)
"""Columns of the ``scheduled_trials`` table (and of ``TrialStore.schedule()``), in order."""

ANSWER_COLUMNS: tuple[str, ...] = (
    "session_id", "subject", "questionnaire", "item", "key", "value", "value_num",
    "answered_at",
)
"""Columns of the ``answers`` table (and of ``TrialStore.answers()``), in order."""

GROUPS: tuple[str, ...] = ("surgeon", "resident")
"""Allowed ``demographics.subject_group`` values."""
SPECIALISATIONS: tuple[str, ...] = (
    "general_surgery", "gynaecology", "urology", "thoracic_surgery", "paediatric_surgery",
    "other",
)
"""Allowed ``demographics.specialisation`` values (the surgical speciality, or the one a
resident trains in)."""
LAPAROSCOPY_LEVELS: tuple[str, ...] = ("none", "1-10", "11-50", "51-200", ">200")
"""Allowed ``laparoscopy_experience``: laparoscopic procedures performed as first surgeon."""
SIMULATOR_LEVELS: tuple[str, ...] = ("none", "occasional", "regular")
"""Allowed ``simulator_experience``: earlier use of surgical simulators."""
ROBOTIC_LEVELS: tuple[str, ...] = ("none", "observed", "assisted", "performed")
"""Allowed ``robotic_experience``: the most involved role in robotic surgery so far."""

DEMOGRAPHIC_FIELDS: dict[str, tuple[str, ...]] = {
    "group": GROUPS,
    "specialisation": SPECIALISATIONS,
    "laparoscopy_experience": LAPAROSCOPY_LEVELS,
    "simulator_experience": SIMULATOR_LEVELS,
    "robotic_experience": ROBOTIC_LEVELS,
}
"""Demographic field -> allowed values (``group`` is stored as ``subject_group``)."""

DEMOGRAPHIC_COLUMNS: tuple[str, ...] = (
    "subject", "subject_group", "specialisation", "laparoscopy_experience",
    "simulator_experience", "robotic_experience", "session_id", "updated_at",
)
"""Columns of the ``demographics`` table, in order."""


def _sql_set(values: tuple[str, ...]) -> str:
    """``('a', 'b')`` for a CHECK (values are constants of this module, no quotes inside)."""
    return "(" + ", ".join(f"'{v}'" for v in values) + ")"

EVENT_COLUMNS: tuple[str, ...] = ("t", "kind", "detail", "created_at")
"""Columns of ``TrialStore.events()``."""

_BUSY_TIMEOUT_MS = 10_000

_SAMPLE_SQL_TYPES = {np.int64: "INTEGER", np.int32: "INTEGER", np.int8: "INTEGER",
                     np.float64: "REAL"}

_SCHEMA_V1 = """
CREATE TABLE schema_version (
    version     INTEGER PRIMARY KEY,
    applied_at  TEXT NOT NULL
);
CREATE TABLE subjects (
    code        TEXT PRIMARY KEY
                CHECK (length(code) BETWEEN 1 AND 32 AND code NOT GLOB '*[^A-Za-z0-9_-]*'),
    created_at  TEXT NOT NULL,
    notes       TEXT
);
CREATE TABLE trials (
    id              INTEGER PRIMARY KEY,
    subject         TEXT NOT NULL REFERENCES subjects(code),
    session_id      INTEGER,
    protocol        TEXT,
    task            TEXT NOT NULL,
    variant         INTEGER,
    schema          TEXT,
    operator        TEXT,
    seed            INTEGER,
    status          TEXT NOT NULL DEFAULT 'running'
                    CHECK (status IN ('running', 'completed', 'interrupted')),
    started_at      TEXT NOT NULL,
    ended_at        TEXT,
    dt              REAL,
    n_samples       INTEGER,
    active_fixtures TEXT NOT NULL DEFAULT '',
    summary_json    TEXT,
    timing_json     TEXT,
    pid             INTEGER,
    host            TEXT,
    proc_token      TEXT,
    config_json     TEXT,
    schema_toml     TEXT,
    vasim_version   TEXT
);
CREATE INDEX trials_subject ON trials(subject);
CREATE INDEX trials_status ON trials(status);
CREATE TABLE samples (
    trial_id INTEGER NOT NULL REFERENCES trials(id) ON DELETE CASCADE,
    k INTEGER NOT NULL, t REAL NOT NULL, x_x REAL, x_y REAL, x_z REAL, g_x REAL, g_y REAL,
    g_z REAL, goal_index INTEGER, f_x REAL, f_y REAL, f_z REAL, ms_x REAL, ms_y REAL,
    ms_z REAL, zoom REAL, audio_pitch REAL, audio_period REAL, audio_volume REAL,
    contact INTEGER,
    PRIMARY KEY (trial_id, k)
) WITHOUT ROWID;
CREATE TABLE point_metrics (
    trial_id   INTEGER NOT NULL REFERENCES trials(id) ON DELETE CASCADE,
    point      INTEGER NOT NULL,
    reached    INTEGER NOT NULL CHECK (reached IN (0, 1)),
    t_reached  REAL,
    error_l1   REAL,
    latency    REAL,
    path_l1    REAL,
    path_l2    REAL,
    n_samples  INTEGER NOT NULL,
    PRIMARY KEY (trial_id, point)
) WITHOUT ROWID;
CREATE TABLE events (
    id          INTEGER PRIMARY KEY,
    trial_id    INTEGER NOT NULL REFERENCES trials(id) ON DELETE CASCADE,
    t           REAL,
    kind        TEXT NOT NULL,
    detail      TEXT NOT NULL DEFAULT '',
    created_at  TEXT NOT NULL
);
CREATE INDEX events_trial ON events(trial_id);
"""
"""Version 1 as released (frozen text: later versions migrate from it, never edit it)."""

_SCHEMA_V2 = f"""
ALTER TABLE samples ADD COLUMN fc_x REAL DEFAULT 0.0;
ALTER TABLE samples ADD COLUMN fc_y REAL DEFAULT 0.0;
ALTER TABLE samples ADD COLUMN fc_z REAL DEFAULT 0.0;
ALTER TABLE samples ADD COLUMN tc_x REAL DEFAULT 0.0;
ALTER TABLE samples ADD COLUMN tc_y REAL DEFAULT 0.0;
ALTER TABLE samples ADD COLUMN tc_z REAL DEFAULT 0.0;
ALTER TABLE samples ADD COLUMN delicate INTEGER NOT NULL DEFAULT 0;
ALTER TABLE samples ADD COLUMN clutch INTEGER NOT NULL DEFAULT 0;
ALTER TABLE samples ADD COLUMN in_view INTEGER NOT NULL DEFAULT -1;
ALTER TABLE trials ADD COLUMN schedule_index INTEGER;
ALTER TABLE trials ADD COLUMN attempt INTEGER;
CREATE INDEX trials_session ON trials(session_id, schedule_index);
CREATE TABLE sessions (
    id              INTEGER PRIMARY KEY,
    subject         TEXT NOT NULL REFERENCES subjects(code),
    protocol        TEXT NOT NULL,
    protocol_toml   TEXT NOT NULL,
    protocol_sha256 TEXT NOT NULL,
    seed            INTEGER NOT NULL,
    status          TEXT NOT NULL DEFAULT 'running'
                    CHECK (status IN ('running', 'completed', 'aborted')),
    created_at      TEXT NOT NULL,
    ended_at        TEXT,
    operator        TEXT NOT NULL,
    n_trials        INTEGER NOT NULL,
    config_json     TEXT,
    notes           TEXT,
    vasim_version   TEXT
);
CREATE INDEX sessions_subject ON sessions(subject);
CREATE UNIQUE INDEX sessions_one_running ON sessions(subject, protocol)
    WHERE status = 'running';
CREATE TABLE scheduled_trials (
    session_id      INTEGER NOT NULL REFERENCES sessions(id) ON DELETE CASCADE,
    trial_index     INTEGER NOT NULL CHECK (trial_index >= 0),
    block           TEXT NOT NULL,
    block_index     INTEGER NOT NULL,
    trial_in_block  INTEGER NOT NULL,
    condition       TEXT NOT NULL,
    schema          TEXT,
    task            TEXT NOT NULL,
    variant         INTEGER NOT NULL,
    probe           INTEGER NOT NULL CHECK (probe IN (0, 1)),
    probe_index     INTEGER,
    repetition      INTEGER NOT NULL,
    trial_id        INTEGER REFERENCES trials(id),
    attempts        INTEGER NOT NULL DEFAULT 0,
    PRIMARY KEY (session_id, trial_index)
) WITHOUT ROWID;
CREATE TABLE demographics (
    subject                 TEXT PRIMARY KEY REFERENCES subjects(code),
    subject_group           TEXT NOT NULL CHECK (subject_group IN {_sql_set(GROUPS)}),
    specialisation          TEXT NOT NULL CHECK (specialisation IN {_sql_set(SPECIALISATIONS)}),
    laparoscopy_experience  TEXT NOT NULL
                            CHECK (laparoscopy_experience IN {_sql_set(LAPAROSCOPY_LEVELS)}),
    simulator_experience    TEXT NOT NULL
                            CHECK (simulator_experience IN {_sql_set(SIMULATOR_LEVELS)}),
    robotic_experience      TEXT NOT NULL
                            CHECK (robotic_experience IN {_sql_set(ROBOTIC_LEVELS)}),
    session_id              INTEGER REFERENCES sessions(id),
    updated_at              TEXT NOT NULL
);
CREATE TABLE answers (
    session_id      INTEGER NOT NULL REFERENCES sessions(id) ON DELETE CASCADE,
    subject         TEXT NOT NULL REFERENCES subjects(code),
    questionnaire   TEXT NOT NULL CHECK (questionnaire IN ('pre', 'post')),
    item            TEXT NOT NULL,
    key             TEXT NOT NULL DEFAULT '',
    value           TEXT NOT NULL,
    value_num       REAL,
    answered_at     TEXT NOT NULL,
    PRIMARY KEY (session_id, questionnaire, item, key)
) WITHOUT ROWID;
CREATE TABLE trial_metrics (
    trial_id    INTEGER NOT NULL REFERENCES trials(id) ON DELETE CASCADE,
    metric      TEXT NOT NULL,
    value       REAL,
    PRIMARY KEY (trial_id, metric)
) WITHOUT ROWID;
"""
"""Version 2: sessions, schedules, demographics, questionnaires, trial metrics, the new
sample columns (their defaults say "not measured" for version-1 trials) and the schedule link
of a trial."""

_SCHEMA_V4 = """
ALTER TABLE point_metrics ADD COLUMN error_l1_mm_s REAL;
ALTER TABLE point_metrics ADD COLUMN path_dev_mean_mm REAL;
ALTER TABLE point_metrics ADD COLUMN path_dev_rms_mm REAL;
ALTER TABLE point_metrics ADD COLUMN path_dev_max_mm REAL;
ALTER TABLE point_metrics ADD COLUMN path_dev_out_frac REAL;
"""
"""Version 4: the per-point rate-independent e_i and path-deviation columns
(``vasim.records.path_deviation``); older rows read NULL (NaN: not measured)."""

_MIGRATIONS: dict[int, str] = {
    1: _SCHEMA_V1, 2: _SCHEMA_V2,
    3: "",   # the store-package split's version-3 step (another branch) replaces this
    4: _SCHEMA_V4,
}
"""Script that takes a store from version v-1 to v (version 0 = empty file)."""


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="microseconds")


@dataclass(frozen=True)
class SessionMeta:
    """What defines a session when it is created (the ``sessions`` row).

    Attributes:
        subject: subject code. protocol: protocol name.
        protocol_toml: the protocol file's text as run (stored verbatim; its sha256 too).
        seed: the randomisation seed of the schedule, an integer in [0, 2**63).
        operator: the input device, e.g. ``"scripted"``.
        config: how the trials are run (JSON-serialisable), or None.
    """

    subject: str
    protocol: str
    protocol_toml: str
    seed: int
    operator: str
    config: Mapping[str, Any] | None = None

    def __post_init__(self) -> None:
        validate_subject_code(self.subject)
        for name in ("protocol", "protocol_toml", "operator"):
            v = getattr(self, name)
            if not isinstance(v, str) or not v:
                raise ConfigError(f"{name} must be a non-empty string, got {v!r}", field=name)
        if isinstance(self.seed, bool) or not isinstance(self.seed, int | np.integer) \
                or not 0 <= self.seed < 2**63:
            raise ConfigError(f"seed must be an integer in [0, 2**63), got {self.seed!r}",
                              field="seed")


@dataclass(frozen=True)
class Demographics:
    """A subject's demographic answers (pre-questionnaire), validated against the allowed
    values of ``DEMOGRAPHIC_FIELDS``.

    Raises:
        ConfigError: naming the field and the bad value, with the allowed ones.

    Example:
        >>> Demographics("resident", "urology", "1-10", "none", "observed").group
        'resident'
    """

    group: str
    specialisation: str
    laparoscopy_experience: str
    simulator_experience: str
    robotic_experience: str

    def __post_init__(self) -> None:
        for name, allowed in DEMOGRAPHIC_FIELDS.items():
            v = getattr(self, name)
            if v not in allowed:
                raise ConfigError(f"{name} must be one of {', '.join(allowed)}; got {v!r}",
                                  field=name)

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> Demographics:
        """Builds it from a dict with exactly the ``DEMOGRAPHIC_FIELDS`` keys.

        Raises:
            ConfigError: a missing or unknown key, or a bad value.
        """
        unknown = sorted(set(values) - set(DEMOGRAPHIC_FIELDS))
        if unknown:
            raise ConfigError(f"unknown demographic field(s) {unknown} (known: "
                              f"{', '.join(DEMOGRAPHIC_FIELDS)})", field=unknown[0])
        missing = [k for k in DEMOGRAPHIC_FIELDS if k not in values]
        if missing:
            raise ConfigError(f"missing demographic field(s) {missing}", field=missing[0])
        return cls(**{k: values[k] for k in DEMOGRAPHIC_FIELDS})


# ------------------------------------------------------------------------- processes
_RECOVERED_PREFIX = "writer process "
"""Start of the event detail ``recover_interrupted`` writes (recognised by the writer)."""
_RECOVERED_SQL = ("SELECT 1 FROM events WHERE trial_id = ? AND detail LIKE '"
                  + _RECOVERED_PREFIX + "%no longer runs%' LIMIT 1")

def _boot_id() -> str | None:
    try:
        return Path("/proc/sys/kernel/random/boot_id").read_text().strip()
    except OSError:
        return None


def _proc_stat(pid: int) -> tuple[str, str] | None:
    """(state, starttime) of a Linux process from /proc, or None if unavailable."""
    try:
        raw = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    rest = raw.rsplit(")", 1)[-1].split()
    if len(rest) < 20:
        return None
    return rest[0], rest[19]


def _proc_token(pid: int) -> str | None:
    """A token that identifies one process incarnation (boot id + start time), if known."""
    boot, stat = _boot_id(), _proc_stat(pid)
    if boot is None or stat is None:
        return None
    return f"{boot}:{stat[1]}"


def _process_alive(pid: int | None, token: str | None) -> bool:
    """True unless the process ``pid`` (on this host) has surely ended."""
    if pid is None:
        return True  # unknown writer: never guess
    if pid == os.getpid():
        # Our pid, but maybe not us: a row left by an earlier process that had this pid
        # (pids are reused, e.g. in containers) carries another start-time token.
        return token is None or _proc_token(pid) in (None, token)
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass  # exists, owned by someone else
    except OSError:
        return True
    stat = _proc_stat(pid)
    if stat is not None and stat[0] in ("Z", "X"):
        return False  # a zombie has finished running; it only awaits its parent
    if token is not None:
        now = _proc_token(pid)
        if now is not None and now != token:
            return False  # the pid now belongs to another process
    return True


# ----------------------------------------------------------------------------- json
def _to_json(v: Mapping[str, Any] | None) -> str | None:
    if v is None:
        return None
    try:
        return dumps(v)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"value is not JSON-serialisable: {e}") from None


# ---------------------------------------------------------------------------- store
class TrialStore:
    """A study's trials in one SQLite file (see the module docstring for the schema).

    Args:
        path: the database file; created (with the schema) if missing or empty. Its folder
            must exist.
        readonly: open for reading only (no schema creation, no interrupted-trial
            recovery); for analysis and reports.

    Raises:
        StoreError: naming the path, if the file is not a SQLite database, not a vasim
            store, written by a newer vasim (schema version), or cannot be opened.

    A store object belongs to the thread that opened it (sqlite3's rule); use one per
    thread or process. ``with TrialStore(p) as st:`` closes it at the end.
    """

    def __init__(self, path: str | os.PathLike[str], *, readonly: bool = False):
        self.path = Path(path)
        self.readonly = readonly
        self._host = socket.gethostname()
        self._con: sqlite3.Connection | None = None
        if self.path.is_dir():
            raise StoreError(f"trial store {self.path} is a directory, not a database file")
        if not self.path.parent.is_dir():
            raise StoreError(f"cannot create trial store {self.path}: folder "
                             f"{self.path.parent} does not exist")
        if readonly and not self.path.exists():
            raise StoreError(f"trial store {self.path} does not exist")
        try:
            if readonly:
                uri = self.path.resolve().as_uri() + "?mode=ro"
                con = sqlite3.connect(uri, uri=True, isolation_level=None,
                                      timeout=_BUSY_TIMEOUT_MS / 1000)
            else:
                con = sqlite3.connect(self.path, isolation_level=None,
                                      timeout=_BUSY_TIMEOUT_MS / 1000)
        except sqlite3.Error as e:
            raise StoreError(f"cannot open trial store {self.path}: {e}") from e
        self._con = con
        try:
            self._configure()
            self._check_schema()
        except StoreError:
            self.close()
            raise
        except sqlite3.Error as e:
            self.close()
            raise StoreError(f"cannot open trial store {self.path}: {e} "
                             "(not a vasim trial store, or unreadable)") from e
        self.recovered: list[int] = [] if readonly else self.recover_interrupted()
        """Ids of the trials this open marked 'interrupted' (their writer had died)."""

    # ------------------------------------------------------------------ plumbing
    @property
    def con(self) -> sqlite3.Connection:
        if self._con is None:
            raise StoreError(f"trial store {self.path} is closed")
        return self._con

    def _configure(self) -> None:
        con = self.con
        con.execute(f"PRAGMA busy_timeout = {_BUSY_TIMEOUT_MS}")
        con.execute("PRAGMA foreign_keys = ON")
        if self.readonly:
            con.execute("PRAGMA query_only = ON")

    def _enable_wal(self) -> None:
        """WAL + synchronous=FULL; only once the file is known to be ours (WAL persists)."""
        con = self.con
        mode = con.execute("PRAGMA journal_mode = WAL").fetchone()[0]
        if str(mode).lower() != "wal":
            raise StoreError(f"trial store {self.path}: cannot enable WAL journaling "
                             f"(got journal_mode={mode!r}; network file system?)")
        con.execute("PRAGMA synchronous = FULL")

    def _header(self) -> tuple[int, int, int]:
        con = self.con
        app = con.execute("PRAGMA application_id").fetchone()[0]
        ver = con.execute("PRAGMA user_version").fetchone()[0]
        n_obj = con.execute("SELECT count(*) FROM sqlite_master").fetchone()[0]
        return int(app), int(ver), int(n_obj)

    def _check_schema(self) -> None:
        app, ver, n_obj = self._header()  # raises sqlite3.DatabaseError for a non-database
        if app == 0 and ver == 0 and n_obj == 0:
            if self.readonly:
                raise StoreError(f"trial store {self.path} is empty (no vasim schema)")
            self._enable_wal()
            self._migrate()
            return
        if app != APPLICATION_ID:
            raise StoreError(
                f"{self.path} is a SQLite database but not a vasim trial store "
                f"(application_id={app:#x}, expected {APPLICATION_ID:#x})"
            )
        if ver > SCHEMA_VERSION:
            raise StoreError(
                f"trial store {self.path} has schema version {ver}, newer than this vasim "
                f"supports ({SCHEMA_VERSION}); upgrade vasim to read it"
            )
        if ver < 1:
            raise StoreError(f"trial store {self.path} has an invalid schema version {ver}")
        if not self.readonly:
            self._enable_wal()
        if ver < SCHEMA_VERSION:
            if self.readonly:
                raise StoreError(f"trial store {self.path} has schema version {ver}; open it "
                                 f"writable once to migrate it to {SCHEMA_VERSION}")
            self._migrate()

    def _migrate(self) -> None:
        with self._transaction():
            app, ver, n_obj = self._header()  # re-read under the write lock
            if ver == SCHEMA_VERSION and app == APPLICATION_ID:
                return  # another process created it meanwhile
            if ver == 0 and n_obj:
                raise StoreError(f"{self.path} is a SQLite database but not a vasim trial "
                                 "store (it has tables and no vasim schema version)")
            for v in range(ver + 1, SCHEMA_VERSION + 1):
                for stmt in _split_sql(_MIGRATIONS[v]):
                    self.con.execute(stmt)
                self.con.execute("INSERT INTO schema_version (version, applied_at) "
                                 "VALUES (?, ?)", (v, _now()))
            self.con.execute(f"PRAGMA application_id = {APPLICATION_ID}")
            self.con.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")

    @contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        """BEGIN IMMEDIATE ... COMMIT, or ROLLBACK on any exception (re-raised)."""
        if self.readonly:
            raise StoreError(f"trial store {self.path} is open read-only")
        con = self.con
        try:
            con.execute("BEGIN IMMEDIATE")
        except sqlite3.OperationalError as exc:      # e.g. another writer holds the lock
            raise StoreError(f"{self.path}: the database is busy or locked ({exc}); "
                             "another vasim process may be writing to it - try again") from exc
        try:
            yield con
        except BaseException:
            if con.in_transaction:
                con.execute("ROLLBACK")
            raise
        con.execute("COMMIT")

    def close(self) -> None:
        """Closes the connection (idempotent)."""
        if self._con is not None:
            self._con.close()
            self._con = None

    def __enter__(self) -> TrialStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._con is None else ("read-only" if self.readonly else "open")
        return f"TrialStore({str(self.path)!r}, {state})"

    @property
    def schema_version(self) -> int:
        """The store's ``PRAGMA user_version``."""
        return int(self.con.execute("PRAGMA user_version").fetchone()[0])

    def integrity_check(self) -> str:
        """Returns SQLite's ``PRAGMA integrity_check`` verdict (``'ok'`` when sound)."""
        rows = self.con.execute("PRAGMA integrity_check").fetchall()
        return "\n".join(str(r[0]) for r in rows)

    # ------------------------------------------------------------------ subjects
    def add_subject(self, code: str, *, notes: str | None = None) -> str:
        """Registers a subject code (no-op if it exists); returns the code.

        Raises:
            ConfigError: if the code does not match ``SUBJECT_CODE_PATTERN``.
        """
        validate_subject_code(code)
        with self._transaction() as con:
            con.execute("INSERT OR IGNORE INTO subjects (code, created_at, notes) "
                        "VALUES (?, ?, ?)", (code, _now(), notes))
        return code

    def subjects(self) -> pd.DataFrame:
        """All subjects: columns ``code, created_at, notes``, ordered by code."""
        rows = self.con.execute(
            "SELECT code, created_at, notes FROM subjects ORDER BY code").fetchall()
        return pd.DataFrame(rows, columns=["code", "created_at", "notes"])

    # ------------------------------------------------------------------ lifecycle
    def begin_trial(self, meta: TrialMeta | Mapping[str, Any]) -> int:
        """Creates the trial row with status 'running' and commits it; returns its id.

        With ``meta.schedule_index`` the trial is an attempt at that scheduled trial of
        ``meta.session_id``: in the same transaction the schedule's ``attempts`` is
        incremented and the row's ``attempt`` set, after checking that the session is
        running and that the scheduled trial has neither a completed trial nor another
        running attempt.

        Raises:
            ConfigError: on invalid meta (e.g. a bad subject code).
            StoreError: unknown session or scheduled trial, session not running, scheduled
                trial already completed or being run.
        """
        if not isinstance(meta, TrialMeta):
            meta = TrialMeta.from_mapping(meta)
        token = _proc_token(meta.pid) if meta.host == self._host else None
        with self._transaction() as con:
            con.execute("INSERT OR IGNORE INTO subjects (code, created_at) VALUES (?, ?)",
                        (meta.subject, _now()))
            attempt = None
            if meta.schedule_index is not None:
                attempt = self._claim_scheduled(con, meta)
            cur = con.execute(
                "INSERT INTO trials (subject, session_id, protocol, task, variant, schema, "
                "operator, seed, status, started_at, dt, active_fixtures, pid, host, "
                "proc_token, config_json, schema_toml, vasim_version, schedule_index, attempt) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, ?, 'running', ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (meta.subject, _int_or_none(meta.session_id), meta.protocol, meta.task,
                 _int_or_none(meta.variant), meta.schema, meta.operator,
                 _int_or_none(meta.seed), _now(), meta.dt, meta.active_fixtures,
                 _int_or_none(meta.pid), meta.host, token,
                 _to_json(meta.config), meta.schema_toml,
                 __version__, _int_or_none(meta.schedule_index), attempt),
            )
            trial_id = cur.lastrowid
        assert trial_id is not None  # sqlite always sets it after an INSERT
        return int(trial_id)

    def _claim_scheduled(self, con: sqlite3.Connection, meta: TrialMeta) -> int:
        """Checks a scheduled trial can start and counts the attempt; returns its number."""
        sid, idx = int(meta.session_id), int(meta.schedule_index)  # type: ignore[arg-type]
        srow = con.execute("SELECT status, subject FROM sessions WHERE id = ?",
                           (sid,)).fetchone()
        if srow is None:
            raise StoreError(f"trial store {self.path}: no session {sid}")
        if srow[0] != "running":
            raise StoreError(f"trial store {self.path}: session {sid} is {srow[0]!r}, "
                             "not 'running'")
        if srow[1] != meta.subject:
            raise StoreError(f"trial store {self.path}: session {sid} belongs to subject "
                             f"{srow[1]!r}, not {meta.subject!r}")
        row = con.execute("SELECT trial_id, attempts FROM scheduled_trials "
                          "WHERE session_id = ? AND trial_index = ?", (sid, idx)).fetchone()
        if row is None:
            raise StoreError(f"trial store {self.path}: session {sid} has no scheduled "
                             f"trial {idx}")
        if row[0] is not None:
            raise StoreError(f"trial store {self.path}: scheduled trial {idx} of session "
                             f"{sid} is already completed (trial {row[0]})")
        running = con.execute(
            "SELECT id FROM trials WHERE session_id = ? AND schedule_index = ? "
            "AND status = 'running'", (sid, idx)).fetchone()
        if running is not None:
            raise StoreError(f"trial store {self.path}: scheduled trial {idx} of session "
                             f"{sid} is being run (trial {running[0]} is 'running')")
        attempt = int(row[1]) + 1
        con.execute("UPDATE scheduled_trials SET attempts = ? WHERE session_id = ? "
                    "AND trial_index = ?", (attempt, sid, idx))
        return attempt

    def finish_trial(
        self,
        trial_id: int,
        samples: SampleBuffer,
        point_metrics: pd.DataFrame | None = None,
        summary: Mapping[str, Any] | None = None,
        *,
        events: Iterable[tuple[float | None, str, str]] = (),
        timing: Mapping[str, Any] | None = None,
        trial_metrics: Mapping[str, float] | None = None,
    ) -> None:
        """Stores a trial's samples, metrics, events and summary; status 'completed'.

        Everything is written in one transaction, committed (and fsync'ed) before this
        returns: the trial is then durable, and nothing of it is stored if this fails or the
        process dies first. A trial that is an attempt at a scheduled trial becomes that
        scheduled trial's ``trial_id`` in the same transaction (if, against the checks of
        ``begin_trial``, another attempt completed it first, this one is kept but closed
        'interrupted' with a ``superseded`` event, so a scheduled trial never has two
        completed trials).

        Args:
            trial_id: from ``begin_trial``; the trial must still be 'running'.
            samples: the trial's sample buffer (its ``active_fixtures``, if not empty,
                replaces the one given at ``begin_trial``).
            point_metrics: ``metrics.point_metrics`` frame (columns ``POINT_COLUMNS``).
            summary: ``metrics.trial_summary`` dict plus any extras (JSON-serialisable).
            events: ``(t [s] or None, kind, detail)`` tuples.
            timing: servo-loop timing statistics (JSON-serialisable), or None.
            trial_metrics: ``trial_metrics.trial_metrics`` dict (name -> float), or None.

        Raises:
            StoreError: unknown trial, trial not 'running', duplicate step k, or SQLite
                failure (the transaction is rolled back).
        """
        self._close_trial(trial_id, "completed", samples, point_metrics, summary, events,
                          timing, trial_metrics, reason=None)

    def keep_interrupted(self, trial_id: int, reason: str, partial: Callable[[], Any], *,
                         samples: SampleBuffer | None = None,
                         events: Iterable[tuple[float | None, str, str]] = ()) -> None:
        """Marks a failed trial 'interrupted' with as much as can be kept, never leaving it
        'running': the partial result (``partial()``: an object with ``samples``,
        ``metrics``, ``summary``, ``events`` and ``trial_metrics``); if computing that fails
        too, the raw ``samples``; if storing those fails, the bare status change. For an
        ``except`` block: its own failures are logged, not raised.
        """
        extra = list(events)
        attempts: list[Callable[[], object]] = []

        def full() -> object:
            res = partial()
            return self.mark_interrupted(
                trial_id, reason=reason, samples=res.samples, point_metrics=res.metrics,
                summary=res.summary, events=[*res.events, *extra],
                trial_metrics=res.trial_metrics)

        attempts.append(full)
        if samples is not None:
            attempts.append(lambda: self.mark_interrupted(trial_id, reason=reason,
                                                          samples=samples, events=extra))
        attempts.append(lambda: self.mark_interrupted(trial_id, reason=reason, events=extra))
        for attempt in attempts:
            try:
                attempt()
                return
            except Exception as exc:                 # fall back to keeping less
                log.warning("trial %s: keeping its partial data failed (%s); keeping less",
                            trial_id, exc)

    def mark_interrupted(
        self,
        trial_id: int,
        *,
        reason: str = "",
        samples: SampleBuffer | None = None,
        point_metrics: pd.DataFrame | None = None,
        summary: Mapping[str, Any] | None = None,
        events: Iterable[tuple[float | None, str, str]] = (),
        trial_metrics: Mapping[str, float] | None = None,
    ) -> bool:
        """Marks a running trial 'interrupted', optionally keeping what it recorded.

        Safe to call from an ``except`` block: a trial that is no longer 'running' (e.g.
        already completed) is left unchanged and ``False`` is returned.

        Args:
            trial_id: the trial. reason: stored as an ``'interrupted'`` event.
            samples, point_metrics, summary, events, trial_metrics: the partial data to
                keep (one transaction with the status change), or None/empty.

        Returns:
            True if the trial was running and is now 'interrupted'.

        Raises:
            StoreError: unknown trial id, or SQLite failure.
        """
        try:
            self._close_trial(trial_id, "interrupted", samples, point_metrics, summary,
                              events, None, trial_metrics, reason=reason)
        except _NotRunning:
            return False
        return True

    def _is_writer(self, pid: int | None, host: str | None, token: str | None) -> bool:
        """True if this process is the one that began a trial with these identifiers."""
        return (pid == os.getpid() and host == self._host and token is not None
                and token == _proc_token(os.getpid()))

    def _close_trial(
        self,
        trial_id: int,
        status: Literal["completed", "interrupted"],
        samples: SampleBuffer | None,
        point_metrics: pd.DataFrame | None,
        summary: Mapping[str, Any] | None,
        events: Iterable[tuple[float | None, str, str]],
        timing: Mapping[str, Any] | None,
        trial_metrics: Mapping[str, float] | None,
        *,
        reason: str | None,
    ) -> None:
        tid = _trial_id(trial_id)
        metric_rows = _metric_rows(point_metrics) if point_metrics is not None else []
        tm_rows = _trial_metric_rows(trial_metrics) if trial_metrics is not None else []
        summary_json = _to_json(summary)
        timing_json = _to_json(timing)
        event_rows = [(None if t is None else float(t), str(kind), str(detail))
                      for t, kind, detail in events]
        if samples is not None and not isinstance(samples, SampleBuffer):
            raise ConfigError(f"samples must be a SampleBuffer, got {type(samples).__name__}")
        try:
            with self._transaction() as con:
                row = con.execute("SELECT status, pid, host, proc_token, session_id, "
                                  "schedule_index FROM trials WHERE id = ?",
                                  (tid,)).fetchone()
                if row is None:
                    raise StoreError(f"trial store {self.path}: no trial {tid}")
                if (row[0] == "interrupted" and status == "completed"
                        and self._is_writer(row[1], row[2], row[3])
                        and con.execute(_RECOVERED_SQL, (tid,)).fetchone() is not None):
                    # Another process's recovery took this live trial for a dead one (it
                    # cannot see our pid, e.g. from another pid namespace); we are its
                    # writer, so it completes rather than losing its samples.
                    event_rows.append((None, "recovery_overruled",
                                       "marked interrupted by another process while alive"))
                elif row[0] != "running":
                    if status == "interrupted":
                        raise _NotRunning
                    raise StoreError(f"trial store {self.path}: trial {tid} is {row[0]!r}, "
                                     "not 'running'; cannot finish it")
                superseded = False
                if status == "completed" and row[5] is not None:
                    # The schedule link is part of the completing transaction.
                    cur = con.execute(
                        "UPDATE scheduled_trials SET trial_id = ? WHERE session_id = ? AND "
                        "trial_index = ? AND trial_id IS NULL", (tid, row[4], row[5]))
                    if cur.rowcount != 1:
                        other = con.execute(
                            "SELECT trial_id FROM scheduled_trials WHERE session_id = ? AND "
                            "trial_index = ?", (row[4], row[5])).fetchone()
                        status = "interrupted"
                        superseded = True
                        reason = (f"superseded: scheduled trial {row[5]} of session {row[4]} "
                                  f"was completed by trial {other[0] if other else '?'}")
                n = 0
                fixtures = ""
                if samples is not None:
                    n = len(samples)
                    fixtures = samples.active_fixtures
                    # trial_id is a validated int: inline it rather than rebuild every row
                    con.executemany(
                        f"INSERT INTO samples (trial_id, {', '.join(FRAME_COLUMNS)}) "
                        f"VALUES ({tid}, {', '.join('?' * len(FRAME_COLUMNS))})",
                        samples.rows(),
                    )
                if metric_rows:
                    con.executemany(
                        f"INSERT INTO point_metrics (trial_id, {', '.join(POINT_COLUMNS)}) "
                        f"VALUES ({tid}, {', '.join('?' * len(POINT_COLUMNS))})",
                        metric_rows,
                    )
                if tm_rows:
                    con.executemany(
                        f"INSERT INTO trial_metrics (trial_id, metric, value) "
                        f"VALUES ({tid}, ?, ?)", tm_rows)
                now = _now()
                if reason is not None:
                    kind = "superseded" if superseded else "interrupted"
                    event_rows.append((None, kind, reason))
                if event_rows:
                    con.executemany(
                        f"INSERT INTO events (trial_id, t, kind, detail, created_at) "
                        f"VALUES ({tid}, ?, ?, ?, '{now}')",
                        event_rows,
                    )
                con.execute(
                    "UPDATE trials SET status = ?, ended_at = ?, n_samples = ?, "
                    "summary_json = ?, timing_json = ?, "
                    "active_fixtures = CASE WHEN ? = '' THEN active_fixtures ELSE ? END "
                    "WHERE id = ?",
                    (status, now, n, summary_json, timing_json, fixtures, fixtures, tid),
                )
        except sqlite3.IntegrityError as e:
            raise StoreError(f"trial store {self.path}: cannot store trial {tid}: {e} "
                             "(duplicate step k?)") from e
        except sqlite3.Error as e:
            raise StoreError(f"trial store {self.path}: cannot store trial {tid}: {e}") from e

    def recover_interrupted(self) -> list[int]:
        """Marks 'interrupted' the running trials whose writing process has ended.

        Only trials written on this host are checked. Called when the store opens.

        Returns:
            The ids of the trials marked.
        """
        rows = self.con.execute(
            "SELECT id, pid, host, proc_token FROM trials WHERE status = 'running'").fetchall()
        dead = [(tid, pid) for tid, pid, host, token in rows
                if host == self._host and not _process_alive(pid, token)]
        marked = []
        for tid, pid in dead:
            reason = (f"{_RECOVERED_PREFIX}{pid} on {self._host} no longer runs; found by "
                      f"process {os.getpid()} when opening the store")
            if self.mark_interrupted(tid, reason=reason):
                marked.append(tid)
        return marked

    def add_event(self, trial_id: int, kind: str, detail: str = "", *,
                  t: float | None = None) -> None:
        """Stores one event at once (its own transaction; not for the 1 kHz loop)."""
        tid = _trial_id(trial_id)
        try:
            with self._transaction() as con:
                con.execute("INSERT INTO events (trial_id, t, kind, detail, created_at) "
                            "VALUES (?, ?, ?, ?, ?)", (tid, t, kind, detail, _now()))
        except sqlite3.IntegrityError as e:
            raise StoreError(f"trial store {self.path}: no trial {tid}: {e}") from e

    # ------------------------------------------------------------------ sessions
    def create_session(self, meta: SessionMeta, schedule: Iterable[Mapping[str, Any]]) -> int:
        """Creates a running session and its realised schedule in one transaction.

        Args:
            meta: the session. schedule: one mapping per scheduled trial with the keys of
                ``SCHEDULE_COLUMNS`` except ``session_id``, ``trial_id`` and ``attempts``
                (e.g. ``dataclasses.asdict`` of ``protocol.ScheduledTrial`` with ``index``
                renamed ``trial_index``), trial indices 0..n-1 in order.

        Returns:
            The session id.

        Raises:
            StoreError: the subject already has a running session of this protocol, or a
                bad schedule.
        """
        cols = [c for c in SCHEDULE_COLUMNS if c not in ("session_id", "trial_id", "attempts")]
        rows = []
        for i, item in enumerate(schedule):
            missing = [c for c in cols if c not in item]
            if missing:
                raise StoreError(f"scheduled trial {i} lacks {missing}")
            if item["trial_index"] != i:
                raise StoreError(f"scheduled trial {i} has trial_index {item['trial_index']!r}"
                                 f"; expected {i} (0..n-1 in order)")
            rows.append(tuple(int(item[c]) if isinstance(item[c], bool | np.bool_)
                              else item[c] for c in cols))
        if not rows:
            raise StoreError("a session needs at least one scheduled trial")
        sha = hashlib.sha256(meta.protocol_toml.encode("utf-8")).hexdigest()
        try:
            with self._transaction() as con:
                con.execute("INSERT OR IGNORE INTO subjects (code, created_at) VALUES (?, ?)",
                            (meta.subject, _now()))
                cur = con.execute(
                    "INSERT INTO sessions (subject, protocol, protocol_toml, protocol_sha256, "
                    "seed, status, created_at, operator, n_trials, config_json, "
                    "vasim_version) VALUES (?, ?, ?, ?, ?, 'running', ?, ?, ?, ?, ?)",
                    (meta.subject, meta.protocol, meta.protocol_toml, sha, int(meta.seed),
                     _now(), meta.operator, len(rows), _to_json(meta.config), __version__))
                sid = cur.lastrowid
                assert sid is not None
                con.executemany(
                    f"INSERT INTO scheduled_trials (session_id, {', '.join(cols)}) "
                    f"VALUES ({int(sid)}, {', '.join('?' * len(cols))})", rows)
        except sqlite3.IntegrityError as e:
            running = self.con.execute(
                "SELECT id FROM sessions WHERE subject = ? AND protocol = ? AND "
                "status = 'running'", (meta.subject, meta.protocol)).fetchone()
            if running is not None:
                raise StoreError(
                    f"trial store {self.path}: subject {meta.subject!r} already has a running "
                    f"session of protocol {meta.protocol!r} (session {running[0]}); resume it "
                    "(`vasim study resume`) or abort it") from e
            raise StoreError(f"trial store {self.path}: cannot create the session: {e}") from e
        return int(sid)

    def session(self, session_id: int) -> dict[str, Any]:
        """One session row as a dict (``SESSION_COLUMNS``) plus ``config`` parsed from JSON.

        Raises:
            StoreError: unknown session.
        """
        sid = _trial_id(session_id)
        row = self.con.execute(f"SELECT {', '.join(SESSION_COLUMNS)} FROM sessions "
                               "WHERE id = ?", (sid,)).fetchone()
        if row is None:
            raise StoreError(f"trial store {self.path}: no session {sid}")
        d = dict(zip(SESSION_COLUMNS, row, strict=True))
        d["config"] = json.loads(d["config_json"]) if d["config_json"] else None
        return d

    def sessions(self, *, subject: str | None = None, protocol: str | None = None,
                 status: SessionStatus | None = None) -> pd.DataFrame:
        """Sessions with their progress, ordered by id.

        Returns:
            DataFrame with ``SESSION_COLUMNS`` except ``protocol_toml`` and
            ``config_json``, plus ``n_completed`` (scheduled trials with a completed trial),
            ``n_interrupted`` (interrupted trial rows of the session) and ``next_index``
            (first unfinished trial index, -1 when all are done).
        """
        where, args = [], []
        for col, v in (("subject", subject), ("protocol", protocol), ("status", status)):
            if v is not None:
                where.append(f"s.{col} = ?")
                args.append(v)
        if status is not None and status not in SESSION_STATUSES:
            raise ConfigError(f"unknown session status {status!r} (expected one of "
                              f"{SESSION_STATUSES})", field="status")
        cols = [c for c in SESSION_COLUMNS if c not in ("protocol_toml", "config_json")]
        sql = (
            f"SELECT {', '.join('s.' + c for c in cols)}, "
            "(SELECT count(*) FROM scheduled_trials q WHERE q.session_id = s.id "
            " AND q.trial_id IS NOT NULL), "
            "(SELECT count(*) FROM trials t WHERE t.session_id = s.id "
            " AND t.status = 'interrupted'), "
            "(SELECT coalesce(min(q.trial_index), -1) FROM scheduled_trials q "
            " WHERE q.session_id = s.id AND q.trial_id IS NULL) "
            "FROM sessions s")
        if where:
            sql += " WHERE " + " AND ".join(where)
        rows = self.con.execute(sql + " ORDER BY s.id", args).fetchall()
        return pd.DataFrame(rows, columns=[*cols, "n_completed", "n_interrupted", "next_index"])

    def schedule(self, session_id: int) -> pd.DataFrame:
        """A session's scheduled trials (``SCHEDULE_COLUMNS``) by trial index; ``probe`` is
        bool, ``probe_index`` and ``trial_id`` nullable integers (pandas ``Int64``).

        Raises:
            StoreError: unknown session.
        """
        sid = _trial_id(session_id)
        self.session(sid)
        rows = self.con.execute(
            f"SELECT {', '.join(SCHEDULE_COLUMNS)} FROM scheduled_trials WHERE session_id = ? "
            "ORDER BY trial_index", (sid,)).fetchall()
        df = pd.DataFrame(rows, columns=list(SCHEDULE_COLUMNS))
        for c in ("session_id", "trial_index", "block_index", "trial_in_block", "variant",
                  "repetition", "attempts"):
            df[c] = df[c].astype(np.int64)
        df["probe"] = df["probe"].astype(bool)
        for c in ("probe_index", "trial_id"):
            df[c] = df[c].astype("Int64")
        return df

    def set_session_status(self, session_id: int, status: SessionStatus, *,
                           notes: str | None = None) -> None:
        """Closes a running session: ``'completed'`` (every scheduled trial has a completed
        trial, checked) or ``'aborted'`` (``notes``: why).

        Raises:
            StoreError: unknown session, session not running, or trials left to complete.
            ConfigError: a status other than 'completed' or 'aborted'.
        """
        if status not in ("completed", "aborted"):
            raise ConfigError(f"a session is closed as 'completed' or 'aborted', got "
                              f"{status!r}", field="status")
        sid = _trial_id(session_id)
        with self._transaction() as con:
            row = con.execute("SELECT status FROM sessions WHERE id = ?", (sid,)).fetchone()
            if row is None:
                raise StoreError(f"trial store {self.path}: no session {sid}")
            if row[0] != "running":
                raise StoreError(f"trial store {self.path}: session {sid} is {row[0]!r}, "
                                 "not 'running'")
            if status == "completed":
                left = con.execute("SELECT count(*) FROM scheduled_trials WHERE session_id = ? "
                                   "AND trial_id IS NULL", (sid,)).fetchone()[0]
                if left:
                    raise StoreError(f"trial store {self.path}: session {sid} still has {left} "
                                     "scheduled trial(s) to complete")
            con.execute("UPDATE sessions SET status = ?, ended_at = ?, "
                        "notes = coalesce(?, notes) WHERE id = ?",
                        (status, _now(), notes, sid))

    # -------------------------------------------------------------- questionnaires
    def set_demographics(self, subject: str, demographics: Demographics, *,
                         session_id: int | None = None) -> None:
        """Stores (or replaces) a subject's demographics.

        Raises:
            ConfigError: bad subject code or demographics.
        """
        validate_subject_code(subject)
        if not isinstance(demographics, Demographics):
            raise ConfigError(f"demographics must be a Demographics, got {demographics!r}")
        d = demographics
        with self._transaction() as con:
            con.execute("INSERT OR IGNORE INTO subjects (code, created_at) VALUES (?, ?)",
                        (subject, _now()))
            con.execute(
                f"INSERT OR REPLACE INTO demographics ({', '.join(DEMOGRAPHIC_COLUMNS)}) "
                f"VALUES ({', '.join('?' * len(DEMOGRAPHIC_COLUMNS))})",
                (subject, d.group, d.specialisation, d.laparoscopy_experience,
                 d.simulator_experience, d.robotic_experience, _int_or_none(session_id),
                 _now()))

    def demographics(self) -> pd.DataFrame:
        """Every subject's demographics (``DEMOGRAPHIC_COLUMNS``), ordered by subject."""
        rows = self.con.execute(f"SELECT {', '.join(DEMOGRAPHIC_COLUMNS)} FROM demographics "
                                "ORDER BY subject").fetchall()
        df = pd.DataFrame(rows, columns=list(DEMOGRAPHIC_COLUMNS))
        df["session_id"] = df["session_id"].astype("Int64")
        return df

    def add_answers(self, session_id: int, questionnaire: Literal["pre", "post"],
                    rows: Iterable[tuple[str, str, str, float | None]], *,
                    demographics: Demographics | None = None) -> int:
        """Stores one questionnaire's answers of a session, all at once (one transaction).

        Args:
            session_id: the session. questionnaire: ``"pre"`` or ``"post"``.
            rows: ``(item, key, value, value_num)`` tuples (see the ``answers`` table).
            demographics: the subject's demographics from this questionnaire, stored in the
                same transaction, or None.

        Returns:
            The number of answer rows stored.

        Raises:
            StoreError: unknown session, or this questionnaire was already answered.
            ConfigError: a bad questionnaire name or row.
        """
        if questionnaire not in ("pre", "post"):
            raise ConfigError(f"questionnaire must be 'pre' or 'post', got {questionnaire!r}",
                              field="questionnaire")
        sid = _trial_id(session_id)
        data = []
        for row in rows:
            item, key, value, num = row
            if not isinstance(item, str) or not item or not isinstance(key, str) \
                    or not isinstance(value, str):
                raise ConfigError(f"an answer row is (item, key, value, value_num) with "
                                  f"strings, got {row!r}")
            data.append((item, key, value, None if num is None else float(num)))
        with self._transaction() as con:
            srow = con.execute("SELECT subject FROM sessions WHERE id = ?", (sid,)).fetchone()
            if srow is None:
                raise StoreError(f"trial store {self.path}: no session {sid}")
            done = con.execute("SELECT count(*) FROM answers WHERE session_id = ? AND "
                               "questionnaire = ?", (sid, questionnaire)).fetchone()[0]
            if done:
                raise StoreError(f"trial store {self.path}: the {questionnaire} questionnaire "
                                 f"of session {sid} is already answered")
            now = _now()
            con.executemany(
                "INSERT INTO answers (session_id, subject, questionnaire, item, key, value, "
                "value_num, answered_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                [(sid, srow[0], questionnaire, item, key, value, num, now)
                 for item, key, value, num in data])
            if demographics is not None:
                d = demographics
                con.execute(
                    f"INSERT OR REPLACE INTO demographics ({', '.join(DEMOGRAPHIC_COLUMNS)}) "
                    f"VALUES ({', '.join('?' * len(DEMOGRAPHIC_COLUMNS))})",
                    (srow[0], d.group, d.specialisation, d.laparoscopy_experience,
                     d.simulator_experience, d.robotic_experience, sid, now))
        return len(data)

    def answers(self, session_id: int | None = None) -> pd.DataFrame:
        """Questionnaire answers (``ANSWER_COLUMNS``), by session, questionnaire, item, key."""
        sql = f"SELECT {', '.join(ANSWER_COLUMNS)} FROM answers"
        args: list[Any] = []
        if session_id is not None:
            sql += " WHERE session_id = ?"
            args.append(_trial_id(session_id))
        rows = self.con.execute(
            sql + " ORDER BY session_id, questionnaire DESC, item, key", args).fetchall()
        df = pd.DataFrame(rows, columns=list(ANSWER_COLUMNS))
        df["value_num"] = df["value_num"].astype(np.float64)
        return df

    # ------------------------------------------------------------------ readers
    def trials(self, status: TrialStatus | None = None, *,
               subject: str | None = None) -> pd.DataFrame:
        """Trial rows (columns ``TRIAL_COLUMNS``), ordered by id, optionally filtered.

        Raises:
            ConfigError: unknown status.
        """
        where, args = [], []
        if status is not None:
            if status not in TRIAL_STATUSES:
                raise ConfigError(f"unknown trial status {status!r} (expected one of "
                                  f"{TRIAL_STATUSES})", field="status")
            where.append("status = ?")
            args.append(status)
        if subject is not None:
            where.append("subject = ?")
            args.append(subject)
        sql = f"SELECT {', '.join(TRIAL_COLUMNS)} FROM trials"
        if where:
            sql += " WHERE " + " AND ".join(where)
        rows = self.con.execute(sql + " ORDER BY id", args).fetchall()
        return pd.DataFrame(rows, columns=list(TRIAL_COLUMNS))

    def trial(self, trial_id: int) -> dict[str, Any]:
        """One trial row as a dict (``TRIAL_COLUMNS``) plus ``summary`` and ``timing``
        parsed from their JSON (None if absent; non-finite numbers come back as None).

        Raises:
            StoreError: unknown trial id.
        """
        tid = _trial_id(trial_id)
        row = self.con.execute(
            f"SELECT {', '.join(TRIAL_COLUMNS)} FROM trials WHERE id = ?", (tid,)).fetchone()
        if row is None:
            raise StoreError(f"trial store {self.path}: no trial {tid}")
        d = dict(zip(TRIAL_COLUMNS, row, strict=True))
        d["summary"] = json.loads(d["summary_json"]) if d["summary_json"] else None
        d["timing"] = json.loads(d["timing_json"]) if d["timing_json"] else None
        d["config"] = json.loads(d["config_json"]) if d["config_json"] else None
        return d

    def samples(self, trial_id: int) -> pd.DataFrame:
        """A trial's samples ordered by k, columns ``samples.FRAME_COLUMNS`` with their
        buffer dtypes (NULL floats -> NaN). Empty for a trial without samples."""
        cols = self._sample_columns(trial_id)
        return pd.DataFrame(cols, columns=list(FRAME_COLUMNS))

    def sample_buffer(self, trial_id: int) -> SampleBuffer:
        """A trial's samples as a ``SampleBuffer`` (with the trial's active fixtures)."""
        fixtures = self.trial(trial_id)["active_fixtures"] or ""
        return SampleBuffer.from_columns(self._sample_columns(trial_id),
                                         active_fixtures=fixtures)

    def _sample_columns(self, trial_id: int) -> dict[str, np.ndarray]:
        tid = _trial_id(trial_id)
        rows = self.con.execute(
            f"SELECT {', '.join(FRAME_COLUMNS)} FROM samples WHERE trial_id = ? ORDER BY k",
            (tid,)).fetchall()
        if not rows:
            return {c: np.empty(0, dtype=FRAME_DTYPES[c]) for c in FRAME_COLUMNS}
        # one 2-D float conversion (None -> NaN) is ~3x faster than per-column arrays; the
        # integer columns (k < 2**53, goal_index, contact) are exact in float64
        block = np.array(rows, dtype=np.float64)
        out: dict[str, np.ndarray] = {}
        for j, c in enumerate(FRAME_COLUMNS):
            dtype = FRAME_DTYPES[c]
            col = block[:, j]
            out[c] = col.copy() if dtype is np.float64 else col.astype(dtype)
        return out

    def point_metrics(self, trial_id: int) -> pd.DataFrame:
        """A trial's per-point metrics, columns ``metrics.POINT_COLUMNS``, by point."""
        tid = _trial_id(trial_id)
        rows = self.con.execute(
            f"SELECT {', '.join(POINT_COLUMNS)} FROM point_metrics WHERE trial_id = ? "
            "ORDER BY point", (tid,)).fetchall()
        cols = list(zip(*rows, strict=True)) if rows else [()] * len(POINT_COLUMNS)
        data: dict[str, Any] = {}
        for c, col in zip(POINT_COLUMNS, cols, strict=True):
            if c in ("point", "n_samples"):
                data[c] = np.array(col, dtype=np.int64)
            elif c == "reached":
                data[c] = np.array(col, dtype=bool)
            else:
                data[c] = np.array(col, dtype=np.float64)
        return pd.DataFrame(data, columns=list(POINT_COLUMNS))

    def trial_metrics(self, trial_id: int | None = None, *, wide: bool = False,
                      ) -> pd.DataFrame:
        """Stored per-trial metrics.

        Args:
            trial_id: one trial, or None for every trial.
            wide: one row per trial (index ``trial_id``) and one float column per metric
                (in ``trial_metrics.TRIAL_METRICS`` order, unknown names after), instead of
                the long ``trial_id, metric, value`` rows.

        Returns:
            DataFrame; NULL values come back as NaN.
        """
        sql = "SELECT trial_id, metric, value FROM trial_metrics"
        args: list[Any] = []
        if trial_id is not None:
            sql += " WHERE trial_id = ?"
            args.append(_trial_id(trial_id))
        rows = self.con.execute(sql + " ORDER BY trial_id, metric", args).fetchall()
        df = pd.DataFrame(rows, columns=["trial_id", "metric", "value"])
        df["trial_id"] = df["trial_id"].astype(np.int64)
        df["value"] = df["value"].astype(np.float64)
        if not wide:
            return df
        from vasim.records.trial_metrics import TRIAL_METRICS

        w = df.pivot(index="trial_id", columns="metric", values="value")
        order = [m for m in TRIAL_METRICS if m in w.columns]
        order += sorted(c for c in w.columns if c not in TRIAL_METRICS)
        w = w[order].astype(np.float64)
        w.columns.name = None
        return w

    def events(self, trial_id: int) -> pd.DataFrame:
        """A trial's events (columns ``EVENT_COLUMNS``), in the order they were stored."""
        tid = _trial_id(trial_id)
        rows = self.con.execute(
            "SELECT t, kind, detail, created_at FROM events WHERE trial_id = ? ORDER BY id",
            (tid,)).fetchall()
        df = pd.DataFrame(rows, columns=list(EVENT_COLUMNS))
        df["t"] = df["t"].astype(np.float64)
        return df


class _NotRunning(Exception):
    """Internal: the trial to close is no longer running."""


def _trial_id(trial_id: object) -> int:
    if isinstance(trial_id, bool) or not isinstance(trial_id, (int, np.integer)):
        raise ConfigError(f"trial_id must be an integer, got {trial_id!r}")
    return int(trial_id)


def _int_or_none(v: int | None) -> int | None:
    return None if v is None else int(v)


def _metric_rows(df: pd.DataFrame) -> list[tuple[Any, ...]]:
    # the v4 path columns are optional: a frame without them stores NULL (not measured)
    df = df.assign(**{c: np.nan for c in PATH_POINT_COLUMNS if c not in df.columns})
    missing = [c for c in POINT_COLUMNS if c not in df.columns]
    if missing:
        raise ConfigError(f"point_metrics lacks the columns {missing} "
                          f"(expected {list(POINT_COLUMNS)})")
    cols = []
    for c in POINT_COLUMNS:
        v = df[c].to_numpy()
        if c in ("point", "n_samples"):
            cols.append([int(a) for a in v])
        elif c == "reached":
            cols.append([int(bool(a)) for a in v])
        else:
            cols.append(np.asarray(v, dtype=np.float64).tolist())
    return list(zip(*cols, strict=True))


def _trial_metric_rows(metrics: Mapping[str, float]) -> list[tuple[str, float | None]]:
    rows = []
    for name, v in metrics.items():
        if not isinstance(name, str) or not name:
            raise ConfigError(f"trial metric names must be non-empty strings, got {name!r}")
        try:
            f = float(v)
        except (TypeError, ValueError):
            raise ConfigError(f"trial metric {name!r} must be a number, got {v!r}") from None
        rows.append((name, f if math.isfinite(f) else None))
    return rows


def _split_sql(script: str) -> list[str]:
    """Splits a DDL script (no ';' inside literals) into statements."""
    return [s.strip() for s in script.split(";") if s.strip()]


__all__ = [
    "ANSWER_COLUMNS",
    "APPLICATION_ID",
    "DEMOGRAPHIC_COLUMNS",
    "DEMOGRAPHIC_FIELDS",
    "EVENT_COLUMNS",
    "GROUPS",
    "LAPAROSCOPY_LEVELS",
    "ROBOTIC_LEVELS",
    "SCHEDULE_COLUMNS",
    "SCHEMA_VERSION",
    "SESSION_COLUMNS",
    "SESSION_STATUSES",
    "SIMULATOR_LEVELS",
    "SPECIALISATIONS",
    "SUBJECT_CODE_PATTERN",
    "TRIAL_COLUMNS",
    "TRIAL_STATUSES",
    "Demographics",
    "SessionMeta",
    "TrialMeta",
    "TrialStore",
    "validate_subject_code",
]
