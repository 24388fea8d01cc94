"""Retention / transfer / gate fields of protocols (vasim/study/protocol/phases.py): the
shipped protocols, errors naming file, field and value, and the pure schedule helpers
(day offsets, sittings, the extension of a gated block)."""

from __future__ import annotations

import copy
import tomllib
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.core.errors import ConfigError
from vasim.core.resources import studies_dir
from vasim.study.protocol import (
    day_offsets,
    extend_gated_block,
    gated_trials,
    generate_schedule,
    load_protocol,
    protocol_from_dict,
    sitting_numbers,
)


def raw(name: str) -> dict[str, Any]:
    return tomllib.loads((studies_dir() / f"{name}.toml").read_text())


def mutate(name: str, path: list[Any], value: Any) -> dict[str, Any]:
    d = copy.deepcopy(raw(name))
    target: Any = d
    for k in path[:-1]:
        target = target[k]
    if value is KeyError:
        del target[path[-1]]
    else:
        target[path[-1]] = value
    return d


def test_the_shipped_retention_protocol() -> None:
    p = load_protocol("vf_retention")
    phases = {b.name: (b.phase, b.delay_days) for b in p.blocks}
    assert phases["retention"] == ("retention", 7.0) and phases["transfer"] == ("transfer", 0.0)
    s = generate_schedule(p, 5)
    assert len(s) == 17 == p.n_trials
    days, sit = day_offsets(p, s), sitting_numbers(p, s)
    # the 13 trials of day 0 (3 baseline + 2 x (4 + 1)), then 4 on day 7, sitting 2
    assert days == (0.0,) * 13 + (7.0,) * 4 and sit == (1,) * 13 + (2,) * 4
    transfer = [t for t in s if t.block == "transfer"]
    assert [t.variant for t in transfer] == [5, 6] and all(t.probe for t in transfer)
    trained = {t.variant for t in s if t.block not in ("transfer",)}
    assert not trained & {5, 6}


def test_the_shipped_proficiency_protocol() -> None:
    p = load_protocol("vf_proficiency")
    (gated,) = [b for b in p.blocks if b.gate is not None]
    assert gated.name == "practice" and gated.gate is not None
    g = gated.gate
    assert (g.metrics, g.k, g.consecutive, g.max_trials, g.expert_group) == (
        ("duration", "path_dev_mean_mm"), 1.0, 2, 10, "surgeon")
    assert p.n_trials == 2 + 4 + 4   # practice: one trial per variant 1..4 (issue #25)


@pytest.mark.parametrize(("name", "path", "value", "field", "shown"), [
    ("vf_retention", ["blocks", 3, "phase"], "recall", "blocks[3].phase", "'recall'"),
    ("vf_retention", ["blocks", 3, "delay_days"], -1.0, "blocks[3].delay_days", "-1.0"),
    ("vf_retention", ["blocks", 3, "delay_days"], 0.0, "blocks[3].delay_days", "0.0"),
    ("vf_retention", ["blocks", 3, "delay_days"], "7", "blocks[3].delay_days", "'7'"),
    ("vf_retention", ["blocks", 3, "probe"], False, "blocks[3].probe", "False"),
    ("vf_retention", ["blocks", 3, "counterbalance"], True, "blocks[3].counterbalance",
     "True"),
    # under the probe rotation (issue #25) a retention probe block lists no variants
    ("vf_retention", ["blocks", 3, "variants"], [5], "blocks[3].variants", "rotation"),
    ("vf_retention", ["blocks", 4, "variants"], [4, 5], "blocks[4].variants[0]", "4"),
    ("vf_retention", ["blocks", 4, "variants"], [1], "blocks[4].variants[0]", "1"),
    ("vf_proficiency", ["blocks", 2, "gate", "k"], -1.0, "blocks[2].gate.k", "-1.0"),
    ("vf_proficiency", ["blocks", 2, "gate", "metrics"], ["speed"],
     "blocks[2].gate.metrics[0]", "'speed'"),
    ("vf_proficiency", ["blocks", 2, "gate", "metrics"], [], "blocks[2].gate.metrics",
     "empty"),
    ("vf_proficiency", ["blocks", 2, "gate", "max_trials"], 2, "blocks[2].gate.max_trials",
     "2"),
    ("vf_proficiency", ["blocks", 2, "gate", "max_trials"], KeyError,
     "blocks[2].gate.max_trials", "missing"),
    ("vf_proficiency", ["blocks", 2, "gate", "consecutive"], 0,
     "blocks[2].gate.consecutive", "0"),
    ("vf_proficiency", ["blocks", 2, "gate", "expert_group"], "consultant",
     "blocks[2].gate.expert_group", "'consultant'"),
    ("vf_proficiency", ["blocks", 2, "gate", "colour"], 1, "blocks[2].gate.colour", "1"),
    ("vf_proficiency", ["blocks", 0, "gate"], {"metrics": ["duration"], "max_trials": 4},
     "blocks[0].gate", "probe"),
])
def test_bad_phase_and_gate_fields_are_named(name, path, value, field, shown) -> None:
    with pytest.raises(ConfigError) as e:
        protocol_from_dict(mutate(name, path, value), source="proto.toml")
    msg = str(e.value)
    assert e.value.field == field, msg
    assert msg.startswith(f"proto.toml: field '{field}'"), msg
    assert shown in msg, msg


