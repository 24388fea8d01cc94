"""A simulated operator is a declared scenario: one TOML file of assumptions, each sourced.

A scenario file (``protocols/scenarios/NAME.toml``; format and sources in
``docs/simulation.md``) holds every parameter of the synthetic cohort that is not physics:

* ``[fixtures.LABEL]``: what a fixture does to the operator (``FixtureEffect``: accuracy
  and speed factors while assisted, practice weight, carry-over to the VF-free trials,
  guidance dependence), by condition label;
* ``[options]``: ``mechanism_gain`` (the gain the scripted engine runs every fixture's
  mechanism at, 1 = as its schema is written, 0 = none) and ``derive_unlisted`` (whether a
  label the file does not list gets the combination of its fixtures' effects,
  ``vasim.operator.combined``, or none);
* ``[groups.G]``: learning rate (mean, sd) AND asymptote per group, and the laparoscopy
  experience categories with their probability and mean skill: the experience is drawn
  first and the skill from it (``skill ~ Beta`` with that mean), so demographics and skill
  are drawn together;
* ``[questionnaire]``: the answer model (``vasim.operator.questionnaire``);
* ``[outcome]``: the trial-level outcome engine (``vasim.operator.outcome``);
* ``[teleop]`` (a *teleoperation* scenario, for the MRCP study's protocols): the person's
  mode penalties ``thread_time``, ``stdt_noise``, ``camera_cost``
  (``vasim.operator.teleop_profile.TeleopEffects``); all three neutral (1, 0, 0) is the
  mechanism alone. A teleoperation scenario has no ``[fixtures]`` (or an empty table) and
  needs no ``[options]`` or ``[outcome]`` (the fixture and outcome engines do not run its
  trials); a scenario without ``[teleop]`` is a VF scenario. ``vasim study simulate``
  refuses a scenario of the other kind than the protocol's (``vasim.study.cohort
  .check_scenario_kind``).

Every parameter is written ``name = { value = X, source = "..." }``; a missing or empty
source is refused. Nothing of the seed's *results* belongs in a scenario (shares, ratings,
F values, orderings): its sentences about mechanisms may be cited as sources.

**Decision** (groups cross over): the loader refuses a scenario in which the group with
the lower mean skill ends up better than the other at some practice (on the mean
subjects' learnable-noise and movement-time factors, ``kappa lambda_P``, P = 0..1000 and
the asymptote), unless ``[groups] crossover_reason = "..."`` says why.

Example:
    >>> s = load_scenario("seed_plausible")
    >>> s.name, s.effects()["ff"].accuracy, s.effects(0.0)["ff"].is_null
    ('seed_plausible', 0.75, True)
    >>> len(s.sha256), s.source("fixtures.ff.accuracy")[:13]
    (64, 'seed sec. 6.2')
"""

from __future__ import annotations

import hashlib
import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vasim.core.config import (
    check_bool,
    check_choice,
    check_keys,
    check_number,
    check_str,
    check_table,
    expect,
    parse_toml,
    rewrap,
)
from vasim.core.errors import ConfigError
from vasim.core.resources import protocols_dir
from vasim.operator.combined import label_effects
from vasim.operator.effects import EFFECT_FIELDS, FixtureEffect, scale_effects
from vasim.operator.profile import OperatorProfile
from vasim.operator.scripted import SKILL_NOISE, SKILL_TIME
from vasim.operator.teleop_profile import TeleopEffects, scale_teleop

DEFAULT_SCENARIO = "seed_plausible"
"""The scenario ``vasim study simulate`` uses without ``--scenario``."""

GROUP_FIELDS = ("learning_rate_mean", "learning_rate_sd", "asymptote", "skill_concentration")
QUESTIONNAIRE_FIELDS = ("choice_noise", "rating_centre", "rating_per_benefit", "rating_sd")
OUTCOME_FIELDS = ("path_deviation_mm", "subject_sd_log", "trial_sd_log")
OPTION_FIELDS = ("mechanism_gain", "derive_unlisted")
TELEOP_FIELDS = ("thread_time", "stdt_noise", "camera_cost")

