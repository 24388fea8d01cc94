"""The PRIMARY learning analysis of the VF study (issue #25): the VF-free probe after each
fixture block.

The question a VF training study asks is transfer: does practice *with* a fixture improve
the *next unassisted* performance? Each probe that closes a fixture block is modelled by
the fixture just practised, with the block position (practice) as a covariate, the
trajectory variant as a factor and a random intercept per subject (statsmodels
``MixedLM``, REML)::

    dv ~ C(practised) + block_position + C(variant),   random intercept per subject

**Decisions**:

* Rows: the probes that close a fixture block (5 per subject in the VF protocol); the
  baseline probes are left out (nothing was practised before them, and they always come
  first: practice, not a fixture level).
* ``block_position`` is the block's position in the session (1..5), a linear covariate
  (with a Williams design every fixture occupies every position equally often, so the
  fixture estimates do not lean on the linearity).
* The variant is a fixed factor: six levels balanced against the fixture by the design
  (``probe.variants`` rotation), too few levels to estimate a variance well.
* Fixture effects are reported as each fixture's difference from the mean of the
  fixtures (sum-to-zero contrasts of the treatment-coded fit, ``t_test``), with 95 % Wald
  intervals.
* Tests (``_nested_f``): F tests of nested within-subject OLS models (subject as a fixed
  effect; exact under normal errors at any N): the fixture term; the variant term; and
  carry-over, reported, not assumed away: adding ``C(previous)``, the fixture practised
  in the block *before* (``none`` after the baseline). A Williams design balances
  first-order carry-over, which makes the term estimable beside ``practised``.
"""

from __future__ import annotations

import math
import re
import warnings
from typing import Any

import numpy as np
import pandas as pd
import statsmodels.formula.api as smf
from statsmodels.stats.anova import anova_lm

from vasim.core.errors import ConfigError
from vasim.study import stats
from vasim.study.report.common import FIXTURE_ORDER, ordered_conditions

FORMULA = "{dv} ~ C(practised) + block_position + C(variant)"
"""The primary probe model's fixed effects (``{dv}`` the outcome column)."""
CARRY_OVER_TERM = "C(previous)"
"""The term whose likelihood-ratio test reports carry-over."""
TRANSFER_COLUMNS: tuple[str, ...] = ("dv", "unit", "term", "condition", "coef", "se", "z",
                                     "p", "ci_low", "ci_high", "n_obs", "n_subjects", "note")
"""Columns of the ``vf_transfer_model`` table (one row per reported estimate)."""
TEST_COLUMNS: tuple[str, ...] = ("dv", "unit", "test", "F", "df1", "df2", "p", "n_obs",
                                 "n_subjects", "note")
"""Columns of the ``vf_transfer_tests`` table (fixture, variant, carry-over)."""

_LEVEL = re.compile(r"^C\((\w+)\)\[T\.(.+)\]$")


def probe_model_data(trials: pd.DataFrame, dv: str) -> pd.DataFrame:
    """The rows of the primary model: every analysed probe that closes a fixture block.

    Args:
        trials: ``VfAnalysis.trials`` (``subject, practised, previous, block_position,
            variant, probe`` and ``dv``).
        dv: the outcome column.

    Returns:
        ``trial_id, subject, practised, previous, block_position, variant, <dv>``;
        ``practised`` a categorical in report order (its first level is the fit's
        treatment reference), ``variant`` text.

    Example:
        >>> t = pd.DataFrame({"trial_id": [1, 2, 3], "subject": "a", "probe": True,
        ...     "practised": ["", "ff", "vg"], "previous": ["", "none", "ff"],
        ...     "block_position": [0, 1, 2], "variant": [1, 2, 3], "latency": [9., 5., 4.]})
        >>> d = probe_model_data(t, "latency")
        >>> d["practised"].tolist(), list(d["practised"].cat.categories)
        (['ff', 'vg'], ['vg', 'ff'])
    """
    d = trials[trials["probe"].astype(bool) & (trials["practised"].astype(str) != "")
               & trials[dv].notna()]
    out = pd.DataFrame({
        "trial_id": d["trial_id"].to_numpy(), "subject": d["subject"].astype(str).to_numpy(),
        "practised": d["practised"].astype(str).to_numpy(),
        "previous": d["previous"].astype(str).to_numpy(),
        "block_position": d["block_position"].astype(np.int64).to_numpy(),
        "variant": ["v" + str(int(v)) for v in d["variant"]],
        dv: d[dv].astype(float).to_numpy()})
    levels = ordered_conditions(out["practised"], FIXTURE_ORDER)
    out["practised"] = pd.Categorical(out["practised"], categories=levels)
    return out


