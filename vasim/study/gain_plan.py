"""What a session's faded, adaptive and combined conditions mean for its trials.

Pure functions of a protocol and its schedule (issue #18 items 1 and 3), used by
``vasim.study.session.Session.trial_config``:

* ``trial_gain``: the fixture gain rule of a scheduled trial (``vasim.fixtures.gain``):
  the block's schedule stage or adaptive rule for its own trials, 1.0 otherwise (probes,
  constant blocks, teleoperation modes);
* ``learning_gain``: the gain the calibrated operator's per-trial adjustment uses
  (``vasim.operator.learning.trial_adjustment``'s ``gain``);
* ``condition_effects``: the calibrated effects by condition label, extended with the
  labels the seed did not calibrate -- a faded/adaptive condition (``ff_faded``) takes its
  schema's effect, a combined schema (``ag_mag``) the combination of its fixtures'
  (``vasim.operator.combined``); labels the seed calibrated keep their numbers.

**Decision** (adaptive trials and the calibrated operator): the gain of an adaptive trial
is only known once it has run (it follows the trainee's deviation), while the operator's
per-trial adjustment is set before the trial (a cohort plans every trial up front). The
adjustment uses the rule's start gain (``AdaptiveRule.start``); within the trial the motion
model feels the live gain through every channel (the force it is pulled by, the zoom it
sees, the volume it hears), and the per-sample gain is logged.
"""

from __future__ import annotations

from collections.abc import Sequence

from vasim.fixtures.gain import AdaptiveRule, GainRule
from vasim.fixtures.schema import load_schema
from vasim.operator.combined import label_effects
from vasim.operator.learning import SEED_EFFECTS, FixtureEffect
from vasim.study.protocol import Block, Protocol, ScheduledTrial
from vasim.trials.kinds import TELEOPERATION_MODES

_EFFECTS: dict[tuple[Block, ...], dict[str, FixtureEffect]] = {}


def trial_gain(protocol: Protocol, scheduled: ScheduledTrial) -> GainRule:
    """The gain rule of one scheduled trial (module docstring).

    Raises:
        KeyError: the scheduled trial names a block the protocol lacks.
    """
    if scheduled.probe:
        return 1.0
    block = next(b for b in protocol.blocks if b.name == scheduled.block)
    if scheduled.condition != block.condition:
        return 1.0
    return block.trial_gain(scheduled.trial_in_block)


def learning_gain(rule: GainRule) -> float:
    """The gain the operator's per-trial adjustment uses: the constant, or the adaptive
    rule's start gain (module docstring's decision)."""
    return rule.start if isinstance(rule, AdaptiveRule) else float(rule)


def schedule_gains(protocol: Protocol, schedule: Sequence[ScheduledTrial]) -> list[float]:
    """``learning_gain`` of every scheduled trial, in schedule order."""
    return [learning_gain(trial_gain(protocol, t)) for t in schedule]


def gain_text(protocol: Protocol, scheduled: ScheduledTrial) -> str:
    """How ``vasim study schedule`` shows a trial's gain: ``"gain 75 %"`` for a schedule's
    stage, ``"adaptive 25-100 %"`` for the rule, ``""`` outside faded/adaptive blocks.

    >>> from vasim.study.protocol import generate_schedule, load_protocol
    >>> p = load_protocol("vf_fading")
    >>> sorted({gain_text(p, t) for t in generate_schedule(p, 7)})
    ['', 'adaptive 25-100 %', 'gain 100 %', 'gain 25 %', 'gain 50 %', 'gain 75 %']
    """
    rule = trial_gain(protocol, scheduled)
    if isinstance(rule, AdaptiveRule):
        return f"adaptive {rule.gain_min * 100:.0f}-{rule.gain_max * 100:.0f} %"
    block = next(b for b in protocol.blocks if b.name == scheduled.block)
    if scheduled.probe or not block.has_gain:
        return ""
    return f"gain {rule * 100:.0f} %"


def condition_effects(protocol: Protocol) -> dict[str, FixtureEffect]:
    """The calibrated effects by condition label for ``protocol`` (module docstring).

    Cached per protocol blocks (what it depends on); the returned mapping must not be
    modified.
    """
    key = protocol.blocks
    out = _EFFECTS.get(key)
    if out is None:
        components: dict[str, tuple[str, ...]] = {}
        for b in protocol.blocks:
            cond = b.condition
            if b.probe or cond in SEED_EFFECTS or cond in TELEOPERATION_MODES:
                continue
            components[cond] = load_schema(b.schema or cond).kinds
        out = _EFFECTS[key] = label_effects(components)
    return out


__all__ = ["condition_effects", "gain_text", "learning_gain", "schedule_gains", "trial_gain"]
