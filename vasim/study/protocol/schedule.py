"""Schedules: a pure function from a protocol and a seed to the list of scheduled trials
(block counterbalancing by Williams squares or permutations, variant shuffles, probes).

The rules are described in :mod:`vasim.study.protocol`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pandas as pd

from vasim.core.bounds import SEED
from vasim.core.config import check_int, is_int
from vasim.study.protocol.model import Block, Protocol
from vasim.trials.kinds import TELEOPERATION_MODES


@dataclass(frozen=True)
class ScheduledTrial:
    """One trial of a session's schedule.

    Attributes:
        index: 0-based position in the session.
        block: block name. block_index: 0-based position of the block in this schedule.
        trial_in_block: 0-based position within the block (appended probes included).
        condition: the protocol's condition label. schema: the fixture schema to run (None
            for a teleoperation mode). task: ``"trajectory"`` or ``"point"``.
        variant: trajectory variant. probe: a fixture-free probe trial.
        probe_index: 1-based number among the session's probe trials (None if not a probe).
        repetition: 0-based round over the block's variants (or over its appended probes).
    """

    index: int
    block: str
    block_index: int
    trial_in_block: int
    condition: str
    schema: str | None
    task: str
    variant: int
    probe: bool
    probe_index: int | None
    repetition: int

    def as_row(self) -> dict[str, Any]:
        """The store's ``scheduled_trials`` columns (``index`` -> ``trial_index``)."""
        return {"trial_index": self.index, "block": self.block, "block_index": self.block_index,
                "trial_in_block": self.trial_in_block, "condition": self.condition,
                "schema": self.schema, "task": self.task, "variant": self.variant,
                "probe": self.probe, "probe_index": self.probe_index,
                "repetition": self.repetition}

    @classmethod
    def from_row(cls, row: Mapping[str, Any]) -> ScheduledTrial:
        """Inverse of ``as_row`` (e.g. a row of ``TrialStore.schedule``)."""
        def opt_int(v: Any) -> int | None:
            return None if v is None or pd.isna(v) else int(v)

        return cls(index=int(row["trial_index"]), block=str(row["block"]),
                   block_index=int(row["block_index"]), trial_in_block=int(row["trial_in_block"]),
                   condition=str(row["condition"]),
                   schema=None if pd.isna(row["schema"]) else str(row["schema"]),
                   task=str(row["task"]), variant=int(row["variant"]), probe=bool(row["probe"]),
                   probe_index=opt_int(row["probe_index"]), repetition=int(row["repetition"]))


def _rng(seed: int, *stream: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(seed), *stream]))


def williams_square(n: int) -> list[list[int]]:
    """Rows of a Williams balanced Latin square for n conditions (0..n-1).

    n rows for even n, 2n for odd n (the square and its mirror image). Every condition
    appears once per row and equally often in every position, and over all rows every
    ordered pair (a, b), a != b, appears as neighbours once (even n) or twice (odd n)
    (Williams 1949, "Experimental designs balanced for the estimation of residual effects
    of treatments").

    Example:
        >>> williams_square(4)
        [[0, 1, 3, 2], [1, 2, 0, 3], [2, 3, 1, 0], [3, 0, 2, 1]]
    """
    if not is_int(n) or n < 1:
        raise ValueError(f"n must be an integer >= 1, got {n!r}")
    first = [0]
    lo, hi = 1, n - 1
    for k in range(1, n):
        if k % 2 == 1:
            first.append(lo)
            lo += 1
        else:
            first.append(hi)
            hi -= 1
    rows = [[(c + r) % n for c in first] for r in range(n)]
    if n % 2 == 1:
        rows += [row[::-1] for row in rows]
    return rows


def block_order(protocol: Protocol, seed: int, sequence: int | None = None) -> list[int]:
    """Indices into ``protocol.blocks`` in this session's order (module docstring rules).

    ``sequence``: the subject's sequence number i (``latin_square``: row i mod R of the
    Williams square); None: the seed (a cohort gives subject j a seed congruent to j - 1,
    ``vasim.study.cohort.counterbalanced_seed``).
    """
    slots = [i for i, b in enumerate(protocol.blocks) if b.counterbalance]
    order = list(range(len(protocol.blocks)))
    if len(slots) < 2 or protocol.block_order == "fixed":
        return order
    if protocol.block_order == "random":
        perm = _rng(seed, 1).permutation(len(slots)).tolist()
    else:
        rows = williams_square(len(slots))
        perm = rows[(seed if sequence is None else sequence) % len(rows)]
    for slot, k in zip(slots, perm, strict=True):
        order[slot] = slots[k]
    return order


