"""Retention (forgetting over a delay) and transfer (to an untrained path) of the simulated
operator's skill: an additive hook on :mod:`vasim.operator.learning` that leaves its
calibrated numbers alone.

``learning.trial_adjustment`` counts every earlier trial of the session fully: practice
``P = sum_h w_h``, carry-over ``rho_f`` and the guidance dependence ``delta_g``. Across a
delay and onto a trajectory never practised, each earlier trial h counts with a weight
``s_h`` in [0, 1]::

    s_h   = R(age_h) x T_h
    R(a)  = (1 + a / tau) ** -psi              power-law forgetting, age a in days
    T_h   = 1 if h ran on this trial's trajectory or this trajectory is a trained one,
            else tau_T                          (transfer to an untrained trajectory)
    P     = sum_h w_h s_h
    VF-free noise x prod_f (1 - rho_f s_f (1 - a_f)) x (1 + delta_g s_g)

(s_f: the weight of the latest trial under fixture f; g: the trial just before). With every
``s_h = 1`` (one sitting, a trained trajectory) this is ``trial_adjustment`` exactly.

Parameters (**decisions**, calibration choices with their motor-learning sources, not fits):

* Forgetting is a power function of the retention interval: Wixted & Ebbesen 1991 ("On the
  form of forgetting", Psychol Sci 2:409) and Rubin & Wenzel 1996 (Psychol Rev 103:734)
  find the power law fits retention curves best; ``tau`` = 1 day (the unit of the delay),
  ``psi`` = 0.15. Arthur, Bennett, Stanush & McNelly 1998 (Hum Perform 11:57, a
  meta-analysis of skill decay) report small losses for continuous, closed-loop tasks over
  days to weeks: R(1 d) = 0.90, R(7 d) = 0.73, R(30 d) = 0.60 of the practice kept. Within a
  sitting (age 0) nothing is forgotten.
* Transfer ``tau_T`` = 0.7: the untrained variants are mirrored or rotated copies of the
  trained trajectory, so most of the motor elements are shared ("identical elements",
  Thorndike & Woodworth 1901; Schmidt & Lee, Motor Control and Learning, ch. 10: positive
  but incomplete transfer between variants of a task), while the route itself is new.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from vasim.operator.learning import (
    DEFAULT_EFFECTS,
    VF_FREE,
    FixtureEffect,
    TrialAdjustment,
)


@dataclass(frozen=True)
class RetentionModel:
    """Forgetting and transfer of practice (module docstring).

    Attributes:
        tau_days: time scale of the power law [d] (> 0).
        psi: forgetting exponent (>= 0; 0: nothing is forgotten).
        transfer: fraction of practice on other trajectories that counts on an untrained
            one, in [0, 1].

    Raises:
        ValueError: naming the field and value.
    """

    tau_days: float = 1.0
    psi: float = 0.15
    transfer: float = 0.7

    def __post_init__(self) -> None:
        for name, lo, hi in (("tau_days", 0.0, 1e4), ("psi", 0.0, 10.0),
                             ("transfer", 0.0, 1.0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) \
                    or not lo <= v <= hi or (name == "tau_days" and v == 0):
                raise ValueError(f"RetentionModel.{name} must be a number in [{lo}, {hi}]"
                                 f"{' and > 0' if name == 'tau_days' else ''}, got {v!r}")

    def retained(self, age_days: float) -> float:
        """R(a) = (1 + a / tau) ** -psi: the fraction of a trial's practice kept after
        ``age_days`` [d] (1 at age 0).

        >>> round(RetentionModel().retained(7.0), 3)
        0.732
        """
        if not math.isfinite(age_days) or age_days < 0:
            raise ValueError(f"age_days must be a finite number >= 0, got {age_days!r}")
        return (1.0 + age_days / self.tau_days) ** -self.psi


DEFAULT_RETENTION = RetentionModel()
"""The model the sessions use (module docstring's parameters)."""


def practice_weights(ages_days: Sequence[float], same_path: Sequence[bool], *,
                     untrained: bool, model: RetentionModel = DEFAULT_RETENTION,
                     ) -> list[float]:
    """The weight s_h of each earlier trial (module docstring).

    Args:
        ages_days: age of each earlier trial at this trial [d], >= 0.
        same_path: whether each earlier trial ran on this trial's trajectory.
        untrained: this trial's trajectory is an untrained (transfer) one.
        model: the retention model.

    Example:
        >>> [round(w, 3) for w in practice_weights([7.0, 0.0], [False, True],
        ...                                         untrained=True)]
        [0.512, 1.0]
    """
    if len(ages_days) != len(same_path):
        raise ValueError(f"ages_days and same_path differ in length ({len(ages_days)} vs "
                         f"{len(same_path)})")
    return [model.retained(a) * (1.0 if (s or not untrained) else model.transfer)
            for a, s in zip(ages_days, same_path, strict=True)]


def weighted_adjustment(history: Sequence[str], condition: str, weights: Sequence[float],
                        effects: Mapping[str, FixtureEffect] = DEFAULT_EFFECTS,
                        ) -> TrialAdjustment:
    """``learning.trial_adjustment`` with each earlier trial counted by its weight.

    Args:
        history: condition labels of the earlier trials, in order.
        condition: this trial's condition label.
        weights: s_h in [0, 1] per earlier trial (:func:`practice_weights`).
        effects: fixture effects by label.

    Returns:
        The adjustment (module docstring's equations); all weights 1 give
        ``trial_adjustment(history, condition, effects)``.
    """
    if len(weights) != len(history):
        raise ValueError(f"weights and history differ in length ({len(weights)} vs "
                         f"{len(history)})")
    for w in weights:
        if not 0.0 <= w <= 1.0:
            raise ValueError(f"weights must be in [0, 1], got {w!r}")

    def effect(c: str) -> FixtureEffect:
        return effects.get(c, FixtureEffect())

    practice = sum((1.0 if h == VF_FREE else effect(h).practice_weight) * w
                   for h, w in zip(history, weights, strict=True))
    if condition != VF_FREE:
        e = effect(condition)
        return TrialAdjustment(practice, e.accuracy, e.speed)
    latest: dict[str, float] = {}
    for h, w in zip(history, weights, strict=True):
        if h != VF_FREE:
            latest.pop(h, None)     # keep first-use order, the latest trial's weight
            latest[h] = w
    order = list(dict.fromkeys(h for h in history if h != VF_FREE))
    noise = 1.0
    for f in order:
        e = effect(f)
        noise *= 1.0 - e.carryover * latest[f] * (1.0 - e.accuracy)
    if history and history[-1] != VF_FREE:
        noise *= 1.0 + effect(history[-1]).dependence * weights[-1]
    return TrialAdjustment(practice, noise, 1.0)


__all__ = ["DEFAULT_RETENTION", "RetentionModel", "practice_weights", "weighted_adjustment"]
