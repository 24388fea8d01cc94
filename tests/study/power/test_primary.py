"""The primary tests power planning counts are the report's own (report/primary.py): on the
same cohort data, ``primary_tests`` gives exactly the rows of the report's ``vf_rm_anova``
table, and an independent one-way RM-ANOVA computed here by hand agrees."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from vasim.study.power.cohort import CohortTrials, schedule_frame, study_data
from vasim.study.protocol import load_protocol
from vasim.study.protocol.schedule import generate_schedule
from vasim.study.report.analysis import analyse_vf
from vasim.study.report.html_page import TableBlock
from vasim.study.report.primary import primary_tests, probe_model_tests
from vasim.study.report.sections.fixture import fixture_effect_section

FIXTURE_MEAN = {"none": 1.0, "vg": 0.95, "ag": 0.8, "ms": 0.7, "mag": 0.9, "ff": 0.6}


def _synthetic_cohort(n_subjects: int, seed: int = 1, drop: int | None = None
                      ) -> CohortTrials:
    """A VF learning-curve cohort with random per-point measures (no simulation): each
    subject's schedule is the protocol's, errors and latencies scale with the fixture."""
    proto = load_protocol("vf_learning_curve")
    rng = np.random.default_rng(seed)
    rows, pts, met = [], [], {}
    tid = 0
    for j in range(1, n_subjects + 1):
        skill = rng.lognormal(0, 0.3)
        for st in generate_schedule(proto, 1000 + j):
            tid += 1
            rows.append({**st.as_row(), "session_id": j, "trial_id": tid, "attempts": 1,
                         "subject": f"S{j:02d}"})
            m = FIXTURE_MEAN[st.condition] * skill
            n_pts = 30
            reached = np.ones(n_pts, dtype=bool)
            if drop == tid:
                reached[:] = False          # a trial without a reached point: excluded
            pts.append(pd.DataFrame({
                "trial_id": tid, "point": np.arange(n_pts), "reached": reached,
                "t_reached": np.cumsum(rng.gamma(4, 0.2, n_pts)),
                "error_l1": m * rng.gamma(5, 0.2, n_pts),
                "error_l1_mm_s": m * rng.gamma(5, 2.0, n_pts),
                "latency": np.where(reached, m * rng.gamma(5, 0.15, n_pts), np.nan)}))
            met[tid] = {"path_dev_mean_mm": m * rng.gamma(8, 0.5)}
    points = pd.concat(pts, ignore_index=True)
    metrics = pd.DataFrame.from_dict(met, orient="index")
    metrics.index = pd.Index(metrics.index.astype(np.int64), name="trial_id")
    return CohortTrials(schedule=schedule_frame(rows), points=points, metrics=metrics,
                        sim_seconds=0.0, n_trials=tid)


@pytest.mark.parametrize("drop", [None, 2, 5])
def test_primary_tests_are_the_reports_rm_anova_rows(drop: int | None) -> None:
    proto = load_protocol("vf_learning_curve")
    data = study_data(proto, _synthetic_cohort(6, drop=drop))
    vf = analyse_vf(data)
    ours = primary_tests(vf)
    section, _ = fixture_effect_section(data, vf)
    table = next(b.data for b in section.blocks
                 if isinstance(b, TableBlock) and b.name == "vf_rm_anova")
    assert len(ours) == len(table) == 6        # 3 dvs x (fixture, trial)
    merged = ours.merge(table, on=["dv", "factor"], suffixes=("", "_report"))
    assert len(merged) == 6
    for col in ("F", "p_unc", "p_gg", "np2", "df1", "df2", "n_subjects"):
        np.testing.assert_allclose(merged[col].astype(float),
                                   merged[f"{col}_report"].astype(float), rtol=0, atol=0)
    # trial 2 is S01's 2nd baseline probe: excluded, S01 lacks probe level 2 and leaves
    # the trial factor only (baselines never enter the fixture cells); trial 5 is an
    # assisted trial: its fixture cell is the mean of the other five, nobody leaves
    n_fix = set(ours.loc[ours["factor"] == "fixture", "n_subjects"])
    n_trial = set(ours.loc[ours["factor"] == "trial", "n_subjects"])
    assert (n_fix, n_trial) == ({6}, {5} if drop == 2 else {6})


def test_fixture_rm_anova_matches_a_hand_computed_one() -> None:
    """Independent implementation of the one-way RM-ANOVA on subject x fixture means."""
    proto = load_protocol("vf_learning_curve")
    data = study_data(proto, _synthetic_cohort(7, seed=4))
    vf = analyse_vf(data)
    row = primary_tests(vf).set_index(["dv", "factor"]).loc[("latency", "fixture")]
    y = vf.fixture_cells.pivot(index="subject", columns="fixture",
                               values="latency").to_numpy(float)
    n, k = y.shape
    grand = y.mean()
    ss_a = n * ((y.mean(axis=0) - grand) ** 2).sum()
    ss_s = k * ((y.mean(axis=1) - grand) ** 2).sum()
    ss_err = ((y - grand) ** 2).sum() - ss_a - ss_s
    f = (ss_a / (k - 1)) / (ss_err / ((k - 1) * (n - 1)))
    assert (row["df1"], row["df2"]) == (k - 1, (k - 1) * (n - 1))
    assert math.isclose(row["F"], f, rel_tol=1e-10)
    assert math.isclose(row["p_unc"], stats.f.sf(f, k - 1, (k - 1) * (n - 1)), rel_tol=1e-8)
    assert row["p_gg"] >= row["p_unc"]          # the GG correction never lowers p


def test_a_factor_with_one_level_is_not_computed_with_its_reason() -> None:
    proto = load_protocol("vf_learning_curve")
    c = _synthetic_cohort(3)
    keep = c.schedule["condition"] == "ff"     # no VF-free trial: no trial factor, 1 fixture
    sched = c.schedule[keep].reset_index(drop=True)
    vf = analyse_vf(study_data(proto, CohortTrials(sched, c.points, c.metrics, 0.0, 0)))
    t = primary_tests(vf)
    assert t["F"].isna().all() and t["reason"].str.contains("needs 2").all()


def test_probe_model_tests_are_the_reports_transfer_fixture_rows() -> None:
    """The PRIMARY test power counts is the report's ``vf_transfer_tests`` fixture row,
    and an independent nested F test by least squares (numpy) agrees: probes closing a
    fixture block, dv ~ subject + fixture practised + block position + variant, F for
    the fixture term."""
    from vasim.study.report.transfer import transfer_model

    proto = load_protocol("vf_learning_curve")
    data = study_data(proto, _synthetic_cohort(12, seed=5))
    vf = analyse_vf(data)
    ours = probe_model_tests(vf).set_index("dv")
    assert set(ours["factor"]) == {"practised"} and len(ours) == len(vf.dvs)
    for dv, _n, unit in vf.dvs:
        _, tests = transfer_model(vf.trials, dv, unit)
        ref = tests.set_index("test").loc["fixture"]
        r = ours.loc[dv]
        assert (r["F"], r["p_unc"], r["df1"], r["df2"]) == (ref["F"], ref["p"], ref["df1"],
                                                            ref["df2"])
        assert r["p_gg"] == r["p_unc"] and r["n_levels"] == 5
        assert math.isclose(r["np2"], r["F"] * r["df1"] / (r["F"] * r["df1"] + r["df2"]))
    # independent: numpy least squares on dummy-coded design matrices
    t = vf.trials
    d = t[t["probe"].astype(bool) & (t["practised"].astype(str) != "")]
    y = d["latency"].to_numpy(float)

    def dummies(col: pd.Series) -> np.ndarray:
        levels = sorted(set(col.astype(str)))
        return np.column_stack([(col.astype(str) == v).to_numpy(float) for v in levels[1:]])

    base = [np.ones(len(d)), dummies(d["subject"]), d["block_position"].to_numpy(float),
            dummies(d["variant"])]
    red = np.column_stack(base)
    full = np.column_stack([*base, dummies(d["practised"])])

    def rss(x: np.ndarray) -> tuple[float, int]:
        beta, *_ = np.linalg.lstsq(x, y, rcond=None)
        return float(((y - x @ beta) ** 2).sum()), int(np.linalg.matrix_rank(x))

    (r0, k0), (r1, k1) = rss(red), rss(full)
    df1, df2 = k1 - k0, len(y) - k1
    f = ((r0 - r1) / df1) / (r1 / df2)
    row = ours.loc["latency"]
    assert (row["df1"], row["df2"]) == (df1, df2) == (4, 12 * 5 - 12 - 1 - 5 - 4)
    assert math.isclose(row["F"], f, rel_tol=1e-8)
    assert math.isclose(row["p_unc"], stats.f.sf(f, df1, df2), rel_tol=1e-6)
