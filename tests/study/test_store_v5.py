"""Store schema version 5: the per-sample fixture gain (vasim/study/store/schema.py,
readers.py; issue #18 item 1): a version-4 store migrates (old rows read gain 1.0), a
read-only version-4 store reads as if migrated, a gained trial round-trips and is exported."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np
import pandas as pd

import vasim.study.store.schema as schema_mod
from vasim.study.export import export_study
from vasim.study.store import APPLICATION_ID, SCHEMA_VERSION, TrialStore
from vasim.trials.registry import run_trial
from vasim.trials.vf import TrialConfig


def v4_store(path: Path) -> None:
    """A version-4 store built with the frozen DDL of versions 1-4 (as vasim wrote it before
    version 5): one trial with 3 samples."""
    con = sqlite3.connect(path, isolation_level=None)
    con.execute("PRAGMA journal_mode = WAL")
    con.execute("BEGIN")
    for v in (1, 2, 3, 4):
        for stmt in schema_mod.split_sql(schema_mod.MIGRATIONS[v]):
            con.execute(stmt)
        con.execute("INSERT INTO schema_version VALUES (?, '2026-01-01T00:00:00+00:00')", (v,))
    con.execute(f"PRAGMA application_id = {APPLICATION_ID}")
    con.execute("PRAGMA user_version = 4")
    con.execute("INSERT INTO subjects VALUES ('S01', '2026-01-01', NULL)")
    con.execute("INSERT INTO trials (id, subject, task, status, started_at, n_samples, "
                "outcome) VALUES (1, 'S01', 'trajectory', 'completed', '2026-01-01', 3, "
                "'reached_all')")
    con.executemany("INSERT INTO samples (trial_id, k, t, f_x, goal_index, contact) "
                    "VALUES (1, ?, ?, ?, 0, 0)",
                    [(k, 0.001 * (k + 1), 0.1 * k) for k in range(3)])
    con.execute("COMMIT")
    con.close()


def test_v4_store_migrates_to_v5_and_old_samples_read_gain_one(tmp_path: Path):
    assert SCHEMA_VERSION >= 5
    p = tmp_path / "v4.db"
    v4_store(p)
    with TrialStore(p, readonly=True) as ro:  # read-only: not migrated, read as if it were
        assert ro.schema_version == 4
        df = ro.samples(1)
        assert df["gain"].tolist() == [1.0, 1.0, 1.0] and df["f_x"].tolist() == [0, .1, .2]
    with TrialStore(p) as st:
        assert st.schema_version == SCHEMA_VERSION
        versions = [r[0] for r in st.con.execute("SELECT version FROM schema_version")]
        assert versions == list(range(1, SCHEMA_VERSION + 1))
        assert st.samples(1)["gain"].tolist() == [1.0, 1.0, 1.0]
        assert np.all(st.sample_buffer(1).view()["gain"] == 1.0)


def test_a_gained_trial_round_trips_and_is_exported(tmp_path: Path):
    db = tmp_path / "s.db"
    with TrialStore(db) as st:
        res, tid = run_trial(TrialConfig(schema="ff", seed=2, max_time=0.3, scene="none",
                                         subject="S01", gain=0.75), st)
        _, tid_full = run_trial(TrialConfig(schema="ff", seed=2, max_time=0.3, scene="none",
                                            subject="S01"), st)
        assert tid is not None and tid_full is not None
        df = st.samples(tid)
        assert len(df) == len(res.samples) and np.all(df["gain"] == 0.75)
        assert np.all(st.samples(tid_full)["gain"] == 1.0)
        assert st.trial(tid)["config"]["gain"] == 0.75
        assert st.trial(tid)["summary"]["gain_mean"] == 0.75
    out = export_study(db, tmp_path / "export", tables=("samples",))
    exported = pd.read_csv(out / "samples.csv")
    by_trial = exported.groupby("trial_id")["gain"].agg(["min", "max"])
    assert by_trial.loc[tid].tolist() == [0.75, 0.75]
    assert by_trial.loc[tid_full].tolist() == [1.0, 1.0]
