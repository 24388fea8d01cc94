"""Readers of a study database: trials, samples, metrics, events, sessions, schedules,
subjects, demographics and answers, as pandas frames (or dicts for one row).

Floats round-trip exactly (SQLite REAL is an IEEE double) with two SQLite caveats: NaN is
stored as NULL (read back as NaN in float columns) and -0.0 is read back as 0.0. Samples
(schema 6) are packed losslessly, bit for bit, NaN and -0.0 included
(``vasim.study.store.packing``).
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pandas as pd

from vasim.core.config import check_choice
from vasim.core.errors import StoreError
from vasim.records.point_metrics import POINT_COLUMNS
from vasim.records.samples import FRAME_COLUMNS, SampleBuffer
from vasim.study.store.connection import StoreConnection
from vasim.study.store.packing import rows_to_columns, unpack_columns
from vasim.study.store.rows import row_id
from vasim.study.store.schema import (
    ANSWER_COLUMNS,
    DEMOGRAPHIC_COLUMNS,
    EVENT_COLUMNS,
    SCHEDULE_COLUMNS,
    SESSION_COLUMNS,
    TRIAL_COLUMNS,
)
from vasim.study.store.vocabulary import (
    SESSION_STATUSES,
    TRIAL_STATUSES,
    SessionStatus,
    TrialOutcome,
    TrialStatus,
    validate_outcome,
)

_SAMPLE_DEFAULTS = {"gain": "1.0"}
"""What a sample column added by a later schema version reads in an older store."""


class StoreReaders(StoreConnection):
    """The readers of ``TrialStore`` (they work on a read-only store too)."""

    def trials(self, status: TrialStatus | None = None, *,
               subject: str | None = None, outcome: TrialOutcome | None = None,
               ) -> pd.DataFrame:
        """Trial rows (columns ``TRIAL_COLUMNS``), ordered by id, optionally filtered by
        status, subject code and outcome (a trial without a subject has ``subject`` None).

        Raises:
            ConfigError: unknown status or outcome.
        """
        where: list[str] = []
        args: list[Any] = []
        if status is not None:
            check_choice(status, "status", TRIAL_STATUSES)
            where.append("status = ?")
            args.append(status)
        if subject is not None:
            where.append("subject = ?")
            args.append(subject)
        if outcome is not None:
            where.append("outcome = ?")
            args.append(validate_outcome(outcome))
        sql = f"SELECT * FROM (SELECT {', '.join(self._trial_exprs)} FROM trials)"
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
        tid = row_id(trial_id)
        row = self.con.execute(
            f"SELECT {', '.join(self._trial_exprs)} FROM trials WHERE id = ?",
            (tid,)).fetchone()
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
        tid = row_id(trial_id)
        if self._packed_samples():
            rows = self.con.execute(
                "SELECT name, dtype, n, codec, data FROM sample_columns WHERE trial_id = ?",
                (tid,)).fetchall()
            if not rows:
                return rows_to_columns([])
            try:
                return unpack_columns(rows)
            except StoreError as e:
                raise StoreError(f"trial store {self.path}: trial {tid}: {e}") from e
        rows = self.con.execute(
            f"SELECT {', '.join(self._sample_exprs())} FROM samples WHERE trial_id = ? "
            "ORDER BY k", (tid,)).fetchall()
        return rows_to_columns(rows)

    def _packed_samples(self) -> bool:
        """True when the samples are packed columns (schema 6); False for an older store
        opened read-only (not migrated), whose ``samples`` rows are read as they are."""
        packed = getattr(self, "_packed_cache", None)
        if packed is None:
            packed = self.con.execute(
                "SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'sample_columns'"
            ).fetchone() is not None
            self._packed_cache = packed
        return bool(packed)

    def _sample_exprs(self) -> tuple[str, ...]:
        """SELECT expressions of ``FRAME_COLUMNS`` of a version-2 to -5 ``samples`` table: a
        column an older store (opened read-only, hence not migrated) lacks reads as its
        migration default (``gain``: 1.0, schema version 5)."""
        exprs = getattr(self, "_sample_exprs_cache", None)
        if exprs is None:
            have = {r[1] for r in self.con.execute("PRAGMA table_info(samples)")}
            exprs = tuple(c if c in have else f"{_SAMPLE_DEFAULTS.get(c, 'NULL')} AS {c}"
                          for c in FRAME_COLUMNS)
            self._sample_exprs_cache = exprs
        return exprs

    def point_metrics(self, trial_id: int) -> pd.DataFrame:
        """A trial's per-point metrics, columns ``metrics.POINT_COLUMNS``, by point."""
        tid = row_id(trial_id)
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
            args.append(row_id(trial_id))
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
        tid = row_id(trial_id)
        rows = self.con.execute(
            "SELECT t, kind, detail, created_at FROM events WHERE trial_id = ? ORDER BY id",
            (tid,)).fetchall()
        df = pd.DataFrame(rows, columns=list(EVENT_COLUMNS))
        df["t"] = df["t"].astype(np.float64)
        return df

    def subjects(self) -> pd.DataFrame:
        """All subjects: columns ``code, created_at, notes``, ordered by code."""
        rows = self.con.execute(
            "SELECT code, created_at, notes FROM subjects ORDER BY code").fetchall()
        return pd.DataFrame(rows, columns=["code", "created_at", "notes"])

    def session(self, session_id: int) -> dict[str, Any]:
        """One session row as a dict (``SESSION_COLUMNS``) plus ``config`` parsed from JSON.

        Raises:
            StoreError: unknown session.
        """
        sid = row_id(session_id)
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
        if status is not None:
            check_choice(status, "status", SESSION_STATUSES)
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
        sid = row_id(session_id)
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

    def demographics(self) -> pd.DataFrame:
        """Every subject's demographics (``DEMOGRAPHIC_COLUMNS``), ordered by subject."""
        rows = self.con.execute(f"SELECT {', '.join(DEMOGRAPHIC_COLUMNS)} FROM demographics "
                                "ORDER BY subject").fetchall()
        df = pd.DataFrame(rows, columns=list(DEMOGRAPHIC_COLUMNS))
        df["session_id"] = df["session_id"].astype("Int64")
        return df

    def answers(self, session_id: int | None = None) -> pd.DataFrame:
        """Questionnaire answers (``ANSWER_COLUMNS``), by session, questionnaire, item, key."""
        sql = f"SELECT {', '.join(ANSWER_COLUMNS)} FROM answers"
        args: list[Any] = []
        if session_id is not None:
            sql += " WHERE session_id = ?"
            args.append(row_id(session_id))
        rows = self.con.execute(
            sql + " ORDER BY session_id, questionnaire DESC, item, key", args).fetchall()
        df = pd.DataFrame(rows, columns=list(ANSWER_COLUMNS))
        df["value_num"] = df["value_num"].astype(np.float64)
        return df


__all__ = ["StoreReaders"]
