"""Sphericity of repeated measures: Greenhouse-Geisser epsilon and Mauchly's test.

Pure functions of a (p, p) covariance matrix of ``p`` orthonormal contrasts of the
within-subject cells (any orthonormal basis gives the same values) and its residual degrees
of freedom ``nu`` (``n - 1`` for one group of ``n`` subjects; ``N - g`` for ``g`` groups of
``N`` subjects in all, the pooled within-group covariance). Shared by the all-within
:func:`vasim.study.stats.anova.rm_anova` and the mixed design
:func:`vasim.study.stats.mixed.mixed_anova`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy import stats


class Mauchly(NamedTuple):
    """Mauchly's test of sphericity.

    Attributes:
        W: Mauchly's criterion ``det(S) / (tr(S)/p)^p``, in ``[0, 1]``.
        chi2: ``-nu rho ln W``.
        df: ``p (p + 1) / 2 - 1``.
        p: p-value exactly as R's ``mauchly.test`` (and ``car``, ``ez``, ``afex``, JASP),
            see :func:`mauchly_test`.
        p_anderson: the same second-order approximation with the number of contrasts
            throughout (Anderson 1958 as published); differs from ``p`` in the 4th decimal.
        p_first_order: the plain chi-square tail ``P(X2_df > chi2)`` (Bartlett's rho
            only), for comparison with software that stops there.
    """

    W: float
    chi2: float
    df: float
    p: float
    p_anderson: float
    p_first_order: float


def gg_epsilon(cov: np.ndarray) -> float:
    """Greenhouse-Geisser (Box 1954) epsilon ``tr(S)^2 / (p tr(S^2))``, in ``[1/p, 1]``.

    Args:
        cov: (p, p) covariance of orthonormal contrasts, ``tr(cov) > 0``.
    """
    p = cov.shape[0]
    tr = float(np.trace(cov))
    return tr * tr / (p * float(np.trace(cov @ cov)))


def mauchly_test(cov: np.ndarray, nu: int, n_cells: int) -> Mauchly:
    """Mauchly's test of sphericity as R's ``stats:::mauchly.test.SSD`` (and ``car``).

    Derived from R's source (``mauchly.test.SSD``; ``car``'s, ``ez``'s and ``afex``'s
    ``mauchly`` copy it): with ``pp`` contrasts (R's ``pp <- nrow(T)``), ``nu`` residual
    degrees of freedom (R's ``n <- object$df``) and ``p`` the number of within-subject
    cells (R's ``p <- ncol(object$SSD)``; ``car``: ``nrow(P)``):

    .. math::

        \\rho = 1 - \\frac{2pp^2 + pp + 2}{6\\,pp\\,\\nu}, \\quad
        w_2 = \\frac{(pp+2)(pp-1)(pp-2)(2pp^3 + 6pp^2 + 3p + 2)}{288 (\\nu\\,pp\\,\\rho)^2},
        \\quad z = -\\nu \\rho \\ln W,

        P = 1 - \\big[(1 - w_2) F_{\\chi^2_f}(z) + w_2 F_{\\chi^2_{f+4}}(z)\\big],
        \\quad f = pp(pp+1)/2 - 1

    (Anderson 1958, §10.7.4; R writes it ``Pr1 + w2 (Pr2 - Pr1)``).

    **Decision**: ``mauchly_test(...).p`` reproduces R to the last digit, including the
    ``3 * p`` term that uses the number of *cells* where Anderson's formula has the number
    of contrasts ``pp`` (R's source mixes the two names), because every published R value
    (JASP 0.04684581 on Field's Bushtucker data; ``ez`` 0.7535238 on pingouin's unbalanced
    mixed data) carries it. Anderson's form with ``pp`` throughout is kept as
    ``p_anderson`` (0.046773 on Bushtucker); SPSS prints .047 for both. The two agree
    whenever ``pp <= 2`` (``w2`` is then 0).

    Args:
        cov: (pp, pp) covariance of orthonormal contrasts, non-singular, ``pp >= 2``.
        nu: residual degrees of freedom of ``cov`` (``n - 1``; ``N - g`` with groups).
        n_cells: number of within-subject cells of the design (``k`` for one factor with
            ``k`` levels, ``a b`` for two within factors, for every effect).

    Returns:
        W, chi2, df, R's p-value, Anderson's p-value and the first-order p-value.

    Examples:
        >>> round(mauchly_test(np.eye(3), nu=10, n_cells=4).W, 12)
        1.0
    """
    pp = cov.shape[0]
    sign, logdet = np.linalg.slogdet(cov)
    tr = float(np.trace(cov))
    log_w = float(logdet) - pp * math.log(tr / pp)
    w = math.exp(log_w) if sign > 0 else 0.0
    rho = 1.0 - (2 * pp * pp + pp + 2) / (6.0 * pp * nu)
    z = -nu * rho * log_w
    f = pp * (pp + 1) / 2 - 1
    pr1 = float(stats.chi2.sf(z, f))
    pr2 = float(stats.chi2.sf(z, f + 4))

    def second_order(three_p: int) -> float:
        w2 = ((pp + 2) * (pp - 1) * (pp - 2) * (2 * pp**3 + 6 * pp**2 + three_p + 2)
              / (288.0 * (nu * pp * rho) ** 2))
        return min(1.0, max(0.0, pr1 + w2 * (pr2 - pr1)))

    return Mauchly(w, z, float(f), second_order(3 * n_cells), second_order(3 * pp), pr1)