def test_a_transfer_variant_run_as_the_probe_variant_is_trained() -> None:
    d = raw("vf_retention")
    del d["probe"]["variants"]         # no rotation: one probe variant
    d["probe"]["variant"] = 5          # the appended probes now run variant 5
    d["blocks"][0]["variants"] = [5]
    d["blocks"][3]["variants"] = [5]
    with pytest.raises(ConfigError, match=r"untrained variant .*variant 5 is run in block") \
            as e:
        protocol_from_dict(d, source="p.toml")
    assert e.value.field == "blocks[4].variants[0]"


def test_retention_needs_an_acquisition_block_before_it() -> None:
    d = raw("vf_retention")
    d["blocks"] = [d["blocks"][3], *d["blocks"][:3]]
    with pytest.raises(ConfigError, match="an acquisition block before it") as e:
        protocol_from_dict(d, source="p.toml")
    assert e.value.field == "blocks[0].phase"


def test_gate_cap_counts_against_the_session_limit() -> None:
    d = raw("vf_proficiency")
    d["blocks"][0]["repetitions"] = 1000
    d["blocks"][1].update(repetitions=1000, variants=[1, 2, 3, 4, 5, 6], probes_after=1000)
    d["blocks"][2]["gate"]["max_trials"] = 1000
    d["blocks"][2]["probes_after"] = 1
    second = copy.deepcopy(d["blocks"][2])
    second["name"] = "practice2"
    d["blocks"].append(second)
    # scheduled: 1000 + 7000 + 2 x 5 = 8010 trials (practice: 4 variants, issue #25); at
    # the caps 8000 + 2 x 1001 = 10002
    with pytest.raises(ConfigError, match="every gate at its cap") as e:
        protocol_from_dict(d, source="p.toml")
    assert "10002" in str(e.value) or "10,002" in str(e.value)
    d["blocks"][2]["probes_after"] = 0
    d["blocks"][3]["probes_after"] = 0
    assert protocol_from_dict(d, source="p.toml").n_trials == 8008   # 10000 at the caps


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32), st.integers(1, 7))
def test_extending_a_gated_block_keeps_the_schedule_consistent(seed: int, n_ext: int) -> None:
    d = raw("vf_proficiency")
    d["blocks"][2].update(variants=[0, 1], repetitions=1)
    d["blocks"][2]["probes_after"] = 1
    d["blocks"][1]["variants"] = [2, 3, 4]
    p = protocol_from_dict(d, source="p.toml")
    s = generate_schedule(p, seed)
    block = p.blocks[2]
    for _ in range(n_ext):
        s = extend_gated_block(p, s, "practice")
    assert [t.index for t in s] == list(range(len(s)))
    own = gated_trials(s, block)
    assert len(own) == 2 + n_ext
    # the block's cycle over its variants continues; rounds count up
    assert [t.variant for t in own] == [[0, 1][k % 2] for k in range(len(own))]
    assert [t.repetition for t in own] == [k // 2 for k in range(len(own))]
    block_rows = [t for t in s if t.block == "practice"]
    assert [t.trial_in_block for t in block_rows] == list(range(len(block_rows)))
    assert block_rows[-1].probe and block_rows[-1].probe_index == 3   # after the 2 baseline probes
    assert not any(t.probe for t in own)


def test_extension_stops_at_the_cap_and_needs_a_gate() -> None:
    p = load_protocol("vf_proficiency")
    s = generate_schedule(p, 0)
    for _ in range(6):   # 4 scheduled practice trials (one per variant) + 6 = the cap
        s = extend_gated_block(p, s, "practice")
    assert len(s) == 2 + 4 + 10
    with pytest.raises(ConfigError, match="cap of 10"):
        extend_gated_block(p, s, "practice")
    with pytest.raises(ConfigError, match="no gate"):
        extend_gated_block(p, s, "ff")
