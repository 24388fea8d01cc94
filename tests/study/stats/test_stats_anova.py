"""Tests of the subject-level repeated-measures ANOVA (vasim/study/stats/anova.py).

References (independent software, published outputs):
* Field, *Discovering Statistics Using SPSS* (3rd ed., 2009, ch. 13), "Bushtucker" data
  (tests/data/reference_bushtucker.csv). SPSS output printed in the book: Mauchly
  W = .136, chi2(5) = 11.41, p = .047; GG eps = .533, HF eps = .666; F(3, 21) = 3.79,
  p = .026; GG-corrected p = .063. More digits from JASP's unit test of the same data
  (jasp-stats/jasp-desktop, JASP-Tests/R/tests/testthat/test-anovarepeatedmeasures.R,
  "Fields Book - Chapter 8"): SS 83.125, SS_error 153.375, MS_error 7.303571,
  F 3.793806, p 0.0255703, eps_gg 0.5328456, eps_hf 0.6657636, eps_lb 0.3333333,
  p_gg 0.06258412, p_hf 0.04833061, W 0.136248.
* pingouin's ``rm_anova2`` data (tests/data/reference_rm_anova2.csv, raphaelvallat/pingouin
  pingouin/datasets/rm_anova2.csv): JASP values quoted in pingouin's test_parametric.py
  (MS 828.817, 682.617, 112.217; F 33.852, 26.959, 12.632; np2 .790, .750, .584) and R
  ``ez::ezANOVA`` values in its test_distribution.py (Metric eps_gg 0.9691030, eps_hf 1,
  W 0.968, Mauchly p 0.8784418; Time x Metric eps_gg 0.7271664, eps_hf 0.831161,
  W 0.625, p 0.1523917).
* ez on pingouin's seeded random 3 x 4 design (same test file): eps_gg 0.9963275 and
  0.9716288 for the main effects, HF 1, W 0.958 / p 0.8436 for the 4-level factor, and
  0.856 for the interaction (ez; pingouin's own value .822 differs, ez follows car).
* statsmodels ``AnovaRM`` as an independent implementation of F and df.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from statsmodels.stats.anova import AnovaRM

from vasim.core.errors import ConfigError
from vasim.study.stats import RM_ANOVA_COLUMNS, StatsWarning, read_long_csv, rm_anova

DATA = Path(__file__).resolve().parents[2] / "data"


def _long(y: np.ndarray, factors: tuple[str, ...] = ("A",)) -> pd.DataFrame:
    """Long table from an (n, a[, b]) array of cell values."""
    rows = []
    for idx in np.ndindex(*y.shape):
        row = {"s": f"S{idx[0]}", "y": float(y[idx])}
        for f, level in zip(factors, idx[1:], strict=True):
            row[f] = f"{f}{level}"
        rows.append(row)
    return pd.DataFrame(rows)


def test_bushtucker_matches_spss_and_jasp() -> None:
    data = read_long_csv(DATA / "reference_bushtucker.csv")
    aov = rm_anova(data, dv="retch", subject="celebrity", within="food")
    assert list(aov.columns) == list(RM_ANOVA_COLUMNS)
    r = aov.iloc[0]
    assert r["effect"] == "food"
    assert (r["df1"], r["df2"]) == (3, 21)
    # JASP (7 significant digits)
    for col, ref in [("SS", 83.125), ("SS_error", 153.375), ("MS_error", 7.303571),
                     ("F", 3.793806), ("p_unc", 0.0255703), ("eps_gg", 0.5328456),
                     ("eps_hf", 0.6657636), ("eps_lb", 0.3333333), ("p_gg", 0.06258412),
                     ("p_hf", 0.04833061), ("mauchly_W", 0.136248)]:
        assert r[col] == pytest.approx(ref, rel=2e-6), col
    # SPSS as printed by Field (3 decimals); GG changes the decision at alpha = .05.
    assert round(r["mauchly_chi2"], 2) == 11.41
    assert r["mauchly_df"] == 5
    assert round(r["mauchly_p"], 3) == 0.047
    assert r["p_unc"] < 0.05 < r["p_gg"]
    # JASP reports p = 0.04684581 through R's mauchly.test, which writes the number of
    # cells (4) instead of p = 3 in the 3p term of Anderson's w2: mauchly_p is R's.
    assert r["mauchly_p"] == pytest.approx(0.04684581, abs=5e-9)
    # With p throughout, Anderson's published formula gives 0.046773 (kept as
    # mauchly_p_anderson; SPSS prints .047 for both). The difference is that term only.
    assert r["mauchly_p_anderson"] == pytest.approx(0.046773, abs=2e-6)
    assert round(r["mauchly_p_anderson"], 3) == 0.047
    assert r["note"] == ""


def test_bushtucker_effect_sizes_closed_form() -> None:
    # One-way within: np2 = SS/(SS+SS_error); ges = SS/SS_total (Bakeman 2005).
    data = read_long_csv(DATA / "reference_bushtucker.csv")
    r = rm_anova(data, dv="retch", subject="celebrity", within="food").iloc[0]
    ss_total = float(((data["retch"] - data["retch"].mean()) ** 2).sum())
    assert r["np2"] == pytest.approx(83.125 / (83.125 + 153.375), rel=1e-12)
    assert r["ges"] == pytest.approx(83.125 / ss_total, rel=1e-12)


def test_two_way_matches_jasp_and_ez() -> None:
    data = read_long_csv(DATA / "reference_rm_anova2.csv")
    aov = rm_anova(data, dv="Performance", subject="Subject", within=["Time", "Metric"])
    assert aov["effect"].tolist() == ["Time", "Metric", "Time:Metric"]
    np.testing.assert_allclose(aov["MS"].round(3), [828.817, 682.617, 112.217])
    np.testing.assert_allclose(aov["F"].round(3), [33.852, 26.959, 12.632])
    np.testing.assert_allclose(aov["np2"].round(3), [0.790, 0.750, 0.584])
    assert aov["df1"].tolist() == [1, 2, 2]
    assert aov["df2"].tolist() == [9, 18, 18]
    time, metric, inter = (aov.iloc[i] for i in range(3))
    # 2-level factor: epsilons 1, Mauchly undefined (NaN, never a made-up number)
    assert time["eps_gg"] == time["eps_hf"] == time["eps_lb"] == 1.0
    assert all(math.isnan(time[c]) for c in
               ("mauchly_W", "mauchly_chi2", "mauchly_df", "mauchly_p"))
    assert time["p_gg"] == time["p_unc"]
    assert "2 levels" in time["note"]
    # ez::ezANOVA
    assert metric["eps_gg"] == pytest.approx(0.9691030, abs=5e-8)
    assert metric["eps_hf"] == 1.0
    assert round(metric["mauchly_W"], 3) == 0.968
    assert metric["mauchly_p"] == pytest.approx(0.8784418, abs=5e-8)
    assert inter["eps_gg"] == pytest.approx(0.7271664, abs=5e-8)
    assert inter["eps_hf"] == pytest.approx(0.831161, abs=5e-7)
    assert round(inter["mauchly_W"], 3) == 0.625
    assert inter["mauchly_p"] == pytest.approx(0.1523917, abs=5e-8)


def test_two_way_generalised_eta_squared_closed_form() -> None:
    # Bakeman (2005), all factors manipulated within subjects:
    # ges = SS_effect / (SS_effect + SS_subjects + SS_AxS + SS_BxS + SS_ABxS)
    data = read_long_csv(DATA / "reference_rm_anova2.csv")
    aov = rm_anova(data, dv="Performance", subject="Subject", within=["Time", "Metric"])
    subj_means = data.groupby("Subject")["Performance"].mean()
    ss_subjects = 6 * ((subj_means - data["Performance"].mean()) ** 2).sum()
    errors = aov["SS_error"].sum()
    for r in aov.to_dict("records"):
        assert r["ges"] == pytest.approx(r["SS"] / (r["SS"] + ss_subjects + errors), rel=1e-12)
        assert r["np2"] == pytest.approx(r["SS"] / (r["SS"] + r["SS_error"]), rel=1e-12)


def test_two_way_against_statsmodels_anovarm() -> None:
    data = read_long_csv(DATA / "reference_rm_anova2.csv")
    ours = rm_anova(data, dv="Performance", subject="Subject", within=["Time", "Metric"])
    ref = AnovaRM(pd.DataFrame(data), "Performance", "Subject",
                  within=["Time", "Metric"]).fit().anova_table
    for _, r in ours.iterrows():
        row = ref.loc[r["effect"]]
        assert r["F"] == pytest.approx(row["F Value"], rel=1e-10)
        assert r["p_unc"] == pytest.approx(row["Pr > F"], rel=1e-8)
        assert (r["df1"], r["df2"]) == (row["Num DF"], row["Den DF"])


def test_three_by_four_interaction_epsilon_matches_ez() -> None:
    # pingouin test_distribution.py: np.random.seed(123); dv = normal(scale=3, size=600)
    rng = np.random.RandomState(123)
    dv = rng.normal(scale=3, size=600)
    df = pd.DataFrame({"dv": dv, "w1": np.repeat(["P1", "P2", "P3"], 200),
                       "w2": np.tile(np.repeat(["A", "B", "C", "D"], 50), 3),
                       "subj": np.tile(np.tile(np.arange(50), 4), 3)})
    aov = rm_anova(df, dv="dv", subject="subj", within=["w1", "w2"])
    w1, w2, inter = (aov.iloc[i] for i in range(3))
    assert w1["eps_gg"] == pytest.approx(0.9963275, abs=5e-8)
    assert w2["eps_gg"] == pytest.approx(0.9716288, abs=5e-8)
    assert w1["eps_hf"] == w2["eps_hf"] == 1.0
    assert round(w2["mauchly_W"], 3) == 0.958
    assert round(w2["mauchly_p"], 4) == 0.8436
    assert round(inter["eps_gg"], 3) == 0.856
    assert inter["mauchly_df"] == 6 * 7 / 2 - 1


def test_cell_means_are_averaged_first() -> None:
    # Three rows per subject x cell whose mean is the Bushtucker value: same ANOVA.
    base = read_long_csv(DATA / "reference_bushtucker.csv")
    spread = pd.concat([base.assign(retch=base["retch"] + d) for d in (-1.5, 0.0, 1.5)])
    a = rm_anova(base, "retch", "celebrity", "food")
    b = rm_anova(spread, "retch", "celebrity", "food")
    pd.testing.assert_frame_equal(a, b, check_exact=False, rtol=1e-12)
    assert b.attrs["n_obs_per_cell"] == (3, 3)


def test_singular_covariance_mauchly_undefined_gg_defined() -> None:
    # 3 subjects, 5 levels: n-1 = 2 < k-1 = 4, the contrast covariance has rank 2.
    y = np.array([[1.0, 3.0, 2.0, 5.0, 4.0], [2.0, 2.5, 4.0, 4.5, 6.0],
                  [0.5, 4.0, 3.0, 7.0, 4.5]])
    with pytest.warns(StatsWarning, match="singular"):
        r = rm_anova(_long(y), dv="y", subject="s", within="A").iloc[0]
    assert all(math.isnan(r[c]) for c in
               ("mauchly_W", "mauchly_chi2", "mauchly_df", "mauchly_p"))
    assert "singular" in r["note"]
    # GG still defined: Box's (1954) formula on the raw (k x k) covariance matrix
    assert r["eps_gg"] == pytest.approx(_box_epsilon(y), rel=1e-12)
    assert 0.25 <= r["eps_gg"] <= 2 / 4 + 1e-12  # rank 2 of p = 4: eps_gg <= rank/p
    assert math.isfinite(r["p_gg"])
    # HF (Lecoutre) defined since n - 1 - p eps_gg = 2 - 4 eps_gg > 0
    g = r["eps_gg"]
    assert r["eps_hf"] == pytest.approx((3 * 4 * g - 2) / (4 * (2 - 4 * g)), rel=1e-12)


def test_two_subjects_hf_undefined() -> None:
    # n = 2: one difference vector, eps_gg = 1/p exactly and HF's denominator is 0.
    y = np.array([[1.0, 3.0, 2.0, 5.0], [2.0, 2.5, 4.0, 4.5]])
    with pytest.warns(StatsWarning, match="singular"):
        r = rm_anova(_long(y), dv="y", subject="s", within="A").iloc[0]
    assert r["eps_gg"] == pytest.approx(1 / 3, rel=1e-12)
    assert math.isnan(r["eps_hf"]) and math.isnan(r["p_hf"])
    assert "Huynh-Feldt epsilon undefined" in r["note"]
    assert math.isnan(r["mauchly_W"])


def _box_epsilon(y: np.ndarray) -> float:
    """Greenhouse-Geisser epsilon from the raw covariance matrix (Box 1954, Winer 1971)."""
    s = np.cov(y, rowvar=False)
    k = s.shape[0]
    num = k**2 * (np.mean(np.diag(s)) - s.mean()) ** 2
    den = (k - 1) * ((s**2).sum() - 2 * k * (s.mean(axis=1) ** 2).sum() + k**2 * s.mean() ** 2)
    return float(num / den)


def test_gg_epsilon_matches_box_formula_on_bushtucker() -> None:
    data = read_long_csv(DATA / "reference_bushtucker.csv")
    y = data.pivot(index="celebrity", columns="food", values="retch").to_numpy(dtype=float)
    r = rm_anova(data, dv="retch", subject="celebrity", within="food").iloc[0]
    assert r["eps_gg"] == pytest.approx(_box_epsilon(y), rel=1e-12)


def test_zero_error_variance_gives_nan_not_inf() -> None:
    # Every subject shows exactly the same pattern: SS_error = 0.
    pattern = np.array([1.0, 2.0, 4.0])
    y = np.stack([pattern + s for s in range(4)])
    with pytest.warns(StatsWarning, match="zero error"):
        r = rm_anova(_long(y), dv="y", subject="s", within="A").iloc[0]
    assert math.isnan(r["F"]) and math.isnan(r["p_unc"]) and math.isnan(r["eps_gg"])
    assert r["SS"] > 0


# --- properties --------------------------------------------------------------------


def _matrix(shape: tuple[int, ...]) -> st.SearchStrategy[np.ndarray]:
    return hnp.arrays(np.float64, shape, elements=st.integers(-20, 20).map(float))


@st.composite
def designs(draw: st.DrawFn) -> np.ndarray:
    n = draw(st.integers(3, 7))
    k = draw(st.integers(2, 5))
    return draw(_matrix((n, k)))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(y=designs(), shift=hnp.arrays(np.float64, 7, elements=st.integers(-100, 100).map(float)))
def test_properties_one_way(y: np.ndarray, shift: np.ndarray) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StatsWarning)
        r = rm_anova(_long(y), "y", "s", "A").iloc[0]
        # adding a constant per subject changes nothing within subjects
        r2 = rm_anova(_long(y + shift[: y.shape[0], None]), "y", "s", "A").iloc[0]
    n, k = y.shape
    p = k - 1
    assert (r["df1"], r["df2"]) == (p, p * (n - 1))
    for col in ("SS", "SS_error", "F", "eps_gg", "eps_hf", "mauchly_W"):
        a, b = r[col], r2[col]
        assert (math.isnan(a) and math.isnan(b)) or a == pytest.approx(b, rel=1e-7, abs=1e-9)
    for col in ("p_unc", "p_gg", "p_hf", "p_lb", "mauchly_p", "np2", "ges"):
        assert math.isnan(r[col]) or 0.0 <= r[col] <= 1.0, col
    if math.isfinite(r["eps_gg"]):
        assert 1.0 / p - 1e-12 <= r["eps_gg"] <= 1.0 + 1e-12
        if k > 2:
            assert r["eps_gg"] == pytest.approx(_box_epsilon(y), rel=1e-9)
        assert r["eps_lb"] == pytest.approx(1.0 / p)
    if math.isfinite(r["eps_hf"]):
        assert r["eps_gg"] - 1e-12 <= r["eps_hf"] <= 1.0
    if math.isfinite(r["p_gg"]) and r["eps_gg"] == 1.0:
        assert r["p_gg"] == r["p_unc"]
    if math.isfinite(r["ges"]) and math.isfinite(r["np2"]):
        assert r["ges"] <= r["np2"] + 1e-12


@settings(max_examples=15, deadline=None)
@given(y=_matrix((5, 2, 3)))
def test_two_way_sums_of_squares_partition(y: np.ndarray) -> None:
    # SS_A + SS_B + SS_AB + SS_subjects + all SS_error = SS_total (orthogonal decomposition)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StatsWarning)
        aov = rm_anova(_long(y, ("A", "B")), "y", "s", ["A", "B"])
    ss_subjects = 6 * ((y.reshape(5, -1).mean(axis=1) - y.mean()) ** 2).sum()
    total = ((y - y.mean()) ** 2).sum()
    assert aov["SS"].sum() + aov["SS_error"].sum() + ss_subjects == pytest.approx(
        total, rel=1e-9, abs=1e-9)


# --- bad input -----------------------------------------------------------------------


def test_missing_column_names_column_and_file() -> None:
    data = read_long_csv(DATA / "reference_bushtucker.csv")
    with pytest.raises(ConfigError, match="column 'time' not found") as err:
        rm_anova(data, dv="time", subject="celebrity", within="food")
    assert "reference_bushtucker.csv" in str(err.value)
    assert err.value.field == "time"


def test_unbalanced_design_lists_missing_cells() -> None:
    data = read_long_csv(DATA / "reference_bushtucker.csv")
    drop = data[~((data["celebrity"] == 3) & (data["food"] == "fish_eye"))]
    with pytest.raises(ConfigError, match="unbalanced") as err:
        rm_anova(drop, dv="retch", subject="celebrity", within="food")
    assert "celebrity=3 x food='fish_eye'" in str(err.value)


def test_non_numeric_and_non_finite_values_named() -> None:
    data = read_long_csv(DATA / "reference_bushtucker.csv")
    bad = data.astype({"retch": object})
    bad.loc[5, "retch"] = "n/a"
    with pytest.raises(ConfigError, match=r"non-numeric values at line 5: 'n/a'"):
        rm_anova(bad, dv="retch", subject="celebrity", within="food")
    bad = data.astype({"retch": float})
    bad.loc[7, "retch"] = np.inf
    with pytest.raises(ConfigError, match=r"non-finite values at line 7: inf"):
        rm_anova(bad, dv="retch", subject="celebrity", within="food")
    bad.loc[7, "retch"] = np.nan
    with pytest.raises(ConfigError, match=r"missing \(NaN/empty\) values at line 7"):
        rm_anova(bad, dv="retch", subject="celebrity", within="food")


def test_too_few_subjects_or_levels() -> None:
    data = read_long_csv(DATA / "reference_bushtucker.csv")
    with pytest.raises(ConfigError, match="at least 2 subjects"):
        rm_anova(data[data["celebrity"] == 1], "retch", "celebrity", "food")
    with pytest.raises(ConfigError, match="at least 2 levels"):
        rm_anova(data[data["food"] == "fish_eye"], "retch", "celebrity", "food")
    with pytest.raises(ConfigError, match="one or two within factors"):
        rm_anova(data, "retch", "celebrity", [])


def test_missing_factor_label_named() -> None:
    data = read_long_csv(DATA / "reference_bushtucker.csv")
    data.loc[3, "food"] = np.nan
    with pytest.raises(ConfigError, match="column 'food' has missing labels at line 3"):
        rm_anova(data, "retch", "celebrity", "food")


# --- statistics refuse what they cannot estimate (issue #16 item 2) ---------------------


def test_zero_error_variance_effect_sizes_are_nan_with_note() -> None:
    pattern = np.array([1.0, 2.0, 4.0])
    y = np.stack([pattern + s for s in range(4)])
    with pytest.warns(StatsWarning, match="effect sizes undefined"):
        r = rm_anova(_long(y), dv="y", subject="s", within="A").iloc[0]
    assert math.isnan(r["np2"]) and math.isnan(r["ges"])  # were 1.0 and 0.93
    assert "zero error variance" in r["note"]


@pytest.mark.parametrize("y", [
    np.full((4, 3), 0.1),                                      # constant dv (issue #16)
    np.array([0.1, 1.1, 2.3, 5.7])[:, None] + np.array([0.3, 0.7, 1.9])[None, :],  # round-off
])
def test_zero_error_within_round_off_is_zero(y: np.ndarray) -> None:
    # The second design has SS_error = 5.5e-30 from rounding alone; it must not give an F of
    # 1e30 or an eta squared of 1.
    with pytest.warns(StatsWarning, match="zero error variance"):
        r = rm_anova(_long(y), dv="y", subject="s", within="A").iloc[0]
    for col in ("F", "p_unc", "np2", "ges", "eps_gg", "p_gg"):
        assert math.isnan(r[col]), col


def test_two_way_zero_error_only_where_zero() -> None:
    # A: every subject the same +1 step (zero A x S error); B: noisy.
    rng = np.random.default_rng(5)
    y = rng.normal(size=(5, 1, 3)) + np.array([0.0, 1.0])[None, :, None]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", StatsWarning)
        aov = rm_anova(_long(y, ("A", "B")), dv="y", subject="s", within=["A", "B"])
    a, b, ab = (aov.iloc[i] for i in range(3))
    assert math.isnan(a["np2"]) and math.isnan(a["F"]) and "zero error" in a["note"]
    # A is additive, so A x B has no error either; B keeps its noise
    assert math.isnan(ab["np2"]) and "zero error" in ab["note"]
    assert 0 < b["np2"] < 1 and "zero error" not in b["note"]
    assert sorted(str(w.message).split("'")[1] for w in caught) == ["A", "A:B"]


def test_overflowing_sums_of_squares_are_nan_with_note() -> None:
    y = np.array([[1e200, -1e200], [-1e200, 1e200], [3e200, 2e200]])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        with pytest.warns(StatsWarning, match="overflow"):
            r = rm_anova(_long(y), dv="y", subject="s", within="A").iloc[0]
    assert math.isnan(r["np2"]) and math.isnan(r["F"]) and "overflow" in r["note"]


def test_mauchly_r_and_anderson_agree_up_to_three_levels() -> None:
    # w2 has the factor (p - 2): with 3 levels (p = 2) R's cells-for-p term cannot matter.
    data = read_long_csv(DATA / "reference_rm_anova2.csv")
    aov = rm_anova(data, dv="Performance", subject="Subject", within=["Time", "Metric"])
    for r in aov.iloc[1:].to_dict("records"):
        assert r["mauchly_p"] == r["mauchly_p_anderson"]
