"""Proficiency gates (vasim/study/gates.py): the benchmark and the decisions as pure
functions (analytic values, invariants), and a simulated gated cohort whose stored decisions
are checked against an independent recomputation from the stored trials."""

from __future__ import annotations

import json
import math
import statistics
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.core.errors import ConfigError
from vasim.study.cohort import CohortPlan, CohortRun, simulate_cohort
from vasim.study.gates import (
    HIGHER_IS_BETTER,
    apply_gates,
    decide,
    expert_benchmark,
    gate_records,
    judge,
)
from vasim.study.protocol import parse_protocol
from vasim.study.session import load_session, run_session, start_session
from vasim.study.store import TrialStore


# ------------------------------------------------------------------------------ pure
def test_benchmark_is_mean_plus_k_sd_with_the_sample_sd() -> None:
    b = expert_benchmark({"path_dev_mean_mm": [2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0],
                          "points_reached": [28.0, 30.0, float("nan")]},
                         ("path_dev_mean_mm", "points_reached"), k=1.5)
    p = b["path_dev_mean_mm"]
    sd = math.sqrt(32.0 / 7.0)            # sum of squares 32 around the mean 5, ddof 1
    assert (p.mean, p.n, p.higher_is_better) == (5.0, 8, False)
    assert p.sd == pytest.approx(sd) and p.limit == pytest.approx(5.0 + 1.5 * sd)
    r = b["points_reached"]              # the NaN is left out; higher is better: mean - k SD
    assert (r.mean, r.n, r.higher_is_better) == (29.0, 2, True)
    assert r.sd == pytest.approx(math.sqrt(2.0)) and r.limit == pytest.approx(
        29.0 - 1.5 * math.sqrt(2.0))
    assert judge({"path_dev_mean_mm": 5.0 + 1.5 * sd, "points_reached": 27.0}, b) == {
        "path_dev_mean_mm": True, "points_reached": True}      # the limit itself passes
    assert judge({"path_dev_mean_mm": 8.5, "points_reached": 26.0}, b) == {
        "path_dev_mean_mm": False, "points_reached": False}
    assert judge({"points_reached": 30.0}, b)["path_dev_mean_mm"] is False   # missing fails
    assert judge({"path_dev_mean_mm": float("nan"), "points_reached": 30.0}, b)[
        "path_dev_mean_mm"] is False


def test_a_benchmark_needs_two_expert_values() -> None:
    with pytest.raises(ConfigError,
                       match=r"got 1, expected at least 2 finite expert values of 'duration'"):
        expert_benchmark({"duration": [10.0, float("nan")]}, ("duration",), k=1.0)


@pytest.mark.parametrize(("passes", "n_sched", "action", "streak"), [
    ([True], 3, "continue", 1),                       # scheduled trials remain
    ([True, True], 3, "continue", 2),                 # a pass early does not end the minimum
    ([False, True, True], 3, "passed", 2),
    ([True, True, False], 3, "extend", 0),
    ([True, False, True], 3, "extend", 1),
    ([False] * 6, 6, "cap", 0),
    ([False] * 5 + [True], 6, "cap", 1),
    ([False] * 4 + [True, True], 6, "passed", 2),     # passing on the cap's last trial
])
def test_decisions(passes, n_sched, action, streak) -> None:
    d = decide(passes, n_scheduled=n_sched, consecutive=2, max_trials=6)
    assert (d.action, d.streak, d.n_trials) == (action, streak, len(passes))


@settings(max_examples=300, deadline=None)
@given(st.lists(st.booleans(), min_size=1, max_size=30), st.integers(1, 5),
       st.integers(1, 30))
def test_decision_invariants(passes, consecutive, n_sched) -> None:
    cap = 30
    n_sched = min(n_sched, cap)
    d = decide(passes, n_scheduled=n_sched, consecutive=consecutive, max_trials=cap)
    tail = len(passes) - len(("".join("1" if p else "0" for p in passes)).rstrip("1"))
    assert d.streak == tail
    if d.action == "passed":
        assert d.streak >= consecutive and len(passes) >= n_sched
    if d.action == "extend":
        assert d.streak < consecutive and n_sched <= len(passes) < cap
    if d.action == "continue":
        assert len(passes) < n_sched


