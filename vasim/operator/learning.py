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

Parameters (``FixtureEffect``) and where each comes from (seed line numbers refer to
``/work/shared/seed/000_85d9e1bca86fa007.txt``):

* a_c (``accuracy``): seed l. 5378-5380, "Tukey HSD test shows that FF is the most effective
  VF in reducing cumulative error, but its effect is not significantly different from AG
  and MS": FF 0.52, MS 0.45, AG 0.66, Mag 0.95, VG 0.95 (VG "generating confusion more than
  helping", l. 5420). The target is the *measured* accuracy, the path deviation (eq. 6.5's
  e follows the time, ``vasim.tasks.trajectory.POI_SPACING``): FF lowest, AG and MS close.
  These factors sit on top of the motion model's own channels, which is why they are not
  in the seed's order: MS's scaling and AG's sound cost accuracy by themselves and Mag's
  zoom already sharpens perception. Calibration history (method of simulated moments,
  ``bench/calibration.py``): an 8-subject cohort with FF 0.70, AG and MS 0.78, VG and Mag
  0.88 made VG the most accurate and MS the least; the 46-subject cohort of 2026-11-25
  with FF 0.60, MS 0.68, AG 0.78, Mag 0.88 gave Mag 3.71 = FF 3.73 mm and FF vs MS
  p_adj = .003; 12-subject pilots then gave (FF .52, MS .58, AG .78, Mag .95) FF 3.58, MS
  3.84, VG 3.94, Mag 3.99, AG 4.04 mm, and (AG .60, MS .53) FF 3.58, AG 3.75, MS 3.80 (the
  path deviation moves ~1.9 mm per unit of FF's or AG's factor, ~0.8 mm per unit of MS's);
  46 subjects with FF .54, AG .58, MS .45 gave AG 3.55, FF 3.67, MS 3.72 mm (AG best), and
  with the values above (2026-11-27) FF 3.638, AG 3.641, MS 3.722, Mag 3.762, VG 3.958 mm
  (FF vs AG p_adj = 1.0, vs MS .82: FF and AG tie at the top).
* v_c (``speed``): l. 5380-5381, "completion time is improved by Mag and ... not
  significantly different from that of AG": Mag 0.80, AG 0.84 (0.88 left Mag vs AG at
  p_adj = .005 in the 46-subject cohort); l. 5371-5372 "they do not
  increase the speed of motion" for the others: FF 1.04 (l. 5403, "Higher Forces improve
  accuracy, but limits the operators movement"; with 1.0 the simulated FF pull alone made
  FF the fastest, against the seed; 1.12 made it the third); MS 1.08 (it restricts motion
  away from the path, l. 5416); VG 1.05 (the confusing arrow, l. 5420).
* w_c (``practice_weight``): l. 5407-5408, "the use of FF seems to need a short adaptation
  period, property that cannot be associated to all VF": an FF trial counts 1.5 trials of
  practice; Mag 1.2 ("a tool that surgeons are used to", l. 5410); the others 1.0.
* rho_c (``carryover``): l. 5361-5368, the cumulative error of the VF-free trials drops
  between the 3rd and the 4th repetition, "this effects continues, even when the support of
  the VF is disabled": 40 % of the assisted accuracy gain remains for FF (haptic guidance,
  a motor-learning aid), 30 % for the others. Partial retention after guidance is removed
  is the motor-learning finding of Winstein, Pohl & Lewthwaite 1994 (Res Q Exerc Sport
  65:316) and Liu & Todorov 2007 for haptic guidance.
* delta_c (``dependence``): the guidance hypothesis (Salmoni, Schmidt & Walter 1984, Psychol
  Bull 95:355; Schmidt 1991): a learner who leans on strong concurrent guidance performs
  worse when it is withdrawn. Error +12 % in the VF-free trial right after an FF block,
  +6 % after Mag (the view suddenly un-magnified), +4 % after AG/VG/MS.

