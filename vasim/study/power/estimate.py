"""Power estimates and their Monte Carlo error (pure).

Each design point (subject count N) simulates ``cohorts`` independent cohorts; a test's
power is estimated by the share of cohorts in which it rejects,
``p_hat = rejections / cohorts``, a binomial proportion whose Monte Carlo standard error is
``sqrt(p_hat (1 - p_hat) / cohorts)`` (:func:`mc_standard_error`). The table also gives a
95 % Wilson score interval (``statsmodels.stats.proportion.proportion_confint``), which,
unlike p_hat +- 1.96 se, stays inside [0, 1] and is not degenerate at 0 or 1 rejections.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from statsmodels.stats.proportion import proportion_confint

COHORT_COLUMNS: tuple[str, ...] = ("n_subjects", "cohort", "seed", "dv", "factor",
                                   "n_complete", "F", "p_unc", "p_gg", "np2", "reason")
"""One row per cohort and primary test: what each simulated cohort's analysis gave."""
POWER_COLUMNS: tuple[str, ...] = ("dv", "factor", "test", "n_subjects", "cohorts",
                                  "rejections", "not_computed", "power", "mc_se",
                                  "ci_low", "ci_high", "alpha", "p_column")
"""Columns of :func:`power_table`."""
TEST_NAMES: dict[tuple[str, str], str] = {
    ("path_deviation", "practised"): "PRIMARY probe model: fixture practised, path deviation",
    ("latency", "practised"): "PRIMARY probe model: fixture practised, latency",
    ("eq65", "practised"): "PRIMARY probe model: fixture practised, eq. 6.5 e",
    ("path_deviation", "fixture"): "seed RM-ANOVA: fixture effect on path deviation",
    ("latency", "fixture"): "seed RM-ANOVA: fixture effect on latency",
    ("eq65", "fixture"): "seed RM-ANOVA: fixture effect on eq. 6.5 e",
    ("path_deviation", "trial"): "seed RM-ANOVA: practice effect on path deviation",
    ("latency", "trial"): "seed RM-ANOVA: practice effect on latency",
    ("eq65", "trial"): "seed RM-ANOVA: practice effect on eq. 6.5 e",
}
"""Names of the tests (dv, factor) in tables and figures, in print order: the PRIMARY
analysis (the post-block probe model's nested F test of the fixture just practised,
``vasim.study.report.primary.probe_model_tests``) first, then the seed's RM-ANOVAs
(secondary, named as the seed's)."""


def mc_standard_error(power: float, cohorts: int) -> float:
    """Monte Carlo standard error of a power estimate, ``sqrt(p (1 - p) / cohorts)``.

    Args:
        power: the estimate p in [0, 1]. cohorts: the number of simulated cohorts (>= 1).

    Raises:
        ValueError: p outside [0, 1] or cohorts < 1.

    Example:
        >>> mc_standard_error(0.8, 200)
        0.0282842712474619
        >>> mc_standard_error(1.0, 10)
        0.0
    """
    if not (0.0 <= power <= 1.0) or not cohorts >= 1:
        raise ValueError(f"power must be in [0, 1] and cohorts >= 1, got {power!r}, "
                         f"{cohorts!r}")
    return math.sqrt(power * (1.0 - power) / cohorts)


def power_table(cohorts: pd.DataFrame, *, alpha: float, p_column: str = "p_gg"
                ) -> pd.DataFrame:
    """Power of every primary test at every N, from the per-cohort test results.

    Args:
        cohorts: one row per cohort and test (:data:`COHORT_COLUMNS`; at least
            ``n_subjects, cohort, dv, factor`` and ``p_column``).
        alpha: significance level: a test rejects when its p < alpha.
        p_column: the p-value column the decision uses (``"p_gg"`` or ``"p_unc"``).

    Returns:
        :data:`POWER_COLUMNS`, sorted by test (:data:`TEST_NAMES` order) then N; a NaN p
        (test not computed) is a non-rejection, counted in ``not_computed``.

    Example:
        >>> c = pd.DataFrame({"n_subjects": [4] * 4, "cohort": [0, 1, 2, 3],
        ...                   "dv": ["latency"] * 4, "factor": ["fixture"] * 4,
        ...                   "p_gg": [0.01, 0.2, 0.04, float("nan")]})
        >>> r = power_table(c, alpha=0.05).iloc[0]
        >>> int(r.rejections), int(r.not_computed), float(r.power), round(float(r.mc_se), 4)
        (2, 1, 0.5, 0.25)
    """
    rows = []
    for (dv, factor, n), g in cohorts.groupby(["dv", "factor", "n_subjects"], sort=True):
        p = g[p_column].to_numpy(dtype=float)
        m = int(g["cohort"].nunique())
        rej = int(np.sum(p < alpha))   # NaN < alpha is False: not computed = not rejected
        est = rej / m
        lo, hi = proportion_confint(rej, m, alpha=0.05, method="wilson")
        lo, hi = min(float(lo), est), max(float(hi), est)   # rounding at 0 or m rejections
        rows.append({"dv": dv, "factor": factor,
                     "test": TEST_NAMES.get((str(dv), str(factor)), f"{factor} on {dv}"),
                     "n_subjects": int(n), "cohorts": m, "rejections": rej,
                     "not_computed": int(np.sum(np.isnan(p))), "power": est,
                     "mc_se": mc_standard_error(est, m), "ci_low": float(lo),
                     "ci_high": float(hi), "alpha": alpha, "p_column": p_column})
    out = pd.DataFrame(rows, columns=list(POWER_COLUMNS))
    order = {k: i for i, k in enumerate(TEST_NAMES)}   # fixture tests first, then practice
    key = [order.get((str(d), str(f)), len(order)) for d, f in zip(out["dv"], out["factor"],
                                                                  strict=True)]
    return (out.assign(_k=key).sort_values(["_k", "dv", "factor", "n_subjects"])
            .drop(columns="_k").reset_index(drop=True))


def smallest_n(table: pd.DataFrame, target: float = 0.8) -> dict[str, int | None]:
    """Per test, the smallest N of the grid whose estimated power reaches ``target``.

    Example:
        >>> t = pd.DataFrame({"test": ["a", "a", "b"], "n_subjects": [8, 12, 8],
        ...                   "power": [0.5, 0.85, 0.2]})
        >>> smallest_n(t)
        {'a': 12, 'b': None}
    """
    out: dict[str, int | None] = {}
    for test, g in table.groupby("test", sort=False):
        ok = g.loc[g["power"] >= target, "n_subjects"]
        out[str(test)] = int(ok.min()) if len(ok) else None
    return out


__all__ = ["COHORT_COLUMNS", "POWER_COLUMNS", "TEST_NAMES", "mc_standard_error",
           "power_table", "smallest_n"]