def test_direction_of_the_higher_is_better_metrics() -> None:
    assert {"points_reached", "completed", "log_dimensionless_jerk"} == HIGHER_IS_BETTER


# ------------------------------------------------------------------- stored decisions
GATED = """
name = "gated_tiny"
description = "a VF-free probe then a gated VF-free block"
task = "trajectory"
max_trial_time_s = 0.5
[[blocks]]
name = "baseline"
condition = "none"
probe = true
counterbalance = false
[[blocks]]
name = "practice"
condition = "none"
variants = [0, 1]
counterbalance = false
probes_after = 1
[blocks.gate]
metrics = ["path_dev_mean_mm", "path_l2"]
k = 0.0
consecutive = 2
max_trials = 5
[questionnaires.pre]
demographics = true
"""


def _recompute(st_: TrialStore, sid: int, protocol_name: str) -> list[tuple[int, str, bool]]:
    """Independent replay: the experts' block trials, mean + 0·SD limits, the trainee's
    values read from the store, and the rule written out by hand."""
    sessions = st_.sessions()
    demo = st_.demographics().set_index("subject")["subject_group"]
    wide = st_.trial_metrics(wide=True)
    expert_ids = []
    for s_id, subj in zip(sessions["id"], sessions["subject"], strict=True):
        if demo.get(subj) == "surgeon":
            sch = st_.schedule(int(s_id))
            expert_ids += [int(t) for t in sch[(sch["block"] == "practice") & ~sch["probe"]]
                           ["trial_id"].dropna()]
    limit = {m: statistics.fmean(wide.loc[expert_ids, m]) for m in ("path_dev_mean_mm",
                                                                  "path_l2")}
    sch = st_.schedule(sid)
    own = sch[(sch["block"] == "practice") & ~sch["probe"]]
    out, run = [], 0
    for k, tid in enumerate(own["trial_id"]):
        ok = all(wide.at[int(tid), m] <= limit[m] for m in limit)
        run = run + 1 if ok else 0
        n = k + 1
        action = ("continue" if n < 2 else "passed" if run >= 2 else "cap" if n >= 5
                  else "extend")
        out.append((int(tid), action, ok))
    return out


def test_a_simulated_gated_cohort_stores_reproducible_decisions(tmp_path: Path) -> None:
    db = tmp_path / "g.db"
    protocol = parse_protocol(GATED, source="gated_tiny.toml")
    rep = simulate_cohort(db, protocol, CohortPlan(n_subjects=4, n_surgeons=2, seed=3),
                          CohortRun(workers=0, progress=False))
    assert rep.sessions_completed == 4
    with TrialStore(db) as st_:
        groups = st_.demographics().set_index("subject")["subject_group"]
        n_extended = 0
        for sid, subj in zip(st_.sessions()["id"], st_.sessions()["subject"], strict=True):
            sid = int(sid)
            records = gate_records(st_, sid)
            sch = st_.schedule(sid)
            own = sch[(sch["block"] == "practice") & ~sch["probe"]]
            assert [r["n_trials"] for _, r in records] == list(range(1, len(own) + 1))
            if groups[subj] == "surgeon":      # experts are not gated: the scheduled 2 trials
                assert len(own) == 2 and {r["action"] for _, r in records} == {"expert"}
                continue
            expected = _recompute(st_, sid, protocol.name)
            got = [(tid, r["action"], r["passed"]) for tid, r in records]
            assert got == expected
            assert got[-1][1] in ("passed", "cap")
            extends = sum(a == "extend" for _, a, _ in got)
            assert len(own) == 2 + extends and len(sch) == 1 + 2 + extends + 1
            assert sch["probe"].iloc[-1] and sch["block"].iloc[-1] == "practice"
            assert st_.session(sid)["n_trials"] == len(sch)
            bench = records[0][1]["benchmark"]
            assert bench["path_dev_mean_mm"]["n"] == 4          # 2 surgeons x 2 trials
            assert all(r["benchmark"] == bench for _, r in records)   # frozen per block
            n_extended += extends
        # running again changes nothing: the decisions are stored, not recomputed
        before = [st_.schedule(int(s)).to_dict("records") for s in st_.sessions()["id"]]
        n_events = st_.con.execute("SELECT count(*) FROM events WHERE kind = 'gate'").fetchone()
    again = simulate_cohort(db, protocol, CohortPlan(n_subjects=4, n_surgeons=2, seed=3),
                            CohortRun(workers=0, progress=False))
    assert again.trials_run == 0
    with TrialStore(db) as st_:
        assert [st_.schedule(int(s)).to_dict("records") for s in st_.sessions()["id"]] == before
        assert st_.con.execute("SELECT count(*) FROM events WHERE kind = 'gate'").fetchone() \
            == n_events
        for sid in st_.sessions()["id"]:
            assert apply_gates(st_, int(sid)) == 0
    assert n_extended >= 1     # seed 3: a trainee failed its first trial and needed a third


