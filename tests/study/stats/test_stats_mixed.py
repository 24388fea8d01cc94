"""Tests of the mixed-design ANOVA (vasim/study/stats/mixed.py).

References (independent software, published outputs):
* pingouin's ``mixed_anova`` dataset (tests/data/reference_mixed_anova.csv, copied from
  raphaelvallat/pingouin src/pingouin/datasets/mixed_anova.csv; 2 groups x 30 subjects x
  3 months). pingouin's tests/test_parametric.py ``test_mixed_anova`` quotes JASP/ez:
  SS 5.45996, 7.62843, 5.16719; DF1 1, 2, 2; DF2 58, 116, 116; F 5.05171, 4.02739,
  2.72800; np2 0.08012, 0.06493, 0.04492; GG eps 0.99812 and W 0.99812 (JAMOVI; pingouin
  itself 0.99875); p_GG 0.02; ng2 0.03067, 0.04234, 0.02908 (JAMOVI).
* pingouin's ``mixed_anova_unbalanced`` dataset (tests/data/reference_mixed_anova_
  unbalanced.csv; 3 groups of 7, 10 and 9 subjects x 4 times), same test: JASP type II
  F 2.3026, 1.7071, 0.8877; p 0.1226, 0.1736, 0.5088; np2 0.1668, 0.0691, 0.0717; DF1 2, 3,
  6; DF2 23, 69, 69; R ``ez::ezANOVA``: GG eps 0.925374, p_GG 0.1779205, Mauchly
  W 0.8850318, p 0.7535238.
* statsmodels OLS residual sums of squares of nested models as an independent computation
  of every SS on the balanced design.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import statsmodels.formula.api as smf
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from vasim.core.errors import ConfigError
from vasim.study.stats import MIXED_ANOVA_COLUMNS, StatsWarning, mixed_anova, read_long_csv

DATA = Path(__file__).resolve().parents[2] / "data"


def _balanced() -> pd.DataFrame:
    return read_long_csv(DATA / "reference_mixed_anova.csv",
                         text_columns=["Subject", "Group", "Time"])


def test_balanced_matches_jasp_jamovi_pingouin() -> None:
    aov = mixed_anova(_balanced(), dv="Scores", within="Time", between="Group",
                      subject="Subject")
    assert list(aov.columns) == list(MIXED_ANOVA_COLUMNS)
    assert aov["Source"].tolist() == ["Group", "Time", "Interaction"]
    np.testing.assert_array_equal(aov["SS"].round(5), [5.45996, 7.62843, 5.16719])
    assert aov["DF1"].tolist() == [1, 2, 2]
    assert aov["DF2"].tolist() == [58, 116, 116]
    np.testing.assert_array_equal(aov["F"].round(5), [5.05171, 4.02739, 2.72800])
    np.testing.assert_array_equal(aov["np2"].round(5), [0.08012, 0.06493, 0.04492])
    np.testing.assert_array_equal(aov["ng2"].round(5), [0.03067, 0.04234, 0.02908])
    # JAMOVI (= afex/car: pooled within-group covariance) 0.99812
    assert round(aov.at[1, "eps"], 5) == 0.99812
    assert round(aov.at[1, "W_spher"], 5) == 0.99812
    assert round(aov.at[1, "p_GG_corr"], 2) == 0.02
    assert aov.at[2, "eps"] == aov.at[1, "eps"]
    # the between row has no sphericity
    assert math.isnan(aov.at[0, "eps"]) and math.isnan(aov.at[0, "p_GG_corr"])
    assert (aov["note"] == "").all()
    assert aov.attrs["group_sizes"] == {"Control": 30, "Meditation": 30}
    # the same numbers with the subject column read as numbers (pandas inference)
    inferred = mixed_anova(read_long_csv(DATA / "reference_mixed_anova.csv"), dv="Scores",
                           within="Time", between="Group", subject="Subject")
    pd.testing.assert_frame_equal(inferred, aov)


def test_unbalanced_groups_match_jasp_and_ez() -> None:
    data = read_long_csv(DATA / "reference_mixed_anova_unbalanced.csv")
    aov = mixed_anova(data, dv="Scores", within="Time", between="Group", subject="Subject")
    assert aov["DF1"].tolist() == [2, 3, 6]
    assert aov["DF2"].tolist() == [23, 69, 69]
    np.testing.assert_array_equal(aov["F"].round(4), [2.3026, 1.7071, 0.8877])
    np.testing.assert_array_equal(aov["p_unc"].round(4), [0.1226, 0.1736, 0.5088])
    np.testing.assert_array_equal(aov["np2"].round(4), [0.1668, 0.0691, 0.0717])
    # ez::ezANOVA (7 significant digits); Mauchly's p as R's mauchly.test
    assert aov.at[1, "eps"] == pytest.approx(0.925374, abs=5e-7)
    assert aov.at[1, "p_GG_corr"] == pytest.approx(0.1779205, abs=5e-7)
    assert aov.at[1, "W_spher"] == pytest.approx(0.8850318, abs=5e-8)
    assert aov.at[1, "p_spher"] == pytest.approx(0.7535238, abs=5e-8)
    assert aov.attrs["group_sizes"] == {"Control": 7, "Meditation": 10, "Therapy": 9}


def _rss(formula: str, data: pd.DataFrame) -> float:
    with warnings.catch_warnings():  # rank-deficient designs: the residual SS is still unique
        warnings.simplefilter("ignore")
        return float(smf.ols(formula, data).fit().ssr)


def test_balanced_sums_of_squares_against_statsmodels_ols() -> None:
    data = pd.DataFrame(_balanced())
    aov = mixed_anova(data, dv="Scores", within="Time", between="Group", subject="Subject")
    subj = "C(Subject)"
    full = f"Scores ~ {subj} + C(Time) + C(Group):C(Time)"
    ss_time = _rss(f"Scores ~ {subj}", data) - _rss(f"Scores ~ {subj} + C(Time)", data)
    ss_inter = _rss(f"Scores ~ {subj} + C(Time)", data) - _rss(full, data)
    ss_ws = _rss(full, data)
    means = data.groupby(["Subject", "Group"], as_index=False)["Scores"].mean()
    ss_b = 3 * (_rss("Scores ~ 1", means) - _rss("Scores ~ C(Group)", means))
    ss_sb = 3 * _rss("Scores ~ C(Group)", means)
    np.testing.assert_allclose(aov["SS"], [ss_b, ss_time, ss_inter], rtol=1e-9)
    np.testing.assert_allclose(aov["SS_error"], [ss_sb, ss_ws, ss_ws], rtol=1e-9)


def test_two_within_levels_eps_one_mauchly_undefined() -> None:
    data = _balanced()
    data = data[data["Time"] != "June"]
    aov = mixed_anova(data, dv="Scores", within="Time", between="Group", subject="Subject")
    assert aov.at[1, "eps"] == aov.at[2, "eps"] == 1.0
    assert aov.at[1, "p_GG_corr"] == aov.at[1, "p_unc"]
    assert math.isnan(aov.at[1, "W_spher"]) and "2 levels" in aov.at[1, "note"]


def _long(y: np.ndarray, groups: list[int]) -> pd.DataFrame:
    """Long table from an (n, k) array and a group index per subject."""
    return pd.DataFrame([{"s": f"S{i}", "g": f"G{groups[i]}", "t": f"T{j}", "y": float(y[i, j])}
                         for i in range(y.shape[0]) for j in range(y.shape[1])])


def test_zero_error_variance_effect_sizes_undefined() -> None:
    # Every subject of a group shows the same values: both error terms are exactly zero.
    y = np.array([[1.0, 2.0, 4.0]] * 3 + [[2.0, 5.0, 5.0]] * 3)
    with pytest.warns(StatsWarning, match="zero error variance"):
        aov = mixed_anova(_long(y, [0, 0, 0, 1, 1, 1]), dv="y", within="t", between="g",
                          subject="s")
    for col in ("F", "p_unc", "np2", "ng2", "p_GG_corr"):
        assert aov[col].isna().all(), col
    assert (aov["SS"] > 0).all()
    assert aov["note"].str.contains("zero error variance").all()


def test_constant_data_all_undefined() -> None:
    y = np.full((6, 3), 7.25)
    with pytest.warns(StatsWarning):
        aov = mixed_anova(_long(y, [0, 0, 0, 1, 1, 1]), dv="y", within="t", between="g",
                          subject="s")
    assert aov[["F", "p_unc", "np2", "ng2", "eps"]].isna().all().all()
    assert (aov["note"] != "").all()


@st.composite
def _designs(draw: st.DrawFn) -> tuple[np.ndarray, list[int]]:
    n_groups = draw(st.integers(2, 3))
    sizes = draw(st.lists(st.integers(2, 4), min_size=n_groups, max_size=n_groups))
    k = draw(st.integers(2, 4))
    y = draw(hnp.arrays(np.float64, (sum(sizes), k), elements=st.integers(-20, 20).map(float)))
    return y, [g for g, m in enumerate(sizes) for _ in range(m)]


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(design=_designs())
def test_sums_of_squares_partition_and_ranges(design: tuple[np.ndarray, list[int]]) -> None:
    y, groups = design
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StatsWarning)
        aov = mixed_anova(_long(y, groups), dv="y", within="t", between="g", subject="s")
    total = float(((y - y.mean()) ** 2).sum())
    parts = aov["SS"].sum() + aov.at[0, "SS_error"] + aov.at[1, "SS_error"]
    assert parts == pytest.approx(total, rel=1e-9, abs=1e-9)
    for col in ("p_unc", "np2", "ng2", "p_GG_corr", "p_spher"):
        vals = aov[col].dropna()
        assert ((vals >= 0) & (vals <= 1)).all(), col
    eps = aov.at[1, "eps"]
    k = y.shape[1]
    assert math.isnan(eps) or 1 / (k - 1) - 1e-12 <= eps <= 1 + 1e-12


def test_subject_in_two_groups_refused() -> None:
    data = _balanced().copy()
    data.loc[data.index[0], "Group"] = "Meditation"  # subject 0, August, now in both groups
    with pytest.raises(ConfigError, match="constant per subject") as err:
        mixed_anova(data, dv="Scores", within="Time", between="Group", subject="Subject")
    assert "reference_mixed_anova.csv" in str(err.value) and "'0'" in str(err.value)


def test_bad_designs_refused() -> None:
    data = _balanced()
    with pytest.raises(ConfigError, match="at least 2 groups"):
        mixed_anova(data[data["Group"] == "Control"], dv="Scores", within="Time",
                    between="Group", subject="Subject")
    with pytest.raises(ConfigError, match="not found"):
        mixed_anova(data, dv="Scores", within="Time", between="Cohort", subject="Subject")
    with pytest.raises(ConfigError, match="two different roles"):
        mixed_anova(data, dv="Scores", within="Time", between="Time", subject="Subject")
    with pytest.raises(ConfigError, match="unbalanced design"):
        mixed_anova(data.drop(index=data.index[3]), dv="Scores", within="Time",
                    between="Group", subject="Subject")
    with pytest.raises(ConfigError, match="may not be named 'Interaction'"):
        mixed_anova(data.rename(columns={"Group": "Interaction"}), dv="Scores",
                    within="Time", between="Interaction", subject="Subject")
    tiny = _long(np.arange(6.0).reshape(2, 3), [0, 1])
    with pytest.raises(ConfigError, match="no error degrees of freedom"):
        mixed_anova(tiny, dv="y", within="t", between="g", subject="s")
