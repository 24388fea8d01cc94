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
older one is migrated in one transaction by the steps in ``_MIGRATIONS``. Later versions
add tables (sessions, questionnaires, ...) and nullable columns; they never rename.

Schema, version 1 (units in brackets; times of day are ISO 8601 UTC text):

``schema_version``
    ``version`` INTEGER PK, ``applied_at`` TEXT.
``subjects`` — pseudonymous: codes only, never names.
    ``code`` TEXT PK (``^[A-Za-z0-9_-]{1,32}$``, also a CHECK), ``created_at`` TEXT,
    ``notes`` TEXT NULL (free text; must not identify the person).
``trials``
    ``id`` INTEGER PK; ``subject`` TEXT -> subjects.code; ``session_id`` INTEGER NULL (the
    session, once sessions exist); ``protocol`` TEXT NULL (protocol name); ``task`` TEXT
    (``'trajectory'``/``'point'``); ``variant`` INTEGER NULL (trajectory variant, 0 =
    original); ``schema`` TEXT NULL (fixture schema name); ``operator`` TEXT NULL (input
    device); ``seed`` INTEGER NULL; ``status`` TEXT in ``'running'``, ``'completed'``,
    ``'interrupted'``; ``started_at``, ``ended_at`` TEXT (ended NULL while running);
    ``dt`` REAL NULL [s] (control step); ``n_samples`` INTEGER NULL (rows in ``samples``,
    set when the trial closes); ``active_fixtures`` TEXT (``''`` = VF-free);
    ``summary_json`` TEXT NULL (``metrics.trial_summary`` + runner extras, JSON, NaN ->
    null); ``timing_json`` TEXT NULL (servo-loop timing statistics, JSON); ``pid``
    INTEGER, ``host`` TEXT, ``proc_token`` TEXT NULL (boot id + process start time) of the
    writing process; ``config_json`` TEXT NULL (the full trial configuration, operator
    profile included, as JSON: with the seed it re-runs the trial); ``schema_toml`` TEXT NULL
    (the resolved fixture schema as TOML, so a trial stays interpretable when the schema
    file changes); ``vasim_version`` TEXT NULL.
``samples`` — one row per logged step, WITHOUT ROWID, PK (trial_id, k).
    ``trial_id`` -> trials.id; ``k`` INTEGER (step); ``t`` REAL [s] since trial start;
    ``x_x, x_y, x_z`` REAL [m] TCP; ``g_x, g_y, g_z`` REAL [m] goal; ``goal_index`` INTEGER;
    ``f_x, f_y, f_z`` REAL [N] rendered force; ``ms_x, ms_y, ms_z`` REAL MS factors;
    ``zoom`` REAL Mag magnification; ``audio_pitch`` REAL, ``audio_period`` REAL [s],
    ``audio_volume`` REAL AG outputs; ``contact`` INTEGER (0/1).
``point_metrics`` — WITHOUT ROWID, PK (trial_id, point); columns of
    ``metrics.POINT_COLUMNS``: ``point`` INTEGER, ``reached`` INTEGER (0/1), ``t_reached``
    REAL [s] NULL, ``error_l1`` REAL [m] NULL, ``latency`` REAL [s] NULL, ``path_l1``,
    ``path_l2`` REAL [m] NULL, ``n_samples`` INTEGER.
``events`` — things that happened during a trial (device NaN, interruption, ...).
    ``id`` INTEGER PK, ``trial_id`` -> trials.id, ``t`` REAL NULL [s] since trial start,
    ``kind`` TEXT, ``detail`` TEXT, ``created_at`` TEXT.

Floats round-trip exactly (SQLite REAL is an IEEE double) with two SQLite caveats: NaN is
stored as NULL (read back as NaN in float columns) and -0.0 is read back as 0.0.

Example:
    >>> import tempfile, pathlib
    >>> from vasim.study.samples import SampleBuffer
    >>> with tempfile.TemporaryDirectory() as d, TrialStore(pathlib.Path(d) / "s.db") as st:
    ...     tid = st.begin_trial(TrialMeta(subject="S01", task="trajectory"))
    ...     buf = SampleBuffer()
    ...     buf.append(0, 0.001, (0, 0, 0), (0, 0, 0.01), 0)
    ...     st.finish_trial(tid, buf)
    ...     st.trial(tid)["status"], len(st.samples(tid))
    ('completed', 1)
