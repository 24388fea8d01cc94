"""Tests of the labelled replication of the seed's per-sample ANOVA.

Reference: closed-form sums of squares of the balanced additive two-way ANOVA
(Montgomery, *Design and Analysis of Experiments*, two-factor model without interaction):
SS_A = b r sum_i (ybar_i.. - ybar)^2, SS_B = a r sum_j (ybar_.j. - ybar)^2,
SS_res = SS_total - SS_A - SS_B on N - a - b + 1 df.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from vasim.core.errors import ConfigError
from vasim.study.stats import SEED_LABEL, StatsWarning, seed_per_sample_anova


def _samples(seed: int = 3, reps: int = 25) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    fixtures = ["none", "VG", "AG", "MS", "Mag", "FF"]
    rows = [{"fixture": f, "trial": t, "error": 1.0 + 0.1 * i - 0.05 * t + rng.normal(0, 0.5)}
            for i, f in enumerate(fixtures) for t in range(1, 9) for _ in range(reps)]
    return pd.DataFrame(rows)


def test_balanced_additive_closed_form() -> None:
    df = _samples()
    a, b, r = 6, 8, 25
    out = seed_per_sample_anova(df, dv="error")
    assert out.attrs["label"] == SEED_LABEL and "not the primary analysis" in SEED_LABEL
    assert out["effect"].tolist() == ["fixture", "trial"]
    y = df["error"].to_numpy()
    grand = y.mean()
    ss_a = b * r * ((df.groupby("fixture")["error"].mean() - grand) ** 2).sum()
    ss_b = a * r * ((df.groupby("trial")["error"].mean() - grand) ** 2).sum()
    ss_res = ((y - grand) ** 2).sum() - ss_a - ss_b
    df_res = len(y) - a - b + 1
    assert out["df2"].tolist() == [df_res, df_res]  # the seed's structure: F(5, N-13)
    assert out["df1"].tolist() == [a - 1, b - 1]
    for row, ss, df1 in ((out.iloc[0], ss_a, a - 1), (out.iloc[1], ss_b, b - 1)):
        f = (ss / df1) / (ss_res / df_res)
        assert row["SS"] == pytest.approx(ss, rel=1e-9)
        assert row["F"] == pytest.approx(f, rel=1e-9)
        assert row["p"] == pytest.approx(stats.f.sf(f, df1, df_res), rel=1e-7, abs=1e-300)


def test_interaction_model_df() -> None:
    df = _samples(reps=5)
    out = seed_per_sample_anova(df, dv="error", interaction=True)
    assert out["effect"].tolist() == ["fixture", "trial", "fixture:trial"]
    assert out["df1"].tolist() == [5, 7, 35]
    assert (out["df2"] == len(df) - 48).all()


def test_bad_input() -> None:
    df = _samples(reps=2)
    with pytest.raises(ConfigError, match="at least 2 levels"):
        seed_per_sample_anova(df[df["fixture"] == "VG"], dv="error")
    with pytest.raises(ConfigError, match="exactly two factors"):
        seed_per_sample_anova(df, dv="error", factors=("fixture",))
    holes = df[~((df["fixture"] == "VG") & (df["trial"] == 3))]
    with pytest.raises(ConfigError, match="fixture='VG' x trial=3"):
        seed_per_sample_anova(holes, dv="error", interaction=True)
    with pytest.raises(ConfigError, match="column 'latency' not found"):
        seed_per_sample_anova(df, dv="latency")


def test_zero_residual_gives_nan_f_not_huge() -> None:
    # Additive data with values that round: the OLS residual is ~1e-30, F would be ~1e30.
    fx = {"none": 0.1, "VG": 0.7}
    tr = {1: 0.3, 2: 1.1, 3: 2.9}
    df = pd.DataFrame([{"fixture": f, "trial": t, "e": fx[f] + tr[t]}
                       for f in fx for t in tr for _ in range(2)])
    with pytest.warns(StatsWarning, match="zero residual variance"):
        r = seed_per_sample_anova(df, dv="e")
    assert r["F"].isna().all() and r["p"].isna().all()
    # type II SS stay defined: 12 (0.6/2)^2 and 4 sum_j (t_j - mean t)^2
    t = np.array([0.3, 1.1, 2.9])
    assert r["SS"].tolist() == pytest.approx([12 * 0.3**2, 4 * ((t - t.mean()) ** 2).sum()])
