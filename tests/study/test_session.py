"""Sessions (vasim/study/session.py, store schema v2): stored schedules replayed on resume,
a real SIGKILL mid-session then resume, questionnaires, and the `vasim study` errors."""

from __future__ import annotations

import hashlib
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from vasim.cli import main
from vasim.core.errors import InputError, StoreError
from vasim.operator.learning import trial_adjustment
from vasim.operator.profile import OperatorProfile
from vasim.records.samples import FRAME_COLUMNS
from vasim.study.protocol import generate_schedule, load_protocol
from vasim.study.session import (
    SessionSettings,
    find_session,
    load_session,
    record_answers,
    run_session,
    start_session,
    trial_seed,
)
from vasim.study.store import TrialStore

TINY = """
name = "tiny"
description = "a five-trial test protocol"
task = "trajectory"
max_trial_time_s = 0.3
[randomisation]
block_order = "random"
variant_order = "random"
[[blocks]]
name = "baseline"
condition = "none"
probe = true
counterbalance = false
[[blocks]]
name = "vg"
condition = "vg"
variants = [1]
probes_after = 1
[[blocks]]
name = "ff"
condition = "ff"
variants = [2]
probes_after = 1
[questionnaires.pre]
demographics = true
[[questionnaires.post.items]]
id = "best"
type = "condition_choice"
select = "best"
prompt = "Which fixture helped most?"
[[questionnaires.post.items]]
id = "note"
type = "text"
prompt = "Comments"
required = false
"""


@pytest.fixture
def tiny(tmp_path: Path) -> Path:
    p = tmp_path / "tiny.toml"
    p.write_text(TINY)
    return p


def _sha(df: pd.DataFrame) -> str:
    block = np.ascontiguousarray(df[list(FRAME_COLUMNS)].to_numpy(dtype=np.float64))
    return hashlib.sha256(block.tobytes()).hexdigest()


def _by_index(store: TrialStore, session_id: int) -> dict[int, str]:
    """schedule index -> sha of the samples of its completed trial."""
    sched = store.schedule(session_id)
    return {int(r.trial_index): _sha(store.samples(int(r.trial_id)))
            for r in sched.itertuples() if not pd.isna(r.trial_id)}


# ------------------------------------------------------------------------- sessions
def test_session_runs_its_stored_schedule(tmp_path: Path, tiny: Path) -> None:
    p = load_protocol(tiny)
    with TrialStore(tmp_path / "s.db") as st:
        sid = start_session(st, p, "S01", seed=11, settings=SessionSettings(skill="expert"))
        sched = st.schedule(sid)
        expected = generate_schedule(p, 11)
        assert sched["condition"].tolist() == [t.condition for t in expected]
        assert sched["variant"].tolist() == [t.variant for t in expected]
        assert sched["probe_index"].tolist() == [t.probe_index or pd.NA for t in expected]
        assert st.session(sid)["protocol_toml"] == TINY and st.session(sid)["seed"] == 11
        assert run_session(st, sid, progress=False) == 5
        assert st.session(sid)["status"] == "completed"
        trials = st.trials().set_index("schedule_index")
        for t in expected:
            tr = trials.loc[t.index]
            assert (tr["status"], tr["attempt"], tr["session_id"]) == ("completed", 1, sid)
            assert (tr["schema"], tr["variant"]) == (t.schema, t.variant)
            cfg = st.trial(int(tr["id"]))["config"]
            # practice: the effective practice of the earlier trials' conditions (FF and Mag
            # trials count more, vasim.operator.learning); seed from (session seed, index)
            adj = trial_adjustment([e.condition for e in expected[:t.index]], t.condition)
            assert cfg["practice"] == round(adj.practice)
            expert = OperatorProfile.expert()   # the fixture's effect on the learnable noise
            assert cfg["profile"]["noise"] == pytest.approx(expert.noise * adj.noise_factor)
            assert cfg["profile"]["fitts_b"] == pytest.approx(expert.fitts_b * adj.time_factor)
            assert cfg["seed"] == trial_seed(11, t.index)
            assert cfg["max_time"] == 0.3 and cfg["reach_radius"] == 0.005
            assert cfg["profile"]["skill"] == pytest.approx(0.9)
        assert st.schedule(sid)["trial_id"].tolist() == trials.sort_index()["id"].tolist()
        # every completed trial has its trial metrics
        assert set(st.trial_metrics()["trial_id"]) == set(trials["id"])
        with pytest.raises(StoreError, match="'completed'"):
            run_session(st, sid, progress=False)


