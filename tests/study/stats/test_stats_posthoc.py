"""Tests of Tukey HSD (vasim/study/stats/posthoc.py).

References:
* R ``TukeyHSD(aov(weight ~ group, data = PlantGrowth))`` (output reproduced in many R
  tutorials, e.g. the rstatix/"R companion" pages): trt1-ctrl diff -0.371,
  lwr -1.0622161, upr 0.3202161, p 0.3908711; trt2-ctrl 0.494, -0.1972161, 1.1852161,
  0.1979960; trt2-trt1 0.865, 0.1737839, 1.5562161, 0.0120064; residual MS 0.389 on 27 df
  (``summary(aov(...))``). Data: tests/data/reference_plantgrowth.csv.
* Unequal n (Tukey-Kramer): ``statsmodels.stats.multicomp.pairwise_tukeyhsd`` and
  ``scipy.stats.tukey_hsd``, two independent implementations.
* Repeated measures: the RM-ANOVA error term of the Bushtucker data from JASP
  (MS_error 7.303571 on 21 df, see test_stats_anova.py), and the randomised-block identity:
  the residual MS and df of the OLS fit ``retch ~ C(food) + C(celebrity)`` (statsmodels).
* lme4/multcomp on a 5-subject x 4-treatment VO2 example (Stack Overflow 74840410,
  ``glht(lmer(vo2 ~ treat + (1|id)), mcp(treat = "Tukey"))``): estimates o-j -3.060,
  w-j 0.770, z-j 1.588, w-o 3.830, z-o 4.648, z-w 0.818, all with Std. Error 0.583 (for a
  balanced design the REML residual variance equals the RM-ANOVA MS_error).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import statsmodels.formula.api as smf
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy import stats
from statsmodels.stats.multicomp import pairwise_tukeyhsd

from vasim.core.errors import ConfigError
from vasim.study.stats import TUKEY_COLUMNS, read_long_csv, rm_anova, tukey_hsd, tukey_hsd_rm

DATA = Path(__file__).resolve().parents[2] / "data"


def test_plantgrowth_matches_r_tukeyhsd() -> None:
    data = read_long_csv(DATA / "reference_plantgrowth.csv")
    res = tukey_hsd(data, dv="weight", between="group")
    assert list(res.comparisons.columns) == list(TUKEY_COLUMNS)
    assert res["k"] == 3 and res["df_error"] == 27
    assert round(res["ms_error"], 3) == 0.389
    ref = [("ctrl", "trt1", -0.371, -1.0622161, 0.3202161, 0.3908711),
           ("ctrl", "trt2", 0.494, -0.1972161, 1.1852161, 0.1979960),
           ("trt1", "trt2", 0.865, 0.1737839, 1.5562161, 0.0120064)]
    for row, (g1, g2, diff, lwr, upr, p) in zip(res.comparisons.to_dict("records"), ref,
                                               strict=True):
        assert (row["group1"], row["group2"]) == (g1, g2)
        assert row["diff"] == pytest.approx(diff, abs=1e-12)
        assert row["diff"] == pytest.approx(row["mean2"] - row["mean1"], abs=1e-15)
        assert row["lwr"] == pytest.approx(lwr, abs=5e-8)
        assert row["upr"] == pytest.approx(upr, abs=5e-8)
        assert row["p_adj"] == pytest.approx(p, abs=5e-8)
        assert row["q"] == pytest.approx(abs(diff) / row["se"], rel=1e-12)


def test_mapping_and_dict_keys() -> None:
    data = read_long_csv(DATA / "reference_plantgrowth.csv")
    res = tukey_hsd(data, dv="weight", between="group")
    assert list(res) == ["ms_error", "df_error", "k", "q_crit", "comparisons"]
    d = res.to_dict()
    assert list(d) == list(res)
    assert list(d["comparisons"][0]) == list(TUKEY_COLUMNS)
    with pytest.raises(KeyError):
        res["kind"]


def test_unequal_n_matches_statsmodels_and_scipy() -> None:
    data = read_long_csv(DATA / "reference_plantgrowth.csv")
    unb = data.drop(index=[3, 4, 5, 14, 30])  # ctrl 7, trt1 9, trt2 9 observations
    res = tukey_hsd(unb, dv="weight", between="group")
    sm = pairwise_tukeyhsd(unb["weight"], unb["group"])
    np.testing.assert_allclose(res.comparisons["diff"], sm.meandiffs, rtol=1e-12)
    np.testing.assert_allclose(res.comparisons["lwr"], sm.confint[:, 0], rtol=1e-9)
    np.testing.assert_allclose(res.comparisons["upr"], sm.confint[:, 1], rtol=1e-9)
    np.testing.assert_allclose(res.comparisons["p_adj"], sm.pvalues, atol=1e-9)
    groups = [unb.loc[unb["group"] == g, "weight"].to_numpy() for g in ("ctrl", "trt1", "trt2")]
    sp = stats.tukey_hsd(*groups)
    ci = sp.confidence_interval(0.95)
    for row, (i, j) in zip(res.comparisons.to_dict("records"), [(0, 1), (0, 2), (1, 2)],
                           strict=True):
        assert row["p_adj"] == pytest.approx(sp.pvalue[i, j], abs=1e-9)
        # scipy reports mean_i - mean_j; ours is mean2 - mean1 = -(that)
        assert row["lwr"] == pytest.approx(-ci.high[i, j], rel=1e-9)
        assert row["upr"] == pytest.approx(-ci.low[i, j], rel=1e-9)


def test_rm_tukey_error_term_is_rm_anova_and_randomised_block() -> None:
    data = read_long_csv(DATA / "reference_bushtucker.csv")
    res = tukey_hsd_rm(data, dv="retch", subject="celebrity", within="food")
    aov = rm_anova(data, dv="retch", subject="celebrity", within="food").iloc[0]
    assert res["ms_error"] == pytest.approx(7.303571, rel=1e-6)  # JASP residual MS
    assert res["df_error"] == 21
    assert res["ms_error"] == pytest.approx(aov["MS_error"], rel=1e-12)
    fit = smf.ols("retch ~ C(food) + C(celebrity)", data=pd.DataFrame(data)).fit()
    assert res["ms_error"] == pytest.approx(fit.mse_resid, rel=1e-10)
    assert res["df_error"] == fit.df_resid
    assert res["k"] == 4 and len(res.comparisons) == 6
    means = pd.DataFrame(data).groupby("food")["retch"].mean()
    for row in res.comparisons.to_dict("records"):
        assert row["mean1"] == pytest.approx(means[row["group1"]])
        assert row["se"] == pytest.approx(math.sqrt(7.303571 / 8), rel=1e-6)
    assert res["q_crit"] == pytest.approx(stats.studentized_range.ppf(0.95, 4, 21))


def test_rm_tukey_standard_error_matches_lme4_glht() -> None:
    vo2 = {"o": [47.48, 42.74, 45.23, 51.65, 49.11], "j": [51.00, 43.82, 49.88, 54.61, 52.20],
           "z": [51.31, 47.56, 50.69, 54.88, 55.01], "w": [51.89, 46.10, 50.98, 53.62, 52.77]}
    df = pd.DataFrame([{"id": i + 1, "treat": t, "vo2": v}
                       for t, vals in vo2.items() for i, v in enumerate(vals)])
    res = tukey_hsd_rm(df, dv="vo2", subject="id", within="treat")
    est = {(r["group1"], r["group2"]): r["diff"] for r in res.comparisons.to_dict("records")}
    # glht reports b - a for "b - a"; ours is mean2 - mean1 with levels sorted j, o, w, z
    for (a, b), ref in {("j", "o"): -3.060, ("j", "w"): 0.770, ("j", "z"): 1.588,
                        ("o", "w"): 3.830, ("o", "z"): 4.648, ("w", "z"): 0.818}.items():
        assert round(est[(a, b)], 3) == ref
    se_diff = res.comparisons["se"].iloc[0] * math.sqrt(2)
    assert round(se_diff, 3) == 0.583


# --- properties --------------------------------------------------------------------


@settings(max_examples=12, deadline=None)
@given(y=hnp.arrays(np.float64, (6, 4), elements=st.integers(-30, 30).map(float)))
def test_rm_tukey_properties(y: np.ndarray) -> None:
    df = pd.DataFrame([{"s": i, "c": f"c{j}", "y": y[i, j]}
                       for i in range(6) for j in range(4)])
    try:
        res = tukey_hsd_rm(df, "y", "s", "c")
    except ConfigError as exc:  # only legitimate for a zero error term
        assert "zero error variance" in str(exc)
        return
    cmp = res.comparisons
    assert ((cmp["p_adj"] >= 0) & (cmp["p_adj"] <= 1)).all()
    assert (cmp["lwr"] <= cmp["diff"]).all() and (cmp["diff"] <= cmp["upr"]).all()
    # interval excludes 0 exactly when p_adj < 0.05
    excl = (cmp["lwr"] > 0) | (cmp["upr"] < 0)
    far = (cmp["p_adj"] - 0.05).abs() > 1e-9
    assert (excl[far] == (cmp["p_adj"] < 0.05)[far]).all()
    # Tukey p >= the unadjusted two-sided t-test p with the same error term (q = t sqrt 2)
    t_p = 2 * stats.t.sf(cmp["q"] / math.sqrt(2), res["df_error"])
    assert (cmp["p_adj"] >= t_p - 1e-12).all()


# --- bad input -----------------------------------------------------------------------


def test_bad_input() -> None:
    data = read_long_csv(DATA / "reference_plantgrowth.csv")
    with pytest.raises(ConfigError, match="column 'grp' not found"):
        tukey_hsd(data, dv="weight", between="grp")
    with pytest.raises(ConfigError, match="at least 2 levels"):
        tukey_hsd(data[data["group"] == "ctrl"], dv="weight", between="group")
    one_each = data.groupby("group").head(1)
    with pytest.raises(ConfigError, match="no error degrees of freedom"):
        tukey_hsd(one_each, dv="weight", between="group")
    const = data.assign(weight=1.0)
    with pytest.raises(ConfigError, match="zero error variance"):
        tukey_hsd(const, dv="weight", between="group")
    bush = read_long_csv(DATA / "reference_bushtucker.csv")
    with pytest.raises(ConfigError, match="unbalanced"):
        tukey_hsd_rm(bush.iloc[1:], dv="retch", subject="celebrity", within="food")


def test_tukey_groups_1_and_1_0_are_different(tmp_path: Path) -> None:
    # Issue #16: group labels "1" and "1.0" merged into one group through pandas inference.
    p = tmp_path / "groups.csv"
    p.write_text("g,y\n" + "".join(f"{g},{y}\n" for g, ys in
                                  (("1", (1, 2, 3)), ("1.0", (4, 5, 6)), ("2", (7, 8, 9)))
                                  for y in ys))
    res = tukey_hsd(read_long_csv(p, text_columns=["g"]), "y", "g")
    assert res.k == 3
    pairs = res.comparisons[["group1", "group2", "diff"]].to_dict("records")
    assert pairs[0] == {"group1": "1", "group2": "1.0", "diff": 3.0}
    # one-way ANOVA error term: three groups of 3 with variance 1 -> MS_error 1, df 6
    assert res.ms_error == pytest.approx(1.0) and res.df_error == 6


def test_tukey_round_off_error_term_refused() -> None:
    # Subjects differ, the pattern over levels is the same up to rounding (SS_error 5.5e-30).
    y = np.array([0.1, 1.1, 2.3, 5.7])[:, None] + np.array([0.3, 0.7, 1.9])[None, :]
    df = pd.DataFrame([{"s": i, "c": f"c{j}", "y": y[i, j]} for i in range(4) for j in range(3)])
    with pytest.raises(ConfigError, match="zero error variance"):
        tukey_hsd_rm(df, dv="y", subject="s", within="c")
