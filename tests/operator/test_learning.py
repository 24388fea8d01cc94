"""Tests of the fixture-specific effects, learning and carry-over of the simulated operator
(vasim/operator/learning.py) with declared effects (the shipped scenario's are tested in
test_scenario.py; the questionnaire in test_questionnaire.py)."""

from __future__ import annotations

import doctest
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import vasim.operator.learning as learning_mod
from vasim.operator.learning import DEFAULT_EFFECTS, FixtureEffect, trial_adjustment
from vasim.operator.profile import OperatorProfile

BASELINE = ["none"] * 3
EFFECTS = {  # declared here: every number below follows from these by the module's equations
    "ff": FixtureEffect(accuracy=0.6, speed=1.1, practice_weight=1.5, carryover=0.4,
                        dependence=0.1),
    "mag": FixtureEffect(accuracy=0.9, speed=0.8, practice_weight=1.2, carryover=0.3,
                         dependence=0.05),
    "ag": FixtureEffect(accuracy=0.8, speed=0.9, carryover=0.3, dependence=0.04),
    "vg": FixtureEffect(accuracy=0.95),
    "ms": FixtureEffect(accuracy=0.7, speed=1.2),
}


def test_doctests():
    assert doctest.testmod(learning_mod).failed == 0


def test_assisted_trials_carry_the_declared_fixture_effect():
    for c, e in EFFECTS.items():
        a = trial_adjustment(BASELINE, c, EFFECTS)
        assert (a.noise_factor, a.time_factor, a.practice) == (e.accuracy, e.speed, 3.0)


def test_default_effects_are_the_shipped_scenarios():
    from vasim.operator.scenario import load_scenario

    assert DEFAULT_EFFECTS == load_scenario("seed_plausible").effects()


def test_practice_counts_ff_and_mag_trials_more():
    assert trial_adjustment(BASELINE + ["ff"] * 6, "none", EFFECTS).practice == 3 + 6 * 1.5
    assert trial_adjustment(BASELINE + ["mag"] * 6, "none", EFFECTS).practice == \
        pytest.approx(3 + 6 * 1.2)
    assert trial_adjustment(BASELINE + ["vg"] * 6, "none", EFFECTS).practice == 9.0
    assert trial_adjustment([], "none") == learning_mod.TrialAdjustment(0.0, 1.0, 1.0)


def test_carry_over_and_guidance_dependence_in_vf_free_trials():
    ff = EFFECTS["ff"]
    after = trial_adjustment(BASELINE + ["ff"] * 6, "none", EFFECTS)   # right after the block
    later = trial_adjustment(BASELINE + ["ff"] * 6 + ["none"], "none", EFFECTS)
    kept = 1 - ff.carryover * (1 - ff.accuracy)
    assert later.noise_factor == pytest.approx(kept)                  # 0.84
    assert after.noise_factor == pytest.approx(kept * (1 + ff.dependence))
    assert after.time_factor == later.time_factor == 1.0              # no speed carry-over
    # every fixture practised leaves its share: two blocks keep more than one
    two = trial_adjustment(BASELINE + ["ff"] * 6 + ["none"] + ["ag"] * 6 + ["none"], "none",
                           EFFECTS)
    ag = EFFECTS["ag"]
    assert two.noise_factor == pytest.approx(kept * (1 - ag.carryover * (1 - ag.accuracy)))
    # no fixture practised yet: baseline trials are unadjusted
    assert trial_adjustment(BASELINE[:2], "none", EFFECTS).noise_factor == 1.0


def test_unknown_conditions_have_no_effect():
    adj = trial_adjustment(BASELINE + ["stdt"] * 2, "mag_ff")
    assert (adj.practice, adj.noise_factor, adj.time_factor) == (5.0, 1.0, 1.0)


def test_apply_scales_the_learnable_noise_and_fitts_constants():
    p = OperatorProfile()
    q = trial_adjustment(BASELINE, "mag", EFFECTS).apply(p)
    e = EFFECTS["mag"]
    assert q.noise == pytest.approx(p.noise * e.accuracy)
    assert q.perception_noise == pytest.approx(p.perception_noise * e.accuracy)
    assert q.gain_noise == pytest.approx(p.gain_noise * e.accuracy)
    assert q.fitts_a == pytest.approx(p.fitts_a * e.speed)
    assert q.fitts_b == pytest.approx(p.fitts_b * e.speed)
    assert (q.skill, q.tremor_amplitude) == (p.skill, p.tremor_amplitude)  # not learnable


@pytest.mark.parametrize("field,value", [("accuracy", 0.0), ("carryover", 1.5),
                                         ("dependence", -0.1), ("speed", math.nan)])
def test_bad_effects_are_refused(field, value):
    with pytest.raises(ValueError, match=field):
        FixtureEffect(**{field: value})


@settings(max_examples=60, deadline=None)
@given(st.lists(st.sampled_from(["none", "vg", "ag", "ms", "mag", "ff"]), max_size=40))
def test_vf_free_noise_never_exceeds_the_largest_dependence(history):
    adj = trial_adjustment(history, "none", EFFECTS)
    worst = 1 + max(e.dependence for e in EFFECTS.values())
    assert 0 < adj.noise_factor <= worst
    assert adj.practice >= len(history)    # every practice weight is >= 1
