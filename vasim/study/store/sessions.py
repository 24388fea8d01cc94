"""Writers of who takes part and how: subjects, sessions with their realised schedules,
demographics and questionnaire answers (``SessionMeta`` is what defines a session)."""

from __future__ import annotations

import hashlib
import sqlite3
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from vasim import __version__
from vasim.core.bounds import SEED
from vasim.core.config import check_choice, check_int, check_str, check_type, expect
from vasim.core.errors import StoreError
from vasim.records.trial_meta import validate_subject_code
from vasim.study.store.connection import StoreConnection
from vasim.study.store.rows import int_or_none, row_id, to_json
from vasim.study.store.schema import DEMOGRAPHIC_COLUMNS, SCHEDULE_COLUMNS, now
from vasim.study.store.vocabulary import Demographics, SessionStatus


@dataclass(frozen=True)
class SessionMeta:
    """What defines a session when it is created (the ``sessions`` row).

    Attributes:
        subject: subject code. protocol: protocol name.
        protocol_toml: the protocol file's text as run (stored verbatim; its sha256 too).
        seed: the randomisation seed of the schedule, an integer in [0, 2**63).
        operator: the input device, e.g. ``"scripted"``.
        config: how the trials are run (JSON-serialisable), or None.
        notes: a note stored with the session (``sessions.notes``), e.g. why a subject
            who completed the protocol runs it again (``vasim study run --again``).
    """

    subject: str
    protocol: str
    protocol_toml: str
    seed: int
    operator: str
    config: Mapping[str, Any] | None = None
    notes: str | None = None

    def __post_init__(self) -> None:
        validate_subject_code(self.subject)
        for name in ("protocol", "protocol_toml", "operator"):
            check_str(getattr(self, name), name, one_line=False)
        check_int(self.seed, "seed", bound=SEED)



