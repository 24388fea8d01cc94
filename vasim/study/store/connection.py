"""Opening a study database: the connection, its pragmas, the schema check, migrations,
transactions and the read-only mode.

``StoreConnection`` is the stateful shell every part of ``TrialStore`` builds on; the
layout it checks and migrates to is ``vasim.study.store.schema``.
"""

from __future__ import annotations

import logging
import os
import socket
import sqlite3
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Self

from vasim.core.errors import StoreError
from vasim.study.store.schema import (
    APPLICATION_ID,
    BUSY_TIMEOUT_MS,
    OUTCOME_FROM_V2_SQL,
    REBUILDS,
    SCHEMA_VERSION,
    TRIAL_COLUMNS,
    apply_migrations,
)

log = logging.getLogger("vasim.study.store")

READ_ONLY_MIN_VERSION = 2
"""The oldest schema a read-only store reads without migrating it (version 1 has no
sessions)."""

PACKED_SAMPLES_VERSION = 6
"""The schema version that packs samples into compressed columns (``packing``)."""


def readonly_uri(path: Path, *, immutable: bool = False) -> str:
    """The ``file:`` URI that opens ``path`` read-only (``mode=ro``; ``immutable=1`` too for
    a file no process can change, e.g. in a read-only folder without its WAL files)."""
    return path.resolve().as_uri() + "?mode=ro" + ("&immutable=1" if immutable else "")


def _is_readonly(exc: sqlite3.Error) -> bool:
    """True for SQLite's "attempt to write a readonly database" family of errors."""
    code = getattr(exc, "sqlite_errorcode", None) or 0
    return (code & 0xFF) == sqlite3.SQLITE_READONLY or "readonly" in str(exc)