def test_resume_replays_the_stored_schedule_after_the_file_changes(
        tmp_path: Path, tiny: Path) -> None:
    with TrialStore(tmp_path / "s.db") as st:
        sid = start_session(st, load_protocol(tiny), "S02", seed=5)
        stored = st.schedule(sid)
        assert run_session(st, sid, progress=False, max_trials=2) == 2
    # The protocol file is edited after the session started: other conditions, variants,
    # time limit. The session must keep what it stored.
    tiny.write_text(TINY.replace('condition = "vg"', 'condition = "mag"')
                    .replace("variants = [1]", "variants = [5]")
                    .replace("max_trial_time_s = 0.3", "max_trial_time_s = 0.6"))
    assert load_protocol(tiny).blocks[1].condition == "mag"
    assert main(["study", "resume", "--db", str(tmp_path / "s.db"), "--subject", "S02"]) == 0
    with TrialStore(tmp_path / "s.db") as st:
        after = st.schedule(sid)
        pd.testing.assert_frame_equal(after.drop(columns=["trial_id", "attempts"]),
                                      stored.drop(columns=["trial_id", "attempts"]))
        trials = st.trials().set_index("schedule_index").sort_index()
        assert trials["schema"].tolist() == stored["schema"].tolist()
        assert trials["variant"].tolist() == stored["variant"].tolist()
        assert "mag" not in set(trials["schema"])
        assert (trials["n_samples"] == 300).all()  # 0.3 s at 1 kHz: the stored limit
        assert st.session(sid)["status"] == "completed"


def test_scheduled_trials_cannot_be_run_twice(tmp_path: Path, tiny: Path) -> None:
    from vasim.records.trial_meta import TrialMeta

    with TrialStore(tmp_path / "s.db") as st:
        sid = start_session(st, load_protocol(tiny), "S03", seed=1)
        run_session(st, sid, progress=False, max_trials=1)
        meta = {"subject": "S03", "task": "trajectory", "session_id": sid}
        with pytest.raises(StoreError, match="already completed"):
            st.begin_trial(TrialMeta(**meta, schedule_index=0))
        tid = st.begin_trial(TrialMeta(**meta, schedule_index=1))
        with pytest.raises(StoreError, match="being run"):
            st.begin_trial(TrialMeta(**meta, schedule_index=1))
        with pytest.raises(StoreError, match="being run"):
            run_session(st, sid, progress=False)
        st.mark_interrupted(tid, reason="test")
        with pytest.raises(StoreError, match="no scheduled trial 99"):
            st.begin_trial(TrialMeta(**meta, schedule_index=99))
        with pytest.raises(StoreError, match="belongs to subject 'S03'"):
            st.begin_trial(TrialMeta(**{**meta, "subject": "S04"}, schedule_index=2))
        with pytest.raises(StoreError, match="still has 4 scheduled"):
            st.set_session_status(sid, "completed")
        with pytest.raises(StoreError, match="already has a running session"):
            start_session(st, load_protocol(tiny), "S03", seed=2)
        st.set_session_status(sid, "aborted", notes="subject left")
        with pytest.raises(StoreError, match="'aborted'"):
            st.begin_trial(TrialMeta(**meta, schedule_index=2))
        assert st.schedule(sid)["attempts"].tolist()[:2] == [1, 1]
        # an aborted session frees the subject for a new one
        assert start_session(st, load_protocol(tiny), "S03", seed=2) == sid + 1


