"""The unconfounded design of every VF protocol with several conditions (issue #25 item 1),
counted on the output of `vasim study schedule` (the table each session would run):

* every assisted condition runs each of its variants equally often within a subject;
* the VF-free trials run on the same variants, each variant equally often across the
  stated number of subjects (a cycle of the probe rotation);
* the probe after each condition runs each variant equally often across the stated
  number of subjects (m x lcm(R, m), R sequences and m variants; fewer where it holds);
* each counterbalanced condition stands in each position equally often, and follows every
  other condition equally often, across a full set of Williams sequences.

The counts are made from the printed table, independently of how the schedule is built.
"""

from __future__ import annotations

import itertools
from collections import Counter
from dataclasses import dataclass

import pytest

from vasim.cli import main


@dataclass(frozen=True)
class Row:
    block: str
    condition: str
    variant: int
    vf_free: bool


def schedule_rows(capsys: pytest.CaptureFixture[str], protocol: str, sequence: int,
                  ) -> list[Row]:
    """The trial table printed by `vasim study schedule` for sequence number ``sequence``."""
    assert main(["study", "schedule", "--protocol", protocol, "--seed", "1000003",
                 "--sequence", str(sequence)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].split()[:4] == ["index", "block", "condition", "variant"]
    out = []
    for line in lines[2:]:
        if not line.strip():
            break
        f = line.split()
        out.append(Row(block=f[1], condition=f[2], variant=int(f[3]),
                       vf_free="VF-free" in line))
    return out


def cohort(capsys: pytest.CaptureFixture[str], protocol: str, n: int) -> list[list[Row]]:
    return [schedule_rows(capsys, protocol, i) for i in range(n)]


def block_sequence(rows: list[Row], conditions: set[str]) -> list[str]:
    """The counterbalanced conditions in session order."""
    seen: list[str] = []
    for r in rows:
        if r.condition in conditions and r.condition not in seen:
            seen.append(r.condition)
    return seen


def after_counts(sessions: list[list[Row]]) -> Counter[tuple[str, int]]:
    """(condition just practised, variant of the VF-free probe that follows it)."""
    return Counter((s[j - 1].condition, r.variant) for s in sessions for j, r in enumerate(s)
                   if r.vf_free and j > 0 and not s[j - 1].vf_free)


# protocol: (counterbalanced conditions, R Williams sequences, assisted variants,
#            subjects over which the probe after each condition is balanced)
DESIGNS = {
    "vf_learning_curve": (("vg", "ag", "ms", "mag", "ff"), 10, (1, 2, 3, 4, 5, 6), 30),
    "vf_learning_curve_revised": (("vg", "ag", "ms", "mag", "ff"), 10, (1, 2, 3, 4, 5, 6),
                                  30),
    "vf_fading": (("ff", "ff_faded", "ff_adaptive", "mag", "mag_faded", "mag_adaptive"), 6,
                  (1, 2, 3, 4), 48),
    "vf_schemas": (("vg", "ag", "mag", "ff", "ag_mag", "mag_ff", "vg_ag"), 14,
                   (1, 2, 3, 4, 5, 6), 42),
    "vf_retention": (("ff", "mag"), 2, (1, 2, 3, 4), 16),
    "vf_point_targeting": (("point_targeting", "vg", "ag", "ff", "mag"), 10, (0,), 10),
}


@pytest.mark.parametrize("protocol", sorted(DESIGNS))
def test_counterbalanced_protocol_is_balanced(capsys: pytest.CaptureFixture[str],
                                              protocol: str) -> None:
    conds, r, variants, n_after = DESIGNS[protocol]
    n = len(conds)
    m = len(variants)
    sessions = cohort(capsys, protocol, n_after)
    # 1. within a subject: each assisted condition runs each variant equally often
    for s in sessions:
        per = Counter((x.condition, x.variant) for x in s if not x.vf_free
                      and x.condition in conds)
        assert set(per) == {(c, v) for c in conds for v in variants}
        assert len(set(per.values())) == 1
    # 2. VF-free trials on the assisted variants (transfer probes aside), each variant
    #    equally often over every m consecutive subjects of the first cycle
    for start in range(0, n_after - m + 1, m):
        free = Counter(x.variant for s in sessions[start:start + m] for x in s
                       if x.vf_free and x.block != "transfer")
        assert set(free) == set(variants)
        assert len(set(free.values())) == 1, free
        # and each VF-free trial number on each variant once
        k_v = Counter((k, x.variant) for s in sessions[start:start + m]
                      for k, x in enumerate([y for y in s if y.vf_free
                                             and y.block != "transfer"]))
        assert set(k_v.values()) == {1}
    # 3. the probe after each condition: each variant equally often over n_after subjects
    after = after_counts(sessions)
    assert after == {(c, v): n_after // m for c in conds for v in variants}
    # 4. Williams: over R consecutive subjects each condition in each position R/n times
    #    and after every other condition R/(n-1)... times (each ordered pair equally often)
    orders = [block_sequence(s, set(conds)) for s in sessions[:r]]
    assert len({tuple(o) for o in orders}) == r
    for pos in range(n):
        assert Counter(o[pos] for o in orders) == dict.fromkeys(conds, r // n)
    pairs = Counter(p for o in orders for p in itertools.pairwise(o))
    assert pairs == {(a, b): r // n for a in conds for b in conds if a != b}
    # the next R subjects repeat the sequences
    assert [block_sequence(s, set(conds)) for s in sessions[r:2 * r]] == \
        orders[:len(sessions[r:2 * r])]


def test_fading_needs_the_cycle_shift(capsys: pytest.CaptureFixture[str]) -> None:
    """vf_fading's 6 sequences and 4 variants: over one cycle of lcm(6, 4) = 12 subjects
    the probe after a condition is not yet balanced (2 or 4 per variant); the shift of the
    rotation by one variant per cycle balances it over 4 cycles (48; previous test)."""
    after = after_counts(cohort(capsys, "vf_fading", 12))
    assert sorted(set(after.values())) == [2, 4]


def test_retention_probes_after_each_fixture_meet_every_variant(
        capsys: pytest.CaptureFixture[str]) -> None:
    """The AB/BA crossover with 4 variants: within the first cycle (4 subjects) the probe
    after FF runs only two variants; the next cycle runs the other two (no fixture tied
    to a variant subset, the confound the plain rotation would keep for ever)."""
    first = after_counts(cohort(capsys, "vf_retention", 4))
    assert {v for (c, v) in first if c == "ff"} in ({1, 3}, {2, 4})
    both = after_counts(cohort(capsys, "vf_retention", 8))
    assert {v for (c, v) in both if c == "ff"} == {1, 2, 3, 4}
    # retention probes on trained variants, transfer probes on the untrained 5 and 6
    s = schedule_rows(capsys, "vf_retention", 3)
    assert {x.variant for x in s if x.block == "retention"} <= {1, 2, 3, 4}
    assert sorted(x.variant for x in s if x.block == "transfer") == [5, 6]


def test_proficiency_runs_every_condition_on_the_same_variants(
        capsys: pytest.CaptureFixture[str]) -> None:
    """One assisted condition and a fixed order (baseline, FF, gated practice: the order
    is the intervention). FF and the practice block each run variants 1..4 once per
    subject; the 2 baseline probes cover 1..4 over every 4 consecutive subjects, each
    probe number on each variant once."""
    sessions = cohort(capsys, "vf_proficiency", 4)
    for s in sessions:
        assert [x.block for x in s] == ["baseline"] * 2 + ["ff"] * 4 + ["practice"] * 4
        assert sorted(x.variant for x in s if x.block == "ff") == [1, 2, 3, 4]
        assert [x.variant for x in s if x.block == "practice"] == [1, 2, 3, 4]
    base = Counter((k, x.variant) for s in sessions
                   for k, x in enumerate([y for y in s if y.block == "baseline"]))
    assert base == {(k, v): 1 for k in range(2) for v in (1, 2, 3, 4)}