class StoreConnection:
    """One SQLite connection to a vasim study database.

    Args:
        path: the database file; created (with the schema) if missing or empty. Its folder
            must exist.
        readonly: open for reading only: a ``mode=ro`` connection, no schema creation, no
            migration (a version-2 store is read as it is) and no interrupted-trial recovery;
            for listing, export and reports. A read-only ``TrialStore`` still finds the
            'running' trials whose writer died (``stale``) and says in one line on stderr
            that it cannot mark them 'interrupted'.

    Raises:
        StoreError: naming the path, if the file is not a SQLite database, not a vasim
            store, written by a newer vasim (schema version), cannot be opened, or (not
            read-only) cannot be written.
    """

    def __init__(self, path: str | os.PathLike[str], *, readonly: bool = False):
        self.path = Path(path)
        self.readonly = readonly
        self._host = socket.gethostname()
        self._con: sqlite3.Connection | None = None
        self._trial_exprs: tuple[str, ...] = TRIAL_COLUMNS
        if self.path.is_dir():
            raise StoreError(f"trial store {self.path} is a directory, not a database file")
        if not self.path.parent.is_dir():
            raise StoreError(f"cannot create trial store {self.path}: folder "
                             f"{self.path.parent} does not exist")
        if readonly and not self.path.exists():
            raise StoreError(f"trial store {self.path} does not exist")
        if not readonly:
            self._check_writable()
        self._con = self._connect()
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

    # ------------------------------------------------------------------ opening
    def _check_writable(self) -> None:
        """**Decision**: a writing open of a file or folder this process cannot write is
        refused at once with the path (SQLite would open it read-only without a word and
        fail at the first write with a bare ``OperationalError``)."""
        folder = self.path.parent
        if self.path.exists() and not os.access(self.path, os.W_OK):
            raise StoreError(f"trial store {self.path} is read-only (no write permission on "
                             "the file); open it for reading (list, export, report) or make "
                             "it writable")
        if not os.access(folder, os.W_OK | os.X_OK):
            what = "write the trial store" if self.path.exists() else "create trial store"
            raise StoreError(f"cannot {what} {self.path}: folder {folder} is read-only "
                             "(a writable store needs its -wal and -shm files beside it)")

    def _connect(self) -> sqlite3.Connection:
        timeout = BUSY_TIMEOUT_MS / 1000
        try:
            if not self.readonly:
                return sqlite3.connect(self.path, isolation_level=None, timeout=timeout)
            try:
                return self._connect_ro(timeout, immutable=False)
            except sqlite3.OperationalError:
                # A WAL database in a folder we cannot write, without its -shm file: SQLite
                # cannot create the shared memory. Nobody can be writing it then (a writer
                # would need that folder too), so read it as immutable.
                if os.access(self.path.parent, os.W_OK):
                    raise
                log.debug("%s: read as immutable (read-only folder)", self.path)
                return self._connect_ro(timeout, immutable=True)
        except sqlite3.DatabaseError as e:
            raise StoreError(f"cannot open trial store {self.path}: {e}") from e

    def _connect_ro(self, timeout: float, *, immutable: bool) -> sqlite3.Connection:
        """A ``mode=ro`` connection, probed with a first read (SQLite opens lazily)."""
        con = sqlite3.connect(readonly_uri(self.path, immutable=immutable), uri=True,
                              isolation_level=None, timeout=timeout)
        try:
            con.execute("SELECT count(*) FROM sqlite_master").fetchone()
        except sqlite3.OperationalError:
            con.close()
            raise
        except sqlite3.DatabaseError:
            pass  # not a database: _check_schema says so with the usual message
        return con

    @property
    def con(self) -> sqlite3.Connection:
        """The open connection.

        Raises:
            StoreError: the store is closed.
        """
        if self._con is None:
            raise StoreError(f"trial store {self.path} is closed")
        return self._con

    def _configure(self) -> None:
        con = self.con
        con.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
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
        if self.readonly:
            if ver < READ_ONLY_MIN_VERSION:
                raise StoreError(f"trial store {self.path} has schema version {ver}; open it "
                                 f"writable once to migrate it to {SCHEMA_VERSION}")
            self._trial_exprs = self._readable_trial_columns()
            return
        self._enable_wal()
        if ver < SCHEMA_VERSION:
            self._migrate()

    def _readable_trial_columns(self) -> tuple[str, ...]:
        """SELECT expressions of ``TRIAL_COLUMNS`` for this (possibly older) store:
        **decision**: a read-only store is not migrated, so a version-2 ``trials`` table is
        read with ``outcome`` computed as the migration would store it and ``label`` NULL."""
        have = {r[1] for r in self.con.execute("PRAGMA table_info(trials)")}
        exprs = []
        for c in TRIAL_COLUMNS:
            if c in have:
                exprs.append(c)
            elif c == "outcome":
                exprs.append(f"({OUTCOME_FROM_V2_SQL}) AS outcome")
            else:
                exprs.append(f"NULL AS {c}")
        return tuple(exprs)

    def _migrate(self) -> None:
        app, ver, _ = self._header()
        rebuild = any(v in REBUILDS for v in range(ver + 1, SCHEMA_VERSION + 1))
        if rebuild:  # cannot change inside a transaction; a rebuild must not cascade
            self.con.execute("PRAGMA foreign_keys = OFF")
        try:
            with self._transaction():
                app, ver, n_obj = self._header()  # re-read under the write lock
                if ver == SCHEMA_VERSION and app == APPLICATION_ID:
                    return  # another process created or migrated it meanwhile
                if ver == 0 and n_obj:
                    raise StoreError(f"{self.path} is a SQLite database but not a vasim "
                                     "trial store (it has tables and no vasim schema version)")
                apply_migrations(self.con, ver)
        finally:
            if rebuild:
                self.con.execute("PRAGMA foreign_keys = ON")
        if 1 <= ver < PACKED_SAMPLES_VERSION:
            self._vacuum()

    def _vacuum(self) -> None:
        """Gives the pages of the dropped per-sample rows back to the file system.

        **Decision**: after the migration to schema 6 (packed samples), which frees ~90 % of
        a store's pages, ``VACUUM`` rewrites the file once (it needs as much free disk
        space as the new file and, for a store of gigabytes, a minute or two); a store that
        cannot be vacuumed now (another process reading it) stays correct, only larger.
        """
        try:
            self.con.execute("VACUUM")
        except sqlite3.OperationalError as exc:
            log.warning("%s: migrated, but VACUUM failed (%s); the file keeps its old size "
                        "until vacuumed", self.path, exc)

    @contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        """BEGIN IMMEDIATE ... COMMIT, or ROLLBACK on any exception (re-raised).

        Raises:
            StoreError: the store is read-only, or the database is busy or cannot be
                written (naming the file).
        """
        if self.readonly:
            raise StoreError(f"trial store {self.path} is open read-only")
        con = self.con
        try:
            con.execute("BEGIN IMMEDIATE")
        except sqlite3.OperationalError as exc:      # e.g. another writer holds the lock
            if _is_readonly(exc):
                raise self._readonly_error(exc) from exc
            raise StoreError(f"{self.path}: the database is busy or locked ({exc}); "
                             "another vasim process may be writing to it - try again") from exc
        try:
            yield con
        except BaseException as exc:
            if con.in_transaction:
                con.execute("ROLLBACK")
            if isinstance(exc, sqlite3.OperationalError) and _is_readonly(exc):
                raise self._readonly_error(exc) from exc
            raise
        try:
            con.execute("COMMIT")
        except sqlite3.OperationalError as exc:
            if con.in_transaction:
                con.execute("ROLLBACK")
            raise StoreError(f"trial store {self.path}: the commit failed ({exc})") from exc

    def _readonly_error(self, exc: sqlite3.Error) -> StoreError:
        return StoreError(f"trial store {self.path} cannot be written ({exc}): the file or "
                          "its folder is read-only")

    # ------------------------------------------------------------------ the shell
    def close(self) -> None:
        """Closes the connection (idempotent)."""
        if self._con is not None:
            self._con.close()
            self._con = None

    def __enter__(self) -> Self:
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


__all__ = ["READ_ONLY_MIN_VERSION", "StoreConnection", "readonly_uri"]
