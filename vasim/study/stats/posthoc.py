"""Tukey HSD post hoc comparisons: between groups (Tukey-Kramer) and repeated measures.

spec/study.md §3 **decision**: Tukey HSD is kept "as in the seed"; within subjects it uses
the per-subject level means and the error term of the one-way RM-ANOVA (it assumes
sphericity). The within-subject-correct alternative is the Holm-corrected paired t-tests of
:func:`vasim.study.stats.paired.pairwise_paired`; reports label both.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import pandas as pd
from scipy import stats

from vasim.core.errors import ConfigError
from vasim.study.stats._data import (
    cell_means,
    error_ss_is_zero,
    factor_column,
    levels_of,
    nan_to_none,
    numeric_column,
    require_columns,
    require_frame,
    source_of,
)

#: Column order of :attr:`TukeyResult.comparisons`.
TUKEY_COLUMNS: tuple[str, ...] = (
    "group1", "group2", "mean1", "mean2", "diff", "se", "q", "lwr", "upr", "p_adj",
)

#: Keys of :meth:`TukeyResult.to_dict` (the JSON object of ``vasim stats tukey``).
TUKEY_KEYS: tuple[str, ...] = ("ms_error", "df_error", "k", "q_crit", "comparisons")


@dataclass(frozen=True, eq=False)
class TukeyResult(Mapping[str, Any]):
    """Result of a Tukey HSD family; read-only mapping over :data:`TUKEY_KEYS`.

    Attributes:
        kind: ``"between"`` (independent groups, Tukey-Kramer) or ``"within"`` (repeated
            measures, RM-ANOVA error term).
        factor: the grouping / within-factor column.
        ms_error: error mean square used for every comparison.
        df_error: its degrees of freedom.
        k: number of levels (means) in the family.
        q_crit: studentized-range quantile ``q(1 - alpha; k, df_error)``.
        alpha: family-wise error rate of the intervals (0.05).
        comparisons: one row per pair of levels, columns :data:`TUKEY_COLUMNS`.
    """

    kind: Literal["between", "within"]
    factor: str
    ms_error: float
    df_error: int
    k: int
    q_crit: float
    alpha: float
    comparisons: pd.DataFrame = field(repr=False)

    def __getitem__(self, key: str) -> Any:
        if key not in TUKEY_KEYS:
            raise KeyError(key)
        return self.comparisons if key == "comparisons" else getattr(self, key)

    def __iter__(self) -> Iterator[str]:
        return iter(TUKEY_KEYS)

    def __len__(self) -> int:
        return len(TUKEY_KEYS)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict with exactly :data:`TUKEY_KEYS`; NaN becomes None."""
        rows = [{c: nan_to_none(r[c]) for c in TUKEY_COLUMNS}
                for r in self.comparisons.to_dict("records")]
        return {"ms_error": nan_to_none(self.ms_error), "df_error": nan_to_none(self.df_error),
                "k": int(self.k), "q_crit": nan_to_none(self.q_crit), "comparisons": rows}


def tukey_hsd(data: pd.DataFrame, dv: str, between: str, *, alpha: float = 0.05) -> TukeyResult:
    """Tukey HSD for independent groups; Tukey-Kramer when group sizes differ.

    Args:
        data: long-format table, one row per independent observation.
        dv: dependent-variable column (finite numbers).
        between: grouping column (at least 2 levels).
        alpha: family-wise error rate of the simultaneous intervals.

    Returns:
        :class:`TukeyResult` with ``ms_error`` the pooled within-group mean square
        (one-way ANOVA), ``df_error = N - k`` and one comparison per pair of levels
        (``group1`` before ``group2`` in level order, see ``levels_of``): ``mean1``,
        ``mean2`` group means, ``diff = mean2 - mean1`` (R ``TukeyHSD`` convention),
        ``se``, ``q = |diff| / se``, simultaneous ``lwr``/``upr`` interval, ``p_adj``.

    Raises:
        ConfigError: bad columns or values, fewer than 2 groups, no error df
            (``N - k < 1``) or zero within-group variance.

    Notes:
        Tukey-Kramer: ``se = sqrt(MS_error / 2 (1/n_i + 1/n_j))`` (equal n: ``sqrt(MS/n)``),
        ``p_adj = P(Q_{k, df} > q)`` and ``diff -+ q_crit se`` with the studentized range
        distribution ``scipy.stats.studentized_range``; identical to R
        ``TukeyHSD(aov(dv ~ group))``.

    Examples:
        >>> df = pd.DataFrame({"g": ["a"] * 3 + ["b"] * 3 + ["c"] * 3,
        ...                    "y": [1.0, 2.0, 3.0, 2.0, 3.0, 4.0, 6.0, 7.0, 8.0]})
        >>> res = tukey_hsd(df, dv="y", between="g")
        >>> res["k"], res["df_error"], res["ms_error"]
        (3, 6, 1.0)
        >>> res.comparisons[["group1", "group2", "diff"]].to_dict("records")[-1]
        {'group1': 'b', 'group2': 'c', 'diff': 4.0}
    """
    data = require_frame(data)
    require_columns(data, [dv, between])
    src = source_of(data)
    y = numeric_column(data, dv)
    g = factor_column(data, between)
    levels = levels_of(g)
    k = len(levels)
    if k < 2:
        raise ConfigError(f"grouping column {between!r} needs at least 2 levels, found {k}: "
                          f"{levels!r}", file=src, field=between)
    groups = [y[(g == lev).to_numpy()].to_numpy() for lev in levels]
    sizes = np.array([len(v) for v in groups], dtype=float)
    means = np.array([v.mean() for v in groups])
    df_error = int(sizes.sum()) - k
    if df_error < 1:
        raise ConfigError(f"no error degrees of freedom: {int(sizes.sum())} observations in "
                          f"{k} groups of {between!r} (need more than one per group somewhere)",
                          file=src, field=dv)
    ss_within = float(sum(((v - v.mean()) ** 2).sum() for v in groups))
    ms_error = ss_within / df_error
    _check_positive(ss_within, ms_error, y.to_numpy(dtype=float), dv, src)
    pairs = list(itertools.combinations(range(k), 2))
    se = np.array([math.sqrt(ms_error / 2.0 * (1 / sizes[i] + 1 / sizes[j])) for i, j in pairs])
    return _family("between", between, levels, means, pairs, se, ms_error, df_error, alpha)