def test_a_trainee_without_experts_is_told_why(tmp_path: Path) -> None:
    protocol = parse_protocol(GATED, source="gated_tiny.toml")
    with TrialStore(tmp_path / "n.db") as st_:
        sid = start_session(st_, protocol, "T01", seed=1)
        with pytest.raises(ConfigError, match=r"no benchmark for subject 'T01'.*0 completed "
                                              r"trial\(s\) of group 'surgeon'"):
            run_session(st_, sid, progress=False)
        s = load_session(st_, sid)
        assert [t is not None for t in s.completed][:2] == [True, True]   # kept, undecided
        assert gate_records(st_, sid) == []


def test_insert_scheduled_matches_the_pure_extension(tmp_path: Path) -> None:
    from vasim.study.protocol import extend_gated_block, generate_schedule

    protocol = parse_protocol(GATED, source="gated_tiny.toml")
    with TrialStore(tmp_path / "i.db") as st_:
        sid = start_session(st_, protocol, "T02", seed=4)
        run_session(st_, sid, progress=False, max_trials=1)
        tid = int(st_.schedule(sid)["trial_id"].iloc[0])
        expected = extend_gated_block(protocol, generate_schedule(protocol, 4), "practice")
        new = next(t for t in expected if t.trial_in_block == 2 and not t.probe)
        st_.insert_scheduled(sid, new.as_row(), event_trial_id=tid, kind="gate",
                             detail=json.dumps({"test": 1}))
        got = load_session(st_, sid).schedule
        assert list(got) == expected
        assert st_.session(sid)["n_trials"] == 5
        from vasim.core.errors import StoreError

        with pytest.raises(StoreError, match="cannot insert scheduled trial 0"):
            st_.insert_scheduled(sid, {**new.as_row(), "trial_index": 0},
                                 event_trial_id=tid, kind="gate", detail="{}")


def test_a_cohort_run_in_pieces_makes_the_same_decisions(tmp_path: Path) -> None:
    protocol = parse_protocol(GATED, source="gated_tiny.toml")
    plan = CohortPlan(n_subjects=3, n_surgeons=2, seed=3)
    simulate_cohort(tmp_path / "whole.db", protocol, plan, CohortRun(workers=0, progress=False))
    first = simulate_cohort(tmp_path / "parts.db", protocol, plan,
                            CohortRun(workers=0, progress=False, max_trials_per_subject=2))
    with TrialStore(tmp_path / "parts.db") as st_:
        trainee = [int(s) for s, subj in zip(st_.sessions()["id"], st_.sessions()["subject"],
                                            strict=True)
                   if st_.demographics().set_index("subject")["subject_group"][subj]
                   != "surgeon"]
        # the experts were cut short: the trainee waits for a complete benchmark
        assert first.trials_run == 4 and all(
            st_.sessions().set_index("id").loc[t, "n_completed"] == 0 for t in trainee)
    for _ in range(10):
        if simulate_cohort(tmp_path / "parts.db", protocol, plan,
                           CohortRun(workers=0, progress=False,
                                     max_trials_per_subject=1)).trials_run == 0:
            break

    def decisions(db: Path) -> list[list[tuple]]:
        with TrialStore(db) as st_:
            return [[(r["n_trials"], r["action"], r["values"], r["benchmark"])
                     for _, r in gate_records(st_, int(s))] for s in st_.sessions()["id"]]

    assert decisions(tmp_path / "parts.db") == decisions(tmp_path / "whole.db")
