"""Subject-level repeated-measures ANOVA (one- and two-way within), with sphericity tests.

spec/study.md §3 **decision**: this is the *primary* analysis of the fixture and trial
effects: the data are first reduced to one cell mean per subject and cell, then tested with
the subject x effect interaction as error term, Mauchly's test of sphericity and the
Greenhouse-Geisser / Huynh-Feldt / lower-bound corrections, partial and generalised eta
squared. The seed's per-sample ANOVA is only reproduced as a labelled replication
(:mod:`vasim.study.stats.seed_replication`).

Method of rm_anova
------------------
With ``Y`` the (n, cells) matrix of cell means and, per effect, ``C`` a (cells, p)
orthonormal contrast matrix (A: ``C_a (x) 1_b/sqrt(b)``, B: ``1_a/sqrt(a) (x) C_b``,
A:B: ``C_a (x) C_b``), the transformed scores ``Z = Y C`` give

.. math::

    SS = n\\,\\lVert \\bar z \\rVert^2, \\quad
    SS_{error} = \\sum_i \\lVert z_i - \\bar z \\rVert^2, \\quad
    F = \\frac{SS/p}{SS_{error}/(p(n-1))}

which equals the classical sums of squares (``SS_A = n b sum_j (m_j - m)^2`` ...).
With ``S`` the (p, p) sample covariance of ``Z`` (the interaction contrasts for A:B,
as in R ``car::Anova`` / ``ez``):

- Greenhouse-Geisser: ``eps_gg = tr(S)^2 / (p tr(S^2))``, in ``[1/p, 1]``.
- Huynh-Feldt with the Lecoutre (1991) correction, as R ``car``/``ez``/JASP:
  ``eps_hf = min(1, ((N - g + 1) p eps_gg - 2) / (p (N - g - p eps_gg)))`` with
  g = 1 group (all-within design), i.e. ``(n p eps_gg - 2) / (p (n - 1 - p eps_gg))``;
  for a single group Lecoutre's and Huynh & Feldt's (1976) formulas coincide.
- Mauchly: ``W = det(S) / (tr(S)/p)^p``,
  ``chi2 = -(n - 1 - (2p^2 + p + 2)/(6p)) ln W`` with ``p(p+1)/2 - 1`` df, and the
  p-value with Anderson's (1958) second-order term, as R ``mauchly.test``:
  ``P(X2_f > chi2) + w2 (P(X2_{f+4} > chi2) - P(X2_f > chi2))``,
  ``w2 = (p+2)(p-1)(p-2)(2p^3+6p^2+3c+2) / (288 ((n-1) p rho)^2)``,
  ``rho = 1 - (2p^2+p+2)/(6p(n-1))``, where R's source has ``c`` = the number of
  within cells of the design (``mauchly_p``) and Anderson ``c = p``
  (``mauchly_p_anderson``); they differ in the 4th decimal at most.

Undefined values are NaN, never a made-up number:

- 2 levels (p = 1): sphericity holds trivially, all epsilons are 1; Mauchly's test
  is undefined (W, chi2, df, p NaN).
- Singular covariance (``n - 1 < p``, more levels than subjects, or contrasts that
  are linearly dependent in the data): W = 0 carries no test, so Mauchly is NaN and
  a :class:`StatsWarning` is issued. GG is still defined (needs only ``tr(S) > 0``);
  HF is defined when ``n - 1 - p eps_gg > 0`` and NaN otherwise.
- Zero error variance (``SS_error`` zero within round-off, see
  :func:`vasim.study.stats._data.error_ss_is_zero`; e.g. a constant dependent
  variable): F, p-values, epsilons and the effect sizes ``np2`` and ``ges`` are NaN.
  **Decision**: ``ges`` is NaN too although its denominator may be positive,
  because an effect measured without error variance is degenerate data, and an
  effect size of a degenerate effect would be read as a finding (issue #16).
- Sums of squares that overflow (values near 1e154 and above): F, p and effect
  sizes are NaN with a note.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np
import pandas as pd
from scipy import stats
from scipy.linalg import helmert

from vasim.core.errors import ConfigError
from vasim.study.stats._data import StatsWarning, cell_means, error_ss_is_zero, source_of
from vasim.study.stats.sphericity import gg_epsilon, mauchly_test

#: Column order of :func:`rm_anova` (the JSON keys of ``vasim stats rm-anova`` are the same
#: minus ``effect``, which keys the object, and ``note``).
RM_ANOVA_COLUMNS: tuple[str, ...] = (
    "effect", "SS", "SS_error", "MS", "MS_error", "df1", "df2", "F", "p_unc",
    "eps_gg", "eps_hf", "eps_lb", "p_gg", "p_hf", "p_lb", "np2", "ges",
    "mauchly_W", "mauchly_chi2", "mauchly_df", "mauchly_p", "mauchly_p_anderson", "note",
)

_TWO_LEVELS = "2 levels: sphericity holds trivially, Mauchly's test undefined"


def orthonormal_contrasts(k: int) -> np.ndarray:
    """(k, k-1) orthonormal contrasts: columns orthogonal to the ones vector and to each other.

    Any such basis gives the same ANOVA, epsilons and Mauchly W (they are invariant to an
    orthogonal change of basis); the normalised Helmert basis is used.

    >>> c = orthonormal_contrasts(3)
    >>> bool(np.allclose(c.T @ c, np.eye(2)) and np.allclose(c.sum(axis=0), 0))
    True
    """
    return helmert(k).T


def rm_anova(data: pd.DataFrame, dv: str, subject: str,
             within: str | Sequence[str]) -> pd.DataFrame:
    """Repeated-measures ANOVA on subject-level cell means, one- or two-way within.

    Several rows for the same subject x cell (e.g. several trials or per-sample rows) are
    **averaged first** into one cell mean; the design must then be balanced (every subject
    has every cell), otherwise ``ConfigError`` lists the missing subject x cells.

    Args:
        data: long-format table, one row per observation.
        dv: dependent-variable column (finite numbers, any unit).
        subject: subject-identifier column.
        within: one factor column, or a list of two (factor A, factor B).

    Returns:
        One row per effect, in the order A, B, A:B (the interaction is named
        ``"A:B"`` with the real column names), with columns (fixed order,
        :data:`RM_ANOVA_COLUMNS`):

        - ``effect``: factor name or ``"A:B"``.
        - ``SS``, ``SS_error``: sums of squares of the effect and of its error term
          (subject x effect interaction).
        - ``MS``, ``MS_error``: mean squares, ``SS/df1`` and ``SS_error/df2``.
        - ``df1``, ``df2``: degrees of freedom, ``p`` and ``p (n-1)`` where ``p`` is the
          number of contrasts of the effect (``k-1``; ``(a-1)(b-1)`` for A:B).
        - ``F``, ``p_unc``: F ratio and its uncorrected p-value.
        - ``eps_gg``, ``eps_hf``, ``eps_lb``: Greenhouse-Geisser, Huynh-Feldt (capped at 1)
          and lower-bound (``1/p``) epsilons.
        - ``p_gg``, ``p_hf``, ``p_lb``: p-values with both df multiplied by the epsilon.
        - ``np2``: partial eta squared, ``SS/(SS + SS_error)``.
        - ``ges``: generalised eta squared (Olejnik & Algina 2003; Bakeman 2005) for an
          all-within design, ``SS/(SS + SS_subjects + sum of all SS_error)``.
        - ``mauchly_W``, ``mauchly_chi2``, ``mauchly_df``, ``mauchly_p``: Mauchly's test of
          sphericity, p exactly as R's ``mauchly.test`` / ``car`` / JASP
          (:func:`vasim.study.stats.sphericity.mauchly_test`); NaN where undefined (see
          Notes).
        - ``mauchly_p_anderson``: the same test's p with Anderson's (1958) formula as
          published (the number of contrasts throughout; R puts the number of cells in one
          term), which SPSS's printed 3 decimals also match; equal to ``mauchly_p`` when
          the effect has at most 3 levels.
        - ``note``: empty, or why a value is NaN (2 levels, singular covariance, zero
          error variance, overflow).

        ``result.attrs`` holds ``n_subjects``, ``levels`` (per factor) and ``n_obs_per_cell``
        (min and max number of raw rows averaged into a cell).

    Raises:
        ConfigError: missing column, non-numeric or non-finite ``dv``, missing labels, fewer
            than 2 subjects or 2 levels, unbalanced design, or more than two factors.

    Notes:
        The method, and which values are undefined (NaN), are in the module
        docstring (Method of rm_anova).

    Examples:
        >>> df = pd.DataFrame({
        ...     "s": [1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4],
        ...     "cond": ["a", "b", "c"] * 4,
        ...     "y": [1.0, 2.0, 4.0, 2.0, 2.5, 5.0, 1.5, 3.5, 4.5, 3.0, 3.0, 6.5]})
        >>> aov = rm_anova(df, dv="y", subject="s", within="cond")
        >>> aov[["effect", "df1", "df2"]].to_dict("records")
        [{'effect': 'cond', 'df1': 2, 'df2': 6}]
        >>> round(float(aov.loc[0, "F"]), 4), round(float(aov.loc[0, "eps_gg"]), 4)
        (33.2667, 0.5216)
    """
    factors = [within] if isinstance(within, str) else list(within)
    if not 1 <= len(factors) <= 2:
        raise ConfigError(f"rm_anova supports one or two within factors, got {factors!r}",
                          file=source_of(data), field="within")
    cm = cell_means(data, dv, subject, factors)
    n = len(cm.subjects)
    y = cm.values.reshape(n, -1)
    sizes = [len(lev) for lev in cm.levels]
    grand = float(y.mean())
    ss_subjects = float(y.shape[1] * ((y.mean(axis=1) - grand) ** 2).sum())

    effects = _effect_contrasts(factors, sizes)
    parts = [_effect_sums(y @ c) for _, c in effects]
    ss_error_sum = sum(p[1] for p in parts)
    n_cells = y.shape[1]
    rows = []
    for (name, c), (ss, ss_err, cov) in zip(effects, parts, strict=True):
        row = _effect_row(name, ss, ss_err, cov, n, c.shape[1], error_ss_is_zero(ss_err, y),
                          ss + ss_subjects + ss_error_sum, n_cells)
        undefined = [t for t in str(row["note"]).split("; ") if t and t != _TWO_LEVELS]
        if undefined:  # a value is NaN for this data (not merely the 2-level case)
            warnings.warn(f"rm_anova effect {name!r}: {'; '.join(undefined)}", StatsWarning,
                          stacklevel=2)
        rows.append(row)
    out = pd.DataFrame(rows, columns=list(RM_ANOVA_COLUMNS))
    out["df1"] = out["df1"].astype("int64")
    out["df2"] = out["df2"].astype("int64")
    out.attrs["n_subjects"] = n
    out.attrs["levels"] = {f: list(lev) for f, lev in zip(factors, cm.levels, strict=True)}
    out.attrs["n_obs_per_cell"] = (int(cm.n_obs.min()), int(cm.n_obs.max()))
    return out


def _effect_contrasts(factors: list[str], sizes: list[int]) -> list[tuple[str, np.ndarray]]:
    """Each effect's name and (cells, p) orthonormal contrasts: A; or A, B and A:B (A:
    ``C_a (x) 1_b/sqrt(b)``, B: ``1_a/sqrt(a) (x) C_b``, A:B: ``C_a (x) C_b``)."""
    if len(factors) == 1:
        return [(factors[0], orthonormal_contrasts(sizes[0]))]
    ca, cb = orthonormal_contrasts(sizes[0]), orthonormal_contrasts(sizes[1])
    ua = np.ones((sizes[0], 1)) / math.sqrt(sizes[0])
    ub = np.ones((sizes[1], 1)) / math.sqrt(sizes[1])
    return [(factors[0], np.kron(ca, ub)), (factors[1], np.kron(ua, cb)),
            (f"{factors[0]}:{factors[1]}", np.kron(ca, cb))]


def _effect_sums(z: np.ndarray) -> tuple[float, float, np.ndarray]:
    """SS, SS_error and (p, p) covariance of the (n, p) transformed scores ``z``."""
    n = z.shape[0]
    zbar = z.mean(axis=0)
    d = z - zbar
    ss = float(n * zbar @ zbar)
    sscp = d.T @ d
    return ss, float(np.trace(sscp)), sscp / (n - 1)


def _effect_row(name: str, ss: float, ss_err: float, cov: np.ndarray, n: int, p: int,
                zero_error: bool, ges_denominator: float, n_cells: int) -> dict[str, object]:
    df1, df2 = p, p * (n - 1)
    notes: list[str] = []
    nan = math.nan
    overflow = not (math.isfinite(ss) and math.isfinite(ss_err))
    f_val = p_unc = np2 = ges = nan
    ms_err = ss_err / df2
    if overflow:
        notes.append("sums of squares overflow (not finite): F, p and effect sizes undefined")
    elif zero_error:
        notes.append("zero error variance: F, p, epsilons and effect sizes undefined")
        ms_err = 0.0
    else:
        f_val = (ss / df1) / ms_err
        p_unc = float(stats.f.sf(f_val, df1, df2))
        np2 = ss / (ss + ss_err)
        ges = ss / ges_denominator

    eps_lb = 1.0 / p
    mauchly = (nan, nan, nan, nan, nan)
    if p == 1:
        eps_gg = eps_hf = 1.0
        notes.append(_TWO_LEVELS)
    elif zero_error or overflow:
        eps_gg = eps_hf = nan
    else:
        eps_gg = gg_epsilon(cov)
        denom = n - 1 - p * eps_gg
        if denom > 1e-9 * (n - 1):  # exactly 0 for n = 2 (rank 1), up to rounding
            eps_hf = min(1.0, (n * p * eps_gg - 2.0) / (p * denom))
        else:
            eps_hf = nan
            notes.append(f"Huynh-Feldt epsilon undefined (n-1-p*eps_gg = {denom:.3g} <= 0)")
        rank = int(np.linalg.matrix_rank(cov))
        if n - 1 < p or rank < p:
            notes.append(f"singular covariance of the {p} contrasts (rank {rank}, n-1 = "
                         f"{n - 1}): Mauchly's test undefined, GG still valid")
        else:
            m = mauchly_test(cov, n - 1, n_cells)
            mauchly = (m.W, m.chi2, m.df, m.p, m.p_anderson)

    def corrected(eps: float) -> float:
        if math.isnan(eps) or math.isnan(f_val):
            return nan
        return float(stats.f.sf(f_val, df1 * eps, df2 * eps))

    return {
        "effect": name, "SS": ss, "SS_error": ss_err, "MS": ss / df1, "MS_error": ms_err,
        "df1": df1, "df2": df2, "F": f_val, "p_unc": p_unc,
        "eps_gg": eps_gg, "eps_hf": eps_hf, "eps_lb": eps_lb,
        "p_gg": corrected(eps_gg), "p_hf": corrected(eps_hf), "p_lb": corrected(eps_lb),
        "np2": np2, "ges": ges,
        "mauchly_W": mauchly[0], "mauchly_chi2": mauchly[1], "mauchly_df": mauchly[2],
        "mauchly_p": mauchly[3], "mauchly_p_anderson": mauchly[4], "note": "; ".join(notes),
    }
