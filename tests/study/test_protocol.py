"""Study protocols (vasim/study/protocol.py): the shipped files, validation errors that name
file, field and value, schedules (reproducible, balanced) and questionnaire answers."""

from __future__ import annotations

import copy
import itertools
import tomllib
from collections import Counter
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.core.errors import ConfigError, InputError
from vasim.core.resources import studies_dir
from vasim.study.protocol import (
    available_protocols,
    block_order,
    generate_schedule,
    load_protocol,
    parse_protocol,
    protocol_from_dict,
    validate_answers,
    williams_square,
)

FIXTURES = ("vg", "ag", "ms", "mag", "ff")


def vf_dict() -> dict:
    return tomllib.loads((studies_dir() / "vf_learning_curve.toml").read_text())


# --------------------------------------------------------------------- shipped files
def test_every_shipped_protocol_loads() -> None:
    names = available_protocols()
    assert {"vf_learning_curve", "vf_point_targeting", "mrcp_vs_stdt"} <= set(names)
    for n in names:
        p = load_protocol(n)
        assert p.text is not None and p.name == n
        assert len(generate_schedule(p, 1)) == p.n_trials


SEED_SCHEMA = {"vg": "vg_seed", "ag": "ag_seed"}


def test_the_seed_and_revised_protocols_run_their_own_vg_and_ag() -> None:
    from vasim.fixtures.schema import load_schema

    seed = load_protocol("vf_learning_curve")
    revised = load_protocol("vf_learning_curve_revised")
    for proto, vg, ag in ((seed, "vg_seed", "ag_seed"), (revised, "vg", "ag")):
        runs = {t.condition: t.schema for t in generate_schedule(proto, 3)}
        assert runs["vg"] == vg and runs["ag"] == ag
        assert runs["ff"] == "ff" and runs["none"] == "none"
    assert load_schema("vg_seed").fixtures[0].params.fade is False
    assert load_schema("vg").fixtures[0].params.fade is True
    assert load_schema("ag_seed").fixtures[0].params.dead_zone is False
    assert load_schema("ag").fixtures[0].params.dead_zone is True
    # the same schedule otherwise
    a = generate_schedule(seed, 11)
    b = generate_schedule(revised, 11)
    assert [(t.condition, t.variant, t.probe) for t in a] == \
        [(t.condition, t.variant, t.probe) for t in b]


def test_a_block_schema_must_exist() -> None:
    d = vf_dict()
    d["blocks"][1]["schema"] = "vg_nonexistent"
    with pytest.raises(ConfigError, match=r"blocks\[1\]\.schema"):
        protocol_from_dict(d)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**63 - 1))
def test_vf_learning_curve_schedule(seed: int) -> None:
    p = load_protocol("vf_learning_curve")
    s = generate_schedule(p, seed)
    assert len(s) == 38 == 3 + 5 * 7
    assert [t.index for t in s] == list(range(38))
    probes = [t for t in s if t.probe]
    # 8 VF-free trials on the assisted trials' variants, rotating (issue #25), numbered
    # 1..8 in session order
    assert len(probes) == 8
    assert all(t.condition == "none" and t.schema == "none" for t in probes)
    offset = seed + seed // 30   # one variant further every lcm(10, 6) = 30 subjects
    assert [t.variant for t in probes] == [1 + (offset + k) % 6 for k in range(8)]
    assert [t.probe_index for t in probes] == list(range(1, 9))
    assert all(t.probe_index is None for t in s if not t.probe)
    # baseline: the first three trials
    assert [t.probe for t in s[:3]] == [True] * 3 and s[0].block == "baseline"
    # five blocks, one per fixture, each 6 assisted trials on variants 1..6 then 1 VF-free
    blocks = [s[3 + 7 * b: 3 + 7 * (b + 1)] for b in range(5)]
    assert sorted(b[0].condition for b in blocks) == sorted(FIXTURES)
    for pos, b in enumerate(blocks, start=1):
        assisted, probe = b[:6], b[6]
        assert {t.condition for t in assisted} == {b[0].condition}
        # the seed's conditions: VG and AG run as the 46 subjects used them
        assert {t.schema for t in assisted} == {SEED_SCHEMA.get(b[0].condition,
                                                                b[0].condition)}
        assert sorted(t.variant for t in assisted) == [1, 2, 3, 4, 5, 6]
        assert not any(t.probe for t in assisted) and probe.probe
        assert {t.block_index for t in b} == {pos}
        assert [t.trial_in_block for t in b] == list(range(7))
    # the same seed gives the same schedule
    assert generate_schedule(p, seed) == s


