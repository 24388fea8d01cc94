"""The design of a power run (pure): the subject counts, cohort seeds, effect sizes and the
integration step.

* ``--subjects`` (:func:`parse_subjects`): ``START:STOP:STEP`` (inclusive of STOP when the
  steps land on it, like R's ``seq``), a comma list ``8,12,20`` or one count ``12``.
* Cohort ``k`` (0-based) of size N draws its seed from ``SeedSequence([seed, 9, N, k])``
  (:func:`cohort_seed`): every design point is an independent Monte Carlo sample
  (**Decision**: no common random numbers across N, so each point's standard error is the
  plain binomial one; the price is a noisier curve *shape*).
* Surgeons among N: ``round(N x 31 / 46)`` (the VF study's 31 surgeons of 46, as
  ``vasim study simulate``).
* Effect sizes (:func:`scaled_effects`): the scenario's declared fixture effects
  (``--scenario``, :mod:`vasim.operator.scenario`; one per condition label)
  scaled by ``effect_scale`` s: every departure from "no effect" is multiplied by s,
  ``accuracy = 1 + s (a - 1)``, ``speed = 1 + s (v - 1)``,
  ``practice_weight = 1 + s (w - 1)``, ``dependence = s delta``; the carry-over fraction
  rho is kept (it is a fraction of the accuracy gain, which already scales). s = 1 is the
  scenario as declared, s = 0 a null fixture effect (every fixture like VF-free; the power of the
  fixture tests is then their type-I error), s = 0.5 half the effects. An effects file
  (``--effects FILE.toml``, :func:`parse_effects`) sets single fixtures' effects first;
  the scale then applies to them. A protocol's ``[power]`` table sets both too
  (:mod:`vasim.study.protocol.power`: scenario < protocol < command line). The
  scenario's mechanism gain scales with s as well (``Scenario.mechanism``).
* Integration step (:data:`FULL_DT`, :data:`COARSE_DT`): the 1 kHz control step of every
  stored trial, or the validated coarse planning step (``--coarse``, see
  :data:`COARSE_DT`).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vasim.core.bounds import ALPHA, COHORTS, EFFECT_SCALE, SEED, SUBJECTS
from vasim.core.config import (
    check_choice,
    check_int,
    check_number,
    check_type,
    expect,
    parse_toml,
)
from vasim.core.errors import ConfigError, InputError
from vasim.operator.effects import FixtureEffect, scale_effect
from vasim.operator.learning import DEFAULT_EFFECTS
from vasim.operator.scenario import Scenario
from vasim.study.protocol import Protocol
from vasim.study.protocol.power import EFFECT_FIELDS, effects_from_tables
from vasim.trials.kinds import TELEOPERATION_MODES

FULL_DT = 1e-3
"""The control step of every stored trial [s] (the haptic 1 kHz)."""
COARSE_DT = 2e-3
"""The planning control step [s] (``--coarse``): half the operator, fixture and sample
work per simulated second, the physics unchanged (the abdomen keeps its own 4 ms step,
every 2nd control step).

**Decision**: 2 ms, because it divides the scene's 4 ms physics step (4 ms would step the
physics every control step too, 5 ms would slow the tissue's clock) and it moved the means
least in the validation (``bench/power.py --validate 8``: 48 trials, the six conditions x
seeds 0-7, the same configurations at 1 and 2 ms): the per-trial means of the
rate-normalised cumulative error, latency and path deviation change by -2.0 %, -3.0 % and
-7.1 %, within :data:`COARSE_TOLERANCE` (a 24-trial run at 4 ms: -4.3 %, -5.7 %, -11.8 %).

**Not effect-preserving**: the change is not uniform. VF-free trials move most (-8 %,
-10 %, -17 %), assisted ones little (-3 % to +7 %), so the fixture effects *shrink* at
2 ms (path deviation relative to VF-free: Mag 0.69 -> 0.88, FF 0.85 -> 0.98, AG 0.77 ->
0.84) and the fixture tests' power is **under**-estimated. ``--coarse`` is therefore for
dry runs, grids and the practice effect; plan a fixture effect's N at the full step (the
command prints this warning with every coarse run). The cumulative error e_i (eq. 6.5)
sums over samples and is halved at 2 ms; the RM-ANOVA is invariant to that common factor.
"""
COARSE_TOLERANCE = 0.10
"""Largest relative change of a per-trial measure's mean (rate-normalised cumulative error,
latency, path deviation) over the validation's trials the coarse step may cause (X)."""
COARSE_WARNING = ("coarse 2 ms step: the per-trial means stay within 10 % of the 1 ms step, "
                  "but VF-free trials improve most, so fixture effects shrink and the "
                  "fixture tests' power is underestimated; plan fixture effects at 1 ms")
"""What every coarse run prints (:data:`COARSE_DT`'s finding)."""
SURGEON_SHARE = 31 / 46
"""Surgeons among the subjects (the VF study's 31 of 46)."""

