"""Power planning's pure design functions: the --subjects grid, cohort seeds, scaled
effects and the design's validation (vasim/study/power/design.py)."""

from __future__ import annotations

import dataclasses
import itertools
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vasim.core.errors import ConfigError, InputError
from vasim.operator.learning import DEFAULT_EFFECTS, trial_adjustment
from vasim.study.power.design import (
    COARSE_DT,
    FULL_DT,
    PowerDesign,
    cohort_seed,
    parse_subjects,
    scaled_effects,
    surgeons_for,
)


def test_range_spec_is_inclusive_like_the_issue_example() -> None:
    assert parse_subjects("10:60:5") == tuple(range(10, 61, 5))
    assert len(parse_subjects("10:60:5")) == 11
    assert parse_subjects("10:59:5")[-1] == 55          # STOP not on a step: not included
    assert parse_subjects(" 4 : 6 ") == (4, 5, 6)       # STEP defaults to 1
    assert parse_subjects("12") == (12,)
    assert parse_subjects("20,8, 12,8") == (8, 12, 20)


@pytest.mark.parametrize(("spec", "words"), [
    ("", "START:STOP:STEP"),
    ("ten", "START:STOP:STEP"),
    ("10:60:0", "STEP 0"),
    ("60:10:5", "START 60 > STOP 10"),
    ("1:5", "got 1"),                 # an RM-ANOVA needs two subjects
    ("8,-3", "START:STOP:STEP"),
    ("8,,12", "START:STOP:STEP"),
    ("10:60:5:1", "START:STOP:STEP"),
    ("2:100000", "design points"),
    ("20000", "got 20000"),           # above the SUBJECTS bound
    ("1.5:3", "START:STOP:STEP"),
])
def test_bad_subject_specs_are_clear_errors(spec: str, words: str) -> None:
    with pytest.raises(InputError) as info:   # a command-line argument (issue #29)
        parse_subjects(spec)
    assert info.value.field == "--subjects"
    assert words in str(info.value)


@given(st.integers(2, 300), st.integers(0, 300), st.integers(1, 50))
def test_range_spec_equals_the_list_of_its_counts(start: int, span: int, step: int) -> None:
    stop = start + span
    got = parse_subjects(f"{start}:{stop}:{step}")
    assert got == tuple(range(start, stop + 1, step))
    assert parse_subjects(",".join(map(str, reversed(got)))) == got
    assert got[0] == start and got[-1] <= stop
    assert all(b - a == step for a, b in itertools.pairwise(got))


@given(st.integers(0, 2**63 - 1), st.integers(2, 10_000), st.integers(0, 100_000))
def test_cohort_seeds_are_63_bit_and_reproducible(seed: int, n: int, k: int) -> None:
    s = cohort_seed(seed, n, k)
    assert 0 <= s < 2**63 and s == cohort_seed(seed, n, k)
    assert s != cohort_seed(seed, n, k + 1) and s != cohort_seed(seed, n + 1, k)


def test_surgeons_follow_the_vf_study_share() -> None:
    assert [surgeons_for(n) for n in (46, 10, 4, 60)] == [31, 7, 3, 40]


def test_scale_one_is_the_calibration_and_zero_no_fixture_effect() -> None:
    assert scaled_effects(1.0) == DEFAULT_EFFECTS
    none = scaled_effects(0.0)
    for e in none.values():
        assert (e.accuracy, e.speed, e.practice_weight, e.dependence) == (1.0, 1.0, 1.0, 0.0)
    # with no effect an assisted trial is a VF-free trial: noise factor 1, practice counts 1
    hist = ["none"] * 3 + ["ff"] * 6
    adj = trial_adjustment(hist, "ff", none)
    assert (adj.noise_factor, adj.time_factor, adj.practice) == (1.0, 1.0, 9.0)
    assert trial_adjustment(hist, "none", none).noise_factor == 1.0