"""

from __future__ import annotations

import json
import math
import os
import re
import socket
import sqlite3
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field, fields
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd

from vasim import __version__
from vasim.errors import ConfigError, StoreError
from vasim.study.metrics import POINT_COLUMNS
from vasim.study.samples import FRAME_COLUMNS, FRAME_DTYPES, SampleBuffer

SCHEMA_VERSION = 1
"""Schema version written to ``PRAGMA user_version``."""

APPLICATION_ID = 0x76534D31  # b"vSM1"
"""``PRAGMA application_id`` of a vasim trial store."""

SUBJECT_CODE_PATTERN = r"^[A-Za-z0-9_-]{1,32}$"
"""Allowed subject codes: 1-32 letters, digits, '_' or '-' (a pseudonym, never a name)."""

_SUBJECT_RE = re.compile(SUBJECT_CODE_PATTERN)

TrialStatus = Literal["running", "completed", "interrupted"]
TRIAL_STATUSES: tuple[str, ...] = ("running", "completed", "interrupted")

TRIAL_COLUMNS: tuple[str, ...] = (
    "id", "subject", "session_id", "protocol", "task", "variant", "schema", "operator", "seed",
    "status", "started_at", "ended_at", "dt", "n_samples", "active_fixtures", "summary_json",
    "timing_json", "pid", "host", "proc_token", "config_json", "schema_toml", "vasim_version",
)
"""Columns of the ``trials`` table (and of ``TrialStore.trials()``), in order."""

EVENT_COLUMNS: tuple[str, ...] = ("t", "kind", "detail", "created_at")
"""Columns of ``TrialStore.events()``."""

_BUSY_TIMEOUT_MS = 10_000

_SAMPLE_SQL_TYPES = {np.int64: "INTEGER", np.int32: "INTEGER", np.int8: "INTEGER",
                     np.float64: "REAL"}

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
    {", ".join(
        f"{c} {_SAMPLE_SQL_TYPES[FRAME_DTYPES[c]]}" + (" NOT NULL" if c in ("k", "t") else "")
        for c in FRAME_COLUMNS)},
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

_MIGRATIONS: dict[int, str] = {1: _SCHEMA_V1}
"""Script that takes a store from version v-1 to v (version 0 = empty file)."""


def validate_subject_code(code: object) -> str:
    """Returns ``code`` if it is a valid subject code, else raises ``ConfigError``.

    Example:
        >>> validate_subject_code("S01")
        'S01'
    """
    if not isinstance(code, str) or not _SUBJECT_RE.fullmatch(code):
        raise ConfigError(
            f"invalid subject code {code!r}: use 1-32 letters, digits, '_' or '-' "
            "(a pseudonymous code, never a name)",
            field="subject",
        )
    return code


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="microseconds")


@dataclass(frozen=True)
class TrialMeta:
    """What is known about a trial when it starts (the ``trials`` row).

    Attributes:
        subject: subject code (``SUBJECT_CODE_PATTERN``); registered on first use.
        task: task kind, e.g. ``"trajectory"`` or ``"point"``.
        variant: trajectory variant (0 = original), or None.
        schema: fixture schema name, or None. operator: input device name, or None.
        seed: random seed of the trial, or None. dt: control step [s], or None.
        active_fixtures: active fixture names, e.g. ``"VG,FF"``; ``""`` for VF-free.
        session_id: session id (once sessions exist), or None. protocol: protocol name.
        pid, host: the writing process (defaults: this process, this host).
        config: the full trial configuration (JSON-serialisable mapping), or None.
        schema_toml: the resolved fixture schema as TOML text, or None.
    """

    subject: str
    task: str
    variant: int | None = None
    schema: str | None = None
    operator: str | None = None
    seed: int | None = None
    dt: float | None = None
    active_fixtures: str = ""
    session_id: int | None = None
    protocol: str | None = None
    pid: int = field(default_factory=os.getpid)
    host: str = field(default_factory=socket.gethostname)
    config: Mapping[str, Any] | None = None
    schema_toml: str | None = None

    def __post_init__(self) -> None:
        validate_subject_code(self.subject)
        if not isinstance(self.task, str) or not self.task:
            raise ConfigError(f"task must be a non-empty string, got {self.task!r}", field="task")
        for name in ("variant", "seed", "session_id", "pid"):
            v = getattr(self, name)
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, np.integer))):
                raise ConfigError(f"{name} must be an integer or None, got {v!r}", field=name)
        if self.dt is not None and not (math.isfinite(self.dt) and self.dt > 0):
            raise ConfigError(f"dt must be > 0 s, got {self.dt!r}", field="dt")
        if not isinstance(self.active_fixtures, str):
            raise ConfigError(f"active_fixtures must be a string, got {self.active_fixtures!r}",
                              field="active_fixtures")

    @classmethod
    def from_mapping(cls, meta: Mapping[str, Any]) -> TrialMeta:
        """Builds a ``TrialMeta`` from a dict; unknown keys raise ``ConfigError``."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(meta) - known)
        if unknown:
            raise ConfigError(f"unknown trial meta field(s) {unknown} (known: {sorted(known)})")
        return cls(**meta)


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
def _plain(v: Any) -> Any:
    if isinstance(v, Mapping):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, np.ndarray):
        return [_plain(x) for x in v.tolist()]
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def _to_json(v: Mapping[str, Any] | None) -> str | None:
    if v is None:
        return None
    try:
        return json.dumps(_plain(v), allow_nan=False)
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
        con.execute("BEGIN IMMEDIATE")
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

        Raises:
            ConfigError: on invalid meta (e.g. a bad subject code).
        """
        if not isinstance(meta, TrialMeta):
            meta = TrialMeta.from_mapping(meta)
        token = _proc_token(meta.pid) if meta.host == self._host else None
        with self._transaction() as con:
            con.execute("INSERT OR IGNORE INTO subjects (code, created_at) VALUES (?, ?)",
                        (meta.subject, _now()))
            cur = con.execute(
                "INSERT INTO trials (subject, session_id, protocol, task, variant, schema, "
                "operator, seed, status, started_at, dt, active_fixtures, pid, host, "
                "proc_token, config_json, schema_toml, vasim_version) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, ?, 'running', ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (meta.subject, _int_or_none(meta.session_id), meta.protocol, meta.task,
                 _int_or_none(meta.variant), meta.schema, meta.operator,
                 _int_or_none(meta.seed), _now(), meta.dt, meta.active_fixtures,
                 _int_or_none(meta.pid), meta.host, token,
                 _to_json(meta.config), meta.schema_toml,
                 __version__),
            )
            trial_id = cur.lastrowid
        assert trial_id is not None  # sqlite always sets it after an INSERT
        return int(trial_id)

    def finish_trial(
        self,
        trial_id: int,
        samples: SampleBuffer,
        point_metrics: pd.DataFrame | None = None,
        summary: Mapping[str, Any] | None = None,
        *,
        events: Iterable[tuple[float | None, str, str]] = (),
        timing: Mapping[str, Any] | None = None,
    ) -> None:
        """Stores a trial's samples, metrics, events and summary; status 'completed'.

        Everything is written in one transaction, committed (and fsync'ed) before this
        returns: the trial is then durable, and nothing of it is stored if this fails or the
        process dies first.

        Args:
            trial_id: from ``begin_trial``; the trial must still be 'running'.
            samples: the trial's sample buffer (its ``active_fixtures``, if not empty,
                replaces the one given at ``begin_trial``).
            point_metrics: ``metrics.point_metrics`` frame (columns ``POINT_COLUMNS``).
            summary: ``metrics.trial_summary`` dict plus any extras (JSON-serialisable).
            events: ``(t [s] or None, kind, detail)`` tuples.
            timing: servo-loop timing statistics (JSON-serialisable), or None.

        Raises:
            StoreError: unknown trial, trial not 'running', duplicate step k, or SQLite
                failure (the transaction is rolled back).
        """
        self._close_trial(trial_id, "completed", samples, point_metrics, summary, events,
                          timing, reason=None)

    def mark_interrupted(
        self,
        trial_id: int,
        *,
        reason: str = "",
        samples: SampleBuffer | None = None,
        point_metrics: pd.DataFrame | None = None,
        summary: Mapping[str, Any] | None = None,
        events: Iterable[tuple[float | None, str, str]] = (),
    ) -> bool:
        """Marks a running trial 'interrupted', optionally keeping what it recorded.

        Safe to call from an ``except`` block: a trial that is no longer 'running' (e.g.
        already completed) is left unchanged and ``False`` is returned.

        Args:
            trial_id: the trial. reason: stored as an ``'interrupted'`` event.
            samples, point_metrics, summary, events: the partial data to keep (one
                transaction with the status change), or None/empty.

        Returns:
            True if the trial was running and is now 'interrupted'.

        Raises:
            StoreError: unknown trial id, or SQLite failure.
        """
        try:
            self._close_trial(trial_id, "interrupted", samples, point_metrics, summary,
                              events, None, reason=reason)
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
        *,
        reason: str | None,
    ) -> None:
        tid = _trial_id(trial_id)
        metric_rows = _metric_rows(point_metrics) if point_metrics is not None else []
        summary_json = _to_json(summary)
        timing_json = _to_json(timing)
        event_rows = [(None if t is None else float(t), str(kind), str(detail))
                      for t, kind, detail in events]
        if samples is not None and not isinstance(samples, SampleBuffer):
            raise ConfigError(f"samples must be a SampleBuffer, got {type(samples).__name__}")
        try:
            with self._transaction() as con:
                row = con.execute("SELECT status, pid, host, proc_token FROM trials "
                                  "WHERE id = ?", (tid,)).fetchone()
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
                now = _now()
                if reason is not None:
                    event_rows.append((None, "interrupted", reason))
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


def _split_sql(script: str) -> list[str]:
    """Splits a DDL script (no ';' inside literals) into statements."""
    return [s.strip() for s in script.split(";") if s.strip()]


__all__ = [
    "APPLICATION_ID",
    "EVENT_COLUMNS",
    "SCHEMA_VERSION",
    "SUBJECT_CODE_PATTERN",
    "TRIAL_COLUMNS",
    "TRIAL_STATUSES",
    "TrialMeta",
    "TrialStore",
    "validate_subject_code",
]
