"""Simulated cohorts (vasim/study/cohort.py): subjects, answer models, an end-to-end cohort
through the real session code (in-process and with worker processes), resumption."""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from vasim.cli import main
from vasim.core.errors import ConfigError
from vasim.operator.scenario import load_scenario
from vasim.study.cohort import (
    DEMOGRAPHIC_MODEL,
    CohortPlan,
    CohortRun,
    cohort_subjects,
    draw_demographics,
    measured_benefits,
    simulate_cohort,
    simulated_answers,
)
from vasim.study.protocol import load_protocol, parse_protocol
from vasim.study.store import TrialStore

TINY = """
name = "tiny_cohort"
description = "a seven-trial test protocol"
task = "trajectory"
max_trial_time_s = 0.25
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
variants = [1, 2]
probes_after = 1
[[blocks]]
name = "ff"
condition = "ff"
variants = [3, 4]
probes_after = 1
[questionnaires.pre]
demographics = true
[[questionnaires.post.items]]
id = "best"
type = "condition_choice"
select = "best"
prompt = "best?"
[[questionnaires.post.items]]
id = "worst"
type = "condition_choice"
select = "worst"
prompt = "worst?"
[[questionnaires.post.items]]
id = "rating"
type = "condition_rating"
prompt = "rate each"
[[questionnaires.post.items]]
id = "sets"
type = "condition_sets"
prompt = "schemas?"
required = false
"""


@pytest.fixture
def tiny(tmp_path: Path) -> Path:
    p = tmp_path / "tiny.toml"
    p.write_text(TINY)
    return p


def test_cohort_subjects_are_reproducible_and_grouped() -> None:
    a = cohort_subjects(46, 31, seed=7)
    assert [s.code for s in a[:2]] == ["SIM001", "SIM002"] and a[-1].code == "SIM046"
    assert Counter(s.group for s in a) == {"surgeon": 31, "resident": 15}
    assert a == cohort_subjects(46, 31, seed=7)
    b = cohort_subjects(46, 31, seed=8)
    assert [s.group for s in a] != [s.group for s in b]
    assert len({s.session_seed for s in a}) == 46
    # the default scenario's group model: skill drawn with the laparoscopy experience,
    # mean skill sum_k p_k m_k (0.725 surgeons, 0.405 residents), the group's asymptote
    sc = load_scenario("seed_plausible")
    big = cohort_subjects(600, 300, seed=1)
    for g in ("surgeon", "resident"):
        skills = [s.profile.skill for s in big if s.group == g]
        assert np.mean(skills) == pytest.approx(sc.groups[g].mean_skill,
                                                abs=4 * np.std(skills) / np.sqrt(300))
        assert {s.profile.asymptote for s in big if s.group == g} == {sc.groups[g].asymptote}
    for bad in ({"n_subjects": 0, "n_surgeons": 0}, {"n_subjects": 3, "n_surgeons": 4}):
        with pytest.raises(ConfigError):
            cohort_subjects(seed=1, **bad)


def test_demographics_follow_the_documented_model() -> None:
    rng = np.random.default_rng(2)
    n = 4000
    draws = [draw_demographics(rng, "resident") for _ in range(n)]
    for field, (values, probs) in DEMOGRAPHIC_MODEL["resident"].items():
        freq = Counter(getattr(d, field) for d in draws)
        for v, p in zip(values, probs, strict=True):
            # binomial standard error sqrt(p (1 - p) / n) <= 0.008; allow 4 of them
            assert freq[v] / n == pytest.approx(p, abs=0.032), (field, v)
    with pytest.raises(ConfigError, match="group"):
        draw_demographics(rng, "nurse")


