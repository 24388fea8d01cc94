"""Mixed-design (split-plot) ANOVA: one between-subjects factor x one within factor.

guides/study-science.md: surgeons vs residents (between) x probe trial (within). The data
are reduced to one cell mean per subject and within level (as :func:`rm_anova`), each
subject belongs to exactly one group, and the three effects are tested as in pingouin's
``mixed_anova`` / R ``afex::aov_ez`` (univariate tests with the Greenhouse-Geisser
correction on the within terms, sphericity from the pooled within-group covariance).

Method of mixed_anova
---------------------
With ``Y`` the (N, k) cell means, ``g(i)`` the group of subject ``i`` (``n_g``
subjects in group ``g``, ``G`` groups), ``m_i`` the subject means and ``C`` the
(k, p = k-1) orthonormal contrasts, ``Z = Y C``:

.. math::

    SS_B = k \\sum_i (\\bar m_{g(i)} - \\bar m)^2, \\quad
    SS_{S(B)} = k \\sum_i (m_i - \\bar m_{g(i)})^2,

    SS_W = N \\lVert \\bar z \\rVert^2, \\quad
    SS_{BW} = \\sum_g n_g \\lVert \\bar z_g - \\bar z \\rVert^2, \\quad
    E = \\sum_i (z_i - \\bar z_{g(i)})(z_i - \\bar z_{g(i)})^T,
    SS_{WS(B)} = \\mathrm{tr}\\,E

with df ``(G-1, N-G)``, ``(p, p(N-G))`` and ``(p(G-1), p(N-G))``. **Decision**: the
within main effect uses the subject-weighted grand mean ``z̄`` (type II sums of
squares, as pingouin and JASP's default for this design; equal to type III when the
groups have equal size) because the study's groups are rarely equal in size and
pingouin/JASP are the published references. The sphericity tests use the pooled
within-group covariance ``S = E / (N - G)`` (as ``car``/``afex``): GG
``eps = tr(S)^2 / (p tr(S^2))`` and Mauchly with ``nu = N - G``.

Undefined values are NaN with a note, never a made-up number: a zero error sum of
squares (zero within round-off of the cell means,
:func:`vasim.study.stats._data.error_ss_is_zero`, e.g. constant data) leaves F, p,
eps and the effect sizes of that term undefined; overflowing sums of squares
(values near 1e154 and above) leave F, p and effect sizes undefined; a
singular ``S`` (fewer residual df than contrasts) leaves Mauchly undefined.
A :class:`StatsWarning` repeats each such note.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from vasim.core.errors import ConfigError
from vasim.study.stats._data import (
    MAX_LISTED,
    StatsWarning,
    cell_means,
    error_ss_is_zero,
    factor_column,
    levels_of,
    python_scalar,
    require_columns,
    require_frame,
    source_of,
)
from vasim.study.stats.anova import orthonormal_contrasts
from vasim.study.stats.sphericity import gg_epsilon, mauchly_test

#: Column order of :func:`mixed_anova`: pingouin's (``Source`` ... ``p_GG_corr``), then the
#: generalised eta squared, the error terms, Mauchly's test and the note.
MIXED_ANOVA_COLUMNS: tuple[str, ...] = (
    "Source", "SS", "DF1", "DF2", "MS", "F", "p_unc", "np2", "eps", "p_GG_corr",
    "ng2", "SS_error", "MS_error", "W_spher", "p_spher", "note",
)

#: Name of the interaction row (pingouin's).
INTERACTION = "Interaction"


def mixed_anova(data: pd.DataFrame, dv: str, within: str, between: str,
                subject: str) -> pd.DataFrame:
    """Mixed-design ANOVA, one between-subjects and one within-subject factor.

    Several rows per subject and within level are averaged first; every subject must have
    every within level (balanced within), and belong to one group (groups may differ in
    size).

    Args:
        data: long-format table, one row per observation.
        dv: dependent-variable column (finite numbers, any unit).
        within: within-subject factor column (>= 2 levels).
        between: between-subjects factor column (>= 2 groups, constant per subject).
        subject: subject-identifier column.

    Returns:
        Three rows, ``Source`` = ``between``, ``within`` and ``"Interaction"``, with columns
        (:data:`MIXED_ANOVA_COLUMNS`):

        - ``SS``, ``DF1``, ``DF2``, ``MS``, ``F``, ``p_unc``: the effect's sum of squares,
          its and its error term's degrees of freedom, mean square, F ratio and p-value.
        - ``np2``: partial eta squared ``SS / (SS + SS_error)``.
        - ``eps``: Greenhouse-Geisser epsilon of the within terms (NaN on the between row,
          where it does not apply; 1 with 2 within levels).
        - ``p_GG_corr``: p-value with both df multiplied by ``eps`` (NaN on the between row;
          use ``p_unc`` there).
        - ``ng2``: generalised eta squared (Olejnik & Algina 2003, both factors
          manipulated): ``SS / (SS + SS_subjects(groups) + SS_within x subjects(groups))``.
        - ``SS_error``, ``MS_error``: the effect's error term (subjects within groups for
          the between row; within x subjects within groups for the other two).
        - ``W_spher``, ``p_spher``: Mauchly's W and p (R ``mauchly.test``) on the within row;
          NaN elsewhere and where undefined.
        - ``note``: empty, or why a value is NaN.

        ``result.attrs`` holds ``n_subjects``, ``group_sizes`` (group -> n), ``levels``
        (within levels) and ``n_obs_per_cell`` (min, max raw rows per subject x level).

    Raises:
        ConfigError: a column is missing or used twice, a ``dv`` value is not a finite
            number, a label is missing, a subject appears in two groups, fewer than 2 groups
            or within levels, no error degrees of freedom (as many subjects as groups), or
            a subject lacks a within level.

    Notes:
        The method, and which values are undefined (NaN), are in the module
        docstring (Method of mixed_anova).

    Examples:
        >>> df = pd.DataFrame({
        ...     "s": [f"S{i}" for i in range(1, 7) for _ in range(3)],
        ...     "g": ["a"] * 9 + ["b"] * 9,
        ...     "t": ["t1", "t2", "t3"] * 6,
        ...     "y": [1, 2, 4, 2, 2, 5, 1, 3, 3, 3, 5, 8, 2, 5, 7, 4, 5, 9]})
        >>> aov = mixed_anova(df, dv="y", within="t", between="g", subject="s")
        >>> aov[["Source", "DF1", "DF2"]].to_dict("records")
        [{'Source': 'g', 'DF1': 1, 'DF2': 4}, {'Source': 't', 'DF1': 2, 'DF2': 8}, \
{'Source': 'Interaction', 'DF1': 2, 'DF2': 8}]
        >>> [round(float(v), 4) for v in aov["F"]]
        [39.0625, 47.4118, 4.3529]
    """
    data = require_frame(data)
    require_columns(data, [dv, within, between, subject])
    src = source_of(data)
    for role, col in (("within", within), ("between", between)):
        if col == INTERACTION:
            raise ConfigError(f"the {role} factor column may not be named {INTERACTION!r} "
                              f"(the name of the interaction row); rename the column",
                              file=src, field=col)
    cm = cell_means(data, dv, subject, [within])
    y = cm.values
    n = y.shape[0]
    group_of = _group_of_subject(data, subject, between, cm.subjects)
    groups = levels_of(pd.Series(group_of))
    if len(groups) < 2:
        raise ConfigError(f"between factor {between!r} needs at least 2 groups, found "
                          f"{len(groups)}: {groups!r}", file=src, field=between)
    if n - len(groups) < 1:
        raise ConfigError(f"{n} subjects in {len(groups)} groups of {between!r} leave no "
                          f"error degrees of freedom (need more subjects than groups)",
                          file=src, field=subject)
    gidx = np.array([groups.index(g) for g in group_of])
    n_g = np.bincount(gidx, minlength=len(groups)).astype(float)
    n_groups = len(groups)
    rows = _effect_rows(between, within, y, _split_plot_sums(y, gidx, n_g), n_groups)
    _warn_undefined(rows)
    out = pd.DataFrame(rows, columns=list(MIXED_ANOVA_COLUMNS))
    out["DF1"] = out["DF1"].astype("int64")
    out["DF2"] = out["DF2"].astype("int64")
    out.attrs["n_subjects"] = n
    out.attrs["group_sizes"] = {g: int(c_) for g, c_ in zip(groups, n_g, strict=True)}
    out.attrs["levels"] = list(cm.levels[0])
    out.attrs["n_obs_per_cell"] = (int(cm.n_obs.min()), int(cm.n_obs.max()))
    return out


def _effect_rows(between: str, within: str, y: np.ndarray,
                 sums: tuple[float, float, float, float, np.ndarray], n_groups: int,
                 ) -> list[dict[str, Any]]:
    """The between, within and interaction rows from the cell means ``y`` and their
    split-plot ``sums`` (``_split_plot_sums``), with the within row's sphericity."""
    ss_b, ss_sb, ss_w, ss_bw, sscp = sums
    n, k = y.shape
    df_res = n - n_groups
    p = k - 1
    ss_ws = float(np.trace(sscp))
    ss_errors = ss_sb + ss_ws

    notes: dict[str, list[str]] = {between: [], within: [], INTERACTION: []}
    zero_b, zero_w = error_ss_is_zero(ss_sb, y), error_ss_is_zero(ss_ws, y)
    eps, mauchly = _sphericity(sscp / df_res, df_res, k, zero_w, notes[within])
    rows = [
        _row(between, ss_b, n_groups - 1, ss_sb, df_res, zero_b, ss_errors, math.nan,
             notes[between]),
        _row(within, ss_w, p, ss_ws, p * df_res, zero_w, ss_errors, eps, notes[within]),
        _row(INTERACTION, ss_bw, p * (n_groups - 1), ss_ws, p * df_res, zero_w, ss_errors,
             eps, notes[INTERACTION]),
    ]
    rows[1]["W_spher"], rows[1]["p_spher"] = mauchly
    return rows


