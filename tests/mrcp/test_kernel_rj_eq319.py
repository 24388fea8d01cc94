"""Eq. 3.19's denominator (issue #17 §3): why RJ divides by Σ w_k and not by Σ Jeval_k.

The seed prints ``J̄eval = Σ_k w_k Jeval_k / Σ_k Jeval_k``. That ratio is homogeneous of
degree 0 in the Jeval values: a trajectory that stays at Jeval = 0.02 (a joint next to its
limit) and one that stays at Jeval = 0.98 (mid-range) get the same value, ``Σ w / (K+1)``,
and a trajectory at the limit (all Jeval = 0) gives 0/0. RJ would then no longer measure
the distance to a limit; with ``Σ w_k`` (a weighted mean, the text's "weighted sum ...
the weights balance the contribution of each point") it does, and equals the single-pose
RJ (eq. 3.15) when the trajectory stays put.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.mrcp.indices.base import prediction_weights
from vasim.mrcp.indices.joint_limits import jeval, joint_distance, rj, rj_trajectory

LO, HI = np.array([-1.0]), np.array([1.0])


def _printed_eq_319(values: np.ndarray) -> float:
    """The seed's printed eq. 3.19, ``Σ w_k Jeval_k / Σ Jeval_k`` (an independent sum)."""
    w = prediction_weights(values.shape[0])
    return float(np.sum(w * values) / np.sum(values))


def _still(theta: float, points: int = 4) -> tuple[np.ndarray, ...]:
    configs = np.full((points, 1), theta)
    return (configs, np.ones(points, dtype=bool), np.ones((points, 1)), np.zeros((points, 1)))


def _rj_still(theta: float) -> float:
    configs, reach, b, err = _still(theta)
    return rj_trajectory(configs, reach, LO, HI, b, err)


def test_printed_denominator_cannot_tell_a_limit_from_mid_range() -> None:
    near, mid = 0.99, 0.0                 # dist 0.01 and 1 of the half range
    j_near = float(jeval(joint_distance(np.array([near]), LO, HI), 1.0)[0])
    j_mid = float(jeval(joint_distance(np.array([mid]), LO, HI), 1.0)[0])
    assert j_near == pytest.approx((1 - np.cos(np.pi * 0.01)) / 2, rel=1e-6)   # 2.47e-4
    assert j_mid == pytest.approx(1.0)
    # the printed form: both trajectories score Σw/(K+1) = (1+1/2+1/3+1/4)/4 = 0.5208
    expected = (1 + 1 / 2 + 1 / 3 + 1 / 4) / 4
    assert _printed_eq_319(np.full(4, j_near)) == pytest.approx(expected)
    assert _printed_eq_319(np.full(4, j_mid)) == pytest.approx(expected)
    # at the limit itself it is 0/0
    with np.errstate(invalid="ignore"):
        assert np.isnan(_printed_eq_319(np.zeros(4)))
    # vasim's Σw denominator keeps the distance to the limit
    assert _rj_still(near) == pytest.approx(j_near)
    assert _rj_still(mid) == pytest.approx(1.0)
    assert _rj_still(1.0) == 0.0

@settings(max_examples=60, deadline=None)
@given(theta=st.floats(-0.999, 0.999), points=st.integers(2, 8))
def test_a_still_trajectory_scores_its_single_pose_rj(theta: float, points: int) -> None:
    configs, reach, b, err = _still(theta, points)
    assert rj_trajectory(configs, reach, LO, HI, b, err) == pytest.approx(
        rj(np.array([theta]), LO, HI, 1.0), abs=1e-12)


@settings(max_examples=60, deadline=None)
@given(values=st.lists(st.floats(0.0, 1.0), min_size=2, max_size=8))
def test_weighted_mean_stays_within_the_points_values(values: list[float]) -> None:
    """Σ w J / Σ w lies between the smallest and largest Jeval (a mean of them)."""
    v = np.array(values)
    w = prediction_weights(v.shape[0])
    mean = float(np.sum(w * v) / np.sum(w))
    assert v.min() - 1e-12 <= mean <= v.max() + 1e-12
