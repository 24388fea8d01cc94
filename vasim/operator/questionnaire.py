"""How the simulated operator judges the fixtures it used: perceived benefit, not error alone.

The seed's subjects did not rate the fixtures by how much they helped: "MS and VG obtained
the worst subjective evaluation results ... most of them gave a low evaluation not because
of its usefulness, but for not being able to appreciate its effects" (seed l. 5415-5419),
VG's arrow "generat[ed] confusion more than helping" (l. 5420-5422), AG's sound was "too
annoying for some subjects" (l. 5404), while FF felt "comfortable and safer" (l. 5401) and
Mag was "a tool that surgeons are used to" (l. 5410). A fixture's answer therefore mixes
what the subject measured on itself with how noticeable and how comfortable the fixture
is.

Model (per subject; c ranges over the protocol's assisted conditions; line numbers refer
to ``/work/shared/seed/000_85d9e1bca86fa007.txt``)::

    b~_c      = b_c - mean_c' b_c'          measured benefit, relative to the subject's others
                (b_c = ln(E_probe / E_c), E the mean path deviation, vasim.study.cohort)
    best      = argmax_c  ( n_c + w b~_c + G_c )
    worst     = argmax_c  ( -k_c - w b~_c + G'_c )
    rating_c  = clip(round( r_c + s b~_c + N(0, sd^2) ), min, max)

G, G' are independent standard Gumbel draws, so with equal measured benefits the choices
follow a multinomial logit (McFadden 1974): P(best = c) = exp(n_c) / sum exp(n). Hence the
calibration to the seed's shares (l. 5386-5389) is exact in closed form: n_c = ln(best
share), k_c = -ln(worst share) -- noticeability and comfort. The rating centres r_c are the
seed's mean ratings (l. 5389-5390). w = ``CHOICE_WEIGHT`` and s = ``RATING_WEIGHT`` let the
subject's own experience move the answers around those centres (centred, so they do not
shift the cohort means). A condition the seed did not study gets neutral values, unless
it is made of the seed's fixtures (:func:`condition_prior`).

**Decision** (conditions the seed did not rate: combined schemas such as AG+Mag, faded and
adaptive fixtures): their priors are derived from their single fixtures, the same way
``vasim.operator.combined`` derives their calibrated effects:

* perceived benefit (the best-share p, noticeability): independent probabilities, each
  fixture's scaled by the condition's gain G, ``p = 1 - prod_i (1 - G p_i)`` -- the
  combination is named best if any of its fixtures would be, and a fixture at gain G is
  noticed G times as often (G = 0: never named best; floored at ``MIN_SHARE``);
* comfort (k = -ln q, q the worst share): the mean of the fixtures' comfort terms,
  ``k = mean_i k_i``, i.e. q the geometric mean of the q_i; the gain leaves it (a fixture's
  annoyance or comfort is its kind's, e.g. AG's sound);
* rating centre: the mean of the fixtures' seed ratings, unchanged by the gain (the
  subject's own measured benefit, which the gain does change, moves the rating through
  ``RATING_WEIGHT``).

A single seed fixture at G = 1 is exactly its seed values; a condition with any fixture
the seed did not rate (e.g. the cone) stays neutral.

Example:
    >>> import numpy as np
    >>> a = perceive({"ff": 0.1, "ms": 0.1}, np.random.default_rng(0))
    >>> sorted(a), a["ff"].rating_mean
    (['ff', 'ms'], 7.08)
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

SEED_BEST_SHARE: dict[str, float] = {"mag": 0.36, "ff": 0.24, "ag": 0.19, "vg": 0.13,
                                     "ms": 0.08}
"""Fraction of the 46 subjects naming each fixture best (seed l. 5386-5387)."""
SEED_WORST_SHARE: dict[str, float] = {"ms": 0.39, "vg": 0.35, "ag": 0.14, "mag": 0.10,
                                      "ff": 0.02}
"""Fraction naming each fixture least useful (seed l. 5388-5389)."""
SEED_MEAN_RATING: dict[str, float] = {"ff": 7.08, "mag": 6.85, "ag": 6.38, "vg": 5.63,
                                      "ms": 4.74}
"""Mean 0-10 rating of each fixture (seed l. 5389-5390)."""

CHOICE_WEIGHT = 2.0
"""w: logit utility per unit of relative measured benefit (a fixture that cut the
subject's path deviation by 10 % more than its others gains 0.2 in utility, ~ x1.2 odds).
**Decision**: the seed reports only the cohort shares, not how they follow performance."""
RATING_WEIGHT = 5.0
"""s: rating points per unit of relative measured benefit (**Decision**, as CHOICE_WEIGHT)."""
RATING_SD = 1.5
"""Between-subject spread of a rating around its centre [rating points] (**Decision**: the
seed gives means only; 1.5 points keeps ratings inside 0-10 without much clipping)."""
NEUTRAL_RATING = 6.0
"""Rating centre of a condition the seed did not study (about the seed's overall mean)."""


MIN_SHARE = 1e-6
"""Smallest best-share a prior gets (a fixture at gain 0 is not noticed; the log of the
share must stay finite)."""


@dataclass(frozen=True)
class ConditionPrior:
    """What the seed says, or what is derived from it, about one condition.

    Attributes:
        best_share: p, the share of subjects naming it best (noticeability, in (0, 1]).
        worst_share: q, the share naming it least useful (-ln q: comfort, in (0, 1]).
        rating: r, the mean 0-10 rating (the rating centre).
    """

    best_share: float
    worst_share: float
    rating: float


def seed_prior(label: str) -> ConditionPrior:
    """The seed's values of a condition label, neutral ones for a label it did not rate
    (shares 1/5, rating ``NEUTRAL_RATING``).

    >>> seed_prior("ff"), seed_prior("cone").rating
    (ConditionPrior(best_share=0.24, worst_share=0.02, rating=7.08), 6.0)
    """
    return ConditionPrior(_share(SEED_BEST_SHARE, label), _share(SEED_WORST_SHARE, label),
                          SEED_MEAN_RATING.get(label, NEUTRAL_RATING))


def condition_prior(kinds: Sequence[str], gain: float = 1.0) -> ConditionPrior | None:
    """The prior of a condition running the fixtures ``kinds`` at gain ``gain`` (module
    docstring's decision), or None when a fixture has no seed rating (neutral then).

    Example (AG+Mag: p = 1 - (1 - 0.19)(1 - 0.36), q = sqrt(0.14 x 0.10)):
        >>> p = condition_prior(("ag", "mag"))
        >>> round(p.best_share, 4), round(p.worst_share, 4), round(p.rating, 3)
        (0.4816, 0.1183, 6.615)
        >>> round(condition_prior(("ff",), gain=0.625).best_share, 6)   # faded FF
        0.15
    """
    if not kinds or any(k not in SEED_MEAN_RATING for k in kinds):
        return None
    g = min(1.0, max(0.0, float(gain)))
    if len(kinds) == 1 and g == 1.0:
        return seed_prior(kinds[0])
    priors = [seed_prior(k) for k in kinds]
    best = 1.0 - math.prod(1.0 - g * p.best_share for p in priors)
    comfort = float(np.mean([-math.log(p.worst_share) for p in priors]))
    return ConditionPrior(best_share=max(MIN_SHARE, best), worst_share=math.exp(-comfort),
                          rating=float(np.mean([p.rating for p in priors])))


@dataclass(frozen=True)
class Perception:
    """One subject's perception of one fixture.

    Attributes:
        best_utility: utility of naming it best (larger = more likely).
        worst_utility: utility of naming it least useful (larger = more likely).
        rating_mean: the rating centre r_c [0-10 points].
        rating: the subject's rating before rounding and clipping [points].
    """

    best_utility: float
    worst_utility: float
    rating_mean: float
    rating: float


def _share(table: Mapping[str, float], c: str) -> float:
    return table.get(c, 1.0 / len(table))


def perceive(measured: Mapping[str, float], rng: np.random.Generator,
             priors: Mapping[str, ConditionPrior] | None = None) -> dict[str, Perception]:
    """Draws one subject's perception of each condition (module docstring).

    Args:
        measured: b_c, the subject's measured log benefit per assisted condition.
        rng: the subject's random stream.
        priors: the prior of a condition the seed did not rate (``condition_prior``);
            a condition without one gets ``seed_prior`` (the seed's, or neutral values).

    Returns:
        condition -> ``Perception``, in the order of ``measured``.
    """
    conds = list(measured)
    if not conds:
        return {}
    b = np.array([measured[c] if math.isfinite(measured[c]) else 0.0 for c in conds])
    rel = b - b.mean()
    g_best = rng.gumbel(size=len(conds))
    g_worst = rng.gumbel(size=len(conds))
    noise = rng.normal(0.0, RATING_SD, size=len(conds))
    out = {}
    for i, c in enumerate(conds):
        prior = (priors or {}).get(c) or seed_prior(c)
        centre = prior.rating
        out[c] = Perception(
            best_utility=math.log(prior.best_share) + CHOICE_WEIGHT * rel[i]
            + float(g_best[i]),
            worst_utility=math.log(prior.worst_share) - CHOICE_WEIGHT * rel[i]
            + float(g_worst[i]),
            rating_mean=centre,
            rating=centre + RATING_WEIGHT * float(rel[i]) + float(noise[i]),
        )
    return out


__all__ = [
    "CHOICE_WEIGHT",
    "MIN_SHARE",
    "NEUTRAL_RATING",
    "RATING_SD",
    "RATING_WEIGHT",
    "SEED_BEST_SHARE",
    "SEED_MEAN_RATING",
    "SEED_WORST_SHARE",
    "ConditionPrior",
    "Perception",
    "condition_prior",
    "perceive",
    "seed_prior",
]
