"""Trial outcomes, trials without a subject and the version-2 -> 3 migration
(vasim/study/store/: schema.py, lifecycle.py, vocabulary.py; issue #20 items 1, 2 and 6)."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as hst

import vasim.study.store.schema as schema_mod
from vasim.cli import main
from vasim.core.errors import ConfigError, StoreError
from vasim.records.samples import SampleBuffer
from vasim.records.trial_meta import SUBJECT_CODE_PATTERN, TrialMeta
from vasim.study.protocol import parse_protocol
from vasim.study.session import MAX_TIMED_OUT_REPEATS, run_session, start_session
from vasim.study.store import (
    APPLICATION_ID,
    SCHEMA_VERSION,
    TRIAL_OUTCOMES,
    TrialStore,
    validate_label,
)


def outcomes(trials) -> dict[int, str | None]:
    """trial id -> outcome, missing values as None (pandas may read them as NaN)."""
    return {int(t): (o if isinstance(o, str) else None)
            for t, o in zip(trials["id"], trials["outcome"], strict=True)}


def buffer(n: int = 3) -> SampleBuffer:
    buf = SampleBuffer(capacity=4)
    for k in range(n):
        buf.append(k, 0.001 * (k + 1), (0.001 * k, 0, 0), (0, 0, 0.01), 0)
    return buf


# ------------------------------------------------------------------- v2 -> v3 migration
V2_TRIALS = [
    # id, subject, status, summary (None: no summary), aborted event
    (1, "S01", "completed", {"completed": True, "points_reached": 30, "n_points": 30}, False),
    (2, "S01", "completed", {"completed": False, "points_reached": 3, "n_points": 30}, False),
    (3, "S02", "interrupted", {"completed": False, "points_reached": 1}, False),
    (4, "S02", "running", None, False),
    (5, "S02", "completed", {"completed": False, "points_reached": 2}, True),
    (6, "S00", "completed", None, False),
]
EXPECTED_OUTCOMES = {1: "reached_all", 2: "timed_out", 3: "interrupted", 4: None,
                     5: "failed", 6: None}


def v2_store(path: Path) -> None:
    """A version-2 store built with the frozen DDL of versions 1 and 2 (as vasim wrote it
    before version 3): the trials of ``V2_TRIALS`` (pid NULL: 'running' is never recovered),
    3 samples and 2 point rows each, a session whose scheduled trial 0 links trial 1."""
    con = sqlite3.connect(path, isolation_level=None)
    con.execute("PRAGMA journal_mode = WAL")
    con.execute("BEGIN")
    for v in (1, 2):
        for stmt in schema_mod.split_sql(schema_mod.MIGRATIONS[v]):
            con.execute(stmt)
        con.execute("INSERT INTO schema_version VALUES (?, '2025-01-01T00:00:00+00:00')", (v,))
    con.execute(f"PRAGMA application_id = {APPLICATION_ID}")
    con.execute("PRAGMA user_version = 2")
    for code in ("S00", "S01", "S02"):
        con.execute("INSERT INTO subjects VALUES (?, '2025-01-01', NULL)", (code,))
    con.execute("INSERT INTO sessions (id, subject, protocol, protocol_toml, protocol_sha256, "
                "seed, status, created_at, operator, n_trials) VALUES (1, 'S01', 'p', 'x', "
                "'0', 1, 'running', '2025-01-01', 'scripted', 1)")
    con.execute("INSERT INTO scheduled_trials (session_id, trial_index, block, block_index, "
                "trial_in_block, condition, schema, task, variant, probe, repetition, "
                "trial_id, attempts) VALUES (1, 0, 'b', 0, 0, 'none', 'none', 'trajectory', "
                "0, 1, 0, 1, 1)")
    for tid, subject, status, summary, aborted in V2_TRIALS:
        con.execute("INSERT INTO trials (id, subject, task, status, started_at, n_samples, "
                    "summary_json, session_id, schedule_index, attempt) VALUES "
                    "(?, ?, 'trajectory', ?, '2025-01-01', 3, ?, ?, ?, ?)",
                    (tid, subject, status, None if summary is None else json.dumps(summary),
                     1 if tid == 1 else None, 0 if tid == 1 else None, 1 if tid == 1 else None))
        con.executemany("INSERT INTO samples (trial_id, k, t) VALUES (?, ?, ?)",
                        [(tid, k, 0.001 * k) for k in range(3)])
        con.executemany("INSERT INTO point_metrics (trial_id, point, reached, n_samples) "
                        "VALUES (?, ?, 1, 1)", [(tid, p) for p in range(2)])
        if aborted:
            con.execute("INSERT INTO events (trial_id, kind, detail, created_at) VALUES "
                        "(?, 'aborted', 'repeated safety stops', '2025-01-01')", (tid,))
    con.execute("COMMIT")
    con.close()


def test_v2_store_is_migrated_to_v3_with_outcomes_from_the_summaries(tmp_path: Path):
    p = tmp_path / "v2.db"
    v2_store(p)
    with TrialStore(p) as st:
        assert st.schema_version == SCHEMA_VERSION >= 3
        assert [v for v, _ in st.con.execute("SELECT * FROM schema_version")] == list(
            range(1, SCHEMA_VERSION + 1))
        trials = st.trials()
        assert outcomes(trials) == EXPECTED_OUTCOMES
        assert trials["label"].isna().all()
        assert trials["subject"].tolist() == [t[1] for t in V2_TRIALS]  # codes kept as stored
        # the rebuild cascaded nothing: every sample, point and the schedule link survive
        assert st.con.execute("SELECT sum(n) FROM sample_columns WHERE name = 'k'"
                              ).fetchone()[0] == 3 * 6
        assert st.con.execute("SELECT count(*) FROM point_metrics").fetchone()[0] == 2 * 6
        assert st.schedule(1)["trial_id"].tolist() == [1]
        assert st.integrity_check() == "ok"
        assert st.con.execute("PRAGMA foreign_key_check").fetchall() == []
        assert st.con.execute("PRAGMA foreign_keys").fetchone()[0] == 1  # back on
        idx = {r[1] for r in st.con.execute("PRAGMA index_list(trials)")}
        assert {"trials_subject", "trials_status", "trials_session", "trials_outcome"} <= idx
        # the migrated table takes a trial without a subject, and still checks foreign keys
        tid = st.begin_trial(TrialMeta(subject=None, task="trajectory"))
        assert st.trial(tid)["subject"] is None
        with pytest.raises(sqlite3.IntegrityError):
            st.con.execute("INSERT INTO sample_columns (trial_id, name, dtype, n, codec, "
                           "data) VALUES (999, 'k', '<i8', 0, 'x', x'')")


def test_a_read_only_open_reads_a_v2_store_without_migrating_it(tmp_path: Path):
    p = tmp_path / "v2.db"
    v2_store(p)
    with TrialStore(p, readonly=True) as ro:
        assert ro.schema_version == 2
        assert outcomes(ro.trials()) == EXPECTED_OUTCOMES
        assert ro.trial(2)["outcome"] == "timed_out" and ro.trial(2)["label"] is None
        assert ro.trials(outcome="failed")["id"].tolist() == [5]
    con = sqlite3.connect(p)
    assert con.execute("PRAGMA user_version").fetchone()[0] == 2  # untouched
    assert "outcome" not in [r[1] for r in con.execute("PRAGMA table_info(trials)")]
    con.close()


def test_a_failed_v3_migration_leaves_the_v2_store_untouched(tmp_path: Path, monkeypatch):
    p = tmp_path / "v2.db"
    v2_store(p)
    broken = schema_mod.MIGRATIONS[3] + "\nCREATE TABLE trials (id INTEGER);\n"
    monkeypatch.setitem(schema_mod.MIGRATIONS, 3, broken)
    with pytest.raises(StoreError, match="already exists"):
        TrialStore(p)
    con = sqlite3.connect(p)
    assert con.execute("PRAGMA user_version").fetchone()[0] == 2
    cols = [r[1] for r in con.execute("PRAGMA table_info(trials)")]
    assert "outcome" not in cols and "trials_v3" not in {
        r[0] for r in con.execute("SELECT name FROM sqlite_master")}
    assert con.execute("SELECT count(*) FROM samples").fetchone()[0] == 18
    con.close()


# ------------------------------------------------------------------------ outcomes
@pytest.fixture
def store(tmp_path: Path):
    with TrialStore(tmp_path / "s.db") as st:
        yield st


@pytest.mark.parametrize(("summary", "outcome"), [
    ({"outcome": "timed_out", "completed": False}, "timed_out"),
    ({"outcome": "reached_all", "completed": True}, "reached_all"),
    ({"outcome": "stopped", "completed": False}, "stopped"),
    ({"completed": True}, "reached_all"),      # a summary of an older runner
    ({"completed": False}, "timed_out"),
    ({"points_reached": 2}, None),             # nothing says how it ended
    (None, None),
])
def test_finish_stores_the_outcome_the_summary_states(store, summary, outcome):
    tid = store.begin_trial(TrialMeta(subject="S01", task="trajectory"))
    store.finish_trial(tid, buffer(), summary=summary)
    row = store.trial(tid)
    assert (row["status"], row["outcome"]) == ("completed", outcome)


def test_an_unknown_outcome_is_refused_and_nothing_is_written(store):
    tid = store.begin_trial(TrialMeta(subject="S01", task="trajectory"))
    with pytest.raises(ConfigError, match="got 'done', expected one of 'reached_all'") as e:
        store.finish_trial(tid, buffer(), summary={"outcome": "done"})
    assert e.value.field == "summary.outcome"
    assert store.trial(tid)["status"] == "running" and store.samples(tid).empty


@pytest.mark.parametrize(("reason", "outcome"), [
    ("KeyboardInterrupt: ", "stopped"),
    ("stopped by the experimenter", "stopped"),   # the viewer's Stop
    ("schema changed", "stopped"),                # the viewer closing it for a change
    ("DeviceError: the device went away", "failed"),
    ("the trial loop failed: RuntimeError: boom", "failed"),
    ("", "failed"),
])
def test_an_early_close_reads_its_outcome_from_the_reason(store, reason, outcome):
    tid = store.begin_trial(TrialMeta(subject="S01", task="trajectory"))
    assert store.mark_interrupted(tid, reason=reason, summary={"outcome": "timed_out"})
    row = store.trial(tid)
    assert (row["status"], row["outcome"]) == ("interrupted", outcome)
    assert row["summary"]["outcome"] == outcome  # the kept summary agrees with the row


def test_keep_interrupted_takes_an_explicit_outcome(store):
    class Partial:
        samples, metrics, summary, events, trial_metrics = buffer(2), None, {}, [], None

    tid = store.begin_trial(TrialMeta(subject="S01", task="trajectory"))
    store.keep_interrupted(tid, "RuntimeError: x", lambda: Partial(), outcome="stopped")
    row = store.trial(tid)
    assert row["outcome"] == "stopped" and row["n_samples"] == 2
    tid2 = store.begin_trial(TrialMeta(subject="S01", task="trajectory"))
    with pytest.raises(ConfigError, match="interrupted trial's outcome"):
        store.mark_interrupted(tid2, outcome="reached_all")


def test_a_dead_writers_trial_is_recovered_with_outcome_interrupted(tmp_path: Path):
    import subprocess
    import sys

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    p = tmp_path / "s.db"
    with TrialStore(p) as st:
        tid = st.begin_trial(TrialMeta(subject="S01", task="trajectory", pid=dead.pid))
    with TrialStore(p) as st:
        assert st.recovered == [tid]
        assert (st.trial(tid)["status"], st.trial(tid)["outcome"]) == ("interrupted",
                                                                        "interrupted")


# --------------------------------------------------------------- no invented subject
def test_a_trial_without_a_subject_stores_null_and_registers_no_subject(store):
    tid = store.begin_trial(TrialMeta(subject=None, task="trajectory"))
    store.finish_trial(tid, buffer(), summary={"outcome": "reached_all"})
    raw = store.con.execute("SELECT subject IS NULL, label FROM trials WHERE id = ?",
                            (tid,)).fetchone()
    assert raw == (1, None)
    assert store.subjects().empty


def test_a_free_practice_label_cannot_read_as_a_subject_code(store):
    tid = store.begin_trial(TrialMeta(subject=None, task="trajectory", label="free: warm-up"))
    assert store.trial(tid)["label"] == "free: warm-up" and store.trial(tid)["subject"] is None
    for bad in ("S00", "warmup", "", "x" * 65):
        with pytest.raises(ConfigError) as e:
            TrialMeta(subject=None, task="trajectory", label=bad)
        assert e.value.field == "label"
    # the table's CHECK says the same, for any other writer
    with pytest.raises(sqlite3.IntegrityError, match="CHECK"):
        store.con.execute("UPDATE trials SET label = 'S00' WHERE id = ?", (tid,))


@given(hst.text(min_size=1, max_size=64))
def test_a_label_is_accepted_exactly_when_it_is_not_a_subject_code(label: str):
    import re

    is_code = re.fullmatch(SUBJECT_CODE_PATTERN, label) is not None
    if is_code:
        with pytest.raises(ConfigError):
            validate_label(label)
    else:
        assert validate_label(label) == label


def test_outcomes_are_the_documented_five():
    assert TRIAL_OUTCOMES == ("reached_all", "timed_out", "stopped", "interrupted", "failed")


# ------------------------------------------------------------------------- the CLI
def test_a_timed_out_cli_trial_is_stored_timed_out_with_its_points(tmp_path: Path, capsys):
    db = tmp_path / "t.sqlite"
    assert main(["trial", "--schema", "ff", "--max-time", "2", "--scene", "none",
                 "--db", str(db)]) == 0
    out = capsys.readouterr().out
    with TrialStore(db, readonly=True) as st:
        (row,) = st.trials().to_dict("records")
        tr = st.trial(int(row["id"]))
        reached = int(st.point_metrics(int(row["id"]))["reached"].sum())
        null_subject = st.con.execute("SELECT subject IS NULL FROM trials").fetchone()[0]
    assert (tr["status"], tr["outcome"]) == ("completed", "timed_out")
    assert tr["summary"]["outcome"] == "timed_out"
    assert tr["summary"]["points_reached"] == reached and 0 < reached < 30
    assert tr["summary"]["n_points"] == 30 and tr["summary"]["sim_time"] == pytest.approx(2.0)
    assert null_subject == 1  # no --subject: NULL, not an invented 'S00'
    assert f"timed out after 2.0 s with {reached} of 30 points" in out


def test_a_cli_trial_that_reaches_every_point_says_so(tmp_path: Path, capsys):
    db = tmp_path / "t.sqlite"
    assert main(["trial", "--schema", "ff", "--scene", "none", "--skill", "expert",
                 "--subject", "S07", "--db", str(db)]) == 0
    out = capsys.readouterr().out
    with TrialStore(db, readonly=True) as st:
        tr = st.trial(1)
    assert (tr["outcome"], tr["subject"]) == ("reached_all", "S07")
    assert tr["summary"]["completed"] is True and tr["summary"]["points_reached"] == 30
    assert f"reached all 30 points in {tr['summary']['sim_time']:.2f} s" in out


def test_a_cli_label_that_reads_as_a_subject_code_is_one_line_error(tmp_path: Path, capsys):
    code = main(["trial", "--schema", "ff", "--max-time", "0.1", "--scene", "none",
                 "--label", "S00", "--db", str(tmp_path / "t.sqlite")])
    err = capsys.readouterr().err
    assert code == 2 and "'S00' could be mistaken for a subject code" in err
    assert len(err.strip().splitlines()) == 1


# ------------------------------------------------------------------ repeat_timed_out
REPEAT = """
name = "repeat"
description = "one trial that always times out"
task = "trajectory"
max_trial_time_s = 0.05
repeat_timed_out = {flag}
[[blocks]]
name = "b"
condition = "none"
probe = true
counterbalance = false
"""


@pytest.mark.parametrize("flag", [True, False])
def test_a_protocol_that_repeats_timed_out_trials_runs_them_again(tmp_path: Path, flag: bool):
    protocol = parse_protocol(REPEAT.format(flag=str(flag).lower()))
    assert protocol.repeat_timed_out is flag
    with TrialStore(tmp_path / "s.db") as st:
        sid = start_session(st, protocol, "S01", seed=3)
        run_session(st, sid, progress=False)
        trials = st.trials()
        sched = st.schedule(sid)
        assert st.session(sid)["status"] == "completed"
        n = 1 + MAX_TIMED_OUT_REPEATS if flag else 1
        assert trials["outcome"].tolist() == ["timed_out"] * n
        assert trials["attempt"].tolist() == list(range(1, n + 1))
        assert int(sched["attempts"].iloc[0]) == n
        assert int(sched["trial_id"].iloc[0]) == int(trials["id"].iloc[-1])  # the last counts
        repeated = [int(t) for t in trials["id"] if "repeated" in set(st.events(int(t))["kind"])]
        assert repeated == [int(t) for t in trials["id"].iloc[:-1]]
        assert trials["seed"].nunique() == n  # a repeat is a new attempt, not a copy


def test_repeat_timed_out_must_be_a_boolean():
    with pytest.raises(ConfigError, match="true or false") as e:
        parse_protocol(REPEAT.format(flag='"yes"'))
    assert "repeat_timed_out" in str(e.value)
