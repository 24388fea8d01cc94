"""The layout of the study database: DDL, version history and migrations (spec/study.md §2).

One SQLite file per study. ``vasim.study.store.TrialStore`` is the only code that talks to
it; this module says what is in it. How a trial's row moves through its life cycle is in
``vasim.study.store.lifecycle``; which process owns a 'running' row in
``vasim.study.store.liveness``.

Durability (**decision**: durability over speed). ``journal_mode=WAL`` (readers never block
the writer; a killed writer leaves only an uncommitted WAL tail, which SQLite ignores) and
``synchronous=FULL`` (each commit is fsync'ed: a trial ``finish_trial`` returned for
survives a process kill *and* an OS crash or power cut; ``NORMAL`` would survive only the
former). The cost is one fsync per trial, not per sample. ``foreign_keys=ON``;
``busy_timeout`` = 10 s for concurrent writers (e.g. two stations sharing one file).
A store opened read-only (``mode=ro`` URI) never writes: no journal-mode change, no
migration, no recovery.

Identification: ``PRAGMA application_id`` = ``APPLICATION_ID`` marks a vasim store and
``PRAGMA user_version`` = ``SCHEMA_VERSION`` its schema; the ``schema_version`` table logs
when each version was applied. A store from a newer vasim is refused (``StoreError``); an
older one is migrated in one transaction by the steps in ``MIGRATIONS`` (version 1 -> 2
adds tables and columns, no row is rewritten; version 2 -> 3 rebuilds ``trials`` because
SQLite cannot drop a NOT NULL: ``subject`` becomes nullable, ``label`` and ``outcome`` are
added and ``outcome`` is filled from the stored summaries, see ``OUTCOME_FROM_V2_SQL``;
version 5 -> 6 packs every trial's ``samples`` rows into ``sample_columns`` and drops
``samples``, the one step that is Python (``DATA_STEPS``), after which the store is
VACUUMed once to give the freed pages back).
Versions add tables and nullable or defaulted columns; they never rename a column. A store
opened read-only is never migrated: a version-2 store is read as it is (``outcome`` computed
by ``OUTCOME_FROM_V2_SQL`` on the fly, ``label`` NULL; a version-2 to -5 store's samples
are read from its ``samples`` rows); a version-1 store must be opened writable once.

Schema, version 6 (units in brackets; times of day are ISO 8601 UTC text; "v2" .. "v6" mark
what versions 2 to 6 added):

``schema_version``
    ``version`` INTEGER PK, ``applied_at`` TEXT.
``subjects`` — pseudonymous: codes only, never names.
    ``code`` TEXT PK (``^[A-Za-z0-9_-]{1,32}$``, also a CHECK), ``created_at`` TEXT,
    ``notes`` TEXT NULL (free text; must not identify the person).
``trials``
    ``id`` INTEGER PK; ``subject`` TEXT NULL -> subjects.code (v3: NULL for a trial without
    a subject, e.g. free practice; never an invented code); ``session_id`` INTEGER NULL (the
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
    2 after one interruption, ...); v3: ``label`` TEXT NULL (a free-practice label the
    experimenter chose, 1-64 characters with at least one a subject code cannot have, e.g. a
    space or ':', so that it can never be mistaken for a subject code; also a CHECK),
    ``outcome`` TEXT NULL in ``TRIAL_OUTCOMES`` (how the trial ended, separate from the row's
    life cycle ``status``: ``'reached_all'`` every point reached, ``'timed_out'`` the time
    limit came first (points reached: ``summary_json``'s ``points_reached`` of
    ``n_points``), ``'stopped'`` by the experimenter (Stop, Ctrl-C), ``'interrupted'`` the
    writing process died, ``'failed'`` an error or an abort by the system (e.g. repeated MRCP
    safety stops); NULL while running or when unknown).
``sample_columns`` (v6) — a trial's samples, one row per column, PK (trial_id, name).
    ``trial_id`` -> trials.id; ``name`` TEXT (a ``samples.FRAME_COLUMNS`` name, the columns
    of the version-5 ``samples`` table below); ``dtype`` TEXT (numpy dtype of the stored
    values: the buffer dtype, ``'<f8'``, ``'<i8'``, ``'<i4'`` or ``'<i1'``); ``n`` INTEGER
    (values: the trial's samples, in order of k); ``codec`` TEXT
    (``'delta-shuffle-zlib1'``); ``data`` BLOB. Every column is kept bit for bit (lossless
    compression, no float32), as stated per column in
    ``vasim.study.store.packing``. A trial without samples has no rows.
``samples`` (versions 1 to 5; dropped by version 6) — one row per logged step, WITHOUT
    ROWID, PK (trial_id, k). ``trial_id`` -> trials.id; ``k`` INTEGER (step); ``t`` REAL
    [s] since trial start; ``x_x, x_y, x_z`` REAL [m] TCP; ``g_x, g_y, g_z`` REAL [m]
    goal; ``goal_index`` INTEGER;
    ``f_x, f_y, f_z`` REAL [N] rendered force; ``ms_x, ms_y, ms_z`` REAL MS factors;
    ``zoom`` REAL Mag magnification; ``audio_pitch`` REAL, ``audio_period`` REAL [s],
    ``audio_volume`` REAL AG outputs; ``contact`` INTEGER (0/1); v2: ``fc_x, fc_y, fc_z``
    REAL [N] tissue contact force (default 0), ``tc_x, tc_y, tc_z`` REAL [N m] tissue contact
    torque (default 0), ``delicate`` INTEGER (0/1, contact with a delicate structure),
    ``clutch`` INTEGER (0/1), ``in_view`` INTEGER (1 tool tip in the camera's field of
    view, 0 outside, -1 not determined: the value every version-1 row reads); v5: ``gain``
    REAL (the fixture gain in force, ``vasim.fixtures.gain``; 1.0 = the schema as written,
    what every older row reads). See ``vasim.records.samples``.
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
stored as NULL (read back as NaN in float columns) and -0.0 is read back as 0.0. Sample
columns are exact too and keep NaN and -0.0 (``vasim.study.store.packing``); samples migrated
from version 5 keep what version 5 had stored.

"""

