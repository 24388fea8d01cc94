"""The unconfounded design of the VF learning-curve study (issue #25 item 1): a Williams
design for the fixture blocks and VF-free trials on the assisted trials' variants,
balanced. Balance is counted here from the realised schedules, independently of how the
schedule is built."""

from __future__ import annotations

import itertools
import math
import tomllib
from collections import Counter

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.core.errors import ConfigError
from vasim.core.resources import studies_dir
from vasim.study.protocol import (
    generate_schedule,
    load_protocol,
    probe_variant_of,
    protocol_from_dict,
    williams_square,
)

FIXTURES = ("vg", "ag", "ms", "mag", "ff")


@settings(max_examples=40, deadline=None)
@given(n=st.integers(2, 14))
def test_williams_square_balances_position_and_carry_over(n: int) -> None:
    """Both balance properties, for n even (n rows) and odd (2n rows): every condition
    equally often in every position, every ordered pair of different conditions equally
    often as neighbours (first-order carry-over)."""
    rows = williams_square(n)
    r = n if n % 2 == 0 else 2 * n
    assert len(rows) == r
    assert all(sorted(row) == list(range(n)) for row in rows)
    for pos in range(n):
        assert Counter(row[pos] for row in rows) == dict.fromkeys(range(n), r // n)
    pairs = Counter(p for row in rows for p in itertools.pairwise(row))
    expected = {(a, b): r * (n - 1) // (n * (n - 1)) for a in range(n) for b in range(n)
                if a != b}
    assert pairs == expected


def test_five_conditions_give_ten_sequences() -> None:
    assert len(williams_square(5)) == 10


@settings(max_examples=60, deadline=None)
@given(seq=st.integers(0, 10**6), m=st.integers(1, 7), n_probes=st.integers(1, 12))
def test_probe_rotation_balances_probe_number_and_variant(seq: int, m: int,
                                                          n_probes: int) -> None:
    """Over any m consecutive sequence numbers within a cycle of L = lcm(10, m) subjects,
    every probe number runs every variant once; within a session, m consecutive probes run
    m different variants; the next cycle's offset is one variant further."""
    d = tomllib.loads((studies_dir() / "vf_learning_curve.toml").read_text())
    d["probe"]["variants"] = list(range(m))
    p = protocol_from_dict(d)
    cycle = math.lcm(10, m)
    seq = seq - seq % cycle + min(seq % cycle, cycle - m)  # a window inside one cycle
    for k in range(1, n_probes + 1):
        got = Counter(probe_variant_of(p, seq + j, k) for j in range(m))
        assert got == dict.fromkeys(range(m), 1)
        start = seq - seq % cycle
        assert probe_variant_of(p, start + cycle, k) == (probe_variant_of(p, start, k) + 1) % m
    run = [probe_variant_of(p, seq, k) for k in range(1, n_probes + 1)]
    for w in range(max(0, n_probes - m + 1)):
        assert len(set(run[w:w + m])) == m


def _cohort(name: str, n: int) -> list[list]:
    p = load_protocol(name)
    return [generate_schedule(p, 10**9 + 7, sequence=i) for i in range(n)]


@pytest.mark.parametrize("name", ["vf_learning_curve", "vf_learning_curve_revised"])
def test_thirty_subjects_balance_every_condition_with_every_variant(name: str) -> None:
    """30 = lcm(10 Williams sequences, 6 variants) consecutive subjects."""
    cohort = _cohort(name, 30)
    assisted = Counter((t.condition, t.variant) for s in cohort for t in s if not t.probe)
    assert assisted == {(c, v): 30 for c in FIXTURES for v in range(1, 7)}
    # within a session each assisted fixture uses each variant once
    for s in cohort:
        per = Counter((t.condition, t.variant) for t in s if not t.probe)
        assert set(per.values()) == {1}
    vf_free = Counter(t.variant for s in cohort for t in s if t.probe)
    assert vf_free == dict.fromkeys(range(1, 7), 30 * 8 // 6)
    # the probe after each fixture block: each fixture x variant 5 times
    after = Counter((s[t.index - 1].condition, t.variant) for s in cohort for t in s
                    if t.probe and t.index > 0 and not s[t.index - 1].probe)
    assert after == {(c, v): 5 for c in FIXTURES for v in range(1, 7)}
    # probe number x variant: 5 each; block position x fixture: 6 each
    assert Counter((t.probe_index, t.variant) for s in cohort for t in s if t.probe) == {
        (k, v): 5 for k in range(1, 9) for v in range(1, 7)}
    assert Counter((t.block_index, t.condition) for s in cohort for t in s
                   if not t.probe) == {(b, c): 6 * 6 for b in range(1, 6) for c in FIXTURES}


def test_ten_subjects_counterbalance_block_order() -> None:
    """Subject i runs Williams row i mod 10: position and carry-over balanced over 10."""
    cohort = _cohort("vf_learning_curve", 10)
    orders = [[s[3 + 7 * b].condition for b in range(5)] for s in cohort]
    assert len({tuple(o) for o in orders}) == 10
    for pos in range(5):
        assert Counter(o[pos] for o in orders) == dict.fromkeys(FIXTURES, 2)
    assert Counter(p for o in orders for p in itertools.pairwise(o)) == {
        (a, b): 2 for a in FIXTURES for b in FIXTURES if a != b}
    # sequence i is the seed by default (a cohort's seeds are congruent to i)
    p = load_protocol("vf_learning_curve")
    a, b = generate_schedule(p, 13), generate_schedule(p, 5, sequence=13)
    assert [(t.condition, t.probe, t.probe and t.variant) for t in a] == \
        [(t.condition, t.probe, t.probe and t.variant) for t in b]


def test_probe_variants_are_the_assisted_variants() -> None:
    p = load_protocol("vf_learning_curve")
    assisted = {v for b in p.blocks if not b.probe for v in b.variants}
    assert p.probe_variants is not None and set(p.probe_variants) == assisted


def test_bad_probe_variants_are_refused_with_file_and_field(tmp_path) -> None:
    text = (studies_dir() / "vf_learning_curve.toml").read_text()
    bad = text.replace("variants = [1, 2, 3, 4, 5, 6] # the VF-free",
                       "variants = [1, 2, 9] # the VF-free")
    f = tmp_path / "bad.toml"
    f.write_text(bad)
    from vasim.study.protocol import load_protocol as load

    with pytest.raises(ConfigError, match=r"bad\.toml: field 'probe\.variants\[2\]': got 9"):
        load(f)


def test_the_schedule_command_shows_sequence_and_variants(capsys) -> None:
    from vasim.cli import main

    assert main(["study", "schedule", "--protocol", "vf_learning_curve", "--seed", "99",
                 "--sequence", "13"]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = [line.split() for line in lines[2:40]]
    probes = [int(r[3]) for r in rows if "VF-free" in " ".join(r)]
    assert probes == [1 + (13 + k) % 6 for k in range(8)]
    order = [r[1] for r in rows[3::7]]
    assert lines[41] == ("block order: Williams sequence 4 of 10 (sequence number 13 mod 10): "
                         "baseline, " + ", ".join(order))
    assert lines[42].startswith("VF-free trials: variants " + " ".join(map(str, probes)))
    assert main(["study", "schedule", "--protocol", "vf_learning_curve", "--seed", "1",
                 "--sequence", "x"]) == 2
