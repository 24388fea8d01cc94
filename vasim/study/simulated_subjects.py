"""The synthetic subjects of a simulated cohort (``vasim.study.cohort``): their codes,
groups and operator profiles, their demographics, their questionnaire answers and the
benefits they measured, each drawn from its own seeded stream (split from ``cohort`` to keep
modules small; what is drawn and from which stream is unchanged).

The demographic model and the answer rules are declared assumptions of the synthetic
cohort (see ``vasim.study.cohort``'s docstring and docs/simulation.md), not data.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from vasim.core.bounds import SEED
from vasim.core.config import check_choice, check_int
from vasim.operator.questionnaire import Perception, perceive
from vasim.operator.scenario import QuestionnaireModel, Scenario, default_scenario
from vasim.operator.scripted import OperatorProfile
from vasim.study.protocol import Protocol, QuestionItem
from vasim.study.store import Demographics

DEMOGRAPHIC_MODEL: dict[str, dict[str, tuple[tuple[str, ...], tuple[float, ...]]]] = {
    "surgeon": {
        "specialisation": (("general_surgery", "gynaecology", "urology", "other"),
                           (0.6, 0.15, 0.15, 0.1)),
        "simulator_experience": (("none", "occasional", "regular"), (0.4, 0.5, 0.1)),
        "robotic_experience": (("none", "observed", "assisted", "performed"),
                               (0.6, 0.2, 0.1, 0.1)),
    },
    "resident": {
        "specialisation": (("general_surgery", "gynaecology", "urology", "other"),
                           (0.6, 0.15, 0.15, 0.1)),
        "simulator_experience": (("none", "occasional", "regular"), (0.3, 0.5, 0.2)),
        "robotic_experience": (("none", "observed", "assisted"), (0.7, 0.25, 0.05)),
    },
}
"""Group -> demographic field -> (values, probabilities) (module docstring)."""

PROPOSALS_P = (0.2, 0.5, 0.3)
"""Probabilities of proposing 0, 1, 2 schemas."""
LIKERT_MEAN, LIKERT_SD = 3.5, 1.0
"""Normal model of a Likert answer before rounding and clipping to 1..5."""

SUBJECT_PREFIX = "SIM"


@dataclass(frozen=True)
class SimulatedSubject:
    """One synthetic subject.

    Attributes:
        number: 1-based subject number j. code: subject code (``SIM001``...).
        group: ``"surgeon"`` or ``"resident"``. profile: the scripted operator.
        demographics: the pre-questionnaire's demographics. session_seed: schedule seed.
    """

    number: int
    code: str
    group: str
    profile: OperatorProfile
    demographics: Demographics
    session_seed: int


def subject_stream(seed: int, *key: int) -> np.random.Generator:
    """The random stream of one (seed, key...) of a simulated cohort (numpy SeedSequence)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), *key]))


def _seed63(seed: int, *key: int) -> int:
    a, b = np.random.SeedSequence([int(seed), *key]).generate_state(2)
    return ((int(a) << 32) | int(b)) & (2**63 - 1)


def draw_demographics(rng: np.random.Generator, group: str,
                      laparoscopy_experience: str | None = None) -> Demographics:
    """Demographics of one simulated subject of ``group`` (``DEMOGRAPHIC_MODEL``), with
    its ``laparoscopy_experience`` (drawn with the skill, ``Scenario.sample_subject``;
    None: drawn here from the default scenario's group).

    Raises:
        ConfigError: unknown group.
    """
    check_choice(group, "group", tuple(DEMOGRAPHIC_MODEL))
    if laparoscopy_experience is None:
        laparoscopy_experience = default_scenario().sample_subject(rng, group)[1]
    values = {"group": group, "laparoscopy_experience": laparoscopy_experience}
    for name, (opts, probs) in DEMOGRAPHIC_MODEL[group].items():
        values[name] = opts[int(rng.choice(len(opts), p=probs))]
    return Demographics.from_mapping(values)