# ------------------------------------------------------------------- SIGKILL + resume
def test_sigkill_mid_session_then_resume(tmp_path: Path, tiny: Path) -> None:
    # A reference run of the same session (same seed) in another database: the resumed
    # session must end with exactly the same trials, whatever the crash interrupted.
    ref_db, db = tmp_path / "ref.db", tmp_path / "s.db"
    max_time = "6"
    with TrialStore(ref_db) as st:
        sid = start_session(st, load_protocol(tiny), "K01", seed=11,
                            settings=SessionSettings(max_trial_time=6.0))
        run_session(st, sid, progress=False)
        reference = _by_index(st, sid)
    child = subprocess.Popen(
        [sys.executable, "-m", "vasim", "study", "run", "--protocol", str(tiny),
         "--subject", "K01", "--db", str(db), "--seed", "11", "--max-time", max_time],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline and child.poll() is None:
            if db.exists():
                con = sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=5)
                try:
                    n_done, n_run = con.execute(
                        "SELECT sum(status = 'completed'), sum(status = 'running') "
                        "FROM trials").fetchone()
                except sqlite3.OperationalError:  # schema not created yet
                    n_done = n_run = None
                con.close()
                if (n_done or 0) >= 2 and (n_run or 0) == 1:
                    break
            time.sleep(0.01)
        else:
            pytest.fail(f"the child never reached its third trial: {child.stderr.read()}")
        os.kill(child.pid, signal.SIGKILL)
    finally:
        child.wait(timeout=30)
    assert child.returncode == -signal.SIGKILL
    with TrialStore(db, readonly=True) as ro:
        sid = int(ro.sessions()["id"].iloc[0])
        before = _by_index(ro, sid)
        killed = ro.trials("running")
    assert len(before) >= 2 and len(killed) == 1
    killed_index = int(killed["schedule_index"].iloc[0])

    assert main(["study", "resume", "--db", str(db), "--subject", "K01"]) == 0

    with TrialStore(db) as st:
        assert st.integrity_check() == "ok"
        assert st.session(sid)["status"] == "completed"
        trials = st.trials()
        done = trials[trials["status"] == "completed"]
        # every scheduled index ends with exactly one completed trial
        assert sorted(done["schedule_index"].tolist()) == list(range(5))
        kt = trials[trials["id"] == int(killed["id"].iloc[0])].iloc[0]
        assert kt["status"] == "interrupted" and kt["attempt"] == 1
        rerun = done[done["schedule_index"] == killed_index].iloc[0]
        assert rerun["attempt"] == 2 and rerun["id"] > kt["id"]
        assert st.schedule(sid)["attempts"].tolist()[killed_index] == 2
        after = _by_index(st, sid)
    # the trials completed before the kill are byte-identical after the resume ...
    assert {i: after[i] for i in before} == before
    # ... and the whole session equals an uninterrupted run of it
    assert after == reference


# ------------------------------------------------------------------- questionnaires
def test_questionnaires_are_stored_tidy_and_once(tmp_path: Path, tiny: Path) -> None:
    with TrialStore(tmp_path / "s.db") as st:
        sid = start_session(st, load_protocol(tiny), "Q01", seed=3)
        pre = {"group": "resident", "specialisation": "general_surgery",
               "laparoscopy_experience": "1-10", "simulator_experience": "regular",
               "robotic_experience": "none"}
        assert record_answers(st, sid, "pre", pre) == 5
        note = "Zoë's note: <b>bold</b>, \"quoted\"\nsecond line"
        assert record_answers(st, sid, "post", {"best": "vg", "note": note}) == 2
        a = st.answers(sid)
        assert a.loc[a["item"] == "note", "value"].item() == note  # stored as given
        d = st.demographics()
        assert d[["subject", "subject_group", "laparoscopy_experience", "session_id"]
                 ].values.tolist() == [["Q01", "resident", "1-10", sid]]
        with pytest.raises(StoreError, match="already answered"):
            record_answers(st, sid, "post", {"best": "ff"})
        with pytest.raises(InputError, match=r"post\.best"):   # input data (issue #29)
            record_answers(st, sid + 0, "post", {"best": "none"})
        # the SQL CHECK holds even if someone bypasses the dataclass
        with pytest.raises(sqlite3.IntegrityError):
            st.con.execute("UPDATE demographics SET subject_group = 'nurse'")


def test_cli_answers_file_and_run(tmp_path: Path, tiny: Path, capsys) -> None:
    answers = tmp_path / "answers.toml"
    answers.write_text('[pre]\ngroup = "surgeon"\nspecialisation = "urology"\n'
                       'laparoscopy_experience = ">200"\nsimulator_experience = "none"\n'
                       'robotic_experience = "performed"\n[post]\nbest = "ff"\n')
    db = tmp_path / "s.db"
    assert main(["study", "run", "--protocol", str(tiny), "--subject", "C01", "--db", str(db),
                 "--seed", "4", "--answers", str(answers)]) == 0
    out = capsys.readouterr().out
    assert "5/5 trials completed" in out and "pre (5 answers)" in out
    assert "post (1 answers)" in out
    assert main(["study", "list", "--db", str(db)]) == 0
    assert "C01" in capsys.readouterr().out
    with TrialStore(db) as st:
        assert find_session(st, session_id=1) == 1
        assert load_session(st, 1).settings.operator == "scripted"


