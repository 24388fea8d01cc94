"""Tests of the linear mixed model wrapper (vasim/study/stats/mixed_model.py).

References: a simulated cohort with known fixed effects (each must lie in its 95 % CI), and
statsmodels' ``MixedLM.from_formula(...).fit(reml=True)`` called directly.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import statsmodels.formula.api as smf

from vasim.core.errors import ConfigError
from vasim.study.stats import MIXED_MODEL_COLUMNS, StatsWarning, mixed_model, read_long_csv

FIX = "C(fixture, Treatment('none'))"
FORMULA = f"error ~ {FIX} + trial"
TRUE = {"Intercept": 10.0, f"{FIX}[T.ff]": -2.0, f"{FIX}[T.vg]": -1.0, "trial": -0.3}


def _cohort(seed: int = 7, n_subjects: int = 24) -> pd.DataFrame:
    """Subjects x 3 fixtures x 4 trials; random intercept sd 1.5, residual sd 0.8 (mm)."""
    rng = np.random.default_rng(seed)
    rows = []
    for s in range(n_subjects):
        u = rng.normal(0.0, 1.5)
        for fixture in ("none", "ff", "vg"):
            for trial in range(4):
                fx = {"none": 0.0, "ff": TRUE[f"{FIX}[T.ff]"], "vg": TRUE[f"{FIX}[T.vg]"]}[fixture]
                y = TRUE["Intercept"] + fx + TRUE["trial"] * trial + u + rng.normal(0.0, 0.8)
                rows.append({"subject": f"S{s:02d}", "fixture": fixture, "trial": trial,
                             "error": y})
    return pd.DataFrame(rows)


def test_known_fixed_effects_recovered_within_ci() -> None:
    fit = mixed_model(_cohort(), FORMULA, groups="subject")
    assert list(fit.columns) == list(MIXED_MODEL_COLUMNS)
    assert fit["term"].tolist() == list(TRUE)
    for row in fit.to_dict("records"):
        assert row["ci_low"] < TRUE[row["term"]] < row["ci_high"], row
        assert row["note"] == ""
    # the random-intercept and residual variances are near the simulated 1.5^2 and 0.8^2
    assert fit.attrs["group_var"] == pytest.approx(1.5**2, rel=0.5)
    assert fit.attrs["resid_var"] == pytest.approx(0.8**2, rel=0.2)
    assert fit.attrs["n_groups"] == 24 and fit.attrs["n_obs"] == 24 * 12
    assert fit.attrs["converged"] is True


def test_same_numbers_as_direct_statsmodels_call() -> None:
    data = _cohort(seed=3)
    fit = mixed_model(data, FORMULA, groups="subject")
    ref = smf.mixedlm(FORMULA, data, groups=data["subject"]).fit(reml=True)
    fe = ref.fe_params.index
    np.testing.assert_allclose(fit["coef"], ref.fe_params, rtol=1e-10)
    np.testing.assert_allclose(fit["se"], ref.bse_fe, rtol=1e-10)
    np.testing.assert_allclose(fit["z"], ref.tvalues[fe], rtol=1e-10)
    np.testing.assert_allclose(fit["p"], ref.pvalues[fe], rtol=1e-10)
    np.testing.assert_allclose(fit[["ci_low", "ci_high"]], ref.conf_int().loc[fe], rtol=1e-10)
    # Wald: z = coef/se, 95 % interval coef -+ 1.95996 se
    np.testing.assert_allclose(fit["z"], fit["coef"] / fit["se"], rtol=1e-12)
    np.testing.assert_allclose(fit["ci_high"] - fit["coef"], 1.959964 * fit["se"], rtol=1e-6)
    assert fit.attrs["llf"] == pytest.approx(ref.llf, rel=1e-12)


def test_boundary_fit_is_noted_not_silent() -> None:
    # No subject effect at all and 4 small groups: the random-intercept variance ends on the
    # boundary (0); statsmodels warns and the wrapper must say so.
    rng = np.random.default_rng(1)
    data = pd.DataFrame({"s": np.repeat(["a", "b", "c", "d"], 5), "y": rng.normal(size=20),
                         "x": np.tile(np.arange(5.0), 4)})
    with pytest.warns(StatsWarning, match="boundary"):
        fit = mixed_model(data, "y ~ x", groups="s")
    assert fit["note"].str.contains("boundary").all()
    assert fit.attrs["group_var"] < 1e-6


def test_non_convergence_is_noted() -> None:
    rng = np.random.default_rng(0)
    data = pd.DataFrame({"s": np.repeat(["a", "b", "c", "d"], 5), "y": rng.normal(size=20),
                         "x": np.tile(np.arange(5.0), 4)})
    with pytest.warns(StatsWarning, match="converge"):
        fit = mixed_model(data, "y ~ x", groups="s")
    assert fit.attrs["converged"] is False
    assert fit["note"].str.contains("converge").all()


def test_bad_input_named() -> None:
    data = _cohort(n_subjects=4)
    with pytest.raises(ConfigError, match="'subj' not found"):
        mixed_model(data, "error ~ trial", groups="subj")
    with pytest.raises(ConfigError, match=r"response column 'err' .* not found"):
        mixed_model(data, "err ~ trial", groups="subject")
    with pytest.raises(ConfigError, match="formula must be"):
        mixed_model(data, "error + trial", groups="subject")
    # a name that is no column is refused before patsy (issue #30: the formula whitelist)
    with pytest.raises(ConfigError, match=r"got 'trail' at character 8 .* expected a column"):
        mixed_model(data, "error ~ trail", groups="subject")
    bad = data.copy()
    bad.loc[5, "error"] = np.nan
    with pytest.raises(ConfigError, match="'error' has missing"):
        mixed_model(bad, "error ~ trial", groups="subject")
    bad.loc[5, "error"] = np.inf
    with pytest.raises(ConfigError, match="'error' has non-finite values at row index 5"):
        mixed_model(bad, "error ~ trial", groups="subject")
    one = data[data["subject"] == "S00"]
    with pytest.raises(ConfigError, match="at least 2 levels"):
        mixed_model(one, "error ~ trial", groups="subject")


def test_no_warning_leaks_on_a_clean_fit() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mixed_model(_cohort(seed=11), FORMULA, groups="subject")


def test_value_columns_left_as_text_are_numbers(tmp_path: Path) -> None:
    # "10" and "10.0" in the response keep read_long_csv from converting it (labels never
    # merge); in the formula it is still a number, not a categorical response.
    data = _cohort(seed=5, n_subjects=6)
    text = data.assign(error=[f"{v:.1f}" for v in data["error"].round(1)])
    text.loc[0, "error"] = "10"  # the same number as "10.0" elsewhere would be
    text.loc[1, "error"] = "10.0"
    p = tmp_path / "mixed_text.csv"
    text.to_csv(p, index=False)
    read = read_long_csv(p, text_columns=["subject", "fixture"])
    assert pd.api.types.is_string_dtype(read["error"])  # stayed text
    fit = mixed_model(read, FORMULA, groups="subject")
    numeric = text.assign(error=text["error"].astype(float))
    ref = mixed_model(numeric, FORMULA, groups="subject")
    np.testing.assert_allclose(fit["coef"], ref["coef"], rtol=1e-10)
