"""The simulated operator's combined schemas and gain hook (vasim/operator/combined.py,
learning.trial_adjustment's gain arguments; issue #18 items 1 and 3)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as hst

from vasim.operator.combined import combine_effects, label_effects
from vasim.operator.learning import FixtureEffect, trial_adjustment

DECLARED = {  # declared here; the expected numbers follow from them
    "ag": FixtureEffect(accuracy=0.66, speed=0.84, carryover=0.3, dependence=0.04),
    "mag": FixtureEffect(accuracy=0.95, speed=0.80, practice_weight=1.2, carryover=0.3,
                         dependence=0.06),
    "ff": FixtureEffect(accuracy=0.52, speed=1.04, practice_weight=1.5, carryover=0.4,
                        dependence=0.12),
    "vg": FixtureEffect(accuracy=0.95, speed=1.05, carryover=0.3, dependence=0.04),
}

effects = hst.builds(FixtureEffect, accuracy=hst.floats(0.05, 1.5),
                     speed=hst.floats(0.5, 1.5), practice_weight=hst.floats(0.0, 3.0),
                     carryover=hst.floats(0.0, 1.0), dependence=hst.floats(0.0, 0.5))


def test_accuracy_benefits_combine_as_independent_probabilities():
    ag, mag = DECLARED["ag"], DECLARED["mag"]
    e = combine_effects([ag, mag])
    b = 1.0 - (1.0 - (1.0 - ag.accuracy)) * (1.0 - (1.0 - mag.accuracy))  # 1 - prod(1 - b_i)
    assert 1.0 - e.accuracy == pytest.approx(b, rel=1e-12)
    assert e.accuracy == pytest.approx(0.66 * 0.95)
    assert e.speed == pytest.approx(0.84 * 0.80)
    assert e.practice_weight == 1.2
    assert 1.0 + e.dependence == pytest.approx(1.04 * 1.06)
    # carry-over: a VF-free trial keeps what each fixture would leave
    kept = (1 - ag.carryover * (1 - ag.accuracy)) * (1 - mag.carryover * (1 - mag.accuracy))
    assert 1.0 - e.carryover * (1.0 - e.accuracy) == pytest.approx(kept, rel=1e-12)


@given(hst.lists(effects, min_size=1, max_size=4), hst.randoms())
def test_combination_is_order_free_and_a_single_fixture_is_itself(es, rnd):
    a = combine_effects(es)
    shuffled = list(es)
    rnd.shuffle(shuffled)
    b = combine_effects(shuffled)
    for f in ("accuracy", "speed", "practice_weight", "carryover", "dependence"):
        assert getattr(a, f) == pytest.approx(getattr(b, f), rel=1e-9, abs=1e-12)
    one = combine_effects(es[:1])
    assert one.accuracy == es[0].accuracy and one.speed == es[0].speed
    if es[0].accuracy != 1.0:
        assert one.carryover == pytest.approx(es[0].carryover, abs=1e-9)


def test_labels_get_the_combination_of_calibrated_fixtures_only():
    out = label_effects({"ag_mag": ("ag", "mag"), "ff_faded": ("ff",), "vg": ("vg",),
                         "ff_cone": ("ff", "cone")}, DECLARED)
    assert out["ff_faded"] == DECLARED["ff"]
    assert out["ag_mag"].accuracy == pytest.approx(0.66 * 0.95)
    assert out["vg"] is DECLARED["vg"]  # declared labels keep their numbers
    assert "ff_cone" not in out  # the cone is not calibrated: no guessing


def test_gain_one_keeps_the_calibrated_numbers_exactly():
    hist = ["none"] * 3 + ["ff"] * 6
    for cond in ("ff", "mag", "none"):
        assert trial_adjustment(hist, cond, DECLARED) == trial_adjustment(
            hist, cond, DECLARED, gain=1.0, history_gains=[1.0] * len(hist))


@pytest.mark.parametrize("g", [0.0, 0.25, 0.5])
def test_the_assisted_benefit_and_the_dependence_scale_with_the_gain(g: float):
    ff = DECLARED["ff"]
    adj = trial_adjustment(["none"], "ff", DECLARED, gain=g)
    assert adj.noise_factor == pytest.approx(1.0 - g * (1.0 - ff.accuracy))
    assert adj.time_factor == pytest.approx(1.0 + g * (ff.speed - 1.0))
    hist = ["none"] * 3 + ["ff"] * 2
    after = trial_adjustment(hist, "none", DECLARED, history_gains=[1.0] * 4 + [g])
    kept = 1.0 - ff.carryover * (1.0 - ff.accuracy)
    assert after.noise_factor == pytest.approx(kept * (1.0 + g * ff.dependence))
    assert after.practice == trial_adjustment(hist, "none", DECLARED).practice
    if g == 0.0:
        assert adj.noise_factor == 1.0 and adj.time_factor == 1.0
        assert math.isclose(after.noise_factor, kept)
