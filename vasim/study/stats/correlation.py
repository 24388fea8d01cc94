"""Spearman rank correlations between questionnaire items (Likert data).

spec/study.md §4: five-point Likert questionnaire (usefulness, expected ET/EM/Q
improvement, comfort, abstraction); the items are compared pairwise with Spearman's rho,
which only uses the order of the answers.
"""

from __future__ import annotations

import itertools
import math
import warnings

import numpy as np
import pandas as pd
from scipy import stats

from vasim.core.errors import ConfigError
from vasim.study.stats._data import (
    MAX_LISTED,
    StatsWarning,
    factor_column,
    levels_of,
    numeric_column,
    python_scalar,
    require_columns,
    require_frame,
    source_of,
)

#: Column order of :func:`spearman_items` (also the JSON keys of ``vasim stats spearman``).
SPEARMAN_COLUMNS: tuple[str, ...] = ("var1", "var2", "n", "rho", "p")


def spearman_items(data: pd.DataFrame, subject: str, item: str, value: str) -> pd.DataFrame:
    """Spearman's rho between every pair of items, over the subjects who answered both.

    Args:
        data: long-format answers, one row per subject x item.
        subject: respondent-identifier column (at least 2 respondents).
        item: item (question) column (at least 2 items).
        value: answer column (numbers, e.g. 1-5 Likert; an empty cell means "no answer").

    Returns:
        One row per pair of items (``var1`` before ``var2`` in level order), columns
        :data:`SPEARMAN_COLUMNS`: ``var1``, ``var2``, ``n`` (respondents who answered
        both), ``rho`` and its two-sided ``p`` from ``scipy.stats.spearmanr``.

    Raises:
        ConfigError: missing column, non-numeric or infinite answer, missing subject or
            item label, a subject answering the same item twice, fewer than 2 respondents
            or fewer than 2 items.

    Notes:
        Ties (usual with Likert answers) get average ranks and rho is Pearson's r of the
        ranks. The p-value is SciPy's: the t approximation
        ``t = rho sqrt((n-2)/(1-rho^2))`` with n-2 df (as SPSS), not R ``cor.test``'s exact
        permutation p for small n without ties.
        Missing answers (an absent row or an empty cell) are dropped pair by pair
        ("pairwise deletion", as pingouin ``pairwise_corr`` and SPSS), so ``n`` may differ
        between pairs. A pair with fewer than 3 common answers, or where one item is
        constant, has ``rho`` and ``p`` NaN (a :class:`StatsWarning` is issued).

    Examples:
        >>> df = pd.DataFrame({"s": [1, 2, 3, 4] * 2, "q": ["use"] * 4 + ["comfort"] * 4,
        ...                    "v": [1, 2, 3, 5, 2, 3, 5, 4]})
        >>> spearman_items(df, subject="s", item="q", value="v").round(4).to_dict("records")
        [{'var1': 'comfort', 'var2': 'use', 'n': 4, 'rho': 0.8, 'p': 0.2}]
    """
    data = require_frame(data)
    require_columns(data, [subject, item, value])
    src = source_of(data)
    v = numeric_column(data, value, allow_missing=True)
    s = factor_column(data, subject)
    it = factor_column(data, item)
    frame = pd.DataFrame({"s": s.to_numpy(), "i": it.to_numpy(), "v": v.to_numpy()})
    dup = frame.duplicated(subset=["s", "i"], keep=False)
    if dup.any():
        pairs = frame.loc[dup, ["s", "i"]].drop_duplicates().itertuples(index=False)
        shown = "; ".join(f"{subject}={python_scalar(a)!r} x {item}={python_scalar(b)!r}"
                          for a, b in list(pairs)[:MAX_LISTED])
        raise ConfigError(f"several answers for the same subject and item: {shown}",
                          file=src, field=item)
    subjects = levels_of(s)
    items = levels_of(it)
    if len(subjects) < 2:
        raise ConfigError(f"need at least 2 respondents in column {subject!r}, found "
                          f"{len(subjects)}", file=src, field=subject)
    if len(items) < 2:
        raise ConfigError(f"need at least 2 items in column {item!r}, found {len(items)}: "
                          f"{items!r}", file=src, field=item)
    wide = frame.pivot(index="s", columns="i", values="v").reindex(index=subjects,
                                                                   columns=items)
    rows = []
    for a, b in itertools.combinations(items, 2):
        both = wide[[a, b]].dropna()
        n = len(both)
        x, z = both[a].to_numpy(), both[b].to_numpy()
        if n < 3 or np.ptp(x) == 0 or np.ptp(z) == 0:
            warnings.warn(f"spearman_items {a!r} vs {b!r}: {n} common answers"
                          f"{'' if n < 3 else ', one item constant'}; rho undefined",
                          StatsWarning, stacklevel=2)
            rho = p = math.nan
        else:
            res = stats.spearmanr(x, z)
            rho, p = float(res.statistic), float(res.pvalue)
        rows.append({"var1": a, "var2": b, "n": n, "rho": rho, "p": p})
    out = pd.DataFrame(rows, columns=list(SPEARMAN_COLUMNS))
    out["n"] = out["n"].astype("int64")
    return out
