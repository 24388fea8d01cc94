"""The score card's proficiency-gate part (issue #18 §4): each metric against the
benchmark, passed or not, the decision and the trainee's curve — from stored decisions,
without a browser."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from tests.viewer.driving import drive
from vasim.study.gates import GATE_EVENT, MetricBenchmark, decide, gate_record, judge
from vasim.study.protocol import parse_protocol
from vasim.study.session import SessionSettings, run_session, start_session
from vasim.study.store import TrialStore
from vasim.viewer.history import trial_gate_card
from vasim.viewer.trainee import gate_card, score_card, score_card_markdown

PROTOCOL = """
name = "gate_card"
description = "one gated block"
task = "trajectory"
[[blocks]]
name = "practice"
condition = "none"
variants = [0]
repetitions = 3
counterbalance = false
[blocks.gate]
metrics = ["path_l2", "points_reached"]
k = 1.0
consecutive = 2
max_trials = 6
"""

BENCH = {"path_l2": MetricBenchmark("path_l2", 0.20, 0.02, 8, 1.0, False),
         "points_reached": MetricBenchmark("points_reached", 28.0, 1.5, 8, 1.0, True)}


def _records() -> list[dict]:
    p = parse_protocol(PROTOCOL, source="gate_card.toml")
    block = p.blocks[0]
    out, hist = [], []
    for i, vals in enumerate([{"path_l2": 0.30, "points_reached": 25.0},
                              {"path_l2": 0.21, "points_reached": 27.0},
                              {"path_l2": 0.215, "points_reached": 26.0}]):
        passes = judge(vals, BENCH)
        hist.append(all(passes.values()))
        dec = decide(hist, n_scheduled=3, consecutive=2, max_trials=6)
        out.append(gate_record(block, i, vals, BENCH, passes, dec, 8))
    return out


def test_gate_card_values_against_the_benchmark() -> None:
    recs = _records()
    card = gate_card(recs[2], recs[:2])
    assert card is not None
    rows = {r.name: r for r in card.rows}
    # path length in mm on the card: limit 0.20 + 1 x 0.02 m = 220 mm, 215 mm passes
    assert rows["path_l2"].value == pytest.approx(215.0)
    assert rows["path_l2"].limit == pytest.approx(220.0) and rows["path_l2"].passed
    assert rows["path_l2"].mean == pytest.approx(200.0) and rows["path_l2"].sd == \
        pytest.approx(20.0)
    # points reached: higher is better, limit 28 - 1.5 = 26.5; 26 fails
    assert rows["points_reached"].limit == pytest.approx(26.5)
    assert not rows["points_reached"].passed and rows["points_reached"].higher_is_better
    assert not card.passed and card.streak == 0 and card.action == "extend"
    assert (card.n_trials, card.max_trials, card.consecutive, card.n_expert) == (3, 6, 2, 8)
    # the trainee's curve in the block: trial 2 passed both, 1 and 3 did not
    assert [(n, ok) for n, ok, _ in card.curve] == [(1, False), (2, True), (3, False)]
    assert card.curve[0][2] == pytest.approx((300.0, 25.0))
    md = score_card_markdown(score_card({"path_l2": 0.215}, title="trial 7",
                                        outcome="reached_all", n_points=30, gate=card))
    assert "#### Proficiency gate — practice" in md and "**not passed** this trial" in md
    assert "| Path length | 215 mm | 200 mm ± 20 mm | ≤ 220 mm | yes |" in md
    assert "| Points reached | 26 | 28 ± 2 | ≥ 26 | no |" in md      # 0 decimals shown
    assert "one more trial added: the gate asks for 2 passes in a row" in md
    assert "| 2 | 210 mm | 27 | yes |" in md


def test_an_experts_trial_has_no_gate_card() -> None:
    rec = _records()[0] | {"benchmark": None, "action": "expert", "passes": {}}
    assert gate_card(rec) is None
    assert "Proficiency gate" not in score_card_markdown(
        score_card({}, title="trial 1", outcome=None, n_points=1, gate=gate_card(rec)))


def test_the_viewer_reads_the_stored_decision_of_a_trial(tmp_path: Path) -> None:
    ungated = PROTOCOL[:PROTOCOL.index("[blocks.gate]")]
    p = parse_protocol(ungated, source="ungated.toml")
    recs = _records()
    with TrialStore(tmp_path / "v.db") as st:
        sid = start_session(st, p, "T01", seed=1,
                            settings=SessionSettings(max_trial_time=0.05))
        run_session(st, sid, progress=False)
        ids = [int(t) for t in st.schedule(sid)["trial_id"]]
        assert trial_gate_card(st, ids[0]) is None     # no decision stored: no gate card
        # the decisions as apply_gates stores them (the viewer only reads them)
        for tid, rec in zip(ids, recs, strict=True):
            st.add_event(tid, GATE_EVENT, json.dumps(rec))
        card = trial_gate_card(st, ids[2])
        assert card is not None and card.n_trials == 3
        assert [n for n, _, _ in card.curve] == [1, 2, 3]
        assert trial_gate_card(st, None) is None
        assert math.isclose(card.rows[0].limit, 220.0)


def test_a_browser_session_decides_the_gate_and_shows_it(tmp_path: Path) -> None:
    """The viewer's protocol session: after a gated trial the controller stores the gate's
    decision and the trainee's score card carries it (surgeons simulated beforehand)."""

    from vasim.study.cohort import CohortPlan, CohortRun, simulate_cohort
    from vasim.study.gates import gate_records
    from vasim.study.protocol import load_protocol
    from vasim.viewer.app_options import TrialOptions
    from vasim.viewer.controller import Command, TrainingController, TrainingSettings

    db = tmp_path / "v.sqlite"
    simulate_cohort(db, load_protocol("vf_proficiency"),
                    CohortPlan(n_subjects=2, n_surgeons=2, seed=1, max_trial_time=0.5),
                    CohortRun(workers=0, progress=False))
    c = TrainingController(TrainingSettings(
        scene="none", db=db, speed=25.0,
        trials=TrialOptions(countdown_s=0.0, pause_s=0.05, max_time=0.5)))


    try:
        for cmd in (Command("mode", "protocol"), Command("subject", "T01"),
                    Command("protocol", "vf_proficiency")):
            c.handle(cmd)
        for _ in range(7):        # 2 baseline + 4 FF + the first gated practice trial
            c.handle(Command("start"))
            assert drive(c, lambda: c.info.trial_id is not None and not c.panel.running)
        sid = c.panel.session_id
        tid = c.info.trial_id
        assert sid is not None and tid is not None
        with TrialStore(db, readonly=True) as st:
            recs = dict(gate_records(st, sid))
        assert list(recs) == [tid] and recs[tid]["action"] == "continue"
        card = c.panel.scorecard
        assert card is not None and card.gate is not None and card.gate.n_trials == 1
        rows = {r.name: r for r in card.gate.rows}
        bench = recs[tid]["benchmark"]
        assert rows["duration"].limit == pytest.approx(bench["duration"]["limit"])
        assert rows["path_dev_mean_mm"].value == pytest.approx(
            recs[tid]["values"]["path_dev_mean_mm"])
        assert card.gate.passed == recs[tid]["passed"]
        assert bench["duration"]["n"] == 8          # 2 surgeons x 4 practice trials (1 per variant)
    finally:
        c.close()