from __future__ import annotations

import sqlite3
from collections.abc import Callable
from datetime import UTC, datetime

from vasim.study.store.vocabulary import (
    GROUPS,
    LAPAROSCOPY_LEVELS,
    ROBOTIC_LEVELS,
    SIMULATOR_LEVELS,
    SPECIALISATIONS,
    TRIAL_OUTCOMES,
)

SCHEMA_VERSION = 6
"""Schema version written to ``PRAGMA user_version``."""

APPLICATION_ID = 0x76534D31  # b"vSM1"
"""``PRAGMA application_id`` of a vasim trial store."""

TRIAL_COLUMNS: tuple[str, ...] = (
    "id", "subject", "session_id", "protocol", "task", "variant", "schema", "operator", "seed",
    "status", "started_at", "ended_at", "dt", "n_samples", "active_fixtures", "summary_json",
    "timing_json", "pid", "host", "proc_token", "config_json", "schema_toml", "vasim_version",
    "schedule_index", "attempt", "label", "outcome",
)
"""Columns of the ``trials`` table (and of ``TrialStore.trials()``), in order."""

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

DEMOGRAPHIC_COLUMNS: tuple[str, ...] = (
    "subject", "subject_group", "specialisation", "laparoscopy_experience",
    "simulator_experience", "robotic_experience", "session_id", "updated_at",
)
"""Columns of the ``demographics`` table, in order."""

EVENT_COLUMNS: tuple[str, ...] = ("t", "kind", "detail", "created_at")
"""Columns of ``TrialStore.events()``."""

BUSY_TIMEOUT_MS = 10_000
"""How long a connection waits for another writer's lock [ms]."""


def now() -> str:
    """The time of day as stored: ISO 8601 UTC text with microseconds."""
    return datetime.now(UTC).isoformat(timespec="microseconds")


def sql_set(values: tuple[str, ...]) -> str:
    """``('a', 'b')`` for a CHECK (values are constants of this package, no quotes inside)."""
    return "(" + ", ".join(f"'{v}'" for v in values) + ")"


_V1_TRIAL_COLUMNS_DDL = """\
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
    vasim_version   TEXT"""
"""The ``trials`` columns of version 1 after ``subject`` (frozen text: version 1's table and
version 3's rebuild both write them, the rebuild only changes ``subject`` and adds columns)."""

