"""What one fixture does to the simulated operator (``FixtureEffect``) and how an effect
scale s shrinks or grows it (``scale_effects``).

The values themselves are never written here: they are the declared assumptions of a
scenario file (``protocols/scenarios/*.toml``, :mod:`vasim.operator.scenario`).
:mod:`vasim.operator.learning` states the per-trial equations the fields enter.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

EFFECT_FIELDS: tuple[str, ...] = ("accuracy", "speed", "practice_weight", "carryover",
                                  "dependence")
"""The fields of a ``FixtureEffect`` in declaration order."""


@dataclass(frozen=True)
class FixtureEffect:
    """What one fixture does to the simulated operator (``vasim.operator.learning``).

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

    @property
    def is_null(self) -> bool:
        """True when the fixture changes nothing in the operator (the null effect)."""
        return self == FixtureEffect()


def scale_effect(e: FixtureEffect, s: float) -> FixtureEffect:
    """``e`` with every departure from "no effect" multiplied by ``s`` >= 0: accuracy,
    speed and practice weight ``1 + s (x - 1)``, dependence ``s delta``; the carry-over
    fraction is kept (it is a fraction of the accuracy gain, which the scale already
    shrinks). ``s = 0`` is the null effect, ``s = 1`` ``e`` itself.

    Raises:
        ValueError: ``s`` < 0, or an effect it would make invalid (accuracy <= 0).

    Example:
        >>> scale_effect(FixtureEffect(accuracy=0.6, dependence=0.1), 0.5)
        FixtureEffect(accuracy=0.8, speed=1.0, practice_weight=1.0, carryover=0.0, dependence=0.05)
        >>> scale_effect(FixtureEffect(accuracy=0.6, carryover=0.3), 0.0).is_null
        True
    """
    if not math.isfinite(s) or s < 0:
        raise ValueError(f"effect scale must be a finite number >= 0, got {s!r}")
    if s == 1.0:
        return e
    if s == 0.0:
        return FixtureEffect()
    return FixtureEffect(accuracy=1.0 + s * (e.accuracy - 1.0),
                         speed=1.0 + s * (e.speed - 1.0),
                         practice_weight=1.0 + s * (e.practice_weight - 1.0),
                         carryover=e.carryover, dependence=s * e.dependence)


def scale_effects(effects: Mapping[str, FixtureEffect], s: float) -> dict[str, FixtureEffect]:
    """:func:`scale_effect` of every label (a new dict)."""
    return {k: scale_effect(v, s) for k, v in effects.items()}


__all__ = ["EFFECT_FIELDS", "FixtureEffect", "scale_effect", "scale_effects"]