# ---------------------------------------------------------------------- CLI errors
@pytest.mark.parametrize(("argv", "needle"), [
    (["study", "run", "--protocol", "nope", "--subject", "S01"], "unknown protocol 'nope'"),
    (["study", "run", "--protocol", "mrcp_vs_stdt", "--subject", "S01", "--max-time", "-1"],
     "argument --max-time: got -1.0, expected a finite number in (0, 86400] s"),
    (["study", "run", "--protocol", "vf_learning_curve", "--subject", "S01", "--operator",
      "browser"], "vasim serve"),
    (["study", "run", "--protocol", "vf_learning_curve", "--subject", "Jane Doe"],
     "Jane Doe"),
    (["study", "resume", "--subject", "S77"], "no session for subject 'S77'"),
    (["study", "simulate", "--protocol", "mrcp_vs_stdt", "--subjects", "2", "--workers", "-1"],
     "argument --workers: got -1, expected an integer in [0, "),
    (["study", "simulate", "--protocol", "mrcp_vs_stdt", "--subjects", "1000000000"],
     "argument --subjects: got 1000000000, expected an integer in [1, 10000]"),
    (["study", "simulate", "--protocol", "mrcp_vs_stdt", "--workers", "1000"],
     "argument --workers: got 1000, expected an integer in [0, "),
    (["study", "run", "--protocol", "vf_learning_curve", "--subject", "A" * 100_000],
     "(100,000 characters), expected a subject code"),
])
def test_cli_errors_are_one_line_exit_2(tmp_path: Path, capsys, argv, needle) -> None:
    db = tmp_path / "s.db"
    TrialStore(db).close()
    assert main([*argv, "--db", str(db)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err and "Traceback" not in err
    with TrialStore(db) as st:  # nothing was started
        assert st.sessions().empty and st.trials().empty


def test_cli_resume_records_only_what_is_missing(tmp_path: Path, tiny: Path, capsys) -> None:
    """`run --answers` stored [pre]; the session was interrupted; `resume --answers` with the
    same file records [post] instead of failing on the already answered [pre]."""
    answers = tmp_path / "answers.toml"
    answers.write_text('[pre]\ngroup = "surgeon"\nspecialisation = "urology"\n'
                       'laparoscopy_experience = ">200"\nsimulator_experience = "none"\n'
                       'robotic_experience = "performed"\n[post]\nbest = "ff"\n')
    db = tmp_path / "s.db"
    with TrialStore(db) as st:
        sid = start_session(st, load_protocol(tiny), "C02", seed=4)
        record_answers(st, sid, "pre", {"group": "surgeon", "specialisation": "urology",
                                         "laparoscopy_experience": ">200",
                                         "simulator_experience": "none",
                                         "robotic_experience": "performed"})
    assert main(["study", "resume", "--db", str(db), "--subject", "C02", "--answers",
                 str(answers)]) == 0
    out = capsys.readouterr().out
    assert "post (1 answers)" in out and "pre (" not in out
    with TrialStore(db) as st:
        assert sorted(set(st.answers(sid)["questionnaire"])) == ["post", "pre"]


def test_cli_run_checks_the_answers_file_before_starting(tmp_path: Path, tiny: Path,
                                                         capsys) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[pre]\ngroup = "surgen"\n')
    db = tmp_path / "s.db"
    assert main(["study", "run", "--protocol", str(tiny), "--subject", "C03", "--db", str(db),
                 "--answers", str(bad)]) == 2
    assert "bad.toml" in capsys.readouterr().err
    with TrialStore(db) as st:
        assert st.sessions().empty                  # no empty running session left behind


def test_a_failing_result_still_closes_the_trial(tmp_path: Path, monkeypatch) -> None:
    """The partial result itself fails (a metric error): the trial is still marked
    interrupted, with its raw samples, not left 'running'."""
    import vasim.trials.vf as trial_mod
    from vasim.trials.registry import run_trial

    def boom(*args: object, **kwargs: object) -> None:
        raise ValueError("metric failure")

    monkeypatch.setattr(trial_mod, "trial_metrics", boom)
    with TrialStore(tmp_path / "s.db") as st:
        with pytest.raises(ValueError, match="metric failure"):
            run_trial(trial_mod.TrialConfig(schema="none", scene="none", seed=1, max_time=1.0),
                      st)
        rows = st.trials()
        assert rows["status"].tolist() == ["interrupted"]
        assert int(rows["n_samples"].iloc[0]) > 0


def test_cli_answer_refuses_a_questionnaire_already_answered(tmp_path: Path, tiny: Path,
                                                             capsys) -> None:
    db = tmp_path / "s.db"
    with TrialStore(db) as st:
        sid = start_session(st, load_protocol(tiny), "C04", seed=4)
    post = tmp_path / "post.toml"
    post.write_text('[post]\nbest = "ff"\n')
    argv = ["study", "answer", "--db", str(db), "--session", str(sid), "--file", str(post)]
    assert main(argv) == 0
    capsys.readouterr()
    assert main(argv) == 2                        # a second answer: not silently skipped
    assert "already answered" in capsys.readouterr().err
