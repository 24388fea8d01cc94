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
  (``vasim.operator.combined``); labels the seed calibrated keep their numbers;
* ``condition_priors``: the questionnaire priors of the same labels
  (``vasim.operator.questionnaire.condition_prior``: combined from the fixtures, faded by
  the block's mean gain ``block_mean_gain``).

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
from vasim.operator.questionnaire import SEED_MEAN_RATING, ConditionPrior, condition_prior
from vasim.study.protocol import Block, Protocol, ScheduledTrial
from vasim.trials.kinds import TELEOPERATION_MODES

_EFFECTS: dict[tuple[Block, ...], dict[str, FixtureEffect]] = {}
_PRIORS: dict[tuple[Block, ...], dict[str, ConditionPrior]] = {}


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


def block_mean_gain(block: Block) -> float:
    """The mean ``learning_gain`` over the block's own trials (1 for a constant block):
    what a subject experienced of the condition as a whole.

    >>> from vasim.study.protocol import load_protocol
    >>> {b.condition: block_mean_gain(b) for b in load_protocol("vf_fading").blocks
    ...  if b.has_gain}
    {'ff_faded': 0.625, 'ff_adaptive': 0.5, 'mag_faded': 0.625, 'mag_adaptive': 0.5}
    """
    n = len(block.variants) * block.repetitions
    if not block.has_gain or n == 0:
        return 1.0
    return float(sum(learning_gain(block.trial_gain(i)) for i in range(n)) / n)


def condition_priors(protocol: Protocol) -> dict[str, ConditionPrior]:
    """The questionnaire priors of the protocol's conditions the seed did not rate: a
    combined schema from its fixtures, a faded/adaptive condition from its schema's
    fixtures at the block's mean gain (``vasim.operator.questionnaire.condition_prior``;
    conditions with an unrated fixture are left out, i.e. neutral). Cached per protocol
    blocks, as ``condition_effects``.

    >>> from vasim.study.protocol import load_protocol
    >>> pr = condition_priors(load_protocol("vf_schemas"))
    >>> sorted(pr), round(pr["mag_ff"].best_share, 4)
    (['ag_mag', 'mag_ff', 'vg_ag'], 0.5136)
    """
    cached = _PRIORS.get(protocol.blocks)
    if cached is not None:
        return dict(cached)
    out: dict[str, ConditionPrior] = {}
    for b in protocol.blocks:
        cond = b.condition
        if b.probe or cond in TELEOPERATION_MODES or cond in out:
            continue
        if cond in SEED_MEAN_RATING and not b.has_gain:
            continue  # the seed rated it
        prior = condition_prior(load_schema(b.schema or cond).kinds, block_mean_gain(b))
        if prior is not None:
            out[cond] = prior
    _PRIORS[protocol.blocks] = out
    return dict(out)


__all__ = ["block_mean_gain", "condition_effects", "condition_priors", "gain_text",
           "learning_gain", "schedule_gains", "trial_gain"]
