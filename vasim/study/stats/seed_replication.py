"""REPLICATION ONLY: the seed's per-sample two-way ANOVA (fixture x trial), not the result.

spec/study.md §3 **decision**: the seed reports F(5, 98131) = 35.030 (error) and 44.099
(latency) for the fixture factor and F(7, 98131) = 22.871 and 87.344 for the trial factor.
A denominator df of 98131 means every per-point sample entered the ANOVA as an independent
observation. Samples of the same subject and trial are strongly correlated, so this
inflates the df and makes p far too small (pseudo-replication). The primary analysis is the
subject-level RM-ANOVA of :func:`vasim.study.stats.anova.rm_anova`; this module only
reproduces the seed's computation so that its numbers can be compared, and every output
carries the label :data:`SEED_LABEL`.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np
import pandas as pd
import statsmodels.formula.api as smf
from statsmodels.stats.anova import anova_lm

from vasim.core.errors import ConfigError
from vasim.study.stats._data import (
    StatsWarning,
    error_ss_is_zero,
    factor_column,
    levels_of,
    numeric_column,
    require_columns,
    require_frame,
    source_of,
)

#: Label attached to every replication table (``result.attrs["label"]``).
SEED_LABEL = ("seed replication: per-sample ANOVA treating samples as independent "
              "(pseudo-replicated df); not the primary analysis")

#: Column order of :func:`seed_per_sample_anova`.
SEED_ANOVA_COLUMNS: tuple[str, ...] = ("effect", "SS", "df1", "df2", "F", "p")


def seed_per_sample_anova(data: pd.DataFrame, dv: str,
                          factors: Sequence[str] = ("fixture", "trial"), *,
                          interaction: bool = False) -> pd.DataFrame:
    """The seed's between-subjects-style two-way ANOVA over per-sample rows (replication).

    Every row (per-point sample) is one observation; subjects are ignored, as in the seed.
    Not the primary analysis: the rows of one subject and trial are not independent, so the
    denominator df (tens of thousands) and the p-values are not valid inference. Use
    :func:`vasim.study.stats.anova.rm_anova` on subject-level cell means instead.

    Args:
        data: long-format per-sample table.
        dv: dependent variable (finite numbers; the seed: eq. 6.5's e, its "cumulative
            error", or latency).
        factors: the two factor columns (the seed: fixture with 6 levels, trial).
        interaction: also fit the factor interaction (every factor cell must have data).
            The seed's df suggest an additive model; with the interaction df2 shrinks by
            the number of interaction parameters.

    Returns:
        One row per model term (factor A, factor B[, A:B]) with columns
        :data:`SEED_ANOVA_COLUMNS`: ``effect``, ``SS`` (type II sum of squares), ``df1``,
        ``df2`` (residual df, the same for every term), ``F`` and ``p`` (NaN, with a
        :class:`StatsWarning`, when the residual sum of squares is zero within round-off,
        :func:`vasim.study.stats._data.error_ss_is_zero`).
        ``result.attrs["label"]`` is :data:`SEED_LABEL`.

    Raises:
        ConfigError: bad columns or values, a factor with fewer than 2 levels, no residual
            df, or a missing factor cell when ``interaction`` is set.

    Notes:
        Ordinary least squares ``dv ~ C(A) + C(B) [+ C(A):C(B)]`` (statsmodels
        ``ols``) and ``anova_lm(typ=2)``. For the additive model type II and type III
        sums of squares are identical, so the seed's choice of SS type does not matter.

    Examples:
        >>> df = pd.DataFrame({"fixture": ["none", "VG"] * 6,
        ...                    "trial": [1, 1, 2, 2, 3, 3] * 2,
        ...                    "e": [3.0, 2.0, 2.5, 1.0, 2.0, 1.5, 3.5, 2.0, 2.0, 1.0, 2.5, 1.0]})
        >>> r = seed_per_sample_anova(df, dv="e")
        >>> r[["effect", "df1", "df2"]].to_dict("records")
        [{'effect': 'fixture', 'df1': 1, 'df2': 8}, {'effect': 'trial', 'df1': 2, 'df2': 8}]
    """
    data = require_frame(data)
    factors = list(factors)
    if len(factors) != 2:
        raise ConfigError(f"the seed's ANOVA has exactly two factors, got {factors!r}",
                          file=source_of(data), field="factors")
    require_columns(data, [dv, *factors])
    src = source_of(data)
    frame = pd.DataFrame({"y": numeric_column(data, dv).to_numpy()})
    for i, f in enumerate(factors):
        col = factor_column(data, f)
        levels = levels_of(col)
        if len(levels) < 2:
            raise ConfigError(f"factor {f!r} needs at least 2 levels, found {levels!r}",
                              file=src, field=f)
        frame[f"f{i}"] = pd.Categorical(col.to_numpy(), categories=levels)
    if interaction:
        cells = frame.groupby(["f0", "f1"], observed=False).size()
        empty = cells.index[cells.to_numpy() == 0]
        if len(empty):
            shown = "; ".join(f"{factors[0]}={a!r} x {factors[1]}={b!r}" for a, b in empty[:8])
            raise ConfigError(f"interaction needs data in every factor cell; empty: {shown}",
                              file=src, field=factors[1])
    formula = "y ~ C(f0) + C(f1)" + (" + C(f0):C(f1)" if interaction else "")
    model = smf.ols(formula, data=frame).fit()
    df_resid = float(model.df_resid)
    if not df_resid >= 1:
        raise ConfigError(f"no residual degrees of freedom ({len(frame)} rows)", file=src,
                          field=dv)
    zero_error = error_ss_is_zero(float(model.ssr), frame["y"].to_numpy())
    if zero_error:
        warnings.warn(f"seed_per_sample_anova {dv!r}: zero residual variance (within "
                      f"round-off): F and p undefined", StatsWarning, stacklevel=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # 0/0 of a zero residual
        table = anova_lm(model, typ=2)
    names = {"C(f0)": factors[0], "C(f1)": factors[1],
             "C(f0):C(f1)": f"{factors[0]}:{factors[1]}"}
    rows = []
    for term, name in names.items():
        if term not in table.index:
            continue
        r = table.loc[term]
        f_val = math.nan if zero_error else float(r["F"])
        rows.append({"effect": name, "SS": float(r["sum_sq"]), "df1": round(float(r["df"])),
                     "df2": round(df_resid), "F": f_val,
                     "p": float(r["PR(>F)"]) if math.isfinite(f_val) else math.nan})
    out = pd.DataFrame(rows, columns=list(SEED_ANOVA_COLUMNS))
    out["df1"] = out["df1"].astype(np.int64)
    out["df2"] = out["df2"].astype(np.int64)
    out.attrs["label"] = SEED_LABEL
    return out