def _warn_undefined(rows: list[dict[str, Any]]) -> None:
    """A ``StatsWarning`` per row with a value undefined for this data (the 2-level case
    is not one: Mauchly's test is simply not defined there)."""
    for row in rows:
        undefined = [t for t in str(row["note"]).split("; ") if t and "2 levels" not in t]
        if undefined:
            warnings.warn(f"mixed_anova {row['Source']!r}: {'; '.join(undefined)}",
                          StatsWarning, stacklevel=3)


def _split_plot_sums(y: np.ndarray, gidx: np.ndarray, n_g: np.ndarray,
                     ) -> tuple[float, float, float, float, np.ndarray]:
    """The split-plot sums of squares of the (N, k) cell means ``y`` with subject ``i`` in
    group ``gidx[i]`` (``n_g`` subjects per group), as in the module docstring.

    Returns:
        ``SS_B``, ``SS_S(B)``, ``SS_W``, ``SS_BW`` and the (p, p) residual SSCP matrix ``E``
        of the orthonormal within contrasts (``SS_WS(B) = tr E``).
    """
    n, k = y.shape
    # between subjects
    m = y.mean(axis=1)
    m_g = np.bincount(gidx, weights=m) / n_g
    ss_b = float(k * ((m_g[gidx] - m.mean()) ** 2).sum())
    ss_sb = float(k * ((m - m_g[gidx]) ** 2).sum())
    # within subjects, on orthonormal contrasts
    z = y @ orthonormal_contrasts(k)
    zbar = z.mean(axis=0)
    z_g = np.stack([z[gidx == j].mean(axis=0) for j in range(len(n_g))])
    ss_w = float(n * zbar @ zbar)
    ss_bw = float((n_g * ((z_g - zbar) ** 2).sum(axis=1)).sum())
    resid = z - z_g[gidx]
    return ss_b, ss_sb, ss_w, ss_bw, resid.T @ resid