_RANGE = re.compile(r"^\s*(\d+)\s*:\s*(\d+)\s*(?::\s*(\d+)\s*)?$")


def parse_subjects(spec: str) -> tuple[int, ...]:
    """The subject counts of a ``--subjects`` spec (module docstring).

    Args:
        spec: ``"START:STOP:STEP"`` (STEP default 1), ``"8,12,20"`` or ``"12"``.

    Returns:
        The distinct counts, ascending.

    Raises:
        ConfigError: (field ``--subjects``) naming the spec and what was expected: not a
            range or list of integers, a count outside ``SUBJECTS`` or below 2 (an RM-ANOVA
            needs two subjects), START > STOP, STEP < 1, or more than 1000 design points.

    Example:
        >>> parse_subjects("10:60:5")[:3], parse_subjects("10:60:5")[-1]
        ((10, 15, 20), 60)
        >>> parse_subjects("12, 8,8")
        (8, 12)
    """
    arg: dict[str, Any] = {"field": "--subjects", "error": InputError}   # an argument
    check_type(spec, "--subjects", str, "a text START:STOP:STEP or a list N1,N2,...",
               error=InputError)
    m = _RANGE.match(spec)
    if m:
        start, stop = int(m.group(1)), int(m.group(2))
        step = int(m.group(3)) if m.group(3) is not None else 1
        expect(step >= 1, spec, f"a STEP >= 1 (STEP {step})", **arg)
        expect(start <= stop, spec, f"START <= STOP (START {start} > STOP {stop})", **arg)
        points = (stop - start) // step + 1
        expect(points <= 1000, spec, f"at most 1000 design points ({points})", **arg)
        counts = list(range(start, stop + 1, step))
    else:
        parts = [p.strip() for p in spec.split(",")]
        expect(spec.strip() and all(p.isdigit() for p in parts), spec,
                "START:STOP:STEP (e.g. 10:60:5), a comma list of counts (e.g. 8,12,20) or "
                "one count", **arg)
        counts = [int(p) for p in parts]
        expect(len(set(counts)) <= 1000, len(set(counts)), "at most 1000 design points",
                **arg)
    for n in counts:
        check_int(n, bound=SUBJECTS, lo=2, **arg)
    return tuple(sorted(set(counts)))


def cohort_seed(seed: int, n_subjects: int, k: int) -> int:
    """The 63-bit seed of cohort ``k`` of size ``n_subjects`` (module docstring).

    Example:
        >>> cohort_seed(7, 10, 0) == cohort_seed(7, 10, 0) != cohort_seed(7, 10, 1)
        True
    """
    a, b = np.random.SeedSequence([int(seed), 9, int(n_subjects), int(k)]).generate_state(2)
    return ((int(a) << 32) | int(b)) & (2**63 - 1)


def surgeons_for(n_subjects: int) -> int:
    """Surgeons in a cohort of ``n_subjects`` (:data:`SURGEON_SHARE`, rounded).

    >>> surgeons_for(46), surgeons_for(10)
    (31, 7)
    """
    return round(n_subjects * SURGEON_SHARE)


def scaled_effects(scale: float, base: Mapping[str, FixtureEffect] = DEFAULT_EFFECTS
                   ) -> dict[str, FixtureEffect]:
    """The fixture effects with every departure from "no effect" times ``scale``.

    Args:
        scale: s >= 0 (module docstring). base: the effects to scale (the scenario's).

    Raises:
        ConfigError: s outside ``EFFECT_SCALE`` or an effect it would make invalid
            (e.g. an accuracy factor <= 0).

    Example:
        >>> e = scaled_effects(0.5)["ff"]   # seed_plausible: FF accuracy 0.75
        >>> round(e.accuracy, 3), round(e.speed, 3), round(e.dependence, 3)
        (0.875, 1.0, 0.0)
        >>> scaled_effects(0.0)["ff"].accuracy
        1.0
    """
    s = check_number(scale, "--effect-scale", bound=EFFECT_SCALE)
    out = {}
    for name, e in base.items():
        try:
            out[name] = scale_effect(e, s)
        except ValueError as exc:
            raise ConfigError(f"got {s!r}: fixture {name!r} would get an invalid effect "
                              f"({exc})", field="--effect-scale") from None
    return out


def check_power_protocol(protocol: Protocol) -> None:
    """Refuses a protocol without the VF study's factors: the primary tests need a fixture
    condition and VF-free probe trials (a teleoperation-mode study has neither).

    Raises:
        ConfigError: (field ``--protocol``) naming the protocol and what it lacks.
    """
    conds = {b.condition for b in protocol.blocks}
    vf = conds - set(TELEOPERATION_MODES)
    expect(vf - {"none"}, protocol.name, "a protocol with a virtual-fixture condition (this "
           f"one has no virtual-fixture condition; conditions: {', '.join(sorted(conds))}): "
           "power planning covers the VF study's fixture and practice tests",
           field="--protocol")
    expect(any(b.probe or b.probes_after > 0 for b in protocol.blocks), protocol.name,
           "a protocol with VF-free (probe) trials (the fixture and practice tests need one)",
           field="--protocol")


