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
shift the cohort means). A condition the seed did not study gets neutral values.

Example:
    >>> import numpy as np
    >>> a = perceive({"ff": 0.1, "ms": 0.1}, np.random.default_rng(0))
    >>> sorted(a), a["ff"].rating_mean
    (['ff', 'ms'], 7.08)
"""

from __future__ import annotations

import math
from collections.abc import Mapping
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


def perceive(measured: Mapping[str, float], rng: np.random.Generator) -> dict[str, Perception]:
    """Draws one subject's perception of each condition (module docstring).

    Args:
        measured: b_c, the subject's measured log benefit per assisted condition.
        rng: the subject's random stream.

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
        centre = SEED_MEAN_RATING.get(c, NEUTRAL_RATING)
        out[c] = Perception(
            best_utility=math.log(_share(SEED_BEST_SHARE, c)) + CHOICE_WEIGHT * rel[i]
            + float(g_best[i]),
            worst_utility=math.log(_share(SEED_WORST_SHARE, c)) - CHOICE_WEIGHT * rel[i]
            + float(g_worst[i]),
            rating_mean=centre,
            rating=centre + RATING_WEIGHT * float(rel[i]) + float(noise[i]),
        )
    return out


__all__ = [
    "CHOICE_WEIGHT",
    "NEUTRAL_RATING",
    "RATING_SD",
    "RATING_WEIGHT",
    "SEED_BEST_SHARE",
    "SEED_MEAN_RATING",
    "SEED_WORST_SHARE",
    "Perception",
    "perceive",
]