LATIN_PERIOD = 720_720
"""lcm(1..16): a latin-square row count R up to 16 (a Williams square of up to 8 blocks)
divides it."""


def counterbalanced_seed(seed: int, j: int) -> int:
    """A random 63-bit session seed congruent to ``j - 1`` modulo :data:`LATIN_PERIOD`.

    **Decision**: ``block_order = "latin_square"`` takes row ``seed % R`` and asks for
    consecutive subjects on consecutive seeds; random session seeds would pick rows at
    random (10 subjects used 6 of 10 rows). With this seed subject ``j`` gets row
    ``(j - 1) % R``: every R consecutive subjects cover the square once.

    Example:
        >>> [counterbalanced_seed(_seed63(7, 6, j), j) % 10 for j in range(1, 13)]
        [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 0, 1]
    """
    base = seed - seed % LATIN_PERIOD
    if base + LATIN_PERIOD > 2**63 - 1:
        base -= LATIN_PERIOD
    return base + (j - 1) % LATIN_PERIOD


def cohort_subjects(n_subjects: int, n_surgeons: int, seed: int, *,
                    prefix: str = SUBJECT_PREFIX,
                    latin_square: bool = False,
                    scenario: Scenario | None = None) -> list[SimulatedSubject]:
    """The cohort's subjects (a pure function of its arguments; module docstring).
    ``latin_square``: session seeds that give subject j latin-square row j - 1
    (:func:`counterbalanced_seed`). ``scenario``: the group models (None: the default)."""
    sc = scenario or default_scenario()
    return _cohort_subjects(n_subjects, n_surgeons, seed, prefix, latin_square, sc)


def _cohort_subjects(n_subjects: int, n_surgeons: int, seed: int, prefix: str,
                     latin_square: bool, sc: Scenario) -> list[SimulatedSubject]:
    """:func:`cohort_subjects`'s body.

    Raises:
        ConfigError: counts out of range.

    Example:
        >>> s = cohort_subjects(4, 3, seed=7)
        >>> [x.code for x in s], sorted(x.group for x in s).count("surgeon")
        (['SIM001', 'SIM002', 'SIM003', 'SIM004'], 3)
    """
    check_int(n_subjects, "subjects", lo=1)
    check_int(n_surgeons, "surgeons", lo=0, hi=n_subjects)
    check_int(seed, "seed", bound=SEED)
    groups = ["surgeon"] * n_surgeons + ["resident"] * (n_subjects - n_surgeons)
    order = subject_stream(seed, 4).permutation(n_subjects).tolist()
    width = max(3, len(str(n_subjects)))
    out = []
    for j in range(1, n_subjects + 1):
        group = groups[order[j - 1]]
        rng = subject_stream(seed, 5, j)
        profile, lap = sc.sample_subject(rng, group)
        session_seed = _seed63(seed, 6, j)
        if latin_square:
            session_seed = counterbalanced_seed(session_seed, j)
        out.append(SimulatedSubject(
            number=j, code=f"{prefix}{j:0{width}d}", group=group, profile=profile,
            demographics=draw_demographics(rng, group, lap), session_seed=session_seed))
    return out


# ------------------------------------------------------------------------ questionnaires
def _item_answer(item: QuestionItem, rng: np.random.Generator,
                 perceived: Mapping[str, Perception]) -> Any:
    """A simulated answer to one item (module docstring); None = left unanswered."""
    t = item.type
    if t == "choice":
        return item.options[int(rng.integers(len(item.options)))]
    if t == "integer":
        return int(rng.integers(item.min, item.max + 1))
    if t == "likert":
        return int(np.clip(round(rng.normal(LIKERT_MEAN, LIKERT_SD)), 1, 5))
    if t == "text":
        return "" if item.required else None
    conds = list(item.conditions)
    p = {c: perceived[c] for c in conds}
    ranked = sorted(conds, key=lambda c: -p[c].best_utility)
    if t == "condition_choice":
        if item.select == "best":
            return ranked[0]
        if item.select == "worst":
            return max(conds, key=lambda c: p[c].worst_utility)
        return conds[int(rng.integers(len(conds)))]
    if t == "condition_rating":
        return {c: int(np.clip(round(p[c].rating), item.min, item.max)) for c in conds}
    # condition_sets
    k = int(rng.choice(len(PROPOSALS_P), p=PROPOSALS_P))
    out = []
    for m in range(1, min(k, item.max_entries) + 1):
        size = item.min_size + m - 1
        if size > len(ranked):
            break
        out.append(ranked[:size])
    return out if out or not item.required else [ranked[:item.min_size]]