def test_measured_benefit_and_rating_model() -> None:
    sched = pd.DataFrame({"condition": ["none", "vg", "vg", "none", "ff"],
                          "probe": [True, False, False, True, False],
                          "trial_id": pd.array([1, 2, 3, 4, 5], dtype="Int64")})
    errors = {1: 3.0, 4: 1.0, 2: 1.0, 3: 3.0, 5: 4.0}  # probe mean 2, vg mean 2, ff 4
    b = measured_benefits(sched, errors)
    assert b["vg"] == pytest.approx(0.0) and b["ff"] == pytest.approx(math.log(0.5))
    # The answers follow the subject's own measured benefit only (the scenario's
    # questionnaire model): with equal benefits there is no preference (shares 1/2, equal
    # mean ratings r0 + s b), whatever the seed's subjects said.
    model = load_scenario("seed_plausible").questionnaire
    p = parse_protocol(TINY)
    rng = np.random.default_rng(0)
    n = 3000
    same = [simulated_answers(p, "post", rng, measured={"vg": 0.1, "ff": 0.1})
            for _ in range(n)]
    se = 0.5 / math.sqrt(n)   # binomial standard error bound
    assert np.mean([r["best"] == "vg" for r in same]) == pytest.approx(0.5, abs=4 * se)
    assert np.mean([r["worst"] == "vg" for r in same]) == pytest.approx(0.5, abs=4 * se)
    centre = model.rating_centre + model.rating_per_benefit * 0.1
    for c in ("vg", "ff"):   # rounding to integers keeps the mean within ~0.1
        assert np.mean([r["rating"][c] for r in same]) == pytest.approx(centre, abs=0.15)
    # a subject's own benefit moves the answers: VG cut its error 20 % more than FF did
    moved = [simulated_answers(p, "post", rng, measured={"vg": 0.2, "ff": 0.0})
             for _ in range(n)]
    gap = (np.mean([r["rating"]["vg"] - r["rating"]["ff"] for r in moved])
           - np.mean([r["rating"]["vg"] - r["rating"]["ff"] for r in same]))
    assert gap == pytest.approx(model.rating_per_benefit * 0.2, abs=0.15)
    p_vg = 1.0 / (1.0 + math.exp(-0.2 / model.choice_noise))   # logit in b / tau
    assert np.mean([r["best"] == "vg" for r in moved]) == pytest.approx(p_vg, abs=4 * se)
    sets = Counter(len(r.get("sets", [])) for r in same)
    assert sets[0] > 0 and sets[1] > 0 and sets[2] == 0  # only 2 conditions: one set of 2


def _check_cohort(db: Path, n_subjects: int) -> dict[tuple[str, int], str]:
    """Invariants of a finished cohort; returns (subject, index) -> samples digest."""
    out = {}
    with TrialStore(db) as st:
        ses = st.sessions()
        assert len(ses) == n_subjects and (ses["status"] == "completed").all()
        assert (ses["n_completed"] == 7).all()
        trials = st.trials()
        done = trials[trials["status"] == "completed"]
        per_index = done.groupby(["session_id", "schedule_index"]).size()
        assert (per_index == 1).all() and len(per_index) == 7 * n_subjects
        a = st.answers()
        assert set(a["questionnaire"]) == {"pre", "post"}
        assert a.groupby("session_id")["item"].apply(lambda s: "rating" in set(s)).all()
        assert len(st.demographics()) == n_subjects
        assert set(st.trial_metrics()["trial_id"]) == set(done["id"])
        for r in done.itertuples():
            s = st.samples(int(r.id))
            out[(r.subject, int(r.schedule_index))] = pd.util.hash_pandas_object(
                s, index=False).sum()
    return out


def test_cohort_end_to_end_in_process_and_with_workers(tmp_path: Path, tiny: Path) -> None:
    p = load_protocol(tiny)
    rep = simulate_cohort(tmp_path / "a.db", p, CohortPlan(n_subjects=3, n_surgeons=2, seed=7),
                          CohortRun(workers=0, progress=False))
    assert (rep.trials_run, rep.sessions_completed, rep.workers) == (21, 3, 0)
    assert rep.sim_seconds == pytest.approx(21 * 0.25)
    a = _check_cohort(tmp_path / "a.db", 3)
    # The same cohort through two worker processes (one writer, the parent): same data.
    rep2 = simulate_cohort(tmp_path / "b.db", p, CohortPlan(n_subjects=3, n_surgeons=2, seed=7),
                           CohortRun(workers=2, progress=False))
    assert rep2.trials_run == 21 and rep2.workers == 2
    assert _check_cohort(tmp_path / "b.db", 3) == a
    with TrialStore(tmp_path / "a.db") as x, TrialStore(tmp_path / "b.db") as y:
        pd.testing.assert_frame_equal(
            x.answers().drop(columns="answered_at"), y.answers().drop(columns="answered_at"))
        pd.testing.assert_frame_equal(x.demographics().drop(columns="updated_at"),
                                      y.demographics().drop(columns="updated_at"))