_RANGES: dict[str, tuple[float, float]] = {
    "accuracy": (1e-3, 10.0), "speed": (1e-3, 10.0), "practice_weight": (0.0, 10.0),
    "carryover": (0.0, 1.0), "dependence": (0.0, 10.0),
    "learning_rate_mean": (0.0, 2.0), "learning_rate_sd": (0.0, 1.0), "asymptote": (0.0, 1.0),
    "skill_concentration": (0.1, 1e4), "p": (0.0, 1.0), "skill_mean": (1e-3, 1.0 - 1e-3),
    "choice_noise": (1e-6, 100.0), "rating_centre": (-100.0, 100.0),
    "rating_per_benefit": (-1000.0, 1000.0), "rating_sd": (0.0, 100.0),
    "path_deviation_mm": (1e-3, 1e3), "subject_sd_log": (0.0, 5.0), "trial_sd_log": (0.0, 5.0),
    "mechanism_gain": (0.0, 1.0),
    "thread_time": (0.1, 10.0), "stdt_noise": (0.0, 5.0), "camera_cost": (0.0, 5.0),
}


@dataclass(frozen=True)
class Experience:
    """One laparoscopy-experience category of a group: its probability and mean skill."""

    name: str
    p: float
    skill_mean: float


@dataclass(frozen=True)
class GroupModel:
    """How one group's subjects are drawn (module docstring)."""

    name: str
    learning_rate_mean: float
    learning_rate_sd: float
    asymptote: float
    skill_concentration: float
    experience: tuple[Experience, ...]

    @property
    def mean_skill(self) -> float:
        """E[skill] over the experience categories."""
        return sum(e.p * e.skill_mean for e in self.experience)

    def curve(self, practice: np.ndarray) -> np.ndarray:
        """The mean subject's learnable-noise factor ``kappa_N lambda_P`` at ``practice``
        (``vasim.operator.scripted``'s equations with this group's mean skill and rate)."""
        lam = self.asymptote + (1.0 - self.asymptote) * (1.0 + practice) ** (
            -self.learning_rate_mean)
        return (1.0 + SKILL_NOISE * (1.0 - self.mean_skill)) * lam

    def time_curve(self, practice: np.ndarray) -> np.ndarray:
        """The mean subject's movement-time factor ``kappa_T lambda_P``."""
        lam = self.asymptote + (1.0 - self.asymptote) * (1.0 + practice) ** (
            -self.learning_rate_mean)
        return (1.0 + SKILL_TIME * (1.0 - self.mean_skill)) * lam


@dataclass(frozen=True)
class QuestionnaireModel:
    """The answer model's parameters (``vasim.operator.questionnaire``)."""

    choice_noise: float
    rating_centre: float
    rating_per_benefit: float
    rating_sd: float


@dataclass(frozen=True)
class OutcomeModel:
    """The trial-level outcome engine's parameters (``vasim.operator.outcome``)."""

    path_deviation_mm: float
    subject_sd_log: float
    trial_sd_log: float


