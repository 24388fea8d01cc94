"""How a simulated subject answers the post-questionnaire: from what it experienced.

Nothing of the seed's subjective *results* (best / worst shares, mean ratings) is in this
model (issue #25): a subject judges each fixture only by its own measured benefit ``b_c``
(``vasim.study.cohort.measured_benefits``: ``b_c = ln(E_unassisted / E_c)``, E the
subject's mean path deviation without and with fixture c; b > 0: the fixture helped), read
through a stated noise model whose parameters are the scenario's ``[questionnaire]``
assumptions (:class:`vasim.operator.scenario.QuestionnaireModel`)::

    best      = argmax_c (  b_c / tau + G_c  )       G, G' independent standard Gumbel
    worst     = argmax_c ( -b_c / tau + G'_c )
    rating_c  = clip(round( r0 + s b_c + N(0, sd^2) ), min, max)

tau = ``choice_noise`` (the judgement noise in units of b: the choice is a multinomial logit
in b / tau, McFadden 1974), r0 = ``rating_centre`` (a fixture with no measured benefit),
s = ``rating_per_benefit``, sd = ``rating_sd``. With equal benefits every fixture is named
best with probability 1 / n and the ratings share one expectation r0: **with no fixture
effect there is no preference** (the noise in each subject's measured b is all that moves
the answers). How the seed's subjects rated a fixture's comfort or noticeability is not
modelled (it would have to come from their results).

Example:
    >>> import numpy as np
    >>> from vasim.operator.scenario import QuestionnaireModel
    >>> m = QuestionnaireModel(choice_noise=0.1, rating_centre=5.0, rating_per_benefit=10.0,
    ...                        rating_sd=0.0)
    >>> a = perceive({"ff": 0.2, "ms": 0.0}, np.random.default_rng(0), m)
    >>> a["ff"].rating_mean, a["ms"].rating_mean
    (7.0, 5.0)
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from vasim.operator.scenario import QuestionnaireModel


@dataclass(frozen=True)
class Perception:
    """One subject's perception of one fixture.

    Attributes:
        best_utility: utility of naming it best (larger = more likely).
        worst_utility: utility of naming it least useful (larger = more likely).
        rating_mean: the expected rating r0 + s b_c [0-10 points] (before noise).
        rating: the subject's rating before rounding and clipping [points].
    """

    best_utility: float
    worst_utility: float
    rating_mean: float
    rating: float


def perceive(measured: Mapping[str, float], rng: np.random.Generator,
             model: QuestionnaireModel) -> dict[str, Perception]:
    """Draws one subject's perception of each condition (module docstring).

    Args:
        measured: b_c, the subject's measured log benefit per assisted condition (a
            non-finite value counts 0: no benefit measured).
        rng: the subject's random stream.
        model: the scenario's questionnaire model.

    Returns:
        condition -> ``Perception``, in the order of ``measured``.
    """
    conds = list(measured)
    if not conds:
        return {}
    b = np.array([measured[c] if math.isfinite(measured[c]) else 0.0 for c in conds])
    g_best = rng.gumbel(size=len(conds))
    g_worst = rng.gumbel(size=len(conds))
    noise = rng.normal(0.0, 1.0, size=len(conds)) * model.rating_sd
    tau = model.choice_noise
    out = {}
    for i, c in enumerate(conds):
        centre = model.rating_centre + model.rating_per_benefit * float(b[i])
        out[c] = Perception(best_utility=float(b[i]) / tau + float(g_best[i]),
                            worst_utility=-float(b[i]) / tau + float(g_worst[i]),
                            rating_mean=centre, rating=centre + float(noise[i]))
    return out


__all__ = ["Perception", "perceive"]