These values are a **calibration** to the seed's reported results, chosen by the method of
simulated moments at the level of the reported orderings and significances (see
``bench/calibration.py``, which prints the simulated statistics beside the seed's); they
are not measurements.

Example:
    >>> adj = trial_adjustment(["none", "none", "none", "ff", "ff"], "ff")
    >>> round(adj.practice, 2), adj.noise_factor, adj.time_factor
    (6.0, 0.52, 1.04)
    >>> ff_block = ["none"] * 3 + ["ff"] * 6
    >>> round(trial_adjustment(ff_block, "none").noise_factor, 4)   # (1 - .4 x .48) x 1.12
    0.905
    >>> round(trial_adjustment(ff_block + ["none"], "none").noise_factor, 4)  # carry-over
    0.808
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from vasim.operator.profile import OperatorProfile

VF_FREE = "none"
"""Condition label of a VF-free trial."""


@dataclass(frozen=True)
class FixtureEffect:
    """What one fixture does to the simulated operator (module docstring).

    Attributes:
        accuracy: a_c > 0, factor on the learnable noise while assisted (< 1 helps).
        speed: v_c > 0, factor on the movement time while assisted (< 1 faster).
        practice_weight: w_c >= 0, trials of practice one assisted trial counts for.
        carryover: rho_c in [0, 1], fraction of the accuracy gain kept in VF-free trials.
        dependence: delta_c >= 0, relative extra noise in the VF-free trial right after.

    Raises:
        ValueError: naming the field and value.
    """

    accuracy: float = 1.0
    speed: float = 1.0
    practice_weight: float = 1.0
    carryover: float = 0.0
    dependence: float = 0.0

    def __post_init__(self) -> None:
        for name, lo, hi in (("accuracy", 0.0, 10.0), ("speed", 0.0, 10.0),
                             ("practice_weight", 0.0, 10.0), ("carryover", 0.0, 1.0),
                             ("dependence", 0.0, 10.0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) \
                    or not lo <= v <= hi or (name in ("accuracy", "speed") and v == 0):
                raise ValueError(f"FixtureEffect.{name} must be a number in [{lo}, {hi}]"
                                 f"{' and > 0' if name in ('accuracy', 'speed') else ''}, "
                                 f"got {v!r}")


SEED_EFFECTS: dict[str, FixtureEffect] = {
    "vg": FixtureEffect(accuracy=0.95, speed=1.05, practice_weight=1.0, carryover=0.3,
                        dependence=0.04),
    "ag": FixtureEffect(accuracy=0.66, speed=0.84, practice_weight=1.0, carryover=0.3,
                        dependence=0.04),
    "ms": FixtureEffect(accuracy=0.45, speed=1.08, practice_weight=1.0, carryover=0.3,
                        dependence=0.04),
    "mag": FixtureEffect(accuracy=0.95, speed=0.80, practice_weight=1.2, carryover=0.3,
                         dependence=0.06),
    "ff": FixtureEffect(accuracy=0.52, speed=1.04, practice_weight=1.5, carryover=0.4,
                        dependence=0.12),
}
"""The calibrated effects of the seed's five fixtures, by condition label (module docstring)."""

OPERATOR_LABEL = "scripted (calibrated to the seed, synthetic)"
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
    mode) has none (**Decision**: no guessing beyond the seed's five fixtures)."""
    return effects.get(cond, FixtureEffect())


def trial_adjustment(history: Sequence[str], condition: str,
                     effects: Mapping[str, FixtureEffect] = SEED_EFFECTS, *,
                     gain: float = 1.0, history_gains: Sequence[float] | None = None,
                     ) -> TrialAdjustment:
    """The adjustment of a trial under ``condition`` after the trials ``history``.

    Args:
        history: condition labels of the subject's earlier trials in the session, in order
            (``"none"`` for VF-free trials).
        condition: this trial's condition label.
        effects: fixture effects by label (default: the seed's calibration).
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
        if gain != 1.0:  # the gain hook (issue #18); G = 1 keeps the calibrated numbers
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
    "OPERATOR_LABEL",
    "SEED_EFFECTS",
    "VF_FREE",
    "FixtureEffect",
    "TrialAdjustment",
    "trial_adjustment",
]