def simulated_answers(protocol: Protocol, questionnaire: str, rng: np.random.Generator, *,
                      demographics: Demographics | None = None,
                      measured: Mapping[str, float] | None = None,
                      model: QuestionnaireModel | None = None) -> dict[str, Any]:
    """A simulated subject's answers to one questionnaire (module docstring's models).

    Args:
        protocol: the protocol. questionnaire: "pre" or "post". rng: the subject's stream.
        demographics: the subject's demographics (asked in "pre").
        measured: measured benefit b_c per condition (``measured_benefits``; missing
            conditions count 0), from which each condition's ``Perception`` is drawn once
            per questionnaire (``vasim.operator.questionnaire.perceive``).
        model: the scenario's questionnaire model (None: the default scenario's).
    """
    q = getattr(protocol, questionnaire)
    out: dict[str, Any] = {}
    if q.demographics and demographics is not None:
        d = demographics
        out.update(group=d.group, specialisation=d.specialisation,
                   laparoscopy_experience=d.laparoscopy_experience,
                   simulator_experience=d.simulator_experience,
                   robotic_experience=d.robotic_experience)
    conds = list(dict.fromkeys(c for item in q.items for c in item.conditions))
    perceived = perceive({c: (measured or {}).get(c, 0.0) for c in conds}, rng,
                         model or default_scenario().questionnaire)
    for item in q.items:
        a = _item_answer(item, rng, perceived)
        if a is not None:
            out[item.id] = a
    return out


def measured_benefits(schedule: pd.DataFrame, errors: Mapping[int, float]) -> dict[str, float]:
    """b_c = ln(E_probe / E_c) per assisted condition of one session.

    Args:
        schedule: the session's ``TrialStore.schedule`` frame. errors: trial id -> its
            error measure (``path_dev_mean_mm`` [mm], or ``total_error_l1``).

    Returns:
        condition -> b_c (0 where a mean is missing or not positive).

    Example:
        >>> sched = pd.DataFrame({"condition": ["none", "ff", "ff"], "probe": [True, False,
        ...                       False], "trial_id": [1, 2, 3]})
        >>> round(measured_benefits(sched, {1: 2.0, 2: 1.0, 3: 1.0})["ff"], 6)
        0.693147
    """
    def mean_error(rows: pd.DataFrame) -> float:
        vals = [errors[int(t)] for t in rows["trial_id"] if not pd.isna(t) and int(t) in errors]
        vals = [v for v in vals if math.isfinite(v)]
        return float(np.mean(vals)) if vals else math.nan

    probe = mean_error(schedule[schedule["probe"].astype(bool)])
    out = {}
    assisted = schedule[~schedule["probe"].astype(bool)]
    for cond, rows in assisted.groupby("condition", sort=False):
        e = mean_error(rows)
        ok = probe > 0 and e > 0 and math.isfinite(probe) and math.isfinite(e)
        out[str(cond)] = math.log(probe / e) if ok else 0.0
    return out


__all__ = ["DEMOGRAPHIC_MODEL", "LATIN_PERIOD", "PROPOSALS_P", "SUBJECT_PREFIX", "SimulatedSubject",
           "cohort_subjects", "counterbalanced_seed", "draw_demographics", "measured_benefits",
           "simulated_answers", "subject_stream"]
