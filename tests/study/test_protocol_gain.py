"""Faded and adaptive protocol blocks (vasim/study/protocol/model.py, loader.py,
vasim/study/gain_plan.py; issue #18 items 1 and 3): validated on load with file, field and
value; each scheduled trial gets its gain; the shipped vf_fading and vf_schemas load."""

from __future__ import annotations

import pytest

from vasim.core.errors import ConfigError
from vasim.fixtures.gain import AdaptiveRule
from vasim.operator.learning import DEFAULT_EFFECTS
from vasim.operator.scenario import load_scenario, parse_scenario
from vasim.study.cohort import scenario_record
from vasim.study.gain_plan import condition_effects, learning_gain, trial_gain
from vasim.study.protocol import generate_schedule, load_protocol, parse_protocol
from vasim.study.session import Session, SessionSettings


def deriving_scenario():
    """seed_plausible with FF slowing the operator (speed 1.2) and unlisted labels derived
    from their fixtures (``derive_unlisted = true``)."""
    text = load_scenario("seed_plausible").text
    old_d = "derive_unlisted = { value = false"
    old_s = 'speed = { value = 1.0, source = "assumed: no effect on movement time" }'
    assert old_d in text and old_s in text
    text = text.replace(old_d, "derive_unlisted = { value = true").replace(
        old_s, 'speed = { value = 1.2, source = "test" }', 1)   # the first: [fixtures.ff]
    return parse_scenario(text)


HEAD = """
name = "g"
description = "gain blocks"
task = "trajectory"
[[blocks]]
name = "base"
condition = "none"
probe = true
"""


def block(extra: str, condition: str = "ff_faded", schema: str | None = "ff") -> str:
    s = f'schema = "{schema}"\n' if schema else ""
    return (HEAD + f'[[blocks]]\nname = "b"\ncondition = "{condition}"\n{s}'
            f"variants = [1, 2, 3, 4]\nrepetitions = 2\nprobes_after = 1\n{extra}\n")


def test_shipped_protocols_load_with_their_gain_rules():
    p = load_protocol("vf_fading")
    by = {b.name: b for b in p.blocks}
    assert by["ff_faded"].gain_schedule == (1.0, 0.75, 0.5, 0.25)
    assert by["mag_adaptive"].adaptive == AdaptiveRule(
        gain_min=0.25, gain_max=1.0, tau_s=2.0, deviation_full_m=0.003, initial=0.5)
    assert not by["ff"].has_gain and p.n_trials == 3 + 6 * 9
    assert p.assisted_conditions == ("ff", "ff_faded", "ff_adaptive", "mag", "mag_faded",
                                      "mag_adaptive")
    s = load_protocol("vf_schemas")
    assert s.assisted_conditions == ("vg", "ag", "mag", "ff", "ag_mag", "mag_ff", "vg_ag")
    assert s.post.items[3].conditions == ("ag_mag", "mag_ff", "vg_ag")


def test_every_scheduled_trial_gets_its_gain():
    p = load_protocol("vf_fading")
    sched = generate_schedule(p, 11)
    gains: dict[str, list] = {}
    for t in sched:
        gains.setdefault(t.condition, []).append(trial_gain(p, t))
    assert gains["ff_faded"] == [1.0, 1.0, 0.75, 0.75, 0.5, 0.5, 0.25, 0.25]
    assert gains["mag_faded"] == gains["ff_faded"]
    assert all(g == p.blocks[3].adaptive for g in gains["ff_adaptive"])
    assert set(gains["ff"]) == set(gains["mag"]) == set(gains["none"]) == {1.0}
    # the trial configurations carry them, and the operator's adjustment follows
    sc = deriving_scenario()
    session = Session(id=1, subject="S01", protocol=p, seed=11, status="running",
                      settings=SessionSettings(extra={"scenario": scenario_record(sc, 1.0)}),
                      schedule=tuple(sched), completed=(None,) * len(sched))
    cfgs = {t.index: session.trial_config(t) for t in sched}
    faded = [t for t in sched if t.condition == "ff_faded"]
    assert [cfgs[t.index].gain for t in faded] == gains["ff_faded"]
    assert all(cfgs[t.index].schema == "ff" for t in faded)
    full, quarter = cfgs[faded[0].index], cfgs[faded[-1].index]
    base = SessionSettings().resolved_profile()
    ff = sc.fixtures["ff"]
    assert ff.speed == 1.2
    assert full.profile.fitts_a == pytest.approx(base.fitts_a * ff.speed)
    assert quarter.profile.fitts_a == pytest.approx(base.fitts_a * (1 + 0.25 * (ff.speed - 1)))
    assert learning_gain(p.blocks[3].adaptive) == 0.5