@given(st.floats(0.0, 1.5))
def test_effects_scale_linearly_about_no_effect(s: float) -> None:
    for name, e in scaled_effects(s).items():
        base = DEFAULT_EFFECTS[name]
        assert math.isclose(e.accuracy - 1.0, s * (base.accuracy - 1.0), abs_tol=1e-12)
        assert math.isclose(e.speed - 1.0, s * (base.speed - 1.0), abs_tol=1e-12)
        assert math.isclose(e.dependence, s * base.dependence, abs_tol=1e-12)
        # the carry-over fraction is kept; at s = 0 the effect is the null one
        assert e.carryover == (base.carryover if s > 0 else 0.0)


@pytest.mark.parametrize("s", [-0.1, 4.0, 6.0, math.nan])
def test_effect_scales_that_break_an_effect_are_refused(s: float) -> None:
    # 4 x FF's departure (accuracy 0.75 in seed_plausible) gives 0: no noise, not an operator
    with pytest.raises(ConfigError) as info:
        scaled_effects(s)
    assert info.value.field == "--effect-scale"


def test_design_validates_its_fields() -> None:
    d = PowerDesign(subjects=(4, 8), cohorts=3, dt=COARSE_DT)
    assert d.n_cohorts == 6 and d.effects == DEFAULT_EFFECTS
    for kwargs, field in [({"cohorts": 0}, "--cohorts"), ({"alpha": 0.9}, "--alpha"),
                          ({"dt": 5e-3}, "dt"), ({"p_column": "p"}, "--p"),
                          ({"subjects": ()}, "--subjects"), ({"subjects": (1,)}, "--subjects"),
                          ({"max_trial_time": -1.0}, "--max-time")]:
        args = {"subjects": (4,), "cohorts": 2, "dt": FULL_DT, **kwargs}
        with pytest.raises(ConfigError) as info:
            PowerDesign(**args)  # type: ignore[arg-type]
        assert info.value.field == field, kwargs


def test_power_needs_a_vf_protocol_with_probes() -> None:
    from vasim.study.power.design import check_power_protocol
    from vasim.study.protocol import load_protocol

    check_power_protocol(load_protocol("vf_learning_curve"))
    with pytest.raises(ConfigError, match="no virtual-fixture condition") as info:
        check_power_protocol(load_protocol("mrcp_vs_stdt"))
    assert info.value.field == "--protocol"
    vf = load_protocol("vf_learning_curve")
    no_probes = dataclasses.replace(vf, blocks=tuple(
        dataclasses.replace(b, probe=False, probes_after=0) for b in vf.blocks))
    with pytest.raises(ConfigError, match=r"expected a protocol with VF-free \(probe\) trials"):
        check_power_protocol(no_probes)


def test_effects_file_sets_single_fixtures_then_the_scale_applies(tmp_path) -> None:
    from vasim.study.power.design import load_effects, parse_effects

    path = tmp_path / "effects.toml"
    path.write_text("[ff]\naccuracy = 0.8\n[combo]\nspeed = 0.5\n", encoding="utf-8")
    base = load_effects(path)
    assert base["ff"].accuracy == 0.8 and base["ff"].speed == DEFAULT_EFFECTS["ff"].speed
    assert base["mag"] == DEFAULT_EFFECTS["mag"]
    assert base["combo"].speed == 0.5 and base["combo"].accuracy == 1.0   # from no effect
    d = PowerDesign(subjects=(4,), cohorts=1, effect_scale=0.5, base_effects=base)
    assert math.isclose(d.effects["ff"].accuracy, 0.9)       # 1 + 0.5 (0.8 - 1)
    assert math.isclose(d.effects["combo"].speed, 0.75)
    for text, field in [("[ff]\nacuracy = 0.8\n", "ff.acuracy"),
                        ("[ff]\naccuracy = 'x'\n", "ff.accuracy"),
                        ("[ff]\naccuracy = 0.0\n", "ff"),           # FixtureEffect: > 0
                        ("[ff]\ncarryover = 1.5\n", "ff"),
                        ("ff = 3\n", "ff"),
                        ("[ff\n", None)]:
        with pytest.raises(ConfigError) as info:
            parse_effects(text, file="e.toml")
        assert info.value.field == field and str(info.value.file) == "e.toml", text
    with pytest.raises(InputError) as info:   # the --effects path (issue #29)
        load_effects(tmp_path / "missing.toml")
    assert info.value.field == "--effects"