def n_sequences(protocol: Protocol) -> int:
    """R, the number of block-order sequences: the Williams square's rows under
    ``latin_square`` with at least two counterbalanced blocks (n for even n, 2n for odd n),
    otherwise 1 (one order, or an order drawn per subject)."""
    n_cb = sum(b.counterbalance for b in protocol.blocks)
    if protocol.block_order == "latin_square" and n_cb >= 2:
        return len(williams_square(n_cb))
    return 1


def probe_variant_of(protocol: Protocol, sequence: int, probe_index: int) -> int:
    """The trajectory variant of the probe trial ``probe_index`` (1-based) of the session
    with sequence number ``sequence``.

    With ``probe.variants`` (v_0..v_{m-1}) the probes rotate: probe k of sequence number i
    runs ``v[(o(i) + k - 1) mod m]`` with the offset ``o(i) = i + floor(i / L)``,
    ``L = lcm(R, m)`` (R: ``n_sequences``). Within each cycle of L subjects (i from a
    multiple of L) the offset is i plus a constant: over any m consecutive sequence numbers
    of a cycle every probe number runs every variant once, and within a session m
    consecutive probes run m different variants. The shift by one variant per cycle
    balances the probe after each counterbalanced block against the variant over m * L
    subjects for every R and m (in cycle c a subject on Williams row r meets variant
    ``(r + c + position + const) mod m``, and c runs over all m residues); the plain
    rotation ``o(i) = i`` does not when R and m share a factor and the Williams rows fall
    unevenly on it (vf_retention: AB/BA with 4 variants would put the probe after FF on
    variants 2 and 4 only, for ever). **Decisions** (issue #25): the VF-free trials are
    balanced across subjects, because a session's number of VF-free trials is not a
    multiple of m; each assisted block uses every variant equally often within the
    session. vf_learning_curve (R = 10, m = 6, L = 30): the first 30 subjects are already
    balanced (the probe after each fixture on each variant 5 times; the rotation's shift
    starts at subject 31); ``tests/study/test_design.py`` and
    ``tests/study/test_design_protocols.py`` count every protocol's balance.
    Without ``probe.variants`` every probe runs ``probe.variant``.

    Example:
        >>> from vasim.study.protocol import load_protocol
        >>> p = load_protocol("vf_learning_curve")
        >>> [probe_variant_of(p, 0, k) for k in range(1, 9)]
        [1, 2, 3, 4, 5, 6, 1, 2]
        >>> [probe_variant_of(p, 4, k) for k in range(1, 9)]
        [5, 6, 1, 2, 3, 4, 5, 6]
        >>> [probe_variant_of(p, 30, k) for k in range(1, 3)]  # cycle 2: shifted by one
        [2, 3]
    """
    vs = protocol.probe_variants
    if vs is None:
        return protocol.probe_variant
    m = len(vs)
    i = int(sequence)
    offset = i + i // math.lcm(n_sequences(protocol), m)
    return vs[(offset + int(probe_index) - 1) % m]


def generate_schedule(protocol: Protocol, seed: int, *, sequence: int | None = None,
                      ) -> list[ScheduledTrial]:
    """The realised schedule of one session: a pure function of protocol, seed (and
    sequence number).

    Args:
        protocol: the validated protocol.
        seed: the session's randomisation seed, an integer in [0, 2**63).
        sequence: the subject's sequence number i: Williams row i mod R
            (``latin_square``) and probe-variant rotation offset i mod m
            (``probe.variants``); None: the seed itself (a simulated cohort's seeds are
            congruent to the subject number - 1, so subject j gets sequence j - 1).

    Returns:
        ``protocol.n_trials`` scheduled trials in session order.

    Raises:
        ConfigError: a bad seed.

    Example:
        >>> from vasim.study.protocol import load_protocol
        >>> p = load_protocol("vf_learning_curve")
        >>> a, b = generate_schedule(p, 1), generate_schedule(p, 1)
        >>> a == b, a[0].block, a[3].block_index
        (True, 'baseline', 1)
    """
    seed = check_int(seed, "seed", bound=SEED)
    seq = seed if sequence is None else check_int(sequence, "sequence", lo=0)
    out: list[ScheduledTrial] = []
    n_probe = 0

    def schema_of(b: Block) -> str | None:
        if b.schema is not None:
            return b.schema
        cond = b.condition
        return None if cond in TELEOPERATION_MODES else cond

    for pos, bi in enumerate(block_order(protocol, seed, seq)):
        b = protocol.blocks[bi]
        rng = _rng(seed, 2, bi)
        k = 0
        for rep in range(b.repetitions):
            variants = list(b.variants)
            if protocol.variant_order == "random" and len(variants) > 1:
                variants = [variants[j] for j in rng.permutation(len(variants)).tolist()]
            for v in variants:
                if b.probe:
                    n_probe += 1
                    if protocol.probe_variants is not None and b.phase != "transfer":
                        # the rotation (issue #25); transfer probes keep their untrained
                        # variants
                        v = probe_variant_of(protocol, seq, n_probe)
                out.append(ScheduledTrial(
                    index=len(out), block=b.name, block_index=pos, trial_in_block=k,
                    condition=b.condition, schema=schema_of(b), task=protocol.task,
                    variant=v, probe=b.probe, probe_index=n_probe if b.probe else None,
                    repetition=rep))
                k += 1
        for rep in range(b.probes_after):
            n_probe += 1
            out.append(ScheduledTrial(
                index=len(out), block=b.name, block_index=pos, trial_in_block=k,
                condition=protocol.probe_condition, schema=protocol.probe_condition,
                task=protocol.task, variant=probe_variant_of(protocol, seq, n_probe),
                probe=True,
                probe_index=n_probe, repetition=rep))
            k += 1
    return out


