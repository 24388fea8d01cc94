"""Parameter recovery (vasim/study/recovery.py) and the outcome engine's cohorts
(vasim/operator/outcome.py, vasim/study/power/outcome.py): issue #25 items 3-4."""

from __future__ import annotations

import doctest
import math

import numpy as np
import pandas as pd
import pytest

import vasim.operator.outcome as outcome_mod
from vasim.operator.scenario import load_scenario
from vasim.study.power.outcome import outcome_cohort, recovery_rows
from vasim.study.protocol import load_protocol
from vasim.study.recovery import design_covariates, estimate_effects, variant_confounded


def test_doctests():
    assert doctest.testmod(outcome_mod).failed == 0


def _frame(effects: dict[str, float], *, n_subjects: int = 12, sd: float = 0.0,
           seed: int = 0, carry: float = 1.0) -> pd.DataFrame:
    """A by-hand data set of the recovery model's form: ln E = subject + ln power law +
    ln ratio while assisted + ln carry x fixtures practised (unassisted)."""
    rng = np.random.default_rng(seed)
    fx = list(effects)
    rows = []
    for i in range(n_subjects):
        order = [fx[(i + k) % len(fx)] for k in range(len(fx))]   # rotated block orders
        conds = ["none"] * 3
        for f in order:
            conds += [f] * 4 + ["none"]
        u = rng.normal(0.0, 0.2)
        seen: set[str] = set()
        for j, c in enumerate(conds):
            lam = (1.0 + j) ** -0.3
            f = effects[c] if c != "none" else carry ** len(seen)
            if c != "none":
                seen.add(c)
            rows.append({"subject": f"S{i}", "trial_index": j, "condition": c,
                         "variant": j % 3,
                         "path_dev_mean_mm": 3.0 * lam * f * math.exp(u + rng.normal(0, sd))})
    return pd.DataFrame(rows)


def test_exact_data_give_back_the_ratios():
    truth = {"ff": 0.7, "mag": 0.85, "vg": 1.1}
    est = estimate_effects(_frame(truth, sd=1e-4, carry=0.97))
    for c, r in truth.items():
        assert est["fixtures"][c]["ratio"] == pytest.approx(r, rel=2e-3)
        assert est["fixtures"][c]["ci_low"] < r < est["fixtures"][c]["ci_high"]
    assert est["carry_per_fixture"]["ratio"] == pytest.approx(0.97, rel=2e-3)
    assert est["variant_in_model"] is True     # every variant runs with and without


def test_covariates_and_the_variant_confound():
    df = design_covariates(pd.DataFrame({
        "subject": ["a"] * 6, "trial_index": range(6),
        "condition": ["none", "ff", "ff", "none", "mag", "none"], "variant": [0, 1, 2, 0, 1, 0],
        "path_dev_mean_mm": 1.0}))
    assert df["carry"].tolist() == [0, 0, 0, 1, 0, 2]
    assert df["after"].tolist() == [0, 0, 0, 1, 0, 1]
    assert variant_confounded(df)          # variant 0 only unassisted: confounded


def test_not_enough_data_is_said_not_hidden():
    est = estimate_effects(_frame({"ff": 0.7}, n_subjects=1))
    assert "not_estimated" in est and est["fixtures"] == {}


def test_outcome_cohorts_are_reproducible_and_follow_the_scenario():
    p = load_protocol("vf_learning_curve")
    sc = load_scenario("seed_plausible")
    a = outcome_cohort(p, sc, n_subjects=4, seed=3)
    b = outcome_cohort(p, sc, n_subjects=4, seed=3)
    pd.testing.assert_frame_equal(a.trials, b.trials)
    assert len(a.trials) == 4 * 38 and set(a.answers) == set(a.trials["subject"])
    assert {"best_vf", "worst_vf", "rating"} <= set(next(iter(a.answers.values())))
    # effect scale 0: every trial's expected deviation is its unassisted one, so each
    # assisted/unassisted pair at the same practice differs by the random terms only
    null = outcome_cohort(p, sc, n_subjects=4, seed=3, effect_scale=0.0, answers=False)
    assert not null.trials.equals(a.trials)


def test_one_cohort_recovers_the_assumed_ratios_within_its_intervals():
    rows = pd.DataFrame(recovery_rows(load_protocol("vf_learning_curve"),
                                      load_scenario("seed_plausible"), n_subjects=10, seed=1))
    assert set(rows["fixture"]) == {"vg", "ag", "ms", "mag", "ff"}
    assert rows["recovered"].notna().all()
    # 5 intervals at 95 %: all five cover in 77 % of cohorts; this seed is one of them
    # (the validation test measures the rate over many cohorts)
    assert rows["covers"].sum() >= 4
