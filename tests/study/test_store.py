"""Tests of the sample buffer (vasim/records/samples.py) and the trial store
(vasim/study/store/)."""

from __future__ import annotations

import doctest
import hashlib
import json
import math
import os
import signal
import sqlite3
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import vasim.records.samples as samples_mod
import vasim.study.store.liveness as liveness_mod
import vasim.study.store.schema as schema_mod
import vasim.study.store.trial_store as store_mod
import vasim.study.store.vocabulary as vocabulary_mod
from vasim.core.errors import ConfigError, StoreError
from vasim.records.point_metrics import POINT_COLUMNS, evaluate_trial
from vasim.records.samples import FRAME_COLUMNS, SampleBuffer
from vasim.records.trial_meta import TrialMeta
from vasim.study.store import APPLICATION_ID, SCHEMA_VERSION, TRIAL_COLUMNS, TrialStore

CHILD = Path(__file__).with_name("_kill_child.py")


def random_buffer(n: int, seed: int = 0, n_points: int = 4) -> SampleBuffer:
    """n samples of random, non-special floats (no NaN, no -0.0) in every column."""
    rng = np.random.default_rng(seed)
    gi = (np.arange(n) * n_points) // max(n, 1)
    buf = SampleBuffer(capacity=16, active_fixtures="VG")
    buf.extend(
        k=np.arange(n) * 3 + 7, t=rng.uniform(0, 100, n), x=rng.normal(size=(n, 3)),
        g=rng.normal(size=(n, 3)), goal_index=gi, force=rng.normal(size=(n, 3)) * 1e3,
        ms=rng.uniform(0.1, 5, size=(n, 3)), zoom=rng.uniform(1, 4, n),
        audio_pitch=rng.uniform(100, 1000, n), audio_period=rng.uniform(0, 1, n),
        audio_volume=rng.uniform(0, 1, n), contact=rng.integers(0, 2, n),
    )
    return buf


@pytest.fixture
def store(tmp_path: Path):
    st = TrialStore(tmp_path / "study.db")
    yield st
    st.close()


def meta(**kw) -> TrialMeta:
    kw.setdefault("subject", "S01")
    kw.setdefault("task", "trajectory")
    return TrialMeta(**kw)


