"""Tests of the paired t-tests, power analysis and gain (vasim/study/stats/paired.py).

References:
* R ``t.test(extra ~ group, data = sleep, paired = TRUE)`` (R for Dummies, "How to compare
  paired data with R"): t = -4.0621, df = 9, p-value = 0.002833, 95 % CI
  [-2.4598858, -0.7001142], mean of the differences -1.58. Data:
  tests/data/reference_sleep.csv.
* R ``pwr::pwr.t.test(type = "paired")`` outputs published online: d = 0.25, power 0.75 ->
  n = 112.9798 and d = 0.5, power 0.75 -> n = 29.7355 (pastebin dTaadhYz); d = 0.15,
  power 0.8 -> n = 350.7638; d = 0.02, n = 33 -> power 0.05142498; n = 32, power 0.8 ->
  d = 0.5112738 (course scripts on GitHub).
* An independent noncentral-t computation with ``scipy.stats.nct`` (power) and a plain
  ``scipy.stats.ttest_rel`` (t, p).
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy import integrate, stats

from vasim.core.errors import ConfigError
from vasim.study.stats import (
    PAIRED_COLUMNS,
    StatsWarning,
    gain,
    min_n_for_power,
    n_for_power,
    paired_power,
    pairwise_paired,
    read_long_csv,
)

DATA = Path(__file__).resolve().parents[2] / "data"


def _nct_power(dz: float, n: float, alpha: float = 0.05) -> float:
    """Two-sided power from the definition of the noncentral t, by quadrature.

    T = (Z + nc) / sqrt(V / df) with Z ~ N(0, 1), V ~ chi2(df), nc = |dz| sqrt(n), so
    P(|T| > q) = E_V[Phi(nc - q s) + Phi(-nc - q s)], s = sqrt(V / df).
    """
    df = n - 1
    q = stats.t.isf(alpha / 2, df)
    nc = abs(dz) * math.sqrt(n)

    def integrand(v: float) -> float:
        s = math.sqrt(v / df)
        return float((stats.norm.cdf(nc - q * s) + stats.norm.cdf(-nc - q * s))
                     * stats.chi2.pdf(v, df))

    hi = stats.chi2.isf(1e-16, df)
    value, _ = integrate.quad(integrand, 0.0, hi, epsabs=1e-13, epsrel=1e-12, limit=200)
    return float(value)


def test_sleep_matches_r_t_test() -> None:
    data = read_long_csv(DATA / "reference_sleep.csv")
    res = pairwise_paired(data, dv="extra", subject="ID", within="group")
    assert list(res.columns) == list(PAIRED_COLUMNS)
    r = res.iloc[0]
    assert (r["group1"], r["group2"], r["n"], r["df"]) == (1, 2, 10, 9)
    assert r["mean_diff"] == pytest.approx(-1.58, abs=1e-12)
    assert round(r["t"], 4) == -4.0621
    assert r["p"] == pytest.approx(0.002833, abs=5e-7)
    assert r["ci_low"] == pytest.approx(-2.4598858, abs=5e-8)
    assert r["ci_high"] == pytest.approx(-0.7001142, abs=5e-8)
    d = (data.loc[data["group"] == 1, "extra"].to_numpy()
         - data.loc[data["group"] == 2, "extra"].to_numpy())
    assert r["cohen_dz"] == pytest.approx(d.mean() / d.std(ddof=1), rel=1e-12)
    # one pair only: Holm = Bonferroni = raw p
    assert r["p_holm"] == r["p_bonf"] == r["p"]


def test_sleep_power_against_noncentral_t() -> None:
    data = read_long_csv(DATA / "reference_sleep.csv")
    r = pairwise_paired(data, dv="extra", subject="ID", within="group").iloc[0]
    assert r["power_observed"] == pytest.approx(_nct_power(r["cohen_dz"], 10), rel=1e-10)
    assert _nct_power(r["cohen_dz"], r["n_power90"]) == pytest.approx(0.9, abs=1e-9)
    assert r["n_power90_ceil"] == math.ceil(r["n_power90"]) == 9
    assert _nct_power(r["cohen_dz"], 8) < 0.9 <= _nct_power(r["cohen_dz"], 9)


@pytest.mark.parametrize(("d", "power", "n_ref"), [
    (0.25, 0.75, 112.9798), (0.5, 0.75, 29.7355), (0.15, 0.8, 350.7638)])
def test_n_for_power_matches_pwr(d: float, power: float, n_ref: float) -> None:
    assert n_for_power(d, power) == pytest.approx(n_ref, abs=5e-5)
    assert n_for_power(-d, power) == n_for_power(d, power)
    assert min_n_for_power(d, power) == math.ceil(n_ref)


def test_power_matches_pwr() -> None:
    assert paired_power(0.02, 33) == pytest.approx(0.05142498, abs=5e-9)
    assert paired_power(0.5112738, 32) == pytest.approx(0.8, abs=5e-7)


def test_power_edge_cases() -> None:
    assert paired_power(0.0, 10) == pytest.approx(0.05, abs=1e-15)
    assert math.isnan(n_for_power(0.0))
    assert min_n_for_power(0.0) is None
    # statsmodels' own "two-sided" option returns NaN here (far tail underflow); ours not
    assert paired_power(3.0, 100) == pytest.approx(1.0, abs=1e-12)
    assert paired_power(0.4, 1000) == pytest.approx(1.0, abs=1e-12)
    # above |dz| = 14.82 the t-test already has power 0.9 with 2 pairs (df = 1)
    assert paired_power(20.0, 2) > 0.9
    assert n_for_power(20.0) == 2.0 and min_n_for_power(20.0) == 2


@settings(max_examples=20, deadline=None)
@given(dz=st.floats(0.05, 4.0), n=st.floats(2.0, 400.0))
def test_power_equals_noncentral_t(dz: float, n: float) -> None:
    assert paired_power(dz, n) == pytest.approx(_nct_power(dz, n), abs=1e-10)


@settings(max_examples=25, deadline=None)
@given(dz=st.floats(0.05, 3.0))
def test_n_for_power_is_the_root(dz: float) -> None:
    n = n_for_power(dz, 0.9)
    assert paired_power(dz, n) == pytest.approx(0.9, abs=1e-8)
    n_int = min_n_for_power(dz, 0.9)
    assert n_int is not None and paired_power(dz, n_int) >= 0.9
    assert n_int == 2 or paired_power(dz, n_int - 1) < 0.9


@settings(max_examples=12, deadline=None)
@given(y=hnp.arrays(np.float64, (7, 4), elements=st.integers(-20, 20).map(float)))
def test_pairwise_properties(y: np.ndarray) -> None:
    df = pd.DataFrame([{"s": i, "c": f"c{j}", "y": y[i, j]} for i in range(7) for j in range(4)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StatsWarning)
        res = pairwise_paired(df, "y", "s", "c")
    assert len(res) == 6
    ok = res["p"].notna()
    p, holm, bonf = (res.loc[ok, c].to_numpy() for c in ("p", "p_holm", "p_bonf"))
    assert ((p >= 0) & (p <= 1)).all()
    assert (holm >= p - 1e-15).all() and (bonf >= holm - 1e-15).all() and (bonf <= 1).all()
    np.testing.assert_allclose(bonf, np.minimum(1.0, p * ok.sum()), rtol=1e-12)
    for r in res[ok].to_dict("records"):
        i, j = int(r["group1"][1]), int(r["group2"][1])
        ref = stats.ttest_rel(y[:, i], y[:, j])
        assert r["t"] == pytest.approx(ref.statistic, rel=1e-9)
        assert r["p"] == pytest.approx(ref.pvalue, rel=1e-9)
        assert r["ci_low"] <= r["mean_diff"] <= r["ci_high"]
        assert 0.05 - 1e-12 <= r["power_observed"] <= 1.0


def test_constant_differences_warn_and_give_nan() -> None:
    df = pd.DataFrame({"s": [1, 2, 3] * 3, "c": ["a"] * 3 + ["b"] * 3 + ["c"] * 3,
                       "y": [1.0, 2.0, 3.0, 2.0, 3.0, 4.0, 0.0, 5.0, 1.0]})
    with pytest.warns(StatsWarning, match="all differences are equal"):
        res = pairwise_paired(df, "y", "s", "c")
    ab = res.iloc[0]
    assert ab["mean_diff"] == -1.0 and math.isnan(ab["t"]) and math.isnan(ab["p_holm"])
    assert pd.isna(ab["n_power90_ceil"])
    # the two valid pairs form the Holm family
    assert res["p_bonf"].iloc[1] == pytest.approx(min(1.0, 2 * res["p"].iloc[1]))


def test_gain_is_ratio_of_means() -> None:
    assert gain([2.0, 4.0], [1.0, 2.0, 3.0]) == pytest.approx(1.5)
    # seed exp. 3 ET: 181.51 / 113.20 = 1.60 (spec/study.md §4)
    assert round(gain([181.51], [113.20]), 2) == 1.60
    assert gain([1e-3], [1.001e-12]) == pytest.approx(1e-3 / 1.001e-12)  # 1e9: still a ratio
    with pytest.raises(ConfigError, match="round-off"):
        gain([3.6e-5], [1e-17])  # a zero displacement up to floating point
    with pytest.raises(ConfigError, match="mean\\(b\\) is zero"):
        gain([1.0], [-1.0, 1.0])
    with pytest.raises(ConfigError, match="non-finite"):
        gain([1.0, float("nan")], [1.0])
    with pytest.raises(ConfigError, match="empty"):
        gain([], [1.0])


def test_bad_input() -> None:
    data = read_long_csv(DATA / "reference_sleep.csv")
    with pytest.raises(ConfigError, match="column 'id' not found"):
        pairwise_paired(data, dv="extra", subject="id", within="group")
    with pytest.raises(ConfigError, match="unbalanced") as err:
        pairwise_paired(data.drop(index=[5]), dv="extra", subject="ID", within="group")
    assert "ID=4 x group=1" in str(err.value)
    with pytest.raises(ConfigError, match="at least 2 subjects"):
        pairwise_paired(data[data["ID"] == 1], dv="extra", subject="ID", within="group")


def test_differences_equal_up_to_rounding_give_nan_dz() -> None:
    # b = a + 0.3 in floating point: sd(d) = 1.3e-16, which gave dz = -2.3e15.
    a = np.array([0.1, 1.1, 2.3, 5.7])
    df = pd.DataFrame({"s": list(range(4)) * 2, "c": ["a"] * 4 + ["b"] * 4,
                       "y": np.concatenate([a, a + 0.3])})
    with pytest.warns(StatsWarning, match="all differences are equal"):
        r = pairwise_paired(df, dv="y", subject="s", within="c").iloc[0]
    assert math.isnan(r["cohen_dz"]) and math.isnan(r["t"]) and math.isnan(r["p_holm"])
    assert r["mean_diff"] == pytest.approx(-0.3)


def test_overflowing_differences_named() -> None:
    df = pd.DataFrame({"s": [0, 1, 2] * 2, "c": ["a"] * 3 + ["b"] * 3,
                       "y": [1e308, -1e308, 0.0, -1e308, 1e308, 1.0]})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        with pytest.warns(StatsWarning, match="overflow"):
            r = pairwise_paired(df, dv="y", subject="s", within="c").iloc[0]
    assert math.isnan(r["cohen_dz"]) and math.isnan(r["t"])