_SCHEMA_V1 = f"""
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
{_V1_TRIAL_COLUMNS_DDL}
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
    subject_group           TEXT NOT NULL CHECK (subject_group IN {sql_set(GROUPS)}),
    specialisation          TEXT NOT NULL CHECK (specialisation IN {sql_set(SPECIALISATIONS)}),
    laparoscopy_experience  TEXT NOT NULL
                            CHECK (laparoscopy_experience IN {sql_set(LAPAROSCOPY_LEVELS)}),
    simulator_experience    TEXT NOT NULL
                            CHECK (simulator_experience IN {sql_set(SIMULATOR_LEVELS)}),
    robotic_experience      TEXT NOT NULL
                            CHECK (robotic_experience IN {sql_set(ROBOTIC_LEVELS)}),
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

_V2_TRIAL_COLUMNS = ", ".join(TRIAL_COLUMNS[:-2])

OUTCOME_FROM_V2_SQL = """CASE
    WHEN status = 'interrupted' THEN 'interrupted'
    WHEN status != 'completed' OR summary_json IS NULL OR NOT json_valid(summary_json)
        THEN NULL
    WHEN EXISTS (SELECT 1 FROM events e WHERE e.trial_id = trials.id AND e.kind = 'aborted')
        THEN 'failed'
    WHEN json_extract(summary_json, '$.completed') = 1 THEN 'reached_all'
    WHEN json_extract(summary_json, '$.completed') = 0 THEN 'timed_out'
    ELSE NULL END"""
"""The outcome of a version-2 ``trials`` row, as an SQL expression over its columns.

**Decision**: completed rows read ``summary.completed`` (true -> ``'reached_all'``, false ->
``'timed_out'``: the only way a version-2 trial ended early without an error was its time
limit), except a trial the MRCP station aborted for repeated safety stops (an ``'aborted'``
event), which is ``'failed'``; every interrupted row is ``'interrupted'`` (version 2 did not
say why); running rows and rows without a readable summary have no outcome (NULL)."""

_SCHEMA_V3 = f"""
CREATE TABLE trials_v3 (
    id              INTEGER PRIMARY KEY,
    subject         TEXT REFERENCES subjects(code),
{_V1_TRIAL_COLUMNS_DDL},
    schedule_index  INTEGER,
    attempt         INTEGER,
    label           TEXT CHECK (label IS NULL OR (length(label) BETWEEN 1 AND 64
                                AND label GLOB '*[^A-Za-z0-9_-]*')),
    outcome         TEXT CHECK (outcome IS NULL OR outcome IN {sql_set(TRIAL_OUTCOMES)})
);
INSERT INTO trials_v3 ({_V2_TRIAL_COLUMNS}, label, outcome)
    SELECT {_V2_TRIAL_COLUMNS}, NULL, {OUTCOME_FROM_V2_SQL} FROM trials;