def transfer_model(trials: pd.DataFrame, dv: str, unit: str
                   ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The primary probe model of one outcome (module docstring).

    Args:
        trials: ``VfAnalysis.trials``. dv: the outcome column. unit: its unit.

    Returns:
        (estimates: :data:`TRANSFER_COLUMNS`, one row per fixture effect (difference from
        the mean of the fixtures, term ``fixture``), the block-position slope (term
        ``block_position``, unit of the dv per block) and each variant contrast (term
        ``variant``, difference from the first variant); tests: :data:`TEST_COLUMNS`, rows
        ``fixture``, ``variant`` and ``carry_over`` (nested F tests, ``_nested_f``;
        ``note`` says why when one is not computed)).

    Raises:
        ConfigError: fewer than 2 subjects or 2 practised fixtures, or statsmodels cannot
            fit the model.
    """
    d = probe_model_data(trials, dv)
    n_sub = int(d["subject"].nunique())
    fixtures = [str(c) for c in d["practised"].cat.categories if (d["practised"] == c).any()]
    if len(fixtures) < 2:
        raise ConfigError(f"{len(fixtures)} practised fixture(s) among the probes; the "
                          "transfer model needs 2", field=dv)
    d["practised"] = d["practised"].cat.remove_unused_categories()
    terms = ["C(practised)", "block_position"]
    if d["block_position"].nunique() < 2:
        terms.remove("block_position")
    if d["variant"].nunique() > 1:
        terms.append("C(variant)")
    formula = f"{dv} ~ " + " + ".join(terms)
    result, note = stats.fit_mixed_model(d, formula, "subject")
    names = [str(n) for n in result.fe_params.index]
    fe = result.fe_params
    n_obs = int(result.nobs)
    rows: list[dict[str, Any]] = []
    # fixture k vs the mean of the K fixtures: beta_k - mean_j beta_j (reference beta = 0)
    coef_of = {f: (names.index(f"C(practised)[T.{f}]") if i else None)
               for i, f in enumerate(fixtures)}
    k = len(fixtures)
    for f in fixtures:
        L = np.zeros(len(names))
        for g, idx in coef_of.items():
            if idx is not None:
                L[idx] += (1.0 if g == f else 0.0) - 1.0 / k
        t = result.t_test(L[None, :])
        est, se = float(np.squeeze(t.effect)), float(np.squeeze(t.sd))
        lo, hi = (float(v) for v in np.squeeze(t.conf_int()))
        rows.append({"term": "fixture", "condition": f, "coef": est, "se": se,
                     "z": est / se if se > 0 else math.nan,
                     "p": float(np.squeeze(t.pvalue)), "ci_low": lo, "ci_high": hi})
    ci = result.conf_int()
    for name in fe.index:
        m = _LEVEL.match(str(name))
        is_variant = m is not None and m.group(1) == "variant"
        if name == "block_position" or is_variant:
            rows.append({"term": "variant" if is_variant else "block_position",
                         "condition": m.group(2) if m is not None and is_variant else "",
                         "coef": float(fe[name]), "se": float(result.bse_fe[name]),
                         "z": float(result.tvalues[name]), "p": float(result.pvalues[name]),
                         "ci_low": float(ci.loc[name].iloc[0]),
                         "ci_high": float(ci.loc[name].iloc[1])})
    est = pd.DataFrame(rows)
    est.insert(0, "dv", dv)
    est.insert(1, "unit", unit)
    est["n_obs"], est["n_subjects"], est["note"] = n_obs, n_sub, note
    tests = [_nested_f(d, dv, terms, "C(practised)", "fixture"),
             _nested_f(d, dv, terms, "C(variant)", "variant"),
             _nested_f(d, dv, terms, CARRY_OVER_TERM, "carry_over")]
    for t in tests:
        t["note"] = "; ".join(x for x in (t["note"], note) if x)
    tt = pd.DataFrame(tests)
    tt.insert(0, "dv", dv)
    tt.insert(1, "unit", unit)
    tt["n_obs"], tt["n_subjects"] = n_obs, n_sub
    est.attrs.update({"formula": formula, "fixtures": tuple(fixtures)})
    return est[list(TRANSFER_COLUMNS)], tt[list(TEST_COLUMNS)]


def _nested_f(d: pd.DataFrame, dv: str, terms: list[str], term: str, name: str
              ) -> dict[str, Any]:
    """The F test of ``term`` in the within-subject model: nested OLS fits (statsmodels
    ``anova_lm``) of ``dv ~ C(subject) + <terms>`` without and with ``term`` (for
    ``C(previous)``, added to the terms; otherwise one of them, left out of the reduced
    model).

    **Decision**: the tests are F tests with the subject as a fixed effect, exact under
    normal errors whatever the number of subjects; the Wald and likelihood-ratio
    chi-square tests of the mixed model are anti-conservative with 5 probes per subject
    (a null cohort of 10 subjects gave carry-over p = 0.009 by the LR test).
    """
    row: dict[str, Any] = {"test": name, "F": math.nan, "df1": 0, "df2": 0, "p": math.nan}
    col = term[2:-1]
    if d[col].nunique() < 2:
        return {**row, "note": f"one level of {col}: no {name} test"}
    full_terms = [*terms, term] if term not in terms else terms
    red_terms = [t for t in full_terms if t != term]
    data = d.assign(subject=d["subject"].astype(str))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            red = smf.ols(f"{dv} ~ " + " + ".join(["C(subject)", *red_terms]), data).fit()
            ful = smf.ols(f"{dv} ~ " + " + ".join(["C(subject)", *full_terms]), data).fit()
            aov = anova_lm(red, ful)
    except (ValueError, np.linalg.LinAlgError) as exc:
        return {**row, "note": f"not computed: {exc}"}
    r = aov.iloc[1]
    df1, df2 = float(r["df_diff"]), float(ful.df_resid)
    if not (df1 > 0 and df2 > 0 and math.isfinite(float(r["F"]))):
        return {**row, "note": f"not estimable ({df1:g} numerator, {df2:g} residual df)"}
    return {**row, "F": float(r["F"]), "df1": int(df1), "df2": int(df2),
            "p": float(r["Pr(>F)"]), "note": ""}


__all__ = ["CARRY_OVER_TERM", "FORMULA", "TEST_COLUMNS", "TRANSFER_COLUMNS",
           "probe_model_data", "transfer_model"]
