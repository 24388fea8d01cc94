"""The compiled shortcuts of Θ agree with the SVD / eigenvalue routes they replace."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.mrcp.indices._theta_kernels import (
    _phi,
    _phi_of,
    _svd_padded,
    sigma_min_at_least,
    sigma_min_many,
)


def test_sigma_min_test_equals_the_eigenvalue_route() -> None:
    rng = np.random.default_rng(0)
    jac = rng.normal(size=(400, 6, 6)) * rng.uniform(0.01, 1.0, size=(400, 1, 1))
    jac[:50, 5] = jac[:50, 4] * 0.999         # nearly rank deficient
    jac[50:60, 5] = 0.0                       # rank deficient
    smin = sigma_min_many(jac)
    for thr in (0.0, 0.001, 0.01, 0.1):
        away = np.abs(smin - thr) > 1e-9 * (1.0 + thr)
        np.testing.assert_array_equal(sigma_min_at_least(jac, thr)[away], (smin >= thr)[away])
    wide = rng.normal(size=(50, 3, 6))       # r < n
    np.testing.assert_array_equal(sigma_min_at_least(wide, 0.2),
                                  sigma_min_many(wide) >= 0.2)


@settings(max_examples=80, deadline=None)
@given(st.integers(0, 10_000), st.sampled_from([0, 1, 2]))
def test_phi_gram_route_equals_the_svd_route(seed: int, rank_drop: int) -> None:
    rng = np.random.default_rng(seed)
    jac = rng.normal(size=(3, 6))
    if rank_drop:                              # lost directions: must take the SVD route
        jac[2] = jac[0] * rank_drop
    origin = rng.normal(size=3)
    dest = origin + rng.normal(size=(6, 3)) * 0.05
    dest[0] = origin                           # a zero-length motion
    dens = rng.uniform(0.1, 1.0, size=6)
    ok = rng.uniform(size=6) > 0.2
    left, sig = _svd_padded(jac)
    expect = _phi(origin, left, sig, dest, dens, ok)
    got = _phi_of(origin, jac, dest, dens, ok, np.empty((3, 3)))
    assert abs(got - expect) <= 1e-9 * max(1.0, abs(expect))
