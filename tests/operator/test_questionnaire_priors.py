"""The simulated questionnaire's priors of conditions the seed did not rate
(vasim/operator/questionnaire.py ``condition_prior``, vasim/study/gain_plan.py
``condition_priors``): combined schemas from their fixtures, faded/adaptive ones from their
gain; the numbers below are the seed's shares combined by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vasim.operator.questionnaire import (
    MIN_SHARE,
    ConditionPrior,
    condition_prior,
    perceive,
    seed_prior,
)
from vasim.study.gain_plan import block_mean_gain, condition_priors
from vasim.study.protocol import load_protocol

# seed shares (best, worst) and ratings: VG .13 .35 5.63, AG .19 .14 6.38, Mag .36 .10 6.85,
# FF .24 .02 7.08
HAND = {
    # p = 1 - (1 - p1)(1 - p2); q = sqrt(q1 q2); r = (r1 + r2) / 2
    ("ag", "mag"): (1 - 0.81 * 0.64, math.sqrt(0.14 * 0.10), (6.38 + 6.85) / 2),
    ("mag", "ff"): (1 - 0.64 * 0.76, math.sqrt(0.10 * 0.02), (6.85 + 7.08) / 2),
    ("vg", "ag"): (1 - 0.87 * 0.81, math.sqrt(0.35 * 0.14), (5.63 + 6.38) / 2),
}


@pytest.mark.parametrize("kinds", list(HAND))
def test_a_combined_schema_combines_its_fixtures(kinds: tuple[str, str]) -> None:
    p = condition_prior(kinds)
    assert p is not None
    best, worst, rating = HAND[kinds]
    assert p.best_share == pytest.approx(best, abs=1e-12)
    assert p.worst_share == pytest.approx(worst, abs=1e-12)
    assert p.rating == pytest.approx(rating, abs=1e-12)
    # the order of the fixtures does not matter
    q = condition_prior(kinds[::-1])
    assert q is not None and q.best_share == pytest.approx(p.best_share, abs=1e-15)


def test_the_hand_numbers() -> None:
    # AG+Mag is named best more often than either part, Mag+FF is the most comfortable
    assert HAND[("ag", "mag")][0] == pytest.approx(0.4816)
    assert HAND[("mag", "ff")][1] == pytest.approx(0.044721, abs=1e-6)
    assert HAND[("vg", "ag")][2] == pytest.approx(6.005)


def test_a_faded_fixture_is_noticed_in_proportion_to_its_gain() -> None:
    ff = seed_prior("ff")
    for g in (1.0, 0.625, 0.5, 0.0):
        p = condition_prior(("ff",), gain=g)
        assert p is not None
        assert p.best_share == pytest.approx(max(MIN_SHARE, g * 0.24), abs=1e-15)
        assert p.worst_share == pytest.approx(ff.worst_share) and p.rating == ff.rating
    # a seed fixture at gain 1 is exactly the seed's
    assert condition_prior(("mag",)) == ConditionPrior(0.36, 0.10, 6.85)
    # a combination faded: 1 - (1 - 0.5 x 0.19)(1 - 0.5 x 0.36)
    p = condition_prior(("ag", "mag"), gain=0.5)
    assert p is not None and p.best_share == pytest.approx(1 - 0.905 * 0.82, abs=1e-12)


def test_an_unrated_fixture_keeps_the_condition_neutral() -> None:
    assert condition_prior(("cone", "ff")) is None
    assert condition_prior(()) is None
    assert seed_prior("cone") == ConditionPrior(0.2, 0.2, 6.0)


def test_protocol_priors_cover_the_new_conditions() -> None:
    schemas = condition_priors(load_protocol("vf_schemas"))
    assert set(schemas) == {"ag_mag", "mag_ff", "vg_ag"}
    assert schemas["ag_mag"].best_share == pytest.approx(HAND[("ag", "mag")][0], abs=1e-12)
    fading = load_protocol("vf_fading")
    pr = condition_priors(fading)
    assert set(pr) == {"ff_faded", "ff_adaptive", "mag_faded", "mag_adaptive"}
    # faded: schedule 1, .75, .5, .25 over equal runs -> mean gain 0.625; adaptive: the
    # rule's start gain 0.5 (gain_plan.learning_gain)
    gains = {b.condition: block_mean_gain(b) for b in fading.blocks if b.has_gain}
    assert gains == {"ff_faded": 0.625, "ff_adaptive": 0.5, "mag_faded": 0.625,
                     "mag_adaptive": 0.5}
    assert pr["ff_faded"].best_share == pytest.approx(0.625 * 0.24, abs=1e-15)
    assert pr["mag_adaptive"].best_share == pytest.approx(0.5 * 0.36, abs=1e-15)
    assert condition_priors(load_protocol("vf_learning_curve")) == {}   # all seed-rated


def test_perceive_uses_the_priors_in_its_utilities() -> None:
    priors = {"ag_mag": condition_prior(("ag", "mag"))}
    assert priors["ag_mag"] is not None
    got = perceive({"ag_mag": 0.0, "ff": 0.0}, np.random.default_rng(3),
                   priors)  # type: ignore[arg-type]
    rng = np.random.default_rng(3)
    g_best, g_worst = rng.gumbel(size=2), rng.gumbel(size=2)
    noise = rng.normal(0.0, 1.5, size=2)
    assert got["ag_mag"].best_utility == pytest.approx(math.log(0.4816) + g_best[0])
    assert got["ag_mag"].worst_utility == pytest.approx(
        math.log(math.sqrt(0.014)) + g_worst[0])
    assert got["ag_mag"].rating == pytest.approx(6.615 + noise[0])
    assert got["ff"].best_utility == pytest.approx(math.log(0.24) + g_best[1])  # the seed's


def test_best_choices_follow_the_combined_shares() -> None:
    """Multinomial logit: with equal measured benefits, P(best = c) = p_c / sum p, so
    AG+Mag against AG and Mag is named best 0.4816 / (0.4816 + 0.19 + 0.36) = 0.467."""
    priors = {"ag_mag": condition_prior(("ag", "mag"))}
    rng = np.random.default_rng(11)
    n = 6000
    wins = 0
    for _ in range(n):
        p = perceive({"ag_mag": 0.0, "ag": 0.0, "mag": 0.0}, rng,
                     priors)  # type: ignore[arg-type]
        wins += max(p, key=lambda c: p[c].best_utility) == "ag_mag"
    expected = 0.4816 / (0.4816 + 0.19 + 0.36)
    se = math.sqrt(expected * (1 - expected) / n)
    assert abs(wins / n - expected) < 4 * se, (wins / n, expected)
