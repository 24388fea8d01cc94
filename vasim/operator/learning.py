"""Fixture-specific effects, learning and carry-over of the simulated operator.

The motion model (``vasim.operator.scripted``) already feels each fixture through its
channel (FF pulls the hand, MS scales the motion, Mag zooms the view, VG and AG are extra
cues). What it cannot express by itself are the hypotheses of the seed's study (chapter 6,
section 6.4.4): that fixtures differ in how much they help accuracy and speed, that an
assisted block leaves something behind in the following VF-free trials, and that practice
under some fixtures teaches faster. This module adds those as per-trial adjustments of the
operator profile, pure functions of the subject's schedule so far.

Model (per trial; c = the trial's condition label, H = conditions of the earlier trials of
the session in order; ``none`` = VF-free)::

    P_eff   = sum_{h in H} w_h                       (practice, w_none = 1)
    assisted (c != none):
        noise  x a_c,   movement time  x v_c
    VF-free (c == none):
        noise  x prod_{f practised} (1 - rho_f (1 - a_f))  x (1 + delta_g)
        (g = the fixture of the trial just before, if it was assisted)

"noise" is the learnable error of the motion model (motor, gain and perceptual noise:
``noise``, ``gain_noise``, ``perception_noise``); movement time scales ``fitts_a`` and
``fitts_b``. The effective practice enters the motion model's power law (rounded to an
integer trial count).

Parameters (``FixtureEffect``, :mod:`vasim.operator.effects`): **assumptions** declared,
each with its source, in a scenario file (``protocols/scenarios/*.toml``,
:mod:`vasim.operator.scenario`); :data:`DEFAULT_EFFECTS` are the shipped
``seed_plausible`` scenario's. None of them is fitted to the seed's results (issue #25:
the former per-fixture factors were tuned on the cohort they were then compared with).

Example:
    >>> ff = FixtureEffect(accuracy=0.6, speed=1.1, practice_weight=1.5, carryover=0.5,
    ...                    dependence=0.1)
    >>> adj = trial_adjustment(["none", "none", "none", "ff", "ff"], "ff", {"ff": ff})
    >>> round(adj.practice, 2), adj.noise_factor, adj.time_factor
    (6.0, 0.6, 1.1)
    >>> ff_block = ["none"] * 3 + ["ff"] * 6
    >>> round(trial_adjustment(ff_block, "none", {"ff": ff}).noise_factor, 4)  # (1-.5x.4)x1.1
    0.88
    >>> round(trial_adjustment(ff_block + ["none"], "none", {"ff": ff}).noise_factor, 4)
    0.8
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from vasim.operator.effects import FixtureEffect
from vasim.operator.profile import OperatorProfile
from vasim.operator.scenario import default_scenario

VF_FREE = "none"
"""Condition label of a VF-free trial."""


DEFAULT_EFFECTS: dict[str, FixtureEffect] = default_scenario().effects()
"""The shipped ``seed_plausible`` scenario's fixture effects, by condition label: declared
assumptions (``protocols/scenarios/seed_plausible.toml``), not seed results."""

SEED_EFFECTS = DEFAULT_EFFECTS
"""Former name of :data:`DEFAULT_EFFECTS`, kept for modules not yet renamed; it no longer
holds factors tuned to the seed (issue #25)."""

OPERATOR_LABEL = "scripted (declared scenario, synthetic)"
"""How a session run by the simulated operator names its operator."""


@dataclass(frozen=True)
class TrialAdjustment:
    """The adjustment of one trial: effective practice, noise and movement-time factors."""

    practice: float
    noise_factor: float
    time_factor: float

    def apply(self, profile: OperatorProfile) -> OperatorProfile:
        """The profile with the learnable noise and the Fitts constants scaled."""
        return profile.replace(
            noise=min(profile.noise * self.noise_factor, 0.1),
            gain_noise=min(profile.gain_noise * self.noise_factor, 2.0),
            perception_noise=min(profile.perception_noise * self.noise_factor, 0.05),
            fitts_a=min(profile.fitts_a * self.time_factor, 10.0),
            fitts_b=min(profile.fitts_b * self.time_factor, 10.0),
        )


def _effect(cond: str, effects: Mapping[str, FixtureEffect]) -> FixtureEffect:
    """A condition's effect; a label it does not know (a combined schema, a teleoperation
    mode) has none (**Decision**: no guessing beyond the scenario's declared labels)."""
    return effects.get(cond, FixtureEffect())


def trial_adjustment(history: Sequence[str], condition: str,
                     effects: Mapping[str, FixtureEffect] = DEFAULT_EFFECTS, *,
                     gain: float = 1.0, history_gains: Sequence[float] | None = None,
                     ) -> TrialAdjustment:
    """The adjustment of a trial under ``condition`` after the trials ``history``.

    Args:
        history: condition labels of the subject's earlier trials in the session, in order
            (``"none"`` for VF-free trials).
        condition: this trial's condition label.
        effects: fixture effects by label (default: the shipped scenario's).
        gain: the fixture gain G in [0, 1] of this trial (``vasim.fixtures.gain``; 1 = the
            schema as written): the assisted factors move toward 1, ``1 - G (1 - a_c)`` and
            ``1 + G (v_c - 1)`` (``vasim.operator.combined`` states the rule).
        history_gains: the gain of each trial of ``history`` (None: all 1); the guidance
            dependence after an assisted trial scales with its gain.

    Returns:
        ``TrialAdjustment`` (module docstring's equations).
    """
    practice = sum(1.0 if h == VF_FREE else _effect(h, effects).practice_weight
                   for h in history)
    if condition != VF_FREE:
        e = _effect(condition, effects)
        if gain != 1.0:  # the gain hook (issue #18); G = 1 keeps the declared numbers
            return TrialAdjustment(practice, 1.0 - gain * (1.0 - e.accuracy),
                                   1.0 + gain * (e.speed - 1.0))
        return TrialAdjustment(practice, e.accuracy, e.speed)
    noise = 1.0
    for f in dict.fromkeys(h for h in history if h != VF_FREE):   # practised fixtures
        e = _effect(f, effects)
        noise *= 1.0 - e.carryover * (1.0 - e.accuracy)
    if history and history[-1] != VF_FREE:
        g_last = 1.0 if not history_gains else history_gains[-1]
        noise *= 1.0 + g_last * _effect(history[-1], effects).dependence  # 1.0 * x == x
    return TrialAdjustment(practice, noise, 1.0)


__all__ = [
    "DEFAULT_EFFECTS",
    "OPERATOR_LABEL",
    "SEED_EFFECTS",
    "VF_FREE",
    "FixtureEffect",
    "TrialAdjustment",
    "trial_adjustment",
]
