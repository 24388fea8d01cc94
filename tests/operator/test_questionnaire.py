"""Answers from what the subject experienced (vasim/operator/questionnaire.py; issue #25
item 3): with no fixture effect there is no preference; a measured benefit moves the answers
by the declared noise model."""

from __future__ import annotations

import doctest

import numpy as np
import pytest
from scipy import stats

import vasim.operator.questionnaire as questionnaire_mod
from vasim.operator.questionnaire import perceive
from vasim.operator.scenario import QuestionnaireModel, load_scenario

FIX = ("vg", "ag", "ms", "mag", "ff")


def test_doctests():
    assert doctest.testmod(questionnaire_mod).failed == 0


def _choices(benefit: dict[str, float], model: QuestionnaireModel, n: int, seed: int):
    rng = np.random.default_rng(seed)
    best = dict.fromkeys(benefit, 0)
    worst = dict.fromkeys(benefit, 0)
    ratings = {c: [] for c in benefit}
    for _ in range(n):
        p = perceive(benefit, rng, model)
        best[max(p, key=lambda c: p[c].best_utility)] += 1
        worst[max(p, key=lambda c: p[c].worst_utility)] += 1
        for c in p:
            ratings[c].append(p[c].rating)
    return best, worst, ratings


def test_equal_benefits_give_no_preference():
    model = load_scenario("seed_plausible").questionnaire
    n = 5000
    best, worst, ratings = _choices(dict.fromkeys(FIX, 0.1), model, n, seed=1)
    # uniform 1/5: a chi-square goodness-of-fit test does not reject at 1 %
    assert stats.chisquare(list(best.values())).pvalue > 0.01
    assert stats.chisquare(list(worst.values())).pvalue > 0.01
    centre = model.rating_centre + model.rating_per_benefit * 0.1
    for c in FIX:   # every rating has the same expectation (4 standard errors)
        assert np.mean(ratings[c]) == pytest.approx(centre, abs=4 * model.rating_sd / n**0.5)


def test_a_measured_benefit_shifts_choices_as_a_logit_and_ratings_linearly():
    model = QuestionnaireModel(choice_noise=0.2, rating_centre=5.0, rating_per_benefit=10.0,
                               rating_sd=1.0)
    b = {"ff": 0.2, "ms": 0.0}
    n = 20000
    best, worst, ratings = _choices(b, model, n, seed=2)
    p_ff = np.exp(0.2 / 0.2) / (np.exp(0.2 / 0.2) + 1.0)   # McFadden logit in b / tau
    se = (p_ff * (1 - p_ff) / n) ** 0.5
    assert best["ff"] / n == pytest.approx(p_ff, abs=4 * se)
    assert worst["ms"] / n == pytest.approx(p_ff, abs=4 * se)
    assert np.mean(ratings["ff"]) - np.mean(ratings["ms"]) == pytest.approx(
        10.0 * 0.2, abs=4 * (2 / n) ** 0.5)


def test_non_finite_benefit_counts_as_none():
    model = QuestionnaireModel(choice_noise=1.0, rating_centre=5.0, rating_per_benefit=10.0,
                               rating_sd=0.0)
    p = perceive({"ff": float("nan")}, np.random.default_rng(0), model)
    assert p["ff"].rating == 5.0