def parse_effects(text: str, *, file: str | Path | None = None,
                  base: Mapping[str, FixtureEffect] = DEFAULT_EFFECTS) -> dict[str, FixtureEffect]:
    """Fixture effects from an effects file (``--effects FILE.toml``): one table per
    condition label, any of :data:`EFFECT_FIELDS`; a field left out keeps ``base``'s (the
    scenario's), a label ``base`` lacks starts from "no effect".

    Example file::

        [ff]            # what if FF removed 20 % of the error instead of 40 %?
        accuracy = 0.8
        [mag]
        speed = 0.9

    Raises:
        ConfigError: naming the file and the field (``ff.accuracy``): invalid TOML, a
            non-table, an unknown field, or a value ``FixtureEffect`` refuses.

    Example:
        >>> e = parse_effects("[ff]\\naccuracy = 0.8\\n")
        >>> e["ff"].accuracy, e["ff"].speed == DEFAULT_EFFECTS["ff"].speed, e["mag"].speed
        (0.8, True, 1.0)
    """
    return effects_from_tables(parse_toml(text, file=file, kind="effects"), file=file,
                               base=base)


def load_effects(path: str | Path, base: Mapping[str, FixtureEffect] = DEFAULT_EFFECTS
                 ) -> dict[str, FixtureEffect]:
    """:func:`parse_effects` of a file, applied over ``base``.

    Raises:
        ConfigError: the file cannot be read, or :func:`parse_effects`'s errors.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the effects file: {exc}", file=p,
                         field="--effects") from None
    return parse_effects(text, file=p, base=base)


@dataclass(frozen=True)
class PowerDesign:
    """What a power run simulates and how it decides (validated on construction).

    Attributes:
        subjects: the subject counts N (``parse_subjects``). cohorts: Monte Carlo cohorts
            per N. seed: base seed (``cohort_seed``). effect_scale: s of
            ``scaled_effects``. alpha: significance level. dt: control step [s]
            (:data:`FULL_DT` or :data:`COARSE_DT`). max_trial_time: trial time limit [s]
            (None: the protocol's). p_column: the p-value a test rejects on, ``"p_gg"``
            (Greenhouse-Geisser) or ``"p_unc"``. base_effects: the fixture effects before
            scaling (the scenario's, or an effects file's over them, :func:`load_effects`).
        scenario: the declared scenario the cohorts' subjects, groups and fixture
            mechanisms come from (None: the shipped default, ``seed_plausible``).
        effects: ``scaled_effects(effect_scale, base_effects)``: what the operator gets.

    **Decision**: a test rejects when its Greenhouse-Geisser p < alpha (``p_column``
    default ``"p_gg"``), because the report prints p_gg beside every F and sphericity
    rarely holds over 6 fixture or 8 probe levels; ``--p uncorrected`` plans for the
    uncorrected p instead. A test that could not be computed in a cohort counts as not
    rejected (and is counted in ``not_computed``).
    """

    subjects: tuple[int, ...]
    cohorts: int
    seed: int = 7
    effect_scale: float = 1.0
    alpha: float = 0.05
    dt: float = FULL_DT
    max_trial_time: float | None = None
    p_column: str = "p_gg"
    base_effects: Mapping[str, FixtureEffect] = field(default_factory=lambda: DEFAULT_EFFECTS)
    scenario: Scenario | None = None
    effects: dict[str, FixtureEffect] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        expect(self.subjects, self.subjects, "at least one subject count", field="--subjects")
        for n in self.subjects:
            check_int(n, "--subjects", bound=SUBJECTS, lo=2)
        check_int(self.cohorts, "--cohorts", bound=COHORTS)
        check_int(self.seed, "--seed", bound=SEED)
        check_number(self.alpha, "--alpha", bound=ALPHA)
        expect(self.dt in (FULL_DT, COARSE_DT), self.dt,
                f"{FULL_DT} (full) or {COARSE_DT} (coarse, validated) s", field="dt")
        check_choice(self.p_column, "--p", ("p_gg", "p_unc"))
        if self.max_trial_time is not None:
            check_number(self.max_trial_time, "--max-time", gt=0)
        object.__setattr__(self, "effects",
                           scaled_effects(self.effect_scale, self.base_effects))

    @property
    def n_cohorts(self) -> int:
        """Cohorts of the whole run (every N)."""
        return self.cohorts * len(self.subjects)


__all__ = [
    "COARSE_DT",
    "COARSE_TOLERANCE",
    "COARSE_WARNING",
    "EFFECT_FIELDS",
    "FULL_DT",
    "SURGEON_SHARE",
    "PowerDesign",
    "check_power_protocol",
    "cohort_seed",
    "load_effects",
    "parse_effects",
    "parse_subjects",
    "scaled_effects",
    "surgeons_for",
]