def test_block_and_variant_orders_are_randomised_across_seeds() -> None:
    d = vf_dict()
    d["randomisation"]["block_order"] = "random"
    p = protocol_from_dict(d)
    orders = {tuple(t.condition for t in generate_schedule(p, seed)[3::7]) for seed in range(40)}
    variants = {tuple(t.variant for t in generate_schedule(p, seed)[3:9]) for seed in range(40)}
    # 40 seeds over 120 block orders / 720 variant orders: collisions are rare
    assert len(orders) > 25 and len(variants) > 30
    # with "fixed" orders every seed gives the file order
    d = vf_dict()
    d["randomisation"] = {"block_order": "fixed", "variant_order": "fixed"}
    fixed = protocol_from_dict(d)
    s = generate_schedule(fixed, 12345)
    assert [t.condition for t in s[3::7]] == list(FIXTURES)
    assert [t.variant for t in s[3:9]] == [1, 2, 3, 4, 5, 6]
    # the shipped protocol counterbalances: 10 Williams sequences over consecutive seeds
    shipped = load_protocol("vf_learning_curve")
    assert shipped.block_order == "latin_square"
    assert len({tuple(t.condition for t in generate_schedule(shipped, seed)[3::7])
                for seed in range(40)}) == 10


@settings(max_examples=12, deadline=None)
@given(n=st.integers(1, 9))
def test_williams_square_is_a_balanced_latin_square(n: int) -> None:
    rows = williams_square(n)
    assert len(rows) == (n if n % 2 == 0 else 2 * n)
    for row in rows:
        assert sorted(row) == list(range(n))
    for col in range(n):  # every condition equally often in every position
        assert set(Counter(r[col] for r in rows).values()) == {len(rows) // n}
    pairs = Counter((a, b) for r in rows for a, b in itertools.pairwise(r))
    if n > 1:  # every ordered pair of neighbours equally often (Williams 1949)
        assert set(pairs.values()) == {1 if n % 2 == 0 else 2}
        assert len(pairs) == n * (n - 1)


def test_latin_square_counterbalances_consecutive_seeds() -> None:
    p = load_protocol("vf_point_targeting")  # 5 counterbalanced blocks: 10 rows
    firsts = Counter(p.blocks[block_order(p, seed)[1]].name for seed in range(100, 110))
    assert set(firsts.values()) == {2} and len(firsts) == 5
    assert block_order(p, 3)[0] == 0  # the baseline keeps its place


def test_mrcp_protocol_validates_and_runs() -> None:
    p = load_protocol("mrcp_vs_stdt")
    assert p.teleoperation_modes == ("stdt", "mrcp", "mrcp_cam")
    s = generate_schedule(p, 5)
    assert len(s) == 18 and Counter(t.condition for t in s) == {"stdt": 6, "mrcp": 6,
                                                                 "mrcp_cam": 6}
    assert all(t.schema is None for t in s)
    p.check_runnable()  # the MRCP slave station exists (vasim.trials.teleop)


# ---------------------------------------------------------------------- validation
def _mutate(path: list, value) -> dict:
    d = vf_dict()
    target = d
    for k in path[:-1]:
        target = target[k]
    if value is KeyError:
        del target[path[-1]]
    else:
        target[path[-1]] = value
    return d


@pytest.mark.parametrize(("path", "value", "field", "shown"), [
    (["colour"], "red", "colour", "'red'"),
    (["blocks", 2, "condition"], "xx", "blocks[2].condition", "'xx'"),
    (["blocks", 1, "variants"], [1, 9], "blocks[1].variants[1]", "9"),
    (["blocks", 1, "variants"], [], "blocks[1].variants", "empty"),
    (["blocks", 0, "repetitions"], "3", "blocks[0].repetitions", "'3'"),
    (["blocks", 0, "colour"], 1, "blocks[0].colour", "1"),
    (["blocks", 3, "probe"], "yes", "blocks[3].probe", "'yes'"),
    (["blocks", 2, "name"], "vg", "blocks[2].name", "'vg'"),
    (["reach_radius_m"], -0.001, "reach_radius_m", "-0.001"),
    (["task"], "suture", "task", "'suture'"),
    (["name"], KeyError, "name", "missing"),
    (["randomisation", "block_order"], "shuffle", "randomisation.block_order", "'shuffle'"),
    (["probe", "condition"], "vg", "probe.condition", "'vg'"),
    (["probe", "variants"], [1, 7], "probe.variants[1]", "7"),
    (["probe", "variants"], [1, 1], "probe.variants", "[1, 1]"),
    (["probe", "variants"], [], "probe.variants", "[]"),
    (["probe", "variant"], 0, "probe.variants", "not both"),
    (["blocks", 0, "variants"], [0], "blocks[0].variants", "rotation"),
    (["questionnaires", "post", "items", 0, "type"], "stars",
     "questionnaires.post.items[0].type", "'stars'"),
    (["questionnaires", "post", "items", 2, "max"], "ten",
     "questionnaires.post.items[2].max", "'ten'"),
    (["questionnaires", "post", "items", 0, "conditions"], ["vg", "zz"],
     "questionnaires.post.items[0].conditions[1]", "'zz'"),
    (["questionnaires", "pre", "demographics"], 1, "questionnaires.pre.demographics", "1"),
])
def test_bad_fields_are_named_with_file_and_value(path, value, field, shown) -> None:
    d = _mutate(path, value)
    with pytest.raises(ConfigError) as e:
        protocol_from_dict(d, source="proto.toml")
    msg = str(e.value)
    assert e.value.field == field, msg
    assert msg.startswith(f"proto.toml: field '{field}'"), msg
    assert shown in msg, msg


def test_schema_for_the_wrong_task_and_invalid_toml_are_refused(tmp_path: Path) -> None:
    d = vf_dict()
    d["task"] = "point"  # ms is a trajectory schema; variants 1..6 do not exist either
    with pytest.raises(ConfigError, match=r"variant|'ms' is for 'trajectory'"):
        protocol_from_dict(d)
    f = tmp_path / "bad.toml"
    f.write_text("name = \n")
    with pytest.raises(ConfigError, match="invalid TOML") as e:
        load_protocol(f)
    assert str(f) in str(e.value)
    with pytest.raises(ConfigError, match="unknown protocol 'nope'"):
        load_protocol("nope")


def test_protocol_text_roundtrips() -> None:
    p = load_protocol("vf_learning_curve")
    again = parse_protocol(p.text, source="stored")
    assert again == p and again.text == p.text


# ------------------------------------------------------------------------- answers
GOOD_PRE = {"group": "surgeon", "specialisation": "urology", "laparoscopy_experience": ">200",
            "simulator_experience": "none", "robotic_experience": "assisted"}
GOOD_POST = {"best_vf": "ff", "worst_vf": "ag",
             "rating": {"vg": 6, "ag": 2, "ms": 7, "mag": 5, "ff": 10},
             "proposed_schemas": [["ff", "vg"], ["mag", "ms", "ff"]],
             "comments": 'the "FF", honestly,\nfelt best'}


def test_answers_become_tidy_rows() -> None:
    p = load_protocol("vf_learning_curve")
    rows, demo = validate_answers(p, "pre", GOOD_PRE)
    assert demo is not None and demo.group == "surgeon"
    assert ("robotic_experience", "", "assisted", None) in rows and len(rows) == 5
    rows, demo = validate_answers(p, "post", GOOD_POST)
    assert demo is None
    assert ("best_vf", "", "ff", None) in rows
    assert ("rating", "ff", "10", 10.0) in rows
    # sets are written in the item's condition order: vg ag ms mag ff
    assert ("proposed_schemas", "1", "vg+ff", None) in rows
    assert ("proposed_schemas", "2", "ms+mag+ff", None) in rows
    assert ("comments", "", GOOD_POST["comments"], None) in rows  # stored as given
    optional = {k: v for k, v in GOOD_POST.items() if k not in ("comments",
                                                                 "proposed_schemas")}
    assert len(validate_answers(p, "post", optional)[0]) == 7


@pytest.mark.parametrize(("q", "change", "field"), [
    ("post", {"rating": {"vg": 11, "ag": 2, "ms": 7, "mag": 5, "ff": 1}}, "post.rating.vg"),
    ("post", {"rating": {"vg": 1}}, "post.rating"),
    ("post", {"best_vf": "none"}, "post.best_vf"),
    ("post", {"proposed_schemas": [["ff"]]}, "post.proposed_schemas"),
    ("post", {"proposed_schemas": [["ff", "xx"]]}, "post.proposed_schemas"),
    ("post", {"proposed_schemas": [["ff", "vg"], ["vg", "ff"]]}, "post.proposed_schemas"),
    ("post", {"favourite": "ff"}, "post.favourite"),
    ("pre", {"group": "nurse"}, "pre.group"),
    ("pre", {"laparoscopy_experience": "lots"}, "pre.laparoscopy_experience"),
])
def test_bad_answers_name_the_item(q: str, change: dict, field: str) -> None:
    p = load_protocol("vf_learning_curve")
    answers = copy.deepcopy(GOOD_PRE if q == "pre" else GOOD_POST)
    answers.update(change)
    with pytest.raises(InputError) as e:   # answers are input data (issue #29)
        validate_answers(p, q, answers, source="answers.toml")  # type: ignore[arg-type]
    assert e.value.field == field and "answers.toml" in str(e.value)
    missing = copy.deepcopy(GOOD_POST)
    del missing["best_vf"]
    with pytest.raises(InputError, match="required"):
        validate_answers(p, "post", missing)


# -- Names with a trailing newline and time limits beyond a day are refused.
def test_protocol_names_with_a_trailing_newline_are_refused(tmp_path: Path) -> None:
    from vasim.study.protocol import load_protocol

    src = Path(__file__).parents[2] / "protocols" / "studies" / "vf_learning_curve.toml"
    text = src.read_text().replace('name = "vf_learning_curve"', 'name = "vf_learning_curve\\n"')
    assert text != src.read_text()
    p = tmp_path / "p.toml"
    p.write_text(text)
    with pytest.raises(ConfigError, match="name"):
        load_protocol(p)


def test_a_protocol_time_limit_beyond_a_day_is_refused(tmp_path: Path) -> None:
    from vasim.study.protocol import load_protocol

    src = Path(__file__).parents[2] / "protocols" / "studies" / "vf_learning_curve.toml"
    text = src.read_text()
    assert "max_trial_time_s" in text
    lines = [("max_trial_time_s = 1e308" if ln.startswith("max_trial_time_s") else ln)
             for ln in text.splitlines()]
    p = tmp_path / "p.toml"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(ConfigError, match="max_trial_time_s"):
        load_protocol(p)


def test_poi_spacing_is_a_protocol_parameter() -> None:
    from vasim.trials.vf import TrialConfig, make_task

    d = vf_dict()
    assert load_protocol("vf_learning_curve").poi_spacing is None   # the task's default
    d["poi_spacing_m"] = 0.0056
    d["reach_radius_m"] = 0.0025
    p = protocol_from_dict(d)
    assert p.poi_spacing == 0.0056
    task = make_task(TrialConfig(reach_radius=p.reach_radius, poi_spacing=p.poi_spacing))
    assert task.n_points == 56 and task.reach_radius == 0.0025
    d["reach_radius_m"] = 0.005
    with pytest.raises(ConfigError, match="poi_spacing_m"):
        protocol_from_dict(d)
