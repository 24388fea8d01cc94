"""Power estimates and their Monte Carlo error (vasim/study/power/estimate.py)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy import stats

from vasim.study.power.estimate import mc_standard_error, power_table, smallest_n


@given(st.integers(1, 5000), st.data())
def test_mc_error_is_the_binomial_sd_of_the_share(m: int, data: st.DataObject) -> None:
    r = data.draw(st.integers(0, m))
    p = r / m
    # the standard deviation of Binomial(m, p) / m, from scipy
    assert math.isclose(mc_standard_error(p, m), stats.binom(m, p).std() / m,
                        rel_tol=1e-9, abs_tol=1e-15)


def test_mc_error_analytic_values() -> None:
    assert mc_standard_error(0.5, 100) == 0.05
    assert math.isclose(mc_standard_error(0.8, 200), math.sqrt(0.16 / 200))
    assert mc_standard_error(0.0, 7) == 0.0
    with pytest.raises(ValueError):
        mc_standard_error(1.2, 10)
    with pytest.raises(ValueError):
        mc_standard_error(0.5, 0)


def test_mc_error_matches_the_spread_of_repeated_estimates() -> None:
    """Independent check: 4000 power runs of 200 cohorts each with true power 0.3; the
    spread of their estimates is the formula's standard error (within 5 %)."""
    rng = np.random.default_rng(3)
    est = (rng.random((4000, 200)) < 0.3).mean(axis=1)
    assert math.isclose(est.std(ddof=1), mc_standard_error(0.3, 200), rel_tol=0.05)


def _cohorts(ps: dict[int, list[float]], dv: str = "latency",
             factor: str = "fixture") -> pd.DataFrame:
    rows = [{"n_subjects": n, "cohort": k, "dv": dv, "factor": factor, "p_gg": p,
             "p_unc": p / 2} for n, lst in ps.items() for k, p in enumerate(lst)]
    return pd.DataFrame(rows)


def test_power_table_counts_rejections_per_n() -> None:
    c = _cohorts({4: [0.01, 0.2, 0.049, 0.05, math.nan], 8: [0.001] * 4 + [0.3]})
    t = power_table(c, alpha=0.05)
    assert list(t["n_subjects"]) == [4, 8]
    r4, r8 = t.iloc[0], t.iloc[1]
    assert (r4.rejections, r4.not_computed, r4.cohorts) == (2, 1, 5)   # 0.05 is not < 0.05
    assert r4.power == 0.4 and math.isclose(r4.mc_se, math.sqrt(0.4 * 0.6 / 5))
    assert r8.power == 0.8 and r4.test == "seed RM-ANOVA: fixture effect on latency"
    assert r4.ci_low < 0.4 < r4.ci_high and 0.0 <= r4.ci_low and r8.ci_high <= 1.0
    # the uncorrected p (halved here) rejects more
    u = power_table(c, alpha=0.05, p_column="p_unc")
    assert u.iloc[0].rejections == 3 and set(u["p_column"]) == {"p_unc"}


def test_power_table_orders_primary_then_fixture_then_practice() -> None:
    c = pd.concat([_cohorts({4: [0.01]}, "latency", "trial"),
                   _cohorts({4: [0.01]}, "eq65", "fixture"),
                   _cohorts({4: [0.01]}, "latency", "practised"),
                   _cohorts({4: [0.01]}, "path_deviation", "fixture")])
    t = power_table(c, alpha=0.05)
    assert list(zip(t["dv"], t["factor"], strict=True)) == [
        ("latency", "practised"), ("path_deviation", "fixture"), ("eq65", "fixture"),
        ("latency", "trial")]
    assert t.iloc[0].test.startswith("PRIMARY probe model")


@given(st.lists(st.one_of(st.floats(0, 1), st.just(math.nan)), min_size=1, max_size=60),
       st.floats(1e-6, 0.5))
def test_power_is_the_share_below_alpha(ps: list[float], alpha: float) -> None:
    t = power_table(_cohorts({6: ps}), alpha=alpha)
    r = t.iloc[0]
    assert r.rejections == sum(1 for p in ps if p < alpha)
    assert 0.0 <= r.power <= 1.0 and r.ci_low <= r.power <= r.ci_high
    assert math.isclose(r.mc_se, math.sqrt(r.power * (1 - r.power) / len(ps)))


def test_smallest_n_reaching_the_target() -> None:
    t = pd.DataFrame({"test": ["a"] * 3 + ["b"], "n_subjects": [4, 8, 12, 4],
                      "power": [0.3, 0.81, 0.79, 0.1]})
    assert smallest_n(t, 0.8) == {"a": 8, "b": None}
