"""Protocol fields of retention and transfer probes and of proficiency gates (issue #18 §2,
§4): a block's ``phase``, its ``delay_days`` (a later sitting: a second session on another
day) and its ``[blocks.gate]``; the protocol-level rules that tie them together.

TOML (every field checked on load, defaults in brackets)::

    [[blocks]]
    name = "retention"
    condition = "none"
    probe = true                    # retention and transfer trials are VF-free probes
    phase = "retention"             # ["acquisition"] | "retention" | "transfer"
    delay_days = 7.0                # [0] this block begins a new sitting this many days
                                    # after the previous trial (0: same sitting)
    counterbalance = false          # required false for a delayed / retention / transfer
                                    # block (its place in time is the design)

    [[blocks]]
    name = "practice"
    condition = "none"
    variants = [0]
    repetitions = 3                 # the minimum: the block's scheduled trials
    [blocks.gate]                   # proficiency gate (acquisition, non-probe blocks)
    metrics = ["duration", "path_dev_mean_mm"]   # trial metrics compared (TRIAL_METRICS)
    k = 1.0                         # [1.0] limit = expert mean ± k·SD (+ for lower-is-better)
    consecutive = 2                 # [2] passes in a row that end the block
    max_trials = 12                 # the block's cap (scheduled + added trials)
    expert_group = "surgeon"        # ["surgeon"] demographics group of the benchmark

**Decisions**:

* Retention and transfer trials are VF-free probe blocks (``probe = true``, the probe
  condition), without appended probes or a gate: what is measured is the skill without
  the fixture.
* *Untrained* (transfer): a transfer block's variants appear in no other block and are not
  the probe variant of a protocol with appended probes; a retention block's variants are
  all *trained* (in an acquisition block, or the probe variant of appended probes):
  retention is measured on what was practised, transfer on what never was. Under a probe
  rotation (``[probe] variants``, issue #25) a retention block takes the rotation's
  variants (all trained) and a transfer block keeps its own listed variants (outside the
  rotation by definition; e.g. vf_retention.toml).
* A retention block lies in a later sitting than the acquisition it follows: the delays
  of the blocks from the last acquisition block up to it (file order, inclusive) sum to
  more than 0. Blocks with a delay, retention and transfer blocks keep their place in the
  file (``counterbalance = false``), so the sittings are the same for every subject.
* The gate's expert group is a demographics ``group`` (``surgeon``: the vocabulary's
  experienced group; the seed's 31 surgeons are the thesis' expert population). A gate
  sits on an acquisition block that is not a probe block (a probe block's trial count is
  the learning curve's trial factor and must not vary).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from vasim.core.bounds import (
    GATE_CONSECUTIVE,
    GATE_K,
    GATE_MAX_TRIALS,
    RETENTION_DELAY_DAYS,
    TRIALS_PER_SESSION,
)
from vasim.core.config import check_choice, check_int, check_number, check_str_tuple, fail

if TYPE_CHECKING:
    from vasim.study.protocol.model import Block, Protocol

PHASES: tuple[str, ...] = ("acquisition", "retention", "transfer")
"""A block's phase: practice (with or without fixtures), delayed VF-free retention probes,
VF-free transfer probes on an untrained trajectory."""

EXPERT_GROUPS: tuple[str, ...] = ("surgeon", "resident")
"""Demographics groups a benchmark can come from (``vasim.study.store.vocabulary.GROUPS``)."""


def _metric_names() -> tuple[str, ...]:
    from vasim.records.trial_metrics import TRIAL_METRICS

    return tuple(TRIAL_METRICS)


@dataclass(frozen=True)
class Gate:
    """A block's proficiency gate (module docstring).

    Attributes:
        metrics: trial-metric names compared with the benchmark (``TRIAL_METRICS``).
        max_trials: cap of the block's trials (scheduled + added).
        k: benchmark width: limit = mean ± k·SD of the expert trials.
        consecutive: passes in a row that end the block.
        expert_group: demographics group whose trials are the benchmark.

    Raises:
        ConfigError: naming the field and the value.
    """

    metrics: tuple[str, ...]
    max_trials: int
    k: float = 1.0
    consecutive: int = 2
    expert_group: str = "surgeon"

    def __post_init__(self) -> None:
        check_str_tuple(self.metrics, "metrics")
        known = _metric_names()
        for i, m in enumerate(self.metrics):
            if m not in known:
                raise fail(m, f"a trial metric ({', '.join(known)})", field=f"metrics[{i}]")
        check_int(self.max_trials, "max_trials", bound=GATE_MAX_TRIALS)
        object.__setattr__(self, "k", check_number(self.k, "k", bound=GATE_K))
        check_int(self.consecutive, "consecutive", bound=GATE_CONSECUTIVE)
        check_choice(self.expert_group, "expert_group", EXPERT_GROUPS)


def check_block_phase(block: Block) -> None:
    """The block-level checks of ``phase``, ``delay_days`` and ``gate``.

    Raises:
        ConfigError: naming the field (relative to the block) and the value.
    """
    check_choice(block.phase, "phase", PHASES)
    object.__setattr__(block, "delay_days",
                       check_number(block.delay_days, "delay_days",
                                    bound=RETENTION_DELAY_DAYS))
    delayed = block.delay_days > 0 or block.phase != "acquisition"
    if delayed and block.counterbalance:
        raise fail(True, "false (a delayed, retention or transfer block keeps its place in "
                   "time)", field="counterbalance")
    if block.phase != "acquisition":
        if not block.probe:
            raise fail(block.probe, f"true (a {block.phase} block is VF-free probe trials)",
                       field="probe")
        if block.probes_after:
            raise fail(block.probes_after, f"0 (a {block.phase} block is itself probes)",
                       field="probes_after")
    g = block.gate
    if g is None:
        return
    if not isinstance(g, Gate):
        raise fail(g, "a [blocks.gate] table", field="gate")
    if block.phase != "acquisition" or block.probe:
        raise fail(block.phase if block.probe is False else "probe = true",
                   "an acquisition block that is not a probe block (a gate)", field="gate")
    base = len(block.variants) * block.repetitions
    if g.max_trials < base:
        raise fail(g.max_trials, f"at least the block's {base} scheduled trials",
                   field="gate.max_trials")
    if g.consecutive > g.max_trials:
        raise fail(g.consecutive, f"at most gate.max_trials ({g.max_trials})",
                   field="gate.consecutive")


def check_protocol_phases(protocol: Protocol) -> None:
    """The protocol-level rules (module docstring's decisions).

    Raises:
        ConfigError: naming the block field and the value.
    """
    blocks = protocol.blocks
    rotation = protocol.probe_variants
    probe_vs = set(rotation) if rotation is not None else {protocol.probe_variant}
    probes_variant = probe_vs if any(b.probes_after for b in blocks) else set()
    trained = {v for b in blocks if b.phase == "acquisition"
               for v in (probe_vs if b.probe and rotation is not None else b.variants)}
    trained |= probes_variant
    others: dict[str, set[int]] = {}
    for b in blocks:
        if b.phase != "transfer":
            others[b.name] = (set(probe_vs) if b.probe and rotation is not None
                              else set(b.variants))
    delay_since_acq: float | None = None
    for i, b in enumerate(blocks):
        if b.phase == "acquisition":
            delay_since_acq = b.delay_days
            continue
        if delay_since_acq is None:
            raise fail(b.phase, "an acquisition block before it (nothing to retain or "
                       "transfer)", field=f"blocks[{i}].phase")
        delay_since_acq += b.delay_days
        if b.phase == "retention":
            if delay_since_acq <= 0:
                raise fail(b.delay_days, "a delay: the delays since the last acquisition "
                           "block sum to 0 (a retention block is a later sitting)",
                           field=f"blocks[{i}].delay_days")
            # under a probe rotation a retention probe block runs the rotation's variants
            retained = (tuple(sorted(probe_vs)) if b.probe and rotation is not None
                        else b.variants)
            for j, v in enumerate(retained):
                if v not in trained:
                    raise fail(v, f"a trained variant ({sorted(trained)}; retention is "
                               "measured on what was practised)",
                               field=f"blocks[{i}].variants[{j}]")
        else:
            used = set().union(*others.values()) | probes_variant
            for j, v in enumerate(b.variants):
                if v in used:
                    where = [n for n, vs in others.items() if v in vs]
                    what = (f"block(s) {', '.join(where)}" if where
                            else "the probe variant of appended probes")
                    raise fail(v, f"an untrained variant (variant {v} is run in {what})",
                               field=f"blocks[{i}].variants[{j}]")
    if blocks and blocks[0].delay_days > 0:
        # issue #30: accepted, exported as a later sitting, yet everything ran at once
        raise fail(blocks[0].delay_days, "0 on the first block (a delay counts from the "
                   "previous trial; the first block has none: give the delay to the block "
                   "that begins the later sitting)", field="blocks[0].delay_days")
    worst = sum(max_trials(b) for b in blocks)
    if worst > TRIALS_PER_SESSION.high:
        raise fail(worst, f"at most {TRIALS_PER_SESSION.high:,} trials per session with "
                   f"every gate at its cap ({TRIALS_PER_SESSION.reason})", field="blocks")


def max_trials(block: Block) -> int:
    """The block's trials at most: its gate's cap (if any) plus its appended probes."""
    if block.gate is None:
        return block.n_trials
    return block.gate.max_trials + block.probes_after


def gated_blocks(protocol: Protocol) -> tuple[Block, ...]:
    """The protocol's blocks with a gate, in file order."""
    return tuple(b for b in protocol.blocks if b.gate is not None)


def sitting_starts(blocks: Sequence[Block]) -> dict[str, float]:
    """Block name -> its delay [days] (for blocks that start a later sitting)."""
    return {b.name: b.delay_days for b in blocks if b.delay_days > 0}


__all__ = ["EXPERT_GROUPS", "PHASES", "Gate", "check_block_phase", "check_protocol_phases",
           "gated_blocks", "max_trials", "sitting_starts"]