@dataclass(frozen=True)
class Scenario:
    """A parsed, validated scenario (module docstring).

    Attributes:
        name, description: from the file. text: the file's text (stored with a session).
        sha256: hex digest of ``text`` (UTF-8). fixtures: label -> effect (as declared,
        scale 1). mechanism_gain, derive_unlisted: ``[options]``. groups: name -> model.
        questionnaire, outcome: the models (outcome None in a teleoperation scenario).
        sources: dotted parameter path -> its source. teleop: the mode penalties of a
        teleoperation scenario (None: a VF scenario).
    """

    name: str
    description: str
    text: str
    sha256: str
    fixtures: Mapping[str, FixtureEffect]
    mechanism_gain: float
    derive_unlisted: bool
    groups: Mapping[str, GroupModel]
    questionnaire: QuestionnaireModel
    outcome: OutcomeModel | None
    sources: Mapping[str, str] = field(repr=False)
    crossover_reason: str | None = None
    teleop: TeleopEffects | None = None

    @property
    def kind(self) -> str:
        """``"teleop"`` (it has ``[teleop]``) or ``"vf"``."""
        return "vf" if self.teleop is None else "teleop"

    def teleop_effects(self, scale: float = 1.0) -> TeleopEffects:
        """The mode penalties at effect scale ``scale`` (``scale_teleop``).

        Raises:
            ConfigError: a VF scenario (no ``[teleop]``).
        """
        if self.teleop is None:
            raise ConfigError(f"scenario {self.name!r} is a VF scenario (no [teleop] "
                              "table)", field="teleop")
        return scale_teleop(self.teleop, scale)

    def effects(self, scale: float = 1.0) -> dict[str, FixtureEffect]:
        """The fixture effects at effect scale ``scale`` (``scale_effect``: 0 none)."""
        return scale_effects(self.fixtures, scale)

    def condition_effects(self, components: Mapping[str, tuple[str, ...]],
                          scale: float = 1.0) -> dict[str, FixtureEffect]:
        """The effects of a protocol's labels: the declared ones; a label the file does not
        list gets the combination of its fixtures' effects (``components``: label -> its
        schema's fixture kinds) if ``derive_unlisted``, else none."""
        eff = self.effects(scale)
        return label_effects(components, eff) if self.derive_unlisted else eff

    def mechanism(self, scale: float = 1.0) -> float:
        """The gain factor of every fixture's mechanism in the scripted engine at effect
        scale ``scale``: ``min(1, mechanism_gain x scale)`` (a gain cannot exceed 1)."""
        return min(1.0, self.mechanism_gain * scale)

    def source(self, path: str) -> str:
        """The declared source of a parameter (dotted path, e.g. ``fixtures.ff.accuracy``).

        Raises:
            KeyError: no such parameter.
        """
        return self.sources[path]

    def sample_subject(self, rng: np.random.Generator, group: str
                       ) -> tuple[OperatorProfile, str]:
        """Draws one subject of ``group``: (operator profile, laparoscopy experience).

        The experience category first, then skill ~ Beta(m k, (1 - m) k) (m its mean skill,
        k the group's concentration), learning rate ~ N(mean, sd) clipped to [0.02, 0.6],
        the group's asymptote; the other profile fields as ``OperatorProfile.sample``
        (reaction delay, tremor, noise spreads: physiology, not scenario).

        Raises:
            ConfigError: a group the scenario does not define.
        """
        g = self.groups[check_choice(group, "group", tuple(self.groups))]
        probs = np.array([e.p for e in g.experience])
        exp = g.experience[int(rng.choice(len(probs), p=probs / probs.sum()))]
        k = g.skill_concentration
        skill = float(rng.beta(exp.skill_mean * k, (1.0 - exp.skill_mean) * k))
        alpha = float(np.clip(rng.normal(g.learning_rate_mean, g.learning_rate_sd), 0.02, 0.6))
        base = OperatorProfile.sample(rng, "surgeon" if group == "surgeon" else "resident")
        prof = base.replace(skill=skill, learning_rate=alpha, asymptote=g.asymptote,
                            anticipation=0.75 - 0.25 * skill)
        return prof, exp.name

    def assumed_record(self, scale: float = 1.0) -> dict[str, Any]:
        """The scenario's assumed fixture effects for ``summary.json`` (``assumed_effects``):
        per label the assisted path-deviation ratio (``accuracy`` at the scale) with its
        source, the carry-over, and the scenario's name and hash."""
        eff = self.effects(scale)
        return {"scenario": self.name, "sha256": self.sha256, "effect_scale": scale,
                "mechanism_gain": self.mechanism(scale),
                "quantity": "ratio of assisted to unassisted path deviation at equal "
                            "practice (the operator's noise factor a_c)",
                "fixtures": {k: {"ratio": e.accuracy, "carryover": e.carryover,
                                 "source": self.sources.get(f"fixtures.{k}.accuracy", "")}
                             for k, e in eff.items()}}


# ------------------------------------------------------------------------------ parsing
def _param(table: Mapping[str, Any], key: str, path: str, file: str | None,
           sources: dict[str, str]) -> Any:
    """A ``{ value, source }`` entry: its value (checked by the caller) after the source."""
    full = f"{path}.{key}"
    entry = check_keys(table.get(key), ("value", "source"), full, file=file,
                       required=("value", "source"))
    sources[full] = check_str(entry["source"], f"{full}.source", file=file)
    return entry["value"]


def _num(table: Mapping[str, Any], key: str, path: str, file: str | None,
         sources: dict[str, str]) -> float:
    if key not in table:
        raise ConfigError("got nothing (missing required field), expected { value = X, "
                          "source = \"...\" }", file=file, field=f"{path}.{key}")
    lo, hi = _RANGES[key]
    return check_number(_param(table, key, path, file, sources), f"{path}.{key}.value",
                        ge=lo, le=hi, file=file)


