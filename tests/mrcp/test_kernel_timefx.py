"""texec, ttransf/TTC, tus, RCnt (Algorithm 1) and NTT."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.mrcp.planar import PlanarArm
from vasim.mrcp.timefx import (
    TransferEstimate,
    continuity_robot,
    estimate_transfer,
    need_of_transfer,
    texec,
    texec_many,
    transfer_complexity,
    transfer_time,
)

T = np.arange(8) * 0.018


def test_texec_roots() -> None:
    # A line reaching 0 in 0.4 s from the last sample.
    assert texec(T, 0.2 - 0.5 * (T - T[-1]), t_max=5.0, degree=1) == pytest.approx(0.4)
    # A falling parabola: y = 0.1 - (t')^2 reaches 0 at t' = sqrt(0.1).
    y = 0.1 - (T - T[-1]) ** 2
    assert texec(T, y, t_max=5.0, degree=2) == pytest.approx(np.sqrt(0.1))
    # No root / a root beyond the window / a rising index -> T_max.
    assert texec(T, np.full(8, 0.7), t_max=5.0) == 5.0
    assert texec(T, 1.0 - 0.01 * T, t_max=5.0, degree=1) == 5.0
    assert texec(T, 0.2 + T, t_max=3.0, degree=1) == 3.0
    # Already at 0 -> 0; a root in the past of a rising line does not count.
    assert texec(T, 0.5 - 0.5 * np.ones(8), t_max=5.0) == 0.0
    assert texec(np.array([0.0]), np.array([0.3]), t_max=2.0) == 2.0
    with pytest.raises(ValueError, match="t_max"):
        texec(T, T, t_max=0.0)


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 3), st.integers(0, 10_000))
def test_texec_many_equals_texec(degree: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    y = rng.random((8, 6)) + np.linspace(0.0, -2.0, 8)[:, None] * rng.random(6)
    many = texec_many(T, y, 5.0, degree)
    one = np.array([texec(T, y[:, j], 5.0, degree) for j in range(6)])
    np.testing.assert_allclose(many, one, atol=1e-12)


def test_transfer_time_and_complexity() -> None:
    # 0.3 m at half of 0.5 m/s.
    assert transfer_time(np.zeros(3), np.array([0.0, 0.3, 0.0]), 0.5) == pytest.approx(1.2)
    amax = np.array([10.0, 10.0])
    straight = np.linspace([0.0, 0.0], [1.0, -1.0], 5)        # constant joint speed
    assert transfer_complexity(straight, 1.0, amax) == pytest.approx(0.0, abs=1e-12)
    bent = np.array([[0.0, 0.0], [0.1, 0.0], [0.3, 0.0]])     # Δ² = 0.1 rad in dt = 0.5 s
    # |θ̈| = 0.1 / 0.25 = 0.4 rad/s² on joint 1 -> mean ratio (0.04 + 0) / 2
    assert transfer_complexity(bent, 1.0, amax) == pytest.approx(0.02)
    assert transfer_complexity(None, 1.0, amax) == 1.0
    assert TransferEstimate(2.0, 0.5).total == 3.0
    with pytest.raises(ValueError, match="max_tcp_speed"):
        transfer_time(np.zeros(3), np.ones(3), 0.0)


def test_estimate_transfer_on_the_planar_arm() -> None:
    arm = PlanarArm("a")
    q = np.array([0.0, 1.5, 0.0])
    tcp, _ = arm.tcp_pose(q)
    est = estimate_transfer(arm, q, tcp + np.array([0.0, 0.05, 0.0]), None, 0.5)
    assert est.ttransf == pytest.approx(0.05 / 0.25)
    assert 0.0 <= est.ttc < 1.0
    far = estimate_transfer(arm, q, np.array([2.0, 0.0, 0.0]), None, 0.5)   # unreachable
    assert far.ttc == 1.0


def test_algorithm_1_and_ntt() -> None:
    tus = {("r1", 0): 2.0, ("r2", 1): 3.0, ("r2", 0): 9.0, ("r3", 1): 1.0, ("r1", 1): 9.0}
    ttr = {("r2", 1): 1.9, ("r3", 1): 0.5}
    # (r2, 0) is RSel's own point and (r1, 1) is RSel itself: both ignored.
    c = continuity_robot(tus, ttr, "r1", 0, threshold=0.9)
    assert (c.robot, c.point, c.tus) == ("r2", 1, 3.0)
    assert c.ntt == pytest.approx(1.9 / 2.0)                # ttransf*_RCnt / tus_RSel
    assert c.transfer
    c = continuity_robot(tus, ttr, "r1", 0, threshold=0.99)
    assert not c.transfer
    best_is_rsel = continuity_robot({("r1", 0): 5.0, ("r2", 1): 1.0}, {("r2", 1): 0.1},
                                    "r1", 0)
    assert (best_is_rsel.robot, best_is_rsel.ntt, best_is_rsel.transfer) == ("r1", 0.0, False)
    assert need_of_transfer(0.0, 1.0) == float("inf")
    assert need_of_transfer(2.0, 0.5) == pytest.approx(1 - (2.0 - 0.5) / 2.0)
