"""Tests of GG epsilon and Mauchly's test (vasim/study/stats/sphericity.py).

R reference values: JASP (R ``mauchly.test``) p = 0.04684581 for W = 0.136248 on Field's
Bushtucker data (8 subjects, 4 levels: nu = 7, 3 contrasts); ``ez::ezANOVA`` p = 0.7535238
for W = 0.8850318 on pingouin's unbalanced mixed data (26 subjects in 3 groups: nu = 23,
4 levels). Both also checked through the ANOVA functions on the raw data.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy import stats

from vasim.study.stats.sphericity import gg_epsilon, mauchly_test


def _cov_with_w(w: float, p: int = 3) -> np.ndarray:
    """A diagonal covariance whose Mauchly W is ``w`` (eigenvalues 1, 1, x)."""
    # W = x / ((2 + x)/3)^3: solve for x in (0, 1] by bisection
    lo, hi = 1e-12, 1.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid / ((2 + mid) / 3) ** 3 < w:
            lo = mid
        else:
            hi = mid
    return np.diag([1.0, 1.0, 0.5 * (lo + hi)])


@pytest.mark.parametrize(("w", "nu", "cells", "p_r"), [
    (0.136248, 7, 4, 0.04684581),     # JASP, Bushtucker
    (0.8850318, 23, 4, 0.7535238),    # ez, pingouin mixed_anova_unbalanced
])
def test_matches_r_values(w: float, nu: int, cells: int, p_r: float) -> None:
    m = mauchly_test(_cov_with_w(w), nu, cells)
    assert m.W == pytest.approx(w, rel=1e-9)
    assert m.p == pytest.approx(p_r, abs=1e-7)  # W is given to 7 digits only
    assert m.df == 5
    rho = 1 - (2 * 9 + 3 + 2) / (6 * 3 * nu)
    assert m.chi2 == pytest.approx(-nu * rho * math.log(w), rel=1e-9)
    assert m.p_first_order == pytest.approx(stats.chi2.sf(m.chi2, 5), rel=1e-12)
    assert m.p_anderson != m.p


def test_two_contrasts_have_no_second_order_term() -> None:
    cov = np.array([[2.0, 0.3], [0.3, 1.0]])
    m = mauchly_test(cov, 9, 3)
    assert m.p == m.p_anderson == m.p_first_order
    assert m.W == pytest.approx(np.linalg.det(cov) / (np.trace(cov) / 2) ** 2, rel=1e-12)


@settings(max_examples=50, deadline=None)
@given(a=hnp.arrays(np.float64, (12, 4), elements=st.floats(-10, 10)),
       scale=st.floats(0.01, 100))
def test_invariants(a: np.ndarray, scale: float) -> None:
    cov = a.T @ a / 11 + 1e-3 * np.eye(4)
    eps = gg_epsilon(cov)
    assert 1 / 4 - 1e-12 <= eps <= 1 + 1e-12
    m = mauchly_test(cov, 11, 5)
    assert 0 <= m.W <= 1 + 1e-12 and 0 <= m.p <= 1
    # both are scale free
    assert gg_epsilon(scale * cov) == pytest.approx(eps, rel=1e-9)
    assert mauchly_test(scale * cov, 11, 5).W == pytest.approx(m.W, rel=1e-6, abs=1e-300)