def test_unlisted_conditions_get_an_effect_only_when_the_scenario_says_so():
    # the shipped scenario: no operator effect for labels it does not list (issue #25)
    eff = condition_effects(load_protocol("vf_schemas"))
    assert "ag_mag" not in eff and eff == DEFAULT_EFFECTS
    sc = deriving_scenario()
    eff = condition_effects(load_protocol("vf_schemas"), sc)
    assert eff["ag_mag"].accuracy == pytest.approx(sc.fixtures["ag"].accuracy
                                                   * sc.fixtures["mag"].accuracy)
    assert eff["vg"] == sc.fixtures["vg"]
    assert condition_effects(load_protocol("vf_learning_curve"), sc, 0.0)["ff"].is_null


@pytest.mark.parametrize(("extra", "condition", "schema", "field", "shown"), [
    ("gain_schedule = [1.0, 1.5]", "ff_faded", "ff", "blocks[1].gain_schedule[1]", "1.5"),
    ("gain_schedule = []", "ff_faded", "ff", "blocks[1].gain_schedule", "()"),
    ("gain_schedule = 0.5", "ff_faded", "ff", "blocks[1].gain_schedule", "0.5"),
    ("adaptive = { tau_s = -1.0 }", "ff_ad", "ff", "blocks[1].adaptive.tau_s", "-1.0"),
    ("adaptive = { tau = 1.0 }", "ff_ad", "ff", "blocks[1].adaptive.tau", "1.0"),
    ("adaptive = 3", "ff_ad", "ff", "blocks[1].adaptive", "3"),
    ("gain_schedule = [1.0]\nadaptive = { tau_s = 1.0 }", "ff_x", "ff",
     "blocks[1].gain_schedule", "(1.0,)"),
    ("gain_schedule = [1.0, 0.5]", "ff_faded", None, "blocks[1].schema", "None"),
    ("gain_schedule = [1.0, 0.5]", "ff", "ff", "blocks[1].condition", "'ff'"),
    ("gain_schedule = [1.0, 0.5]", "stdt", "ff", "blocks[1].condition", "'stdt'"),
    ("gain_schedule = [1.0, 0.5]", "x_faded", "none", "blocks[1].schema", "'none'"),
    ("gain_schedule = [1.0, 0.5]", "x_faded", "nonesuch", "blocks[1].schema", "'nonesuch'"),
])
def test_bad_gain_blocks_name_file_field_and_value(extra, condition, schema, field, shown):
    with pytest.raises(ConfigError) as err:
        parse_protocol(block(extra, condition, schema), source="g.toml")
    assert err.value.field == field, str(err.value)
    assert str(err.value.file) == "g.toml" and f"got {shown}" in str(err.value)


def test_a_probe_block_has_no_gain():
    text = HEAD.replace('probe = true', 'probe = true\nschema = "none"\n'
                        'gain_schedule = [0.5]').replace('"none"\nprobe', '"nf"\nprobe', 1)
    with pytest.raises(ConfigError) as err:
        parse_protocol(text, source="g.toml")
    assert err.value.field == "blocks[0].probe"


def test_the_schedule_command_shows_each_trials_gain(capsys):
    from vasim.cli import main

    assert main(["study", "schedule", "--protocol", "vf_fading", "--seed", "7"]) == 0
    lines = capsys.readouterr().out.splitlines()[2:]
    lines = lines[:lines.index("")]   # the design lines follow the table (issue #25)
    faded = [line.split("  ")[-1].strip() for line in lines if " ff_faded " in line
             and "VF-free" not in line]
    assert faded == ["gain 100 %"] * 2 + ["gain 75 %"] * 2 + ["gain 50 %"] * 2 + [
        "gain 25 %"] * 2
    assert all(line.endswith("adaptive 25-100 %") for line in lines
               if " mag_adaptive " in line and "VF-free" not in line)
    constant = [line for line in lines if line.split()[1] == "ff"]
    assert len(constant) == 9 and not any("gain" in line for line in constant)
