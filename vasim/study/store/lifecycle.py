"""The life cycle of a stored trial: the writers that begin, finish and close trial rows.

1. ``begin_trial(meta)`` commits a ``trials`` row with status ``'running'`` at once, so a
   run that dies is visible afterwards;
2. ``finish_trial(...)`` writes every sample, the per-point metrics, the events, the summary,
   the trial's ``outcome`` and status ``'completed'`` in **one transaction**: a trial's data
   are either all in the store or not at all, never half-written;
3. ``mark_interrupted(...)`` / ``keep_interrupted(...)`` close a trial that stopped early
   (Stop, Ctrl-C, an error), optionally with the samples gathered so far (again in one
   transaction), outcome ``'stopped'`` or ``'failed'``;
4. ``recover_interrupted()`` (when a writable store opens) closes as ``'interrupted'`` (outcome
   ``'interrupted'`` too) every trial left 'running' by a process of this host that no longer
   runs (``vasim.study.store.liveness``).

The status says where a row is in this life cycle; the outcome says how the trial itself
ended (``vocabulary.TRIAL_OUTCOMES``): a trial that hit its time limit is 'completed' (all
its data are stored) with outcome ``'timed_out'``.
"""

from __future__ import annotations

import logging
import os
import sqlite3
from collections.abc import Callable, Iterable, Mapping
from typing import Any, Literal

import pandas as pd

from vasim import __version__
from vasim.core.config import check_type, expect
from vasim.core.errors import StoreError
from vasim.records.point_metrics import POINT_COLUMNS
from vasim.records.samples import SampleBuffer
from vasim.records.trial_meta import TrialMeta
from vasim.study.store.connection import StoreConnection
from vasim.study.store.liveness import is_writer, proc_token, process_alive
from vasim.study.store.packing import pack_columns
from vasim.study.store.rows import (
    int_or_none,
    point_metric_rows,
    row_id,
    to_json,
    trial_metric_rows,
)
from vasim.study.store.schema import now
from vasim.study.store.vocabulary import (
    TrialOutcome,
    outcome_of_reason,
    outcome_of_summary,
    validate_outcome,
)

log = logging.getLogger("vasim.study.store")

Event = tuple[float | None, str, str]

RECOVERED_PREFIX = "writer process "
"""Start of the event detail ``recover_interrupted`` writes (recognised by the writer)."""
_RECOVERED_SQL = ("SELECT 1 FROM events WHERE trial_id = ? AND detail LIKE '"
                  + RECOVERED_PREFIX + "%no longer runs%' LIMIT 1")


class _NotRunning(Exception):
    """Internal: the trial to close is no longer running."""


