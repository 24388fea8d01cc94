"""A protocol's effect sizes for power planning: the optional ``[power]`` table (issue #18,
"effect sizes from the protocol or the command line"). Pure parsing and validation.

Layout (every field optional)::

    [power]
    effect_scale = 0.5                  # [1] x every departure from "no effect"
    [power.effects.ff]                  # by condition label of the protocol
    accuracy = 0.8                      # FixtureEffect fields: accuracy, speed,
    speed = 1.0                         # practice_weight, carryover, dependence

These are the fields of ``vasim study power``'s ``--effect-scale`` and ``--effects FILE``
(the file's tables are the ``[power.effects.*]`` tables here), parsed by the same
:func:`effects_from_tables`.

**Decisions**:

* A ``[power.effects]`` label must be one of the protocol's conditions: the planning values
  of a protocol belong to its conditions, and a misspelt label (``[power.effects.f]``)
  would otherwise be silently unused. The labels of an ``--effects`` file are held to the
  same rule (issue #30; ``vasim.cli.power.check_effects_labels``).
* Precedence (:func:`resolve_effects`): the declared scenario's effects (assumptions)
  (``vasim.operator.learning.DEFAULT_EFFECTS``), then the protocol's ``[power.effects]``
  field by field, then an ``--effects`` file field by field; the scale is
  ``--effect-scale`` if given, else the protocol's ``effect_scale``, else 1. The command
  line always wins, and a field neither names keeps the scenario's value.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from vasim.core.bounds import EFFECT_SCALE
from vasim.core.config import check_keys, check_number, check_table, fail, join
from vasim.core.errors import ConfigError
from vasim.operator.learning import DEFAULT_EFFECTS, FixtureEffect

EFFECT_FIELDS: tuple[str, ...] = ("accuracy", "speed", "practice_weight", "carryover",
                                  "dependence")
"""The fields of an effect table (``FixtureEffect``'s)."""
POWER_KEYS: tuple[str, ...] = ("effect_scale", "effects")
"""The keys of a protocol's ``[power]`` table."""


def effects_from_tables(data: Mapping[str, Any], *, file: str | Path | None = None,
                        prefix: str = "",
                        base: Mapping[str, FixtureEffect] = DEFAULT_EFFECTS
                        ) -> dict[str, FixtureEffect]:
    """``base`` with the effect tables of ``data`` (label -> {field: value}) applied field
    by field; a label ``base`` lacks starts from "no effect" (``FixtureEffect()``).

    Raises:
        ConfigError: naming ``file`` and the field (``{prefix}.ff.accuracy``): a non-table,
            an unknown field, a non-number, or a value ``FixtureEffect`` refuses.

    Example:
        >>> e = effects_from_tables({"ff": {"accuracy": 0.8}})
        >>> e["ff"].accuracy, e["ff"].speed == DEFAULT_EFFECTS["ff"].speed
        (0.8, True)
    """
    out = dict(base)
    for label, table in data.items():
        path = join(prefix, str(label))
        t = check_keys(table, EFFECT_FIELDS, path, file=file)
        values = {k: getattr(out.get(str(label), FixtureEffect()), k) for k in EFFECT_FIELDS}
        for k, v in t.items():
            values[k] = check_number(v, join(path, k), file=file)
        try:
            out[str(label)] = FixtureEffect(**values)
        except ValueError as exc:
            raise ConfigError(str(exc), file=file, field=path) from None
    return out


@dataclass(frozen=True)
class PowerPlan:
    """A protocol's ``[power]`` table (module docstring), validated on construction.

    Attributes:
        effect_scale: the scale s (None: not set, 1 unless the command line sets it).
        effects: label -> {field: value}, the planning effects as written (applied over
            the scenario's effects by :meth:`base_effects`).

    Raises:
        ConfigError: naming the field (``power.effect_scale``, ``power.effects.ff.accuracy``)
            and the value.
    """

    effect_scale: float | None = None
    effects: Mapping[str, Mapping[str, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.effect_scale is not None:
            check_number(self.effect_scale, "power.effect_scale", bound=EFFECT_SCALE)
        tables = check_table(self.effects, "power.effects")
        object.__setattr__(self, "effects", {str(k): dict(check_table(
            v, f"power.effects.{k}")) for k, v in tables.items()})
        self.base_effects()  # every field checked, and the effect it makes

    def base_effects(self, base: Mapping[str, FixtureEffect] = DEFAULT_EFFECTS
                     ) -> dict[str, FixtureEffect]:
        """``base`` with this plan's effect tables applied (before any scale)."""
        return effects_from_tables(self.effects, prefix="power.effects", base=base)

    def check_labels(self, conditions: tuple[str, ...]) -> None:
        """Refuses an effects label that is not one of ``conditions`` (module decision)."""
        for label in self.effects:
            if label not in conditions:
                raise fail(label, f"a condition of the protocol ({', '.join(conditions)})",
                           field=f"power.effects.{label}")


def power_plan_from_table(raw: object) -> PowerPlan:
    """A :class:`PowerPlan` from the parsed ``[power]`` table.

    Raises:
        ConfigError: an unknown key or a bad value, naming the field (the loader adds the
            file).
    """
    t = check_keys(raw, POWER_KEYS, "power")
    return PowerPlan(effect_scale=t.get("effect_scale"), effects=t.get("effects", {}))


def resolve_effects(plan: PowerPlan | None, *, cli_scale: float | None,
                    cli_tables: Mapping[str, Any] | None = None,
                    cli_file: str | Path | None = None,
                    base: Mapping[str, FixtureEffect] = DEFAULT_EFFECTS
                    ) -> tuple[float, dict[str, FixtureEffect]]:
    """The effect scale and the unscaled effects of a power run (module decision's
    precedence: scenario < protocol < command line).

    Args:
        plan: the protocol's ``[power]`` (None: none). cli_scale: ``--effect-scale`` (None:
            not given). cli_tables: the parsed ``--effects`` file (None: none), named
            ``cli_file`` in errors. base: the scenario's effects (declared assumptions).

    Example:
        >>> plan = PowerPlan(effect_scale=0.5, effects={"ff": {"accuracy": 0.8}})
        >>> s, e = resolve_effects(plan, cli_scale=None, cli_tables={"ff": {"speed": 1.0}})
        >>> s, e["ff"].accuracy, e["ff"].speed, e["mag"] == DEFAULT_EFFECTS["mag"]
        (0.5, 0.8, 1.0, True)
        >>> resolve_effects(plan, cli_scale=2.0)[0], resolve_effects(None, cli_scale=None)[0]
        (2.0, 1.0)
    """
    effects = dict(base) if plan is None else plan.base_effects(base)
    if cli_tables is not None:
        effects = effects_from_tables(cli_tables, file=cli_file, base=effects)
    if cli_scale is not None:
        scale = float(cli_scale)
    elif plan is not None and plan.effect_scale is not None:
        scale = float(plan.effect_scale)
    else:
        scale = 1.0
    return scale, effects


__all__ = [
    "EFFECT_FIELDS",
    "POWER_KEYS",
    "PowerPlan",
    "effects_from_tables",
    "power_plan_from_table",
    "resolve_effects",
]