DROP TABLE trials;
ALTER TABLE trials_v3 RENAME TO trials;
CREATE INDEX trials_subject ON trials(subject);
CREATE INDEX trials_status ON trials(status);
CREATE INDEX trials_session ON trials(session_id, schedule_index);
CREATE INDEX trials_outcome ON trials(outcome);
"""
"""Version 3: ``trials`` rebuilt (SQLite's 12-step table change, run with foreign keys off)
with a nullable ``subject`` and the new ``label`` and ``outcome`` columns; ``outcome`` of
the existing rows from ``OUTCOME_FROM_V2_SQL``."""

_SCHEMA_V4 = """
ALTER TABLE point_metrics ADD COLUMN error_l1_mm_s REAL;
ALTER TABLE point_metrics ADD COLUMN path_dev_mean_mm REAL;
ALTER TABLE point_metrics ADD COLUMN path_dev_rms_mm REAL;
ALTER TABLE point_metrics ADD COLUMN path_dev_max_mm REAL;
ALTER TABLE point_metrics ADD COLUMN path_dev_out_frac REAL;
"""
"""Version 4: the per-point rate-independent e_i and path-deviation columns
(``vasim.records.path_deviation``); older rows read NULL (NaN: not measured)."""

_SCHEMA_V5 = """
ALTER TABLE samples ADD COLUMN gain REAL NOT NULL DEFAULT 1.0;
"""
"""Version 5: the fixture gain in force at each sample (``vasim.fixtures.gain``: fading
schedules and assist-as-needed); every older row reads 1.0, the schema as written, which is
what every trial before version 5 ran."""

_SCHEMA_V6 = """
CREATE TABLE sample_columns (
    trial_id    INTEGER NOT NULL REFERENCES trials(id) ON DELETE CASCADE,
    name        TEXT NOT NULL,
    dtype       TEXT NOT NULL,
    n           INTEGER NOT NULL CHECK (n >= 0),
    codec       TEXT NOT NULL,
    data        BLOB NOT NULL,
    PRIMARY KEY (trial_id, name)
);
"""
"""Version 6 (issue #27 item 5): a trial's samples as one compressed blob per column
(``vasim.study.store.packing``) instead of one row per sample; the step
:func:`samples_to_columns` moves every trial's rows into it and drops ``samples``.

**Decision**: a rowid table (not WITHOUT ROWID, which SQLite advises against for rows
larger than ~1/20 of a page: a blob is kilobytes)."""

MIGRATIONS: dict[int, str] = {1: _SCHEMA_V1, 2: _SCHEMA_V2, 3: _SCHEMA_V3, 4: _SCHEMA_V4,
                              5: _SCHEMA_V5, 6: _SCHEMA_V6}
"""Script that takes a store from version v-1 to v (version 0 = empty file)."""


def samples_to_columns(con: sqlite3.Connection) -> None:
    """Version 6's data step: every trial's ``samples`` rows packed into ``sample_columns``
    (``packing.pack_columns``, lossless), then ``samples``
    dropped. One trial at a time (memory: one trial's rows); a progress bar for a long one.
    """
    from vasim.core.progress import progress_bar
    from vasim.records.samples import FRAME_COLUMNS
    from vasim.study.store.packing import pack_columns, rows_to_columns

    tids = [int(r[0]) for r in con.execute("SELECT DISTINCT trial_id FROM samples")]
    select = (f"SELECT {', '.join(FRAME_COLUMNS)} FROM samples WHERE trial_id = ? "
              "ORDER BY k")
    with progress_bar(len(tids), "store: packing samples (schema 6)", "trial",
                      leave=False) as bar:
        for tid in tids:
            cols = rows_to_columns(con.execute(select, (tid,)).fetchall())
            con.executemany(
                f"INSERT INTO sample_columns (trial_id, name, dtype, n, codec, data) "
                f"VALUES ({tid}, ?, ?, ?, ?, ?)", pack_columns(cols))
            bar.update(1)
    con.execute("DROP TABLE samples")


DATA_STEPS: dict[int, Callable[[sqlite3.Connection], None]] = {6: samples_to_columns}
"""Python steps run after version v's script, in the same transaction."""

REBUILDS: frozenset[int] = frozenset({3})
"""Versions whose script rebuilds a table: run with ``PRAGMA foreign_keys = OFF`` (else
dropping the old table would cascade-delete every sample) and checked with
``PRAGMA foreign_key_check`` before the commit."""


def split_sql(script: str) -> list[str]:
    """Splits a DDL script (no ';' inside literals) into statements."""
    return [s.strip() for s in script.split(";") if s.strip()]


def apply_migrations(con: sqlite3.Connection, from_version: int) -> None:
    """Runs the scripts from ``from_version + 1`` to ``SCHEMA_VERSION`` on ``con``.

    The caller holds the write transaction (and has switched foreign keys off if a
    version in ``REBUILDS`` is among them); the application id and user version are set
    last, so a failure anywhere leaves nothing once the transaction rolls back.

    Raises:
        sqlite3.Error: a statement failed; sqlite3.IntegrityError: a rebuilt table broke a
            foreign key.
    """
    for v in range(from_version + 1, SCHEMA_VERSION + 1):
        for stmt in split_sql(MIGRATIONS[v]):
            con.execute(stmt)
        if v in DATA_STEPS:
            DATA_STEPS[v](con)
        if v in REBUILDS:
            broken = con.execute("PRAGMA foreign_key_check").fetchall()
            if broken:
                raise sqlite3.IntegrityError(
                    f"schema version {v}: {len(broken)} row(s) break a foreign key, e.g. "
                    f"{tuple(broken[0])}")
        con.execute("INSERT INTO schema_version (version, applied_at) VALUES (?, ?)",
                    (v, now()))
    con.execute(f"PRAGMA application_id = {APPLICATION_ID}")
    con.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")


__all__ = [
    "ANSWER_COLUMNS",
    "APPLICATION_ID",
    "BUSY_TIMEOUT_MS",
    "DATA_STEPS",
    "DEMOGRAPHIC_COLUMNS",
    "EVENT_COLUMNS",
    "MIGRATIONS",
    "OUTCOME_FROM_V2_SQL",
    "REBUILDS",
    "SCHEDULE_COLUMNS",
    "SCHEMA_VERSION",
    "SESSION_COLUMNS",
    "TRIAL_COLUMNS",
    "apply_migrations",
    "now",
    "samples_to_columns",
    "split_sql",
    "sql_set",
]
