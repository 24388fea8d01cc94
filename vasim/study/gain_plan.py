"""What a session's faded, adaptive and combined conditions mean for its trials.

Pure functions of a protocol and its schedule (issue #18 items 1 and 3), used by
``vasim.study.session.Session.trial_config``:

* ``trial_gain``: the fixture gain rule of a scheduled trial (``vasim.fixtures.gain``):
  the block's schedule stage or adaptive rule for its own trials, 1.0 otherwise (probes,
  constant blocks, teleoperation modes);
* ``learning_gain``: the gain the simulated operator's per-trial adjustment uses
  (``vasim.operator.learning.trial_adjustment``'s ``gain``);
* ``condition_effects``: a scenario's declared effects by condition label
  (``vasim.operator.scenario``), at an effect scale. **Decision** (issue #25): a label the
  scenario does not list (``ff_faded``, ``ag_mag``) gets no operator effect, only its
  simulated mechanism, unless the scenario's ``derive_unlisted`` asks for the combination
  of its fixtures' declared effects (``vasim.operator.combined``); nothing of the seed is
  applied to conditions the seed did not run.

**Decision** (adaptive trials and the simulated operator): the gain of an adaptive trial
is only known once it has run (it follows the trainee's deviation), while the operator's
per-trial adjustment is set before the trial (a cohort plans every trial up front). The
adjustment uses the rule's start gain (``AdaptiveRule.start``); within the trial the motion
model feels the live gain through every channel (the force it is pulled by, the zoom it
sees, the volume it hears), and the per-sample gain is logged.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

from vasim.fixtures.gain import AdaptiveRule, GainRule
from vasim.fixtures.schema import load_schema
from vasim.operator.effects import FixtureEffect
from vasim.operator.scenario import Scenario, default_scenario
from vasim.study.protocol import Block, Protocol, ScheduledTrial
from vasim.trials.kinds import TELEOPERATION_MODES

_EFFECTS: dict[tuple[tuple[Block, ...], str, float], dict[str, FixtureEffect]] = {}


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


def scale_gain(rule: GainRule, factor: float) -> GainRule:
    """A gain rule with every gain times ``factor`` in [0, 1] (a scenario's mechanism
    gain, ``Scenario.mechanism``): a constant ``G factor``; an adaptive rule with its
    bounds and start scaled.

    >>> scale_gain(1.0, 0.0), scale_gain(AdaptiveRule(gain_min=0.2), 0.5).gain_max
    (0.0, 0.5)
    """
    f = float(factor)
    if isinstance(rule, AdaptiveRule):
        return replace(rule, gain_min=rule.gain_min * f, gain_max=rule.gain_max * f,
                       initial=None if rule.initial is None else rule.initial * f)
    return float(rule) * f


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


def condition_effects(protocol: Protocol, scenario: Scenario | None = None,
                      scale: float = 1.0) -> dict[str, FixtureEffect]:
    """The operator effects by condition label for ``protocol`` under ``scenario`` (None:
    the shipped default) at effect scale ``scale`` (module docstring).

    Cached per protocol blocks, scenario hash and scale; the returned mapping must not be
    modified.

    >>> from vasim.study.protocol import load_protocol
    >>> eff = condition_effects(load_protocol("vf_schemas"))
    >>> "ag_mag" in eff, eff["ff"].accuracy
    (False, 0.75)
    """
    sc = scenario or default_scenario()
    key = (protocol.blocks, sc.sha256, float(scale))
    out = _EFFECTS.get(key)
    if out is None:
        components: dict[str, tuple[str, ...]] = {}
        if sc.derive_unlisted:
            for b in protocol.blocks:
                cond = b.condition
                if b.probe or cond in sc.fixtures or cond in TELEOPERATION_MODES:
                    continue
                components[cond] = load_schema(b.schema or cond).kinds
        out = _EFFECTS[key] = sc.condition_effects(components, scale)
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


__all__ = ["block_mean_gain", "condition_effects", "gain_text",
           "learning_gain", "scale_gain", "schedule_gains", "trial_gain"]