def _group(name: str, t: Mapping[str, Any], file: str | None,
           sources: dict[str, str]) -> GroupModel:
    path = f"groups.{name}"
    t = check_keys(t, (*GROUP_FIELDS, "experience"), path, file=file,
                   required=(*GROUP_FIELDS, "experience"))
    vals = {k: _num(t, k, path, file, sources) for k in GROUP_FIELDS}
    cats = check_table(t["experience"], f"{path}.experience", file=file)
    expect(bool(cats), cats, "at least one experience category", file=file,
           field=f"{path}.experience")
    exps = []
    for cname, ct in cats.items():
        cpath = f"{path}.experience.{cname}"
        ct = check_keys(ct, ("p", "skill_mean"), cpath, file=file, required=("p", "skill_mean"))
        exps.append(Experience(cname, _num(ct, "p", cpath, file, sources),
                               _num(ct, "skill_mean", cpath, file, sources)))
    total = sum(e.p for e in exps)
    expect(math.isclose(total, 1.0, abs_tol=1e-6), total, "probabilities summing to 1",
           file=file, field=f"{path}.experience")
    return GroupModel(name=name, experience=tuple(exps), **vals)


def parse_scenario(text: str, *, file: str | Path | None = None) -> Scenario:
    """Parses and validates a scenario's TOML text (module docstring).

    Raises:
        ConfigError: naming the file, the field and the value.
    """
    f = None if file is None else str(file)
    raw = parse_toml(text, file=f, kind="scenario")
    teleop_raw = raw.get("teleop") if isinstance(raw, Mapping) else None
    is_teleop = teleop_raw is not None
    top = check_keys(raw, ("name", "description", "options", "fixtures", "groups",
                           "questionnaire", "outcome", "teleop"), file=f,
                     required=("name", "groups", "questionnaire") if is_teleop else
                     ("name", "options", "fixtures", "groups", "questionnaire", "outcome"))
    sources: dict[str, str] = {}
    name = check_str(top["name"], "name", file=f)
    desc = check_str(top.get("description", ""), "description", empty=True, file=f)
    teleop = None
    if is_teleop:
        tt = check_keys(top["teleop"], TELEOP_FIELDS, "teleop", file=f,
                        required=TELEOP_FIELDS)
        teleop = TeleopEffects(**{k: _num(tt, k, "teleop", f, sources)
                                  for k in TELEOP_FIELDS})
        fx = check_table(top.get("fixtures", {}), "fixtures", file=f)
        expect(not fx, fx, "no fixture effects in a teleoperation scenario (it has "
               "[teleop]; a VF scenario has none)", file=f, field="fixtures")
    if "options" in top or not is_teleop:
        opts = check_keys(top["options"], OPTION_FIELDS, "options", file=f,
                          required=OPTION_FIELDS)
        mech = _num(opts, "mechanism_gain", "options", f, sources)
        derive = check_bool(_param(opts, "derive_unlisted", "options", f, sources),
                            "options.derive_unlisted.value", file=f)
    else:
        mech, derive = 1.0, False
    fixtures: dict[str, FixtureEffect] = {}
    for label, ft in check_table(top.get("fixtures", {}), "fixtures", file=f).items():
        path = f"fixtures.{label}"
        ft = check_keys(ft, EFFECT_FIELDS, path, file=f, required=EFFECT_FIELDS)
        vals = {k: _num(ft, k, path, f, sources) for k in EFFECT_FIELDS}
        try:
            fixtures[label] = FixtureEffect(**vals)
        except ValueError as exc:
            raise ConfigError(str(exc), file=f, field=path) from None
    gt = check_table(top["groups"], "groups", file=f)
    reason = gt.pop("crossover_reason", None)
    if reason is not None:
        reason = check_str(reason, "groups.crossover_reason", file=f)
    groups = {g: _group(g, t, f, sources) for g, t in gt.items()}
    for needed in ("surgeon", "resident"):
        expect(needed in groups, sorted(groups), f"a [groups.{needed}] table (a required "
               "group)", file=f, field=f"groups.{needed}")
    q = check_keys(top["questionnaire"], QUESTIONNAIRE_FIELDS, "questionnaire", file=f,
                   required=QUESTIONNAIRE_FIELDS)
    outcome = None
    if "outcome" in top:
        o = check_keys(top["outcome"], OUTCOME_FIELDS, "outcome", file=f,
                       required=OUTCOME_FIELDS)
        outcome = OutcomeModel(**{k: _num(o, k, "outcome", f, sources)
                                  for k in OUTCOME_FIELDS})
    sc = Scenario(
        name=name, description=desc, text=text,
        sha256=hashlib.sha256(text.encode("utf-8")).hexdigest(),
        fixtures=fixtures, mechanism_gain=mech, derive_unlisted=derive, groups=groups,
        questionnaire=QuestionnaireModel(**{k: _num(q, k, "questionnaire", f, sources)
                                            for k in QUESTIONNAIRE_FIELDS}),
        outcome=outcome, sources=sources, crossover_reason=reason, teleop=teleop)
    if reason is None:
        check_no_crossover(sc, file=f)
    return sc