class SessionWriters(StoreConnection):
    """The subject, session and questionnaire writers of ``TrialStore``."""

    def add_subject(self, code: str, *, notes: str | None = None) -> str:
        """Registers a subject code (no-op if it exists); returns the code.

        Raises:
            ConfigError: if the code does not match ``SUBJECT_CODE_PATTERN``.
        """
        validate_subject_code(code)
        with self._transaction() as con:
            con.execute("INSERT OR IGNORE INTO subjects (code, created_at, notes) "
                        "VALUES (?, ?, ?)", (code, now(), notes))
        return code

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
                            (meta.subject, now()))
                cur = con.execute(
                    "INSERT INTO sessions (subject, protocol, protocol_toml, protocol_sha256, "
                    "seed, status, created_at, operator, n_trials, config_json, "
                    "vasim_version, notes) VALUES (?, ?, ?, ?, ?, 'running', ?, ?, ?, ?, ?, ?)",
                    (meta.subject, meta.protocol, meta.protocol_toml, sha, int(meta.seed),
                     now(), meta.operator, len(rows), to_json(meta.config), __version__,
                     meta.notes))
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

    def set_session_status(self, session_id: int, status: SessionStatus, *,
                           notes: str | None = None) -> None:
        """Closes a running session: ``'completed'`` (every scheduled trial has a completed
        trial, checked) or ``'aborted'`` (``notes``: why).

        Raises:
            StoreError: unknown session, session not running, or trials left to complete.
            ConfigError: a status other than 'completed' or 'aborted'.
        """
        check_choice(status, "status", ("completed", "aborted"))
        sid = row_id(session_id)
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
                        (status, now(), notes, sid))

    def release_scheduled(self, session_id: int, trial_index: int, *, reason: str) -> int:
        """Makes a scheduled trial pending again, so that it is run as a new attempt: its
        completed trial stays stored (and keeps its outcome) but is no longer the scheduled
        trial's ``trial_id``; a ``'repeated'`` event on that trial says why. One transaction.
        For protocols that repeat timed-out trials (``vasim.study.session``).

        Returns:
            The id of the trial released.

        Raises:
            StoreError: unknown session or scheduled trial, session not running, or the
                scheduled trial has no completed trial.
        """
        sid, idx = row_id(session_id, "session_id"), row_id(trial_index, "trial_index")
        with self._transaction() as con:
            srow = con.execute("SELECT status FROM sessions WHERE id = ?", (sid,)).fetchone()
            if srow is None:
                raise StoreError(f"trial store {self.path}: no session {sid}")
            if srow[0] != "running":
                raise StoreError(f"trial store {self.path}: session {sid} is {srow[0]!r}, "
                                 "not 'running'")
            row = con.execute("SELECT trial_id FROM scheduled_trials WHERE session_id = ? "
                              "AND trial_index = ?", (sid, idx)).fetchone()
            if row is None or row[0] is None:
                raise StoreError(f"trial store {self.path}: scheduled trial {idx} of session "
                                 f"{sid} has no completed trial to release")
            con.execute("UPDATE scheduled_trials SET trial_id = NULL WHERE session_id = ? "
                        "AND trial_index = ?", (sid, idx))
            con.execute("INSERT INTO events (trial_id, t, kind, detail, created_at) "
                        "VALUES (?, NULL, 'repeated', ?, ?)", (int(row[0]), reason, now()))
        return int(row[0])

    def insert_scheduled(self, session_id: int, row: Mapping[str, Any], *,
                         event_trial_id: int, kind: str, detail: str) -> None:
        """Inserts one scheduled trial into a running session (a proficiency gate adding a
        trial), in one transaction with the event that records why: the scheduled trials
        from ``row["trial_index"]`` on move one index on (and those of the same block one
        ``trial_in_block`` on), ``sessions.n_trials`` grows by one.

        Args:
            session_id: the session. row: the new trial's ``scheduled_trials`` columns
                (as ``create_session``'s rows). event_trial_id, kind, detail: the event
                stored on the trial whose result made the decision.

        Raises:
            StoreError: unknown or not running session, an index out of range, or a trial
                row already linked to an index that would move.
        """
        cols = [c for c in SCHEDULE_COLUMNS if c not in ("session_id", "trial_id", "attempts")]
        missing = [c for c in cols if c not in row]
        if missing:
            raise StoreError(f"the scheduled trial to insert lacks {missing}")
        sid, idx = row_id(session_id, "session_id"), row_id(row["trial_index"], "trial_index")
        values = tuple(int(row[c]) if isinstance(row[c], bool | np.bool_) else row[c]
                       for c in cols)
        with self._transaction() as con:
            srow = con.execute("SELECT status, n_trials FROM sessions WHERE id = ?",
                               (sid,)).fetchone()
            if srow is None:
                raise StoreError(f"trial store {self.path}: no session {sid}")
            if srow[0] != "running":
                raise StoreError(f"trial store {self.path}: session {sid} is {srow[0]!r}, "
                                 "not 'running'")
            if not 0 < idx <= srow[1]:
                raise StoreError(f"trial store {self.path}: cannot insert scheduled trial "
                                 f"{idx} into session {sid} of {srow[1]} trials")
            later = con.execute("SELECT count(*) FROM trials WHERE session_id = ? AND "
                                "schedule_index >= ?", (sid, idx)).fetchone()[0]
            if later:
                raise StoreError(f"trial store {self.path}: session {sid} already has trials "
                                 f"at scheduled index {idx} or later; cannot insert there")
            moving = con.execute("SELECT trial_index FROM scheduled_trials WHERE session_id = ? "
                                 "AND trial_index >= ? ORDER BY trial_index DESC",
                                 (sid, idx)).fetchall()
            for (i,) in moving:   # from the end: the primary key never collides
                con.execute("UPDATE scheduled_trials SET trial_index = trial_index + 1, "
                            "trial_in_block = trial_in_block + (block = ?) "
                            "WHERE session_id = ? AND trial_index = ?",
                            (row["block"], sid, i))
            con.execute(f"INSERT INTO scheduled_trials (session_id, {', '.join(cols)}) "
                        f"VALUES ({sid}, {', '.join('?' * len(cols))})", values)
            con.execute("UPDATE sessions SET n_trials = n_trials + 1 WHERE id = ?", (sid,))
            con.execute("INSERT INTO events (trial_id, t, kind, detail, created_at) "
                        "VALUES (?, NULL, ?, ?, ?)",
                        (row_id(event_trial_id, "event_trial_id"), kind, detail, now()))

    def set_demographics(self, subject: str, demographics: Demographics, *,
                         session_id: int | None = None) -> None:
        """Stores (or replaces) a subject's demographics.

        Raises:
            ConfigError: bad subject code or demographics.
        """
        validate_subject_code(subject)
        check_type(demographics, "demographics", Demographics, "a Demographics")
        d = demographics
        with self._transaction() as con:
            con.execute("INSERT OR IGNORE INTO subjects (code, created_at) VALUES (?, ?)",
                        (subject, now()))
            con.execute(
                f"INSERT OR REPLACE INTO demographics ({', '.join(DEMOGRAPHIC_COLUMNS)}) "
                f"VALUES ({', '.join('?' * len(DEMOGRAPHIC_COLUMNS))})",
                (subject, d.group, d.specialisation, d.laparoscopy_experience,
                 d.simulator_experience, d.robotic_experience, int_or_none(session_id),
                 now()))

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
        check_choice(questionnaire, "questionnaire", ("pre", "post"))
        sid = row_id(session_id)
        data = []
        for row in rows:
            item, key, value, num = row
            expect(isinstance(item, str) and item and isinstance(key, str)
                   and isinstance(value, str), row,
                   "an answer row (item, key, value, value_num) with strings", field="rows")
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
            stamp = now()
            con.executemany(
                "INSERT INTO answers (session_id, subject, questionnaire, item, key, value, "
                "value_num, answered_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                [(sid, srow[0], questionnaire, item, key, value, num, stamp)
                 for item, key, value, num in data])
            if demographics is not None:
                d = demographics
                con.execute(
                    f"INSERT OR REPLACE INTO demographics ({', '.join(DEMOGRAPHIC_COLUMNS)}) "
                    f"VALUES ({', '.join('?' * len(DEMOGRAPHIC_COLUMNS))})",
                    (srow[0], d.group, d.specialisation, d.laparoscopy_experience,
                     d.simulator_experience, d.robotic_experience, sid, stamp))
        return len(data)


__all__ = ["SessionMeta", "SessionWriters"]