# ----------------------------------------------------------- sittings, phases and gates
def block_of(protocol: Protocol, name: str) -> Block:
    """The protocol's block called ``name``.

    Raises:
        KeyError: no such block.
    """
    for b in protocol.blocks:
        if b.name == name:
            return b
    raise KeyError(f"protocol {protocol.name!r} has no block {name!r}")


def day_offsets(protocol: Protocol, schedule: list[ScheduledTrial] | tuple[ScheduledTrial, ...],
                ) -> tuple[float, ...]:
    """The day of each scheduled trial relative to the session's first sitting [d].

    A block with ``delay_days`` > 0 begins a new sitting that many days after the trial
    before it; every trial of the block and those after it share the new day until the next
    delayed block. A pure function of the schedule (blocks in schedule order).

    Example:
        >>> from vasim.study.protocol import load_protocol
        >>> p = load_protocol("vf_retention")
        >>> s = generate_schedule(p, 1)
        >>> sorted(set(day_offsets(p, s)))
        [0.0, 7.0]
    """
    out: list[float] = []
    day = 0.0
    seen: set[str] = set()
    for t in schedule:
        if t.block not in seen:
            seen.add(t.block)
            day += block_of(protocol, t.block).delay_days
        out.append(day)
    return tuple(out)


def sitting_numbers(protocol: Protocol,
                    schedule: list[ScheduledTrial] | tuple[ScheduledTrial, ...],
                    ) -> tuple[int, ...]:
    """The 1-based sitting of each scheduled trial (a new one at every delayed block)."""
    out: list[int] = []
    n = 1
    seen: set[str] = set()
    for t in schedule:
        if t.block not in seen:
            seen.add(t.block)
            if out and block_of(protocol, t.block).delay_days > 0:
                n += 1
        out.append(n)
    return tuple(out)


def gated_trials(schedule: list[ScheduledTrial] | tuple[ScheduledTrial, ...],
                 block: Block) -> list[ScheduledTrial]:
    """The trials of a gated ``block`` the gate judges (its own, not its appended probes)."""
    return [t for t in schedule if t.block == block.name and t.condition == block.condition
            and t.probe == block.probe]


def extend_gated_block(protocol: Protocol,
                       schedule: list[ScheduledTrial] | tuple[ScheduledTrial, ...],
                       block_name: str) -> list[ScheduledTrial]:
    """The schedule with one more trial of a gated block (pure; what the store applies).

    The new trial follows the block's last own trial (before its appended probes): its
    variant continues the block's cycle over ``variants`` (listed order), its repetition is
    the round it falls in; the trials after it move one index on (and the block's appended
    probes one ``trial_in_block`` on). Probe numbers are unchanged (a gated block is not a
    probe block).

    Raises:
        ConfigError: the block has no gate, or is at its cap.
    """
    from vasim.core.errors import ConfigError

    b = block_of(protocol, block_name)
    if b.gate is None:
        raise ConfigError(f"block {block_name!r} has no gate", field="block")
    own = gated_trials(schedule, b)
    if len(own) >= b.gate.max_trials:
        raise ConfigError(f"block {block_name!r} is at its cap of {b.gate.max_trials} trials",
                          field="block")
    last = own[-1]
    k = len(own)
    new = ScheduledTrial(
        index=last.index + 1, block=b.name, block_index=last.block_index, trial_in_block=k,
        condition=last.condition, schema=last.schema, task=last.task,
        variant=b.variants[k % len(b.variants)], probe=False, probe_index=None,
        repetition=k // len(b.variants))
    out: list[ScheduledTrial] = []
    for t in schedule:
        if t.index <= last.index:
            out.append(t)
            continue
        if t.index == last.index + 1:
            out.append(new)
        out.append(replace(t, index=t.index + 1,
                           trial_in_block=t.trial_in_block + (t.block == b.name)))
    if len(out) == len(schedule):
        out.append(new)
    return out
