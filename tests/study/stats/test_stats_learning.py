"""Tests of learning-curve summaries and power-law fits (vasim/study/stats/learning.py).

Checks: exact recovery of noise-free power laws (closed form), agreement with an
independent optimiser (``scipy.optimize.least_squares``) and an independent
finite-difference delta method, Monte Carlo coverage of the 95 % band, and the per-trial
summary against direct NumPy computations.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from scipy import optimize, stats

from vasim.core.errors import ConfigError
from vasim.study.stats import fit_learning_curves, fit_power_law, learning_curve_summary


def test_exact_power_law_recovered() -> None:
    n = np.arange(1, 9, dtype=float)
    fit = fit_power_law(n, 10.0 * n**-0.5)
    assert (fit.a, fit.b) == (pytest.approx(10.0, rel=1e-9), pytest.approx(0.5, rel=1e-9))
    assert math.isnan(fit.c) and not fit.asymptote
    assert fit.rss == pytest.approx(0.0, abs=1e-16) and fit.dof == 6
    fit3 = fit_power_law(n, 5.0 * n**-0.7 + 2.0, asymptote=True)
    assert fit3.asymptote
    assert (fit3.a, fit3.b, fit3.c) == (pytest.approx(5.0, rel=1e-7), pytest.approx(0.7, rel=1e-7),
                                        pytest.approx(2.0, rel=1e-7))
    np.testing.assert_allclose(fit3.predict([1, 4]), [7.0, 5.0 * 4**-0.7 + 2.0], rtol=1e-7)


def _noisy(seed: int, n_subjects: int = 10) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    n = np.tile(np.arange(1, 9, dtype=float), n_subjects)
    return n, 12.0 * n**-0.4 + rng.normal(0.0, 0.8, n.size)


def test_fit_matches_independent_optimiser_and_standard_errors() -> None:
    n, y = _noisy(1)
    fit = fit_power_law(n, y)
    ls = optimize.least_squares(lambda p: p[0] * n ** (-p[1]) - y, x0=[1.0, 0.0],
                                xtol=1e-14, ftol=1e-14, gtol=1e-14)
    assert (fit.a, fit.b) == (pytest.approx(ls.x[0], rel=1e-6), pytest.approx(ls.x[1], rel=1e-6))
    # SE from s^2 (J^T J)^-1 with the analytic Jacobian at the optimum
    a, b = ls.x
    jac = np.column_stack([n**-b, -a * np.log(n) * n**-b])
    s2 = float((ls.fun**2).sum()) / (n.size - 2)
    se = np.sqrt(np.diag(s2 * np.linalg.inv(jac.T @ jac)))
    assert (fit.se_a, fit.se_b) == (pytest.approx(se[0], rel=1e-4), pytest.approx(se[1], rel=1e-4))


def test_band_equals_finite_difference_delta_method() -> None:
    n, y = _noisy(2)
    fit = fit_power_law(n, y, asymptote=True)
    grid = np.array([1.0, 2.5, 8.0, 12.0])
    band = fit.band(grid)
    assert list(band.columns) == ["trial", "fit", "lower", "upper"]
    p = np.array([fit.a, fit.b, fit.c])
    h = 1e-6 * np.maximum(1.0, np.abs(p))
    grads = []
    for i in range(3):
        dp = np.zeros(3)
        dp[i] = h[i]
        up = (p[0] + dp[0]) * grid ** -(p[1] + dp[1]) + p[2] + dp[2]
        dn = (p[0] - dp[0]) * grid ** -(p[1] - dp[1]) + p[2] - dp[2]
        grads.append((up - dn) / (2 * h[i]))
    g = np.stack(grads, axis=1)
    half = stats.t.ppf(0.975, fit.dof) * np.sqrt(np.einsum("ij,jk,ik->i", g, fit.cov, g))
    np.testing.assert_allclose(band["upper"] - band["fit"], half, rtol=1e-5)
    np.testing.assert_allclose(band["fit"] - band["lower"], half, rtol=1e-5)


def test_band_coverage_monte_carlo() -> None:
    # 95 % band for the mean curve at trial 4 covers the true value ~95 % of the time.
    truth = 12.0 * 4.0**-0.4
    hits = 0
    runs = 300
    for seed in range(runs):
        n, y = _noisy(1000 + seed, n_subjects=6)
        band = fit_power_law(n, y).band([4.0])
        hits += int(band["lower"].iloc[0] <= truth <= band["upper"].iloc[0])
    # binomial sd at 0.95 over 300 runs is 0.0126: accept +- 3.5 sd
    assert 0.906 <= hits / runs <= 0.994


def test_power_law_bad_input() -> None:
    with pytest.raises(ConfigError, match="must be > 0"):
        fit_power_law([0, 1, 2], [3.0, 2.0, 1.0])
    with pytest.raises(ConfigError, match="has 3 values but y has 2"):
        fit_power_law([1, 2, 3], [3.0, 2.0])
    with pytest.raises(ConfigError, match="at least 3 distinct trial indices"):
        fit_power_law([1, 1, 2, 2], [3.0, 2.9, 2.0, 2.1], asymptote=True)
    with pytest.raises(ConfigError, match="non-finite"):
        fit_power_law([1, 2, 3], [3.0, float("inf"), 1.0])


def _trials() -> pd.DataFrame:
    rows = []
    rng = np.random.default_rng(7)
    for mode, (a, b) in {"StdT": (150.0, 0.3), "MRCP": (110.0, 0.25)}.items():
        for s in range(5):
            for t in range(1, 11):  # 10 trials: numeric sort puts 10 after 9
                for _rep in range(2):  # two rows per subject x trial, averaged first
                    rows.append({"mode": mode, "subject": f"S{s}", "trial": t,
                                 "ET": a * t**-b + rng.normal(0, 3)})
    return pd.DataFrame(rows)


def test_learning_curve_summary_against_numpy() -> None:
    df = _trials()
    out = learning_curve_summary(df, dv="ET", subject="subject", trial="trial",
                                 condition="mode")
    assert list(out.columns) == ["mode", "trial", "n", "mean", "q25", "q75"]
    assert out["mode"].tolist()[:10] == ["MRCP"] * 10  # sorted levels
    assert out["trial"].tolist()[:10] == list(range(1, 11))
    row = out[(out["mode"] == "StdT") & (out["trial"] == 10)].iloc[0]
    sub = df[(df["mode"] == "StdT") & (df["trial"] == 10)].groupby("subject")["ET"].mean()
    assert row["n"] == 5
    assert row["mean"] == pytest.approx(sub.mean(), rel=1e-12)
    assert row["q25"] == pytest.approx(np.percentile(sub, 25), rel=1e-12)
    assert row["q75"] == pytest.approx(np.percentile(sub, 75), rel=1e-12)
    flat = learning_curve_summary(df[df["mode"] == "StdT"], "ET", "subject", "trial")
    assert list(flat.columns) == ["trial", "n", "mean", "q25", "q75"]


def test_fit_learning_curves_per_condition() -> None:
    df = _trials()
    out = fit_learning_curves(df, dv="ET", subject="subject", trial="trial", condition="mode")
    assert list(out.columns) == ["mode", "n_obs", "a", "b", "c", "se_a", "se_b", "se_c", "rss",
                                 "dof"]
    res = out.set_index("mode")
    assert res.loc["StdT", "n_obs"] == 50 and res.loc["StdT", "dof"] == 48
    assert abs(res.loc["StdT", "b"] - 0.3) < 4 * res.loc["StdT", "se_b"]
    assert abs(res.loc["MRCP", "a"] - 110.0) < 4 * res.loc["MRCP", "se_a"]
    assert res["c"].isna().all()
    bad = df.assign(trial=df["trial"] - 1)  # trial 0
    with pytest.raises(ConfigError, match=r"mode='MRCP'.*must be > 0"):
        fit_learning_curves(bad, "ET", "subject", "trial", "mode")
    text = df.assign(trial="T" + df["trial"].astype(str))
    with pytest.raises(ConfigError, match="must be numeric"):
        fit_learning_curves(text, "ET", "subject", "trial")