class TrialLifecycle(StoreConnection):
    """The trial life cycle writers of ``TrialStore`` (module docstring)."""

    def begin_trial(self, meta: TrialMeta | Mapping[str, Any]) -> int:
        """Creates the trial row with status 'running' and commits it; returns its id.

        A trial without a subject (``meta.subject`` None) is stored with ``subject`` NULL
        (and its ``label``, if any); no subject code is invented for it. With
        ``meta.schedule_index`` the trial is an attempt at that scheduled trial of
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
        token = proc_token(meta.pid) if meta.host == self._host else None
        with self._transaction() as con:
            if meta.subject is not None:
                con.execute("INSERT OR IGNORE INTO subjects (code, created_at) VALUES (?, ?)",
                            (meta.subject, now()))
            attempt = None
            if meta.schedule_index is not None:
                attempt = self._claim_scheduled(con, meta)
            cur = con.execute(
                "INSERT INTO trials (subject, session_id, protocol, task, variant, schema, "
                "operator, seed, status, started_at, dt, active_fixtures, pid, host, "
                "proc_token, config_json, schema_toml, vasim_version, schedule_index, attempt, "
                "label) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, ?, 'running', ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (meta.subject, int_or_none(meta.session_id), meta.protocol, meta.task,
                 int_or_none(meta.variant), meta.schema, meta.operator,
                 int_or_none(meta.seed), now(), meta.dt, meta.active_fixtures,
                 int_or_none(meta.pid), meta.host, token,
                 to_json(meta.config), meta.schema_toml,
                 __version__, int_or_none(meta.schedule_index), attempt, meta.label),
            )
            trial_id = cur.lastrowid
        assert trial_id is not None  # sqlite always sets it after an INSERT
        return int(trial_id)

    def _claim_scheduled(self, con: sqlite3.Connection, meta: TrialMeta) -> int:
        """Checks a scheduled trial can start and counts the attempt; returns its number."""
        sid, idx = int(meta.session_id), int(meta.schedule_index)  # type: ignore[arg-type]  # check
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
        events: Iterable[Event] = (),
        timing: Mapping[str, Any] | None = None,
        trial_metrics: Mapping[str, float] | None = None,
    ) -> None:
        """Stores a trial's samples, metrics, events, summary and outcome; status
        'completed'.

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
            summary: ``metrics.trial_summary`` dict plus any extras (JSON-serialisable);
                its ``outcome`` (else its ``completed`` flag, see
                ``vocabulary.outcome_of_summary``) becomes the row's ``outcome``.
            events: ``(t [s] or None, kind, detail)`` tuples.
            timing: servo-loop timing statistics (JSON-serialisable), or None.
            trial_metrics: ``trial_metrics.trial_metrics`` dict (name -> float), or None.

        Raises:
            StoreError: unknown trial, trial not 'running', duplicate step k, or SQLite
                failure (the transaction is rolled back).
            ConfigError: an unknown ``summary["outcome"]``.
        """
        self._close_trial(trial_id, "completed", samples, point_metrics, summary, events,
                          timing, trial_metrics, reason=None,
                          outcome=outcome_of_summary(summary))

    def keep_interrupted(self, trial_id: int, reason: str, partial: Callable[[], Any], *,
                         samples: SampleBuffer | None = None,
                         events: Iterable[Event] = (),
                         outcome: TrialOutcome | None = None) -> None:
        """Marks a failed trial 'interrupted' with as much as can be kept, never leaving it
        'running': the partial result (``partial()``: an object with ``samples``,
        ``metrics``, ``summary``, ``events`` and ``trial_metrics``); if computing that fails
        too, the raw ``samples``; if storing those fails, the bare status change. For an
        ``except`` block: its own failures are logged, not raised. ``outcome``: as in
        ``mark_interrupted``.
        """
        extra = list(events)
        attempts: list[Callable[[], object]] = []

        def full() -> object:
            res = partial()
            return self.mark_interrupted(
                trial_id, reason=reason, samples=res.samples, point_metrics=res.metrics,
                summary=res.summary, events=[*res.events, *extra],
                trial_metrics=res.trial_metrics, outcome=outcome)

        attempts.append(full)
        if samples is not None:
            attempts.append(lambda: self.mark_interrupted(
                trial_id, reason=reason, samples=samples, events=extra, outcome=outcome))
        attempts.append(lambda: self.mark_interrupted(trial_id, reason=reason, events=extra,
                                                      outcome=outcome))
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
        events: Iterable[Event] = (),
        trial_metrics: Mapping[str, float] | None = None,
        outcome: TrialOutcome | None = None,
    ) -> bool:
        """Marks a running trial 'interrupted', optionally keeping what it recorded.

        Safe to call from an ``except`` block: a trial that is no longer 'running' (e.g.
        already completed) is left unchanged and ``False`` is returned.

        Args:
            trial_id: the trial. reason: stored as an ``'interrupted'`` event.
            samples, point_metrics, summary, events, trial_metrics: the partial data to
                keep (one transaction with the status change), or None/empty.
            outcome: ``'stopped'``, ``'failed'`` or ``'interrupted'``; None: read from the
                reason (``vocabulary.outcome_of_reason``). A kept summary's ``outcome`` is
                set to it, so the row and its summary agree.

        Returns:
            True if the trial was running and is now 'interrupted'.

        Raises:
            StoreError: unknown trial id, or SQLite failure.
            ConfigError: an unknown outcome.
        """
        out = outcome_of_reason(reason) if outcome is None else validate_outcome(outcome)
        expect(out not in ("reached_all", "timed_out"), out, "'stopped', 'failed' or "
               "'interrupted' (an interrupted trial's outcome)", field="outcome")
        if summary is not None:
            summary = {**summary, "outcome": out}
        try:
            self._close_trial(trial_id, "interrupted", samples, point_metrics, summary,
                              events, None, trial_metrics, reason=reason, outcome=out)
        except _NotRunning:
            return False
        return True

    def _close_trial(
        self,
        trial_id: int,
        status: Literal["completed", "interrupted"],
        samples: SampleBuffer | None,
        point_metrics: pd.DataFrame | None,
        summary: Mapping[str, Any] | None,
        events: Iterable[Event],
        timing: Mapping[str, Any] | None,
        trial_metrics: Mapping[str, float] | None,
        *,
        reason: str | None,
        outcome: str | None,
    ) -> None:
        tid = row_id(trial_id)
        metric_rows = point_metric_rows(point_metrics) if point_metrics is not None else []
        tm_rows = trial_metric_rows(trial_metrics) if trial_metrics is not None else []
        summary_json = to_json(summary)
        timing_json = to_json(timing)
        event_rows = [(None if t is None else float(t), str(kind), str(detail))
                      for t, kind, detail in events]
        if samples is not None:
            check_type(samples, "samples", SampleBuffer, "a SampleBuffer")
        # packed before the write lock is taken (schema 6: one compressed blob per column)
        packed = _packed(samples, self.path, tid)
        try:
            with self._transaction() as con:
                row = con.execute("SELECT status, pid, host, proc_token, session_id, "
                                  "schedule_index FROM trials WHERE id = ?",
                                  (tid,)).fetchone()
                if row is None:
                    raise StoreError(f"trial store {self.path}: no trial {tid}")
                if (row[0] == "interrupted" and status == "completed"
                        and row[2] == self._host and is_writer(row[1], row[3])
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
                        status = "interrupted"   # the outcome stays what the run reached
                        superseded = True
                        reason = (f"superseded: scheduled trial {row[5]} of session {row[4]} "
                                  f"was completed by trial {other[0] if other else '?'}")
                n = 0
                fixtures = ""
                if samples is not None:
                    n = len(samples)
                    fixtures = samples.active_fixtures
                    con.executemany(
                        "INSERT INTO sample_columns (trial_id, name, dtype, n, codec, data) "
                        f"VALUES ({tid}, ?, ?, ?, ?, ?)", packed)
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
                stamp = now()
                if reason is not None:
                    kind = "superseded" if superseded else "interrupted"
                    event_rows.append((None, kind, reason))
                if event_rows:
                    con.executemany(
                        f"INSERT INTO events (trial_id, t, kind, detail, created_at) "
                        f"VALUES ({tid}, ?, ?, ?, '{stamp}')",
                        event_rows,
                    )
                con.execute(
                    "UPDATE trials SET status = ?, ended_at = ?, n_samples = ?, "
                    "summary_json = ?, timing_json = ?, outcome = ?, "
                    "active_fixtures = CASE WHEN ? = '' THEN active_fixtures ELSE ? END "
                    "WHERE id = ?",
                    (status, stamp, n, summary_json, timing_json, outcome, fixtures, fixtures,
                     tid),
                )
        except sqlite3.IntegrityError as e:
            raise StoreError(f"trial store {self.path}: cannot store trial {tid}: {e} "
                             "(duplicate step k?)") from e
        except sqlite3.Error as e:
            raise StoreError(f"trial store {self.path}: cannot store trial {tid}: {e}") from e

    def stale_trials(self) -> list[tuple[int, int | None]]:
        """``(trial id, pid)`` of the 'running' trials of this host whose writing process has
        ended (read only: nothing is written)."""
        rows = self.con.execute(
            "SELECT id, pid, host, proc_token FROM trials WHERE status = 'running'").fetchall()
        return [(int(tid), pid) for tid, pid, host, token in rows
                if host == self._host and not process_alive(pid, token)]

    def recover_interrupted(self) -> list[int]:
        """Marks 'interrupted' (outcome ``'interrupted'``) the running trials whose writing
        process has ended.

        Only trials written on this host are checked. Called when a writable store opens.

        Returns:
            The ids of the trials marked.

        Raises:
            StoreError: the store is read-only.
        """
        if self.readonly:
            raise StoreError(f"trial store {self.path} is open read-only: cannot mark its "
                             "stale trials interrupted")
        marked = []
        for tid, pid in self.stale_trials():
            reason = (f"{RECOVERED_PREFIX}{pid} on {self._host} no longer runs; found by "
                      f"process {os.getpid()} when opening the store")
            if self.mark_interrupted(tid, reason=reason, outcome="interrupted"):
                marked.append(tid)
        return marked

    def add_event(self, trial_id: int, kind: str, detail: str = "", *,
                  t: float | None = None) -> None:
        """Stores one event at once (its own transaction; not for the 1 kHz loop)."""
        tid = row_id(trial_id)
        try:
            with self._transaction() as con:
                con.execute("INSERT INTO events (trial_id, t, kind, detail, created_at) "
                            "VALUES (?, ?, ?, ?, ?)", (tid, t, kind, detail, now()))
        except sqlite3.IntegrityError as e:
            raise StoreError(f"trial store {self.path}: no trial {tid}: {e}") from e


def _packed(samples: SampleBuffer | None, path: object, tid: int,
            ) -> list[tuple[str, str, int, str, bytes]]:
    """The ``sample_columns`` rows of ``samples`` (none for no or zero samples).

    Raises:
        StoreError: two samples share a step k (naming the store and trial).
    """
    if samples is None or len(samples) == 0:
        return []
    try:
        return pack_columns(samples.columns())
    except StoreError as e:
        raise StoreError(f"trial store {path}: cannot store trial {tid}: {e}") from e


__all__ = ["RECOVERED_PREFIX", "TrialLifecycle"]
