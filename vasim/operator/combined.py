"""The simulated operator's effect of a combined schema and of a fixture at reduced gain.

A scenario declares single fixtures' effects (``vasim.operator.scenario``); the seed's next
study (sec. 7.2.3, issue #18 item 3) combines them (AG+Mag, Mag+FF, VG+AG), and the fading
study (item 1) runs them at a gain G in [0, 1]. Neither has a measurement, so both are
*rules*, stated here and applied to the declared single effects (a combination only when
the scenario's ``derive_unlisted`` says so).

**Decision** (combination rule): the fixtures of a schema act on the trainee through
independent channels, so their benefits combine as independent probabilities of removing
error. With ``b_i = 1 - a_i`` the accuracy benefit of fixture i (the fraction of the
learnable noise it removes), the combined benefit is ``B = 1 - prod_i (1 - b_i)``, i.e.
``a = prod_i a_i``; the same rule on the other factors:

* speed: ``v = prod_i v_i`` (each fixture's slow-down or speed-up applies in turn);
* practice weight: ``w = max_i w_i`` (one trial is one trial; the most engaging fixture
  sets how much it teaches);
* carry-over: what a VF-free trial keeps is what each fixture would leave,
  ``1 - rho (1 - a) = prod_i (1 - rho_i (1 - a_i))``, solved for rho;
* guidance dependence: ``1 + delta = prod_i (1 + delta_i)``.

A single fixture is its own combination; the order does not matter; a benefit never
exceeds 1 (``a > 0``).

**Decision** (gain): at gain G the assisted factors move linearly toward "no effect",
``a_G = 1 - G (1 - a)`` and ``v_G = 1 + G (v - 1)`` (the benefit scales with the gain, as
the fixture's output does, ``vasim.fixtures.gain``), and the guidance dependence left after
an assisted trial scales with that trial's gain, ``delta_G = G delta`` (the guidance
hypothesis: what was not leaned on is not missed; Winstein, Pohl & Lewthwaite 1994 found
faded feedback retained better). Practice and carry-over are left as they are: a faded
trial is practice all the same. ``vasim.operator.learning.trial_adjustment`` applies it
(its ``gain`` and ``history_gains`` arguments; G = 1 keeps the declared numbers).

Example:
    >>> e = combine_effects([FixtureEffect(accuracy=0.8, speed=0.9),
    ...                      FixtureEffect(accuracy=0.5, speed=1.1)])
    >>> round(e.accuracy, 6), round(e.speed, 6)
    (0.4, 0.99)
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from vasim.operator.effects import FixtureEffect


def combine_effects(effects: Sequence[FixtureEffect]) -> FixtureEffect:
    """The effect of a schema whose fixtures have ``effects`` (module docstring's rule).

    Raises:
        ValueError: no effect given.
    """
    if not effects:
        raise ValueError("combine_effects needs at least one fixture effect")
    if len(effects) == 1:  # a single fixture is its own combination (exactly)
        return effects[0]
    acc = math.prod(e.accuracy for e in effects)
    kept = math.prod(1.0 - e.carryover * (1.0 - e.accuracy) for e in effects)
    benefit = 1.0 - acc
    rho = (1.0 - kept) / benefit if abs(benefit) > 1e-12 else 0.0
    return FixtureEffect(
        accuracy=acc,
        speed=math.prod(e.speed for e in effects),
        practice_weight=max(e.practice_weight for e in effects),
        carryover=min(1.0, max(0.0, rho)),
        dependence=math.prod(1.0 + e.dependence for e in effects) - 1.0,
    )


def label_effects(components: Mapping[str, Sequence[str]],
                  base: Mapping[str, FixtureEffect],
                  ) -> dict[str, FixtureEffect]:
    """``base`` extended with the effect of every condition label it lacks.

    Args:
        components: condition label -> the fixture kinds its schema runs (e.g.
            ``{"ag_mag": ("ag", "mag"), "ff_faded": ("ff",)}``).
        base: the declared single effects (labels already there keep their effect).

    Returns:
        A new mapping: ``base`` plus the combination of each new label whose fixtures all
        have a declared effect (a label with an undeclared fixture, e.g. the cone,
        gets none: no guessing beyond the declared fixtures).
    """
    out = dict(base)
    for label, kinds in components.items():
        if label in out or not kinds or any(k not in base for k in kinds):
            continue
        out[label] = combine_effects([base[k] for k in kinds])
    return out


__all__ = ["combine_effects", "label_effects"]
