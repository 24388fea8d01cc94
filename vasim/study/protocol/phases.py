"""Protocol fields of retention and transfer probes and of proficiency gates (issue #18 §2,
§4): a block's ``phase``, its ``delay_days`` (a later sitting: a second session on another
day) and its ``[blocks.gate]``; the protocol-level rules that tie them together
(:func:`vasim.study.protocol.model.check_block_phase` and
:func:`~vasim.study.protocol.model.check_protocol_phases`, beside the ``Block`` and
``Protocol`` they check: issue #29 item 4, no ``model`` <-> ``phases`` module cycle).

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

from dataclasses import dataclass

from vasim.core.bounds import (
    GATE_CONSECUTIVE,
    GATE_K,
    GATE_MAX_TRIALS,
)
from vasim.core.config import check_choice, check_int, check_number, check_str_tuple, fail

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


__all__ = ["EXPERT_GROUPS", "PHASES", "Gate"]
