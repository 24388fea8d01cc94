"""Forgetting and transfer of the simulated operator (vasim/operator/retention.py): the
power law's values, the weighted adjustment against the unweighted one, and monotonicity."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.operator.learning import DEFAULT_EFFECTS, trial_adjustment
from vasim.operator.retention import (
    DEFAULT_RETENTION,
    RetentionModel,
    practice_weights,
    weighted_adjustment,
)

CONDITIONS = ("none", "vg", "ag", "ms", "mag", "ff")


def test_power_law_values() -> None:
    m = RetentionModel(tau_days=1.0, psi=0.15)
    assert m.retained(0.0) == 1.0
    assert m.retained(1.0) == pytest.approx(2.0 ** -0.15)          # 0.9013
    assert m.retained(7.0) == pytest.approx(math.exp(-0.15 * math.log(8.0)))   # 0.7320
    assert RetentionModel(tau_days=2.0, psi=0.5).retained(6.0) == pytest.approx(0.5)
    assert RetentionModel(psi=0.0).retained(365.0) == 1.0          # no forgetting
    with pytest.raises(ValueError, match="age_days"):
        m.retained(-1.0)
    with pytest.raises(ValueError, match="transfer"):
        RetentionModel(transfer=1.5)
    with pytest.raises(ValueError, match="tau_days"):
        RetentionModel(tau_days=0.0)


def test_practice_weights_combine_forgetting_and_transfer() -> None:
    w = practice_weights([7.0, 7.0, 0.0], [True, False, False], untrained=True)
    r7 = DEFAULT_RETENTION.retained(7.0)
    assert w == pytest.approx([r7, r7 * 0.7, 0.7])
    # a trained trajectory: transfer does not apply
    assert practice_weights([0.0, 3.0], [False, False], untrained=False) == \
        pytest.approx([1.0, DEFAULT_RETENTION.retained(3.0)])


def test_retention_probe_after_an_ff_block_by_hand() -> None:
    # 3 VF-free + 6 FF trials on day 0, then a VF-free probe on day 7 on a trained path
    history = ["none"] * 3 + ["ff"] * 6
    w = practice_weights([7.0] * 9, [True] * 9, untrained=False)
    adj = weighted_adjustment(history, "none", w)
    r = DEFAULT_RETENTION.retained(7.0)
    ff = DEFAULT_EFFECTS["ff"]
    assert adj.practice == pytest.approx((3 + 6 * ff.practice_weight) * r)
    expected = (1 - ff.carryover * r * (1 - ff.accuracy)) * (1 + ff.dependence * r)
    assert adj.noise_factor == pytest.approx(expected)
    same_day = trial_adjustment(history, "none")
    assert adj.practice < same_day.practice and adj.noise_factor > same_day.noise_factor


@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from(CONDITIONS), max_size=30), st.sampled_from(CONDITIONS))
def test_weights_of_one_give_the_calibrated_adjustment(history, condition) -> None:
    assert weighted_adjustment(history, condition, [1.0] * len(history)) == \
        trial_adjustment(history, condition)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.sampled_from(CONDITIONS), min_size=1, max_size=20),
       st.floats(0.0, 3650.0), st.floats(0.0, 3650.0))
def test_longer_delays_keep_less_practice(history, a, b) -> None:
    lo, hi = sorted((a, b))
    n = len(history)
    near = weighted_adjustment(history, "none", practice_weights([lo] * n, [True] * n,
                                                                 untrained=False))
    far = weighted_adjustment(history, "none", practice_weights([hi] * n, [True] * n,
                                                                untrained=False))
    assert far.practice <= near.practice + 1e-12
    assert far.time_factor == near.time_factor == 1.0