def _group_of_subject(data: pd.DataFrame, subject: str, between: str,
                      subjects: list[Any]) -> list[Any]:
    """The group of each subject (in ``subjects`` order); refuses a subject in two groups."""
    subj = factor_column(data, subject)
    grp = factor_column(data, between)
    pairs = pd.DataFrame({"s": subj.to_numpy(), "g": grp.to_numpy()})
    per_subject = pairs.groupby("s", sort=False)["g"].unique()
    mixed = [(s, list(g)) for s, g in per_subject.items() if len(g) > 1]
    if mixed:
        shown = "; ".join(f"{python_scalar(s)!r} in {[python_scalar(v) for v in g]!r}"
                          for s, g in mixed[:MAX_LISTED])
        more = f" and {len(mixed) - MAX_LISTED} more" if len(mixed) > MAX_LISTED else ""
        raise ConfigError(f"between factor {between!r} must be constant per subject; "
                          f"{len(mixed)} subject(s) of {subject!r} appear in several groups: "
                          f"{shown}{more} (subject codes must be unique across groups)",
                          file=source_of(data), field=between)
    return [per_subject[s][0] for s in subjects]


def _sphericity(cov: np.ndarray, df_res: int, k: int, zero_error: bool,
                notes: list[str]) -> tuple[float, tuple[float, float]]:
    """GG epsilon and (Mauchly W, p) of the pooled within-group contrast covariance."""
    nan = math.nan
    p = cov.shape[0]
    if p == 1:
        notes.append("2 levels: sphericity holds trivially, Mauchly's test undefined")
        return 1.0, (nan, nan)
    if zero_error or not np.isfinite(cov).all():
        return nan, (nan, nan)
    eps = gg_epsilon(cov)
    rank = int(np.linalg.matrix_rank(cov))
    if df_res < p or rank < p:
        notes.append(f"singular covariance of the {p} contrasts (rank {rank}, N-g = "
                     f"{df_res}): Mauchly's test undefined, GG still valid")
        return eps, (nan, nan)
    res = mauchly_test(cov, df_res, k)
    return eps, (res.W, res.p)


def _row(source: str, ss: float, df1: int, ss_err: float, df2: int, zero_error: bool,
         ss_errors: float, eps: float, notes: list[str]) -> dict[str, Any]:
    nan = math.nan
    f_val = p_unc = p_gg = np2 = ng2 = nan
    ms_err = ss_err / df2
    if not (math.isfinite(ss) and math.isfinite(ss_err)):
        notes.append("sums of squares overflow (not finite): F, p and effect sizes undefined")
    elif zero_error:
        notes.append("zero error variance: F, p, eps and effect sizes undefined")
        eps = nan
    else:
        f_val = (ss / df1) / ms_err
        p_unc = float(stats.f.sf(f_val, df1, df2))
        if not math.isnan(eps):
            p_gg = float(stats.f.sf(f_val, df1 * eps, df2 * eps))
        np2 = ss / (ss + ss_err)
        ng2 = ss / (ss + ss_errors)
    return {"Source": source, "SS": ss, "DF1": df1, "DF2": df2, "MS": ss / df1, "F": f_val,
            "p_unc": p_unc, "np2": np2, "eps": eps, "p_GG_corr": p_gg, "ng2": ng2,
            "SS_error": ss_err, "MS_error": ms_err, "W_spher": nan, "p_spher": nan,
            "note": "; ".join(notes)}