def check_no_crossover(sc: Scenario, *, file: str | None = None) -> None:
    """Refuses groups whose mean curves cross (module docstring's decision).

    Raises:
        ConfigError: (field ``groups``) naming the groups and the practice where they cross.
    """
    gs = sorted(sc.groups.values(), key=lambda g: -g.mean_skill)
    p = np.concatenate([np.arange(0.0, 1001.0), [1e12]])
    for better, worse in itertools.pairwise(gs):
        for what, a, b in (("learnable noise", better.curve(p), worse.curve(p)),
                           ("movement time", better.time_curve(p), worse.time_curve(p))):
            cross = np.nonzero(a > b * (1 + 1e-9))[0]
            at = ("" if not cross.size else "the asymptote" if cross[0] == p.size - 1
                  else f"practice {int(p[cross[0]])}")
            expect(not cross.size, worse.name, f"the less experienced group (mean skill "
                   f"{worse.mean_skill:.3f}) not to overtake {better.name!r} (mean skill "
                   f"{better.mean_skill:.3f}); it is better in {what} from {at} (lower its "
                   "learning rate or raise its asymptote, or set groups.crossover_reason)",
                   file=file, field="groups")


def scenario_path(name_or_path: str | Path) -> Path:
    """The file of a scenario: a path to an existing file, or a name in
    ``protocols/scenarios`` (``.toml`` optional).

    Raises:
        ConfigError: (field ``--scenario``) no such file, naming what exists.
    """
    p = Path(name_or_path)
    if p.is_file():
        return p
    folder = protocols_dir() / "scenarios"
    cand = folder / (p.name if p.suffix == ".toml" else f"{p.name}.toml")
    if str(p) == p.name and cand.is_file():
        return cand
    have = sorted(x.stem for x in folder.glob("*.toml")) if folder.is_dir() else []
    raise ConfigError(f"got {str(name_or_path)!r}, expected a scenario file or one of "
                      f"{', '.join(have)} (protocols/scenarios)", field="--scenario")


_CACHE: dict[str, Scenario] = {}


def load_scenario(name_or_path: str | Path = DEFAULT_SCENARIO) -> Scenario:
    """Reads and parses a scenario (:func:`scenario_path`, :func:`parse_scenario`).

    Raises:
        ConfigError: missing or unreadable file, or :func:`parse_scenario`'s errors.
    """
    p = scenario_path(name_or_path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read the scenario: {exc}", file=p,
                          field="--scenario") from None
    return scenario_from_text(text, file=p)


def scenario_from_text(text: str, *, file: str | Path | None = None) -> Scenario:
    """:func:`parse_scenario`, cached by the text's hash (sessions store the text)."""
    key = hashlib.sha256(text.encode("utf-8")).hexdigest()
    sc = _CACHE.get(key)
    if sc is None:
        try:
            sc = _CACHE[key] = parse_scenario(text, file=file)
        except ConfigError as exc:
            raise rewrap(exc, file=file) from None
    return sc


def default_scenario() -> Scenario:
    """The shipped :data:`DEFAULT_SCENARIO`."""
    return load_scenario(DEFAULT_SCENARIO)


__all__ = ["DEFAULT_SCENARIO", "Experience", "GroupModel", "OutcomeModel",
           "QuestionnaireModel", "Scenario", "check_no_crossover", "default_scenario",
           "load_scenario", "parse_scenario", "scenario_from_text", "scenario_path"]