def tukey_hsd_rm(data: pd.DataFrame, dv: str, subject: str, within: str, *,
                 alpha: float = 0.05) -> TukeyResult:
    """Repeated-measures Tukey HSD on per-subject level means with the RM error term.

    Args:
        data: long-format table; several rows per subject x level are averaged first.
        dv: dependent-variable column (finite numbers).
        subject: subject-identifier column (at least 2 subjects).
        within: within-subject factor column (at least 2 levels); the design must be
            balanced after averaging.
        alpha: family-wise error rate of the simultaneous intervals.

    Returns:
        :class:`TukeyResult` with ``ms_error`` and ``df_error = (k-1)(n-1)`` the error term
        of the one-way RM-ANOVA (subject x level interaction) and the comparisons of
        :func:`tukey_hsd` with ``se = sqrt(MS_error / n)``.

    Raises:
        ConfigError: as :func:`vasim.study.stats.anova.rm_anova`, or zero error variance.

    Notes:
        This is the randomised-block Tukey test (subjects as blocks), the same as R
        ``TukeyHSD(aov(dv ~ level + subject))`` on the cell means. It pools one error term
        for all pairs and so assumes sphericity; the paired t-tests with Holm correction
        (:func:`vasim.study.stats.paired.pairwise_paired`) do not.

    Examples:
        >>> df = pd.DataFrame({"s": [1, 1, 1, 2, 2, 2, 3, 3, 3],
        ...                    "c": ["a", "b", "c"] * 3,
        ...                    "y": [1.0, 2.0, 4.0, 2.0, 2.5, 5.0, 1.5, 3.5, 4.5]})
        >>> res = tukey_hsd_rm(df, dv="y", subject="s", within="c")
        >>> res["df_error"], round(res["ms_error"], 6)
        (4, 0.194444)
    """
    cm = cell_means(data, dv, subject, [within])
    y = cm.values
    n, k = y.shape
    resid = y - y.mean(axis=1, keepdims=True) - y.mean(axis=0, keepdims=True) + y.mean()
    df_error = (k - 1) * (n - 1)
    ss_error = float((resid**2).sum())
    ms_error = ss_error / df_error
    _check_positive(ss_error, ms_error, y, dv, source_of(data))
    pairs = list(itertools.combinations(range(k), 2))
    se = np.full(len(pairs), math.sqrt(ms_error / n))
    return _family("within", within, cm.levels[0], y.mean(axis=0), pairs, se, ms_error,
                   df_error, alpha)


def _check_positive(ss_error: float, ms_error: float, values: np.ndarray, dv: str,
                    src: str | None) -> None:
    """Refuses an error term that is zero within round-off of ``values`` or not finite."""
    if not math.isfinite(ms_error) or not ms_error > 0 or error_ss_is_zero(ss_error, values):
        raise ConfigError(f"zero error variance in {dv!r}: the Tukey statistics are undefined",
                          file=src, field=dv)


def _family(kind: Literal["between", "within"], factor: str, levels: list[Any],
            means: np.ndarray, pairs: list[tuple[int, int]], se: np.ndarray, ms_error: float,
            df_error: int, alpha: float) -> TukeyResult:
    if not 0.0 < alpha < 1.0:
        raise ConfigError(f"alpha must be in (0, 1), got {alpha!r}", field="alpha")
    k = len(levels)
    q_crit = float(stats.studentized_range.ppf(1.0 - alpha, k, df_error))
    rows = []
    for (i, j), s in zip(pairs, se, strict=True):
        diff = float(means[j] - means[i])
        q = abs(diff) / s
        rows.append({
            "group1": levels[i], "group2": levels[j], "mean1": float(means[i]),
            "mean2": float(means[j]), "diff": diff, "se": float(s), "q": q,
            "lwr": diff - q_crit * s, "upr": diff + q_crit * s,
            "p_adj": min(1.0, float(stats.studentized_range.sf(q, k, df_error))),
        })
    return TukeyResult(kind=kind, factor=factor, ms_error=ms_error, df_error=df_error, k=k,
                       q_crit=q_crit, alpha=alpha,
                       comparisons=pd.DataFrame(rows, columns=list(TUKEY_COLUMNS)))