# --------------------------------------------------------------------------- buffer
def test_buffer_append_grows_and_keeps_every_row():
    buf = SampleBuffer(capacity=2)
    for k in range(9):
        buf.append(k, 0.001 * k, (k, 0.0, 0.0), np.array([0.0, k, 0.0]), k // 3)
    assert len(buf) == 9 and buf.capacity == 16  # 2 -> 4 -> 8 -> 16
    v = buf.view()
    assert v["k"].tolist() == list(range(9))
    assert v["x"][:, 0].tolist() == list(range(9))
    assert v["g"][:, 1].tolist() == list(range(9))
    assert v["goal_index"].tolist() == [0, 0, 0, 1, 1, 1, 2, 2, 2]
    # defaults: no force, MS 1, zoom 1, no audio, no contact
    assert np.all(v["force"] == 0) and np.all(v["ms"] == 1) and np.all(v["zoom"] == 1)
    assert np.all(v["audio_volume"] == 0) and np.all(v["contact"] == 0)
    assert v["k"].dtype == np.int64 and v["goal_index"].dtype == np.int32
    assert v["contact"].dtype == np.int8


def test_buffer_view_is_read_only_and_stable():
    buf = SampleBuffer(capacity=1)
    buf.append(0, 0.0, (1, 2, 3), (4, 5, 6), 0, (7, 8, 9), (1, 2, 1), 2.0, 440.0, 0.5, 0.25, 1)
    v = buf.view()
    with pytest.raises(ValueError):
        v["x"][0, 0] = 5.0
    buf.append(1, 0.1, (0, 0, 0), (0, 0, 0), 0)  # grows: the old view keeps its rows
    assert v["x"].tolist() == [[1.0, 2.0, 3.0]]
    c = buf.view(copy=True)
    c["x"][0, 0] = 5.0
    assert buf.view()["x"][0, 0] == 1.0


def test_buffer_frame_columns_and_roundtrip():
    buf = random_buffer(50)
    df = buf.to_frame()
    assert tuple(df.columns) == FRAME_COLUMNS
    assert FRAME_COLUMNS[:8] == ("k", "t", "x_x", "x_y", "x_z", "g_x", "g_y", "g_z")
    again = SampleBuffer.from_columns(df, active_fixtures="VG")
    pd.testing.assert_frame_equal(again.to_frame(), df, check_exact=True)
    rows = list(buf.rows())
    assert len(rows) == 50 and len(rows[0]) == len(FRAME_COLUMNS)
    assert all(type(v) in (int, float) for v in rows[0])


def test_buffer_bad_input():
    with pytest.raises(ValueError, match="capacity"):
        SampleBuffer(capacity=0)
    buf = SampleBuffer()
    with pytest.raises(ValueError, match="'x'"):
        buf.extend(k=[0, 1], t=[0, 1], x=np.zeros((3, 3)), g=np.zeros((2, 3)), goal_index=[0, 0])
    with pytest.raises(ValueError):
        buf.append(0, 0.0, (1.0, 2.0), (0, 0, 0), 0)  # a 2-vector
    with pytest.raises(ValueError, match="missing"):
        SampleBuffer.from_columns({"k": [0]})


# ---------------------------------------------------------------------- open / schema
def test_new_store_has_schema_pragmas_and_tables(store: TrialStore, tmp_path: Path):
    con = store.con
    assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert con.execute("PRAGMA synchronous").fetchone()[0] == 2  # FULL
    assert con.execute("PRAGMA foreign_keys").fetchone()[0] == 1
    assert con.execute("PRAGMA application_id").fetchone()[0] == APPLICATION_ID
    assert store.schema_version == SCHEMA_VERSION
    tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
    assert {"schema_version", "subjects", "trials", "sample_columns", "point_metrics",
            "events"} <= tables
    assert "samples" not in tables   # version 6 packs samples into columns
    # a new store is built by the migration steps, each logged: 1, 2, ...
    assert con.execute("SELECT version FROM schema_version").fetchall() == [
        (v,) for v in range(1, SCHEMA_VERSION + 1)]
    store.close()
    with TrialStore(tmp_path / "study.db") as again:  # reopening changes nothing
        assert again.schema_version == SCHEMA_VERSION
        assert again.integrity_check() == "ok"


def test_newer_schema_version_is_refused(tmp_path: Path):
    p = tmp_path / "study.db"
    TrialStore(p).close()
    con = sqlite3.connect(p)
    con.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    con.commit()
    con.close()
    with pytest.raises(StoreError, match="newer") as e:
        TrialStore(p)
    assert str(p) in str(e.value)


def test_foreign_sqlite_db_is_refused(tmp_path: Path):
    p = tmp_path / "other.db"
    con = sqlite3.connect(p)
    con.execute("CREATE TABLE cats (name TEXT)")
    con.commit()
    con.close()
    with pytest.raises(StoreError, match="not a vasim trial store") as e:
        TrialStore(p)
    assert str(p) in str(e.value)
    # and it is left untouched (not even switched to WAL)
    con = sqlite3.connect(p)
    assert con.execute("PRAGMA application_id").fetchone()[0] == 0
    assert con.execute("PRAGMA journal_mode").fetchone()[0] == "delete"
    con.close()


def test_garbage_file_directory_and_missing_folder(tmp_path: Path):
    junk = tmp_path / "junk.db"
    junk.write_bytes(b"this is not sqlite at all" * 100)
    with pytest.raises(StoreError, match=r"junk\.db"):
        TrialStore(junk)
    with pytest.raises(StoreError, match="directory"):
        TrialStore(tmp_path)
    with pytest.raises(StoreError, match="does not exist"):
        TrialStore(tmp_path / "nope" / "study.db")


def test_readonly_store_reads_but_never_writes(tmp_path: Path):
    p = tmp_path / "study.db"
    with TrialStore(p) as st:
        tid = st.begin_trial(meta())
        st.finish_trial(tid, random_buffer(10))
    with TrialStore(p, readonly=True) as ro:
        assert len(ro.samples(tid)) == 10
        with pytest.raises(StoreError, match="read-only"):
            ro.begin_trial(meta())
    with pytest.raises(StoreError, match="does not exist"):
        TrialStore(tmp_path / "absent.db", readonly=True)


# --------------------------------------------------------------------------- subjects
@pytest.mark.parametrize("code", ["John Doe", "", "x" * 33, "S01;DROP TABLE trials", "Zoë",
                                  "a/b", None, 7])
def test_bad_subject_code_is_rejected(store: TrialStore, code):
    with pytest.raises(ConfigError, match="subject code") as e:
        store.add_subject(code)
    assert repr(code) in str(e.value)
    if code is not None:  # None: a trial without a subject (test_store_outcomes.py)
        with pytest.raises(ConfigError, match="subject code"):
            store.begin_trial({"subject": code, "task": "trajectory"})
    assert store.subjects().empty and store.trials().empty


def test_subject_check_constraint_in_sql(store: TrialStore):
    with pytest.raises(sqlite3.IntegrityError):
        store.con.execute("INSERT INTO subjects (code, created_at) VALUES ('Jane Roe', 'x')")


def test_subjects_are_registered_once(store: TrialStore):
    store.add_subject("S01", notes="resident")
    store.add_subject("S01")
    store.begin_trial(meta(subject="S01"))
    store.begin_trial(meta(subject="S-02_b"))
    assert store.subjects()["code"].tolist() == ["S-02_b", "S01"]


def test_meta_validation():
    with pytest.raises(ConfigError, match=r"got \['name'\], expected known trial meta fields"):
        TrialMeta.from_mapping({"subject": "S01", "task": "t", "name": "Jane"})
    with pytest.raises(ConfigError, match="dt"):
        meta(dt=0.0)
    with pytest.raises(ConfigError, match="seed"):
        meta(seed=1.5)


# -------------------------------------------------------------------------- lifecycle
def test_roundtrip_is_exact(store: TrialStore):
    buf = random_buffer(5000, seed=3)
    v = buf.view()
    pm, summary = evaluate_trial(v["t"], v["x"], v["g"], v["goal_index"], 4)
    pm.loc[3, ["t_reached", "latency"]] = np.nan  # NaN travels as NULL
    summary["note"] = "NaN becomes null"
    tid = store.begin_trial(meta(variant=2, schema="vg", operator="scripted", seed=11,
                                 dt=1e-3, protocol="vf-learning", session_id=4))
    running = store.trial(tid)
    assert running["status"] == "running" and running["n_samples"] is None
    store.finish_trial(tid, buf, pm, summary, events=[(0.5, "nonfinite_input", "dX=nan")],
                       timing={"p99_us": 120.5, "overruns": 0})

    back = store.samples(tid)
    pd.testing.assert_frame_equal(back, buf.to_frame(), check_exact=True)
    # every column bit for bit (schema 6 packs them losslessly, vasim/study/store/packing.py)
    for c in FRAME_COLUMNS:
        assert back[c].to_numpy().tobytes() == buf.to_frame()[c].to_numpy().tobytes(), c
    pd.testing.assert_frame_equal(store.point_metrics(tid), pm, check_exact=True)
    again = store.sample_buffer(tid)
    assert again.active_fixtures == "VG"
    pd.testing.assert_frame_equal(again.to_frame(), buf.to_frame(), check_exact=True)

    tr = store.trial(tid)
    assert tr["status"] == "completed" and tr["n_samples"] == 5000
    assert (tr["variant"], tr["schema"], tr["seed"], tr["dt"]) == (2, "vg", 11, 1e-3)
    assert (tr["protocol"], tr["session_id"], tr["active_fixtures"]) == ("vf-learning", 4, "VG")
    assert tr["pid"] == os.getpid() and tr["ended_at"] >= tr["started_at"]
    assert tr["timing"] == {"p99_us": 120.5, "overruns": 0}
    expected = {k: (None if isinstance(v, float) and math.isnan(v) else v)
                for k, v in summary.items()}
    assert tr["summary"] == expected
    ev = store.events(tid)
    assert ev[["t", "kind", "detail"]].values.tolist() == [[0.5, "nonfinite_input", "dX=nan"]]
    assert list(store.trials().columns) == list(TRIAL_COLUMNS)
    assert store.trials("completed")["id"].tolist() == [tid]
    assert store.trials("running").empty


def test_nan_samples_come_back_as_nan(store: TrialStore):
    buf = SampleBuffer()
    buf.append(0, 0.0, (np.nan, 1.0, 2.0), (0, 0, 0), 0, (np.inf, -np.inf, 0.0))
    tid = store.begin_trial(meta())
    store.finish_trial(tid, buf)
    back = store.samples(tid)
    assert math.isnan(back.at[0, "x_x"]) and back.at[0, "x_y"] == 1.0
    assert back.at[0, "f_x"] == np.inf and back.at[0, "f_y"] == -np.inf


def test_finish_twice_and_unknown_trial(store: TrialStore):
    tid = store.begin_trial(meta())
    store.finish_trial(tid, random_buffer(3))
    with pytest.raises(StoreError, match="'completed'"):
        store.finish_trial(tid, random_buffer(3))
    assert store.mark_interrupted(tid) is False  # never downgrades a completed trial
    assert store.trial(tid)["status"] == "completed"
    with pytest.raises(StoreError, match="no trial 999"):
        store.finish_trial(999, random_buffer(3))
    with pytest.raises(StoreError, match="no trial 999"):
        store.trial(999)
    with pytest.raises(ConfigError, match="status"):
        store.trials("done")  # type: ignore[arg-type]


def test_failed_finish_writes_nothing(store: TrialStore):
    buf = random_buffer(100)
    buf.append(7, 0.0, (0, 0, 0), (0, 0, 0), 3)  # duplicate step k = 7 (the first row's)
    tid = store.begin_trial(meta())
    with pytest.raises(StoreError, match="duplicate"):
        store.finish_trial(tid, buf)
    assert store.trial(tid)["status"] == "running"
    assert store.samples(tid).empty and store.point_metrics(tid).empty
    with pytest.raises(ConfigError, match="lacks the columns"):
        store.finish_trial(tid, random_buffer(3), pd.DataFrame({"point": [0]}))
    store.finish_trial(tid, random_buffer(3))
    assert store.trial(tid)["n_samples"] == 3


def test_mark_interrupted_keeps_partial_data(store: TrialStore):
    tid = store.begin_trial(meta())
    buf = random_buffer(40)
    assert store.mark_interrupted(tid, reason="Ctrl-C", samples=buf) is True
    tr = store.trial(tid)
    assert tr["status"] == "interrupted" and tr["n_samples"] == 40
    assert len(store.samples(tid)) == 40
    assert store.events(tid)["detail"].tolist() == ["Ctrl-C"]
    assert store.mark_interrupted(tid) is False
    with pytest.raises(StoreError, match="'interrupted'"):
        store.finish_trial(tid, buf)


def test_finish_trial_100k_samples(store: TrialStore):
    # Its speed is measured by bench/store.py; here: all 100k rows land, in order.
    buf = random_buffer(100_000, seed=5, n_points=20)
    v = buf.view()
    pm, summary = evaluate_trial(v["t"], v["x"], v["g"], v["goal_index"], 20)
    tid = store.begin_trial(meta())
    store.finish_trial(tid, buf, pm, summary)
    assert store.trial(tid)["n_samples"] == 100_000
    np.testing.assert_array_equal(store.samples(tid)["k"].to_numpy(), v["k"])


# -------------------------------------------------------------------------- recovery
def dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_trial_of_a_live_process_stays_running(tmp_path: Path):
    p = tmp_path / "study.db"
    with TrialStore(p) as st:
        tid = st.begin_trial(meta())
        with TrialStore(p) as other:  # a second opener, e.g. the report while recording
            assert other.recovered == []
            assert other.trial(tid)["status"] == "running"


def test_trial_of_a_dead_process_is_marked_interrupted(tmp_path: Path):
    p = tmp_path / "study.db"
    with TrialStore(p) as st:
        dead = st.begin_trial(meta(pid=dead_pid()))
        remote = st.begin_trial(meta(pid=dead_pid(), host="another-station"))
    with TrialStore(p) as st:
        assert st.recovered == [dead]
        assert st.trial(dead)["status"] == "interrupted"
        assert st.events(dead)["kind"].tolist() == ["interrupted"]
        assert st.trial(remote)["status"] == "running"  # cannot check another host


def test_recycled_pid_is_not_mistaken_for_the_writer(tmp_path: Path):
    p = tmp_path / "study.db"
    with TrialStore(p) as st:
        tid = st.begin_trial(meta(pid=os.getppid()))  # alive, but ...
        if st.trial(tid)["proc_token"] is None:
            pytest.skip("no /proc process start times on this platform")
        # ... recorded with another incarnation's start time: the pid was recycled
        st.con.execute("UPDATE trials SET proc_token = 'other-boot:1' WHERE id = ?", (tid,))
    with TrialStore(p) as st:
        assert st.recovered == [tid]


# ------------------------------------------------------------------------- kill tests
def _sha(frame: pd.DataFrame) -> str:
    return hashlib.sha256(
        np.ascontiguousarray(frame.to_numpy(dtype=np.float64)).tobytes()).hexdigest()


@pytest.mark.parametrize("mode", ["between", "finish"])
def test_sigkill_leaves_completed_trials_intact(tmp_path: Path, mode: str):
    db = tmp_path / "study.db"
    proc = subprocess.Popen([sys.executable, str(CHILD), str(db), mode],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    watchdog = threading.Timer(60, proc.kill)
    watchdog.start()
    done, trial3, marker = [], None, ""
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            if line.startswith("MARKER"):
                os.kill(proc.pid, signal.SIGKILL)
                marker = line
                break
            msg = json.loads(line)
            if "trial3" in msg:
                trial3 = msg["trial3"]
            else:
                done.append(msg)
        proc.wait(timeout=30)
    finally:
        watchdog.cancel()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    err = proc.stderr.read() if proc.stderr else ""
    assert proc.returncode == -signal.SIGKILL, f"child did not die by SIGKILL:\n{err}"
    assert len(done) == 2 and trial3 is not None, err
    if mode == "finish":  # uncommitted pages of trial 3 had reached the WAL file
        assert int(marker.split("wal_bytes=")[1]) > 0, marker

    with TrialStore(db) as st:
        assert st.integrity_check() == "ok"
        assert st.recovered == [trial3]
        for msg in done:
            tid = msg["trial"]
            tr = st.trial(tid)
            assert tr["status"] == "completed" and tr["n_samples"] == msg["n"]
            s = st.samples(tid)
            assert len(s) == msg["n"]
            assert _sha(s[list(FRAME_COLUMNS)]) == msg["samples_sha"]
            assert _sha(st.point_metrics(tid)) == msg["metrics_sha"]
            assert tr["summary"] == msg["summary"]
        t3 = st.trial(trial3)
        assert t3["status"] == "interrupted" and t3["n_samples"] == 0
        assert st.samples(trial3).empty and st.point_metrics(trial3).empty
        n3 = st.con.execute("SELECT count(*) FROM sample_columns WHERE trial_id = ?",
                            (trial3,)).fetchone()[0]
        assert n3 == 0
        assert st.trials("interrupted")["id"].tolist() == [trial3]
        assert st.events(trial3)["kind"].tolist() == ["interrupted"]


# --------------------------------------------------------------------------- doctests
@pytest.mark.parametrize("module", [samples_mod, store_mod, vocabulary_mod, liveness_mod])
def test_docstring_examples_run(module):
    result = doctest.testmod(module)
    assert result.failed == 0 and result.attempted > 0


def test_point_columns_match_store_table(store: TrialStore):
    cols = [r[1] for r in store.con.execute("PRAGMA table_info(point_metrics)")]
    assert cols == ["trial_id", *POINT_COLUMNS]
    tid = store.begin_trial(meta())
    store.finish_trial(tid, random_buffer(5))
    names = [r[0] for r in store.con.execute(
        "SELECT name FROM sample_columns WHERE trial_id = ? ORDER BY rowid", (tid,))]
    assert names == list(FRAME_COLUMNS)


def test_writer_completes_a_trial_another_process_wrongly_recovered(tmp_path: Path):
    # A reader that cannot see the writer's pid (another pid namespace) marks the live trial
    # interrupted; the writer's finish still lands, with an event saying what happened.
    with TrialStore(tmp_path / "s.db") as writer:
        tid = writer.begin_trial(meta())
        writer.mark_interrupted(tid, reason="writer process 999999 on h no longer runs; x")
        writer.finish_trial(tid, random_buffer(5))
        tr = writer.trial(tid)
        assert tr["status"] == "completed" and tr["n_samples"] == 5
        assert "recovery_overruled" in writer.events(tid)["kind"].tolist()


def test_a_stale_row_with_our_pid_but_another_start_time_is_recovered(tmp_path: Path):
    path = tmp_path / "s.db"
    with TrialStore(path) as st:
        tid = st.begin_trial(meta())
        st.con.execute("UPDATE trials SET proc_token = 'other-boot:1' WHERE id = ?", (tid,))
        st.con.commit()
    with TrialStore(path) as st:
        assert st.recovered == [tid]
        assert st.trial(tid)["status"] == "interrupted"


def test_config_and_schema_are_stored_with_the_trial(store: TrialStore):
    tid = store.begin_trial(meta(config={"schema": "ff", "seed": 3, "dt": 1e-3},
                                 schema_toml='name = "ff"\n'))
    tr = store.trial(tid)
    assert tr["config"] == {"schema": "ff", "seed": 3, "dt": 1e-3}
    assert tr["schema_toml"] == 'name = "ff"\n' and tr["vasim_version"]


# --------------------------------------------------------------------- v1 -> v3 migration
def _v1_store(path: Path) -> list[tuple]:
    """A version-1 store built with the frozen v1 script, one trial with 3 samples; returns
    the sample rows as stored."""
    con = sqlite3.connect(path, isolation_level=None)
    con.execute("PRAGMA journal_mode = WAL")
    con.execute("BEGIN")
    for stmt in schema_mod.split_sql(schema_mod.MIGRATIONS[1]):
        con.execute(stmt)
    con.execute("INSERT INTO schema_version VALUES (1, '2025-01-01T00:00:00+00:00')")
    con.execute(f"PRAGMA application_id = {APPLICATION_ID}")
    con.execute("PRAGMA user_version = 1")
    con.execute("INSERT INTO subjects VALUES ('S01', '2025-01-01', NULL)")
    con.execute("INSERT INTO trials (id, subject, task, status, started_at, n_samples) "
                "VALUES (1, 'S01', 'trajectory', 'completed', '2025-01-01', 3)")
    rows = [(1, k, 0.001 * (k + 1), 0.1 * k, 0.2, 0.3, 0.0, 0.0, 0.01, 0, 0.5, 0.0, 0.0,
             1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, k % 2) for k in range(3)]
    con.executemany(f"INSERT INTO samples VALUES ({', '.join('?' * 21)})", rows)
    con.execute("COMMIT")
    con.close()
    return rows


def test_v1_store_is_migrated_to_v3_in_place(tmp_path: Path):
    p = tmp_path / "v1.db"
    rows = _v1_store(p)
    with pytest.raises(StoreError, match="open it writable once"):
        TrialStore(p, readonly=True)
    with TrialStore(p) as st:
        assert st.schema_version == SCHEMA_VERSION
        assert [v for v, _ in st.con.execute("SELECT * FROM schema_version")] == list(
            range(1, SCHEMA_VERSION + 1))
        tables = {r[0] for r in st.con.execute("SELECT name FROM sqlite_master "
                                               "WHERE type = 'table'")}
        assert {"sessions", "scheduled_trials", "demographics", "answers",
                "trial_metrics"} <= tables
        s = st.samples(1)
        assert list(s.columns) == list(FRAME_COLUMNS)
        # the v1 values are untouched; the new columns read their "not measured" defaults
        assert s["x_x"].tolist() == [r[3] for r in rows]
        assert s["contact"].tolist() == [0, 1, 0]
        assert (s[["fc_x", "fc_y", "fc_z", "tc_x", "tc_y", "tc_z"]] == 0.0).all().all()
        assert (s["delicate"] == 0).all() and (s["clutch"] == 0).all()
        assert (s["in_view"] == -1).all()
        tr = st.trial(1)
        assert tr["status"] == "completed" and tr["schedule_index"] is None
        assert tr["outcome"] is None  # no summary: the migration does not guess
        assert st.trial_metrics(1).empty and st.integrity_check() == "ok"
        # and the migrated store takes v2 data
        tid = st.begin_trial(meta())
        st.finish_trial(tid, random_buffer(4), trial_metrics={"path_l1": 1.5})
        assert st.trial_metrics(tid)["value"].tolist() == [1.5]
    with TrialStore(p, readonly=True) as ro:  # reopening: nothing left to migrate
        assert ro.schema_version == SCHEMA_VERSION


def test_a_failed_migration_leaves_the_v1_store_untouched(tmp_path: Path, monkeypatch):
    p = tmp_path / "v1.db"
    _v1_store(p)
    broken = schema_mod.MIGRATIONS[2] + "\nCREATE TABLE sessions (id INTEGER);\n"
    monkeypatch.setitem(schema_mod.MIGRATIONS, 2, broken)
    with pytest.raises(StoreError, match="already exists"):
        TrialStore(p)
    con = sqlite3.connect(p)
    assert con.execute("PRAGMA user_version").fetchone()[0] == 1
    names = {r[0] for r in con.execute("SELECT name FROM sqlite_master")}
    assert "sessions" not in names and "trial_metrics" not in names
    cols = [r[1] for r in con.execute("PRAGMA table_info(samples)")]
    assert "in_view" not in cols and len(cols) == 21  # trial_id + 20 v1 columns
    con.close()


def test_trial_metrics_are_stored_in_the_closing_transaction(store: TrialStore):
    tid = store.begin_trial(meta())
    store.finish_trial(tid, random_buffer(3), trial_metrics={"mean_jerk": 2.0,
                                                             "out_of_view_time": math.nan})
    wide = store.trial_metrics(wide=True)
    assert wide.loc[tid, "mean_jerk"] == 2.0 and math.isnan(wide.loc[tid, "out_of_view_time"])
    with pytest.raises(ConfigError, match="must be a number"):
        tid2 = store.begin_trial(meta())
        store.finish_trial(tid2, random_buffer(3), trial_metrics={"x": "big"})
    assert store.trial(tid2)["status"] == "running"  # nothing of it was written
    assert store.trial_metrics(tid2).empty and store.samples(tid2).empty


def test_buffer_optional_columns_default_and_reset_on_clear():
    buf = SampleBuffer(capacity=1)
    buf.append(0, 0.001, (0, 0, 0), (0, 0, 0), 0, f_contact=(1.0, 2.0, 3.0),
               tau_contact=(0.0, 0.1, 0.0), delicate=1, clutch=1, in_view=0)
    buf.append(1, 0.002, (0, 0, 0), (0, 0, 0), 0)  # grows; defaults for the new row
    v = buf.view()
    assert v["f_contact"].tolist() == [[1.0, 2.0, 3.0], [0.0, 0.0, 0.0]]
    assert v["in_view"].tolist() == [0, -1] and v["delicate"].tolist() == [1, 0]
    assert v["clutch"].tolist() == [1, 0] and v["tau_contact"][1].tolist() == [0, 0, 0]
    buf.clear()  # a reused buffer must not leak the old rows' contact values
    buf.append(0, 0.001, (0, 0, 0), (0, 0, 0), 0)
    v = buf.view()
    assert v["in_view"].tolist() == [-1] and v["f_contact"].tolist() == [[0.0, 0.0, 0.0]]
    assert v["delicate"].tolist() == [0] and v["clutch"].tolist() == [0]
    buf.set_column("in_view", 1)
    assert buf.view()["in_view"].tolist() == [1]
    with pytest.raises(ValueError, match="unknown sample column"):
        buf.set_column("colour", 1)
    # an older frame without the optional columns still builds a buffer
    old = buf.to_frame().drop(columns=["fc_x", "fc_y", "fc_z", "in_view"])
    assert SampleBuffer.from_columns(old).view()["in_view"].tolist() == [-1]


def test_a_locked_database_is_a_store_error(tmp_path: Path) -> None:
    db = tmp_path / "s.db"
    TrialStore(db).close()
    holder = sqlite3.connect(db, timeout=0.1)
    holder.execute("BEGIN IMMEDIATE")
    try:
        with TrialStore(db) as st:
            st.con.execute("PRAGMA busy_timeout = 100")
            with pytest.raises(StoreError, match="busy or locked"):
                st.add_subject("S01")
    finally:
        holder.rollback()
        holder.close()


def test_v2_point_metrics_gain_the_v4_path_columns_as_not_measured(tmp_path: Path):
    """A version-2 store's per-point rows keep their values; the v4 path-deviation and
    rate-independent e columns read NaN (not measured)."""
    p = tmp_path / "v2.db"
    con = sqlite3.connect(p, isolation_level=None)
    con.execute("BEGIN")
    for v in (1, 2):
        for stmt in schema_mod.split_sql(schema_mod.MIGRATIONS[v]):
            con.execute(stmt)
        con.execute("INSERT INTO schema_version VALUES (?, '2025-01-01T00:00:00+00:00')", (v,))
    con.execute(f"PRAGMA application_id = {APPLICATION_ID}")
    con.execute("PRAGMA user_version = 2")
    con.execute("INSERT INTO subjects VALUES ('S01', '2025-01-01', NULL)")
    con.execute("INSERT INTO trials (id, subject, task, status, started_at, n_samples) "
                "VALUES (1, 'S01', 'trajectory', 'completed', '2025-01-01', 0)")
    con.execute("INSERT INTO point_metrics VALUES (1, 0, 1, 1.5, 2.25, 1.5, 1.0, 1.0, 3)")
    con.execute("COMMIT")
    con.close()
    with TrialStore(p) as st:
        assert st.schema_version == SCHEMA_VERSION
        pm = st.point_metrics(1)
        assert list(pm.columns) == list(POINT_COLUMNS)
        assert pm.loc[0, "error_l1"] == 2.25 and pm.loc[0, "n_samples"] == 3
        for c in ("error_l1_mm_s", "path_dev_mean_mm", "path_dev_rms_mm", "path_dev_max_mm",
                  "path_dev_out_frac"):
            assert math.isnan(pm.loc[0, c]), c
