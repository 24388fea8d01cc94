"""The declared scenario of the simulated operator (vasim/operator/scenario.py; issue #25
item 3): loading, validation with clear errors, sources, effect scale, groups."""

from __future__ import annotations

import doctest
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import vasim.operator.scenario as scenario_mod
from vasim.core.errors import ConfigError
from vasim.operator.effects import EFFECT_FIELDS, FixtureEffect, scale_effect
from vasim.operator.scenario import load_scenario, parse_scenario, scenario_path

SHIPPED = ("seed_plausible", "null")


def _text(name: str = "seed_plausible") -> str:
    return scenario_path(name).read_text(encoding="utf-8")


def test_doctests():
    assert doctest.testmod(scenario_mod).failed == 0


@pytest.mark.parametrize("name", SHIPPED)
def test_every_parameter_of_a_shipped_scenario_has_a_source(name):
    sc = load_scenario(name)
    lines = [x for x in sc.text.splitlines() if not x.lstrip().startswith("#")]
    n_values = len(re.findall(r"\{\s*value\s*=", "\n".join(lines)))
    assert len(sc.sources) == n_values > 40
    assert all(s.strip() for s in sc.sources.values())
    assert set(sc.fixtures) == {"vg", "ag", "ms", "mag", "ff"}
    assert sc.sha256 == scenario_mod.hashlib.sha256(sc.text.encode()).hexdigest()


def test_the_null_scenario_has_no_fixture_effect_at_all():
    sc = load_scenario("null")
    assert all(e.is_null for e in sc.effects().values())
    assert sc.mechanism() == 0.0


def test_effect_scale_zero_removes_every_effect_and_one_keeps_the_declared():
    sc = load_scenario("seed_plausible")
    assert all(e.is_null for e in sc.effects(0.0).values())
    assert sc.effects(1.0) == dict(sc.fixtures)
    assert sc.mechanism(0.0) == 0.0 and sc.mechanism(1.0) == 1.0 and sc.mechanism(3.0) == 1.0


@settings(max_examples=100, deadline=None)
@given(st.floats(0.01, 0.99), st.floats(0.5, 1.5), st.floats(0.0, 1.0), st.floats(0.0, 1.0))
def test_scaling_is_linear_in_the_departure_and_halves_compose(acc, speed, rho, s):
    e = FixtureEffect(accuracy=acc, speed=speed, carryover=rho, dependence=0.2)
    h = scale_effect(e, s)
    assert h.accuracy - 1.0 == pytest.approx(s * (acc - 1.0))
    assert h.speed - 1.0 == pytest.approx(s * (speed - 1.0))
    assert h.dependence == pytest.approx(0.2 * s)
    twice = scale_effect(scale_effect(e, 0.5), 2.0)
    for f in EFFECT_FIELDS:
        assert getattr(twice, f) == pytest.approx(getattr(e, f))


def test_no_seed_result_is_in_the_generative_questionnaire():
    import vasim.operator.questionnaire as q

    for name in ("SEED_BEST_SHARE", "SEED_WORST_SHARE", "SEED_MEAN_RATING", "seed_prior"):
        assert not hasattr(q, name)
    src = open(q.__file__, encoding="utf-8").read()
    for value in ("0.36", "7.08", "6.85", "4.74", "0.39"):   # the seed's shares/ratings
        assert value not in src


@pytest.mark.parametrize("old,new,field", [
    ('accuracy = { value = 0.75, source = "seed sec. 6.2', 'accuracy = { value = 0.75, '
     'sourc = "x", source = "seed sec. 6.2', "fixtures.ff.accuracy.sourc"),
    ('accuracy = { value = 0.75, source = "seed sec. 6.2', 'accuracy = { value = -1, '
     'source = "seed sec. 6.2', "fixtures.ff.accuracy.value"),
    ('[questionnaire]\nchoice_noise = { value = 0.1, source = "assumed: Gumbel',
     '[questionnaire]\nchoice_noise = { value = 0.1, source = "", x = "assumed: Gumbel',
     "questionnaire.choice_noise"),
    ('p = { value = 0.6, source = "assumed" }', 'p = { value = 0.7, source = "assumed" }',
     "groups.surgeon.experience"),
])
def test_bad_scenarios_are_refused_naming_the_field(old, new, field):
    text = _text()
    assert old in text
    with pytest.raises(ConfigError) as exc:
        parse_scenario(text.replace(old, new, 1), file="x.toml")
    assert exc.value.file == "x.toml" and exc.value.field.startswith(field), exc.value


def test_a_missing_source_is_refused():
    text = _text().replace(', source = "assumed: no effect on movement time" }', " }", 1)
    with pytest.raises(ConfigError, match="source"):
        parse_scenario(text)


def test_groups_that_cross_over_are_refused_unless_the_file_says_why():
    # residents learning faster toward a lower plateau would end up better than surgeons
    old = 'asymptote = { value = 0.6, source = "assumed (as surgeons)'
    assert old in _text()
    text = _text().replace(old, 'asymptote = { value = 0.1, source = "assumed (as surgeons)')
    with pytest.raises(ConfigError, match=r"got 'resident', expected the less experienced "
                       r"group \(mean skill [0-9.]+\) not to overtake 'surgeon'") as exc:
        parse_scenario(text)
    assert exc.value.field == "groups"
    ok = text.replace("[groups.surgeon]\n", '[groups]\ncrossover_reason = "testing"\n\n'
                      "[groups.surgeon]\n", 1)
    assert parse_scenario(ok).crossover_reason == "testing"


def test_unknown_scenario_names_what_exists():
    with pytest.raises(ConfigError, match="null, seed_plausible"):
        load_scenario("no_such_scenario")


def test_experience_and_skill_are_drawn_together_and_experts_plateau_lower():
    sc = load_scenario("seed_plausible")
    rng = np.random.default_rng(5)
    draws = [sc.sample_subject(rng, g) for g in ["surgeon", "resident"] * 600]
    by_cat: dict[str, list[float]] = {}
    for prof, cat in draws:
        by_cat.setdefault(cat, []).append(prof.skill)
    means = {c: float(np.mean(v)) for c, v in by_cat.items()}
    # the declared category means come back (Beta with that mean; 3 SE tolerance)
    for g in sc.groups.values():
        for e in g.experience:
            v = by_cat[e.name]
            assert means[e.name] == pytest.approx(e.skill_mean,
                                                  abs=3 * np.std(v) / np.sqrt(len(v)))
    assert means[">200"] > means["51-200"] > means["11-50"] > means["1-10"] > means["none"]
    s, r = sc.groups["surgeon"], sc.groups["resident"]
    p = np.arange(0.0, 500.0)
    assert np.all(s.curve(p) <= r.curve(p)) and np.all(s.time_curve(p) <= r.time_curve(p))
    assert all(prof.asymptote == sc.groups["surgeon"].asymptote for prof, _ in draws[::2])