def test_cohort_resumes_where_it_stopped(tmp_path: Path, tiny: Path) -> None:
    db = tmp_path / "c.db"
    p = load_protocol(tiny)
    first = simulate_cohort(db, p, CohortPlan(n_subjects=2, n_surgeons=1, seed=3),
                            CohortRun(workers=0, progress=False, max_trials_per_subject=5))
    assert first.trials_run == 10 and first.sessions_completed == 0
    with TrialStore(db) as st:
        # a crash left one trial 'running' with a dead writer pid: it must be re-run
        tid = st.begin_trial({"subject": "SIM002", "task": "trajectory", "session_id": 2,
                              "schedule_index": 5, "pid": 2**22 + 12345})
        assert st.trial(tid)["status"] == "running"
    assert main(["study", "simulate", "--protocol", str(tiny), "--subjects", "2",
                 "--surgeons", "1", "--seed", "3", "--db", str(db), "--workers", "0"]) == 0
    _check_cohort(db, 2)
    with TrialStore(db) as st:
        assert st.trial(tid)["status"] == "interrupted"
        assert st.schedule(2)["attempts"].tolist()[5] == 2
    # another cohort seed must not silently reuse these subjects
    with pytest.raises(ConfigError, match="another cohort"):
        simulate_cohort(db, p, CohortPlan(n_subjects=2, n_surgeons=1, seed=4),
                        CohortRun(workers=0, progress=False))


def test_latin_square_cohorts_are_counterbalanced() -> None:
    """Subject j takes row (j - 1) % R of the Williams square: R consecutive simulated
    subjects use every row once (random session seeds used 6 of 10 rows)."""
    from vasim.study.protocol import block_order, load_protocol, williams_square

    protocol = load_protocol("vf_point_targeting")
    assert protocol.block_order == "latin_square"
    n_rows = len(williams_square(sum(b.counterbalance for b in protocol.blocks)))
    subjects = cohort_subjects(2 * n_rows, n_rows, seed=7, latin_square=True)
    orders = [tuple(block_order(protocol, s.session_seed)) for s in subjects]
    assert len(set(orders[:n_rows])) == n_rows
    assert orders[:n_rows] == orders[n_rows:]
    assert len({s.session_seed for s in subjects}) == 2 * n_rows      # still distinct seeds
    plain = cohort_subjects(2 * n_rows, n_rows, seed=7)
    assert [s.code for s in plain] == [s.code for s in subjects]


def test_a_cohort_of_another_size_does_not_mix_into_the_store(tmp_path: Path) -> None:
    """The same seed with another cohort size makes other subjects surgeons: re-running into
    the same database is refused instead of mixing the two cohorts' groups."""
    from vasim.study.cohort import prepare_sessions

    protocol = parse_protocol(TINY)
    seed = next(s for s in range(100)
                if [x.group for x in cohort_subjects(3, 2, seed=s)]
                != [x.group for x in cohort_subjects(4, 3, seed=s)][:3])
    with TrialStore(tmp_path / "c.sqlite") as st:
        first = prepare_sessions(st, protocol, cohort_subjects(3, 2, seed=seed),
                                 cohort_seed=seed)
        again = prepare_sessions(st, protocol, cohort_subjects(3, 2, seed=seed),
                                 cohort_seed=seed)
        assert [sid for _, sid in again] == [sid for _, sid in first]   # same cohort: reused
        with pytest.raises(ConfigError, match="cohort of another size"):
            prepare_sessions(st, protocol, cohort_subjects(4, 3, seed=seed), cohort_seed=seed)
