"""Study protocols are data: TOML files under ``protocols/studies/`` (spec/study.md §1).

A protocol names the task, its blocks of trials (condition, trajectory variants,
repetitions, fixture-free probe trials), how block order and variant order are randomised,
and the questionnaires before and after the session. ``load_protocol`` parses a file once
into frozen dataclasses, validated on load: an unknown key, a wrong type, an unknown schema,
a variant out of range, an empty block... raise ``ConfigError`` naming the file, the dotted
field path (``blocks[2].condition``) and the value. ``generate_schedule(protocol, seed)`` is
a pure function from a protocol and a seed to the list of scheduled trials; a session stores
the seed *and* the realised schedule (the store's ``scheduled_trials``), and a resumed
session replays the stored schedule, never recomputing it.

TOML layout (every field is checked; defaults in brackets)::

    name = "vf_learning_curve"          # required: letters, digits, '_', '-', '.'
    description = "one line"            # required
    task = "trajectory"                 # required: "trajectory" | "point"
    reach_radius_m = 0.005              # [0.005] r_reach: the goal advances at |x - p_i| <= r
    max_trial_time_s = 180.0            # [180] simulated time limit of one trial [s]
    excessive_force_n = 2.0             # [2.0] threshold of the excessive-force metrics [N]
    path_tolerance_m = 0.002            # [0.002] tolerance tube of path_dev_out_frac [m]
    poi_spacing_m = 0.0105              # [task default] arc length between trajectory POIs [m]

    [randomisation]
    block_order = "random"              # ["fixed"] | "random" | "latin_square"
    variant_order = "random"            # ["fixed"] | "random"

    [probe]                             # the fixture-free probe trials (learning curve)
    condition = "none"                  # ["none"] a schema without fixtures
    variant = 0                         # [0] all probe trials use this trajectory

    [[blocks]]                          # at least one; run in file order unless randomised
    name = "baseline"                   # required, unique
    condition = "none"                  # required: a schema name (protocols/schemas) or, in
                                        # the MRCP protocols, a mode "stdt"|"mrcp"|"mrcp_cam"
    variants = [0]                      # [[0]] trajectory variants (0..6; point task: 0)
    repetitions = 3                     # [1] every variant this many times
    probe = true                        # [false] these trials are probe trials
    counterbalance = false              # [true] takes part in the block-order randomisation
    probes_after = 0                    # [0] probe trials appended after the block's trials
    schema = "vg_seed"                  # [condition] the schema run, when the condition is
                                        # a label for another schema of the same fixture

    [questionnaires.pre]
    demographics = true                 # [false] group, specialisation, experience levels
    [[questionnaires.pre.items]]        # further items (same layout as post)

    [[questionnaires.post.items]]
    id = "best_vf"                      # required identifier, unique per questionnaire
    type = "condition_choice"           # required, see ITEM_TYPES
    prompt = "Which fixture helped most?"   # required
    required = true                     # [true]
    select = "best"                     # condition_choice: "best" | "worst" (what is asked)
    conditions = ["vg", "ag"]           # condition_*: [the protocol's assisted conditions]
    options = ["a", "b"]                # choice: required
    min = 0                             # integer / condition_rating: [0]
    max = 10                            # integer / condition_rating: [10]
    anchors = ["...", ..., "..."]       # likert: [none] five labels
    max_entries = 3                     # condition_sets: [3] proposals at most
    min_size = 2                        # condition_sets: [2] conditions per proposal
    max_length = 2000                   # text: [2000] characters

Item types (``ITEM_TYPES``): ``choice`` (one of ``options``), ``text`` (free text, stored as
given), ``integer`` (in [min, max]), ``likert`` (five-point, 1..5), ``condition_choice``
(one of ``conditions``: best / worst fixture), ``condition_rating`` (an integer in
[min, max] per condition: the 0-10 rating of each fixture), ``condition_sets`` (up to
``max_entries`` sets of >= ``min_size`` conditions: proposed schemas).

Schedule rules (**decisions**):

* Blocks with ``counterbalance = false`` keep their position in the file; the others are
  permuted among the positions they occupy: ``"fixed"`` keeps the file order, ``"random"``
  draws a uniform permutation per subject from the seed, ``"latin_square"`` takes row
  ``seed mod R`` of a Williams balanced Latin square (R = n rows for an even number n of
  counterbalanced blocks, 2n for odd n; each block appears once in every position and
  follows every other block equally often over R consecutive rows: give a cohort
  consecutive seeds).
* Within a block the trials are ``repetitions`` rounds over ``variants``; ``"random"``
  shuffles each round independently (every variant once before any twice), ``"fixed"``
  keeps the listed order. ``probes_after`` probe trials (``probe.condition`` on
  ``probe.variant``) follow the block's trials.
* Randomness: ``numpy.random.default_rng(SeedSequence([seed, stream, block]))``, one stream
  for the block order and one per block for its variants. numpy does not promise the same
  stream across versions: the realised schedule is what is stored and replayed.
* Probe trials are numbered 1, 2, ... in schedule order (``probe_index``: the VF study's
  8-level "trial" factor).

Example:
    >>> p = load_protocol("vf_learning_curve")
    >>> s = generate_schedule(p, seed=7)
    >>> len(s), sum(t.probe for t in s), {t.variant for t in s if t.probe}
    (38, 8, {0})
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cache
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd

from vasim.core.errors import ConfigError
from vasim.core.resources import available_files, data_file, read_data_file, studies_dir
from vasim.study.store import DEMOGRAPHIC_FIELDS, Demographics
from vasim.trials.kinds import TELEOPERATION_MODES, check_trial_time

TaskKind = Literal["trajectory", "point"]
TASKS: tuple[str, ...] = ("trajectory", "point")
BLOCK_ORDERS: tuple[str, ...] = ("fixed", "random", "latin_square")
VARIANT_ORDERS: tuple[str, ...] = ("fixed", "random")
ITEM_TYPES: tuple[str, ...] = ("choice", "text", "integer", "likert", "condition_choice",
                               "condition_rating", "condition_sets")
N_VARIANTS = {"trajectory": 7, "point": 1}
"""Variants per task: the trajectory's original + six mirrored/rotated; one point task."""
LIKERT_POINTS = 5

_NAME_RE = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")  # fullmatch: no trailing "\n"
_ID_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")  # fullmatch


# ---------------------------------------------------------------------------- checks
def _is_int(v: object) -> bool:
    return isinstance(v, int | np.integer) and not isinstance(v, bool)


def _check_str(v: object, name: str, *, one_line: bool = True, empty: bool = False) -> None:
    if not isinstance(v, str) or (not empty and not v) or (one_line and "\n" in v):
        what = "a one-line string" if one_line else "a string"
        raise ConfigError(f"must be {what}{'' if empty else ' (not empty)'}, got {v!r}",
                          field=name)


def _check_int(v: object, name: str, lo: int | None = None, hi: int | None = None) -> None:
    if not _is_int(v):
        raise ConfigError(f"must be an integer, got {v!r}", field=name)
    if (lo is not None and v < lo) or (hi is not None and v > hi):  # type: ignore[operator]
        rng = f"[{lo if lo is not None else '-inf'}, {hi if hi is not None else 'inf'}]"
        raise ConfigError(f"must be an integer in {rng}, got {v!r}", field=name)


def _check_bool(v: object, name: str) -> None:
    if not isinstance(v, bool):
        raise ConfigError(f"must be true or false, got {v!r}", field=name)


def _check_choice(v: object, name: str, choices: Sequence[str]) -> None:
    if not isinstance(v, str) or v not in choices:
        raise ConfigError(f"must be one of {', '.join(map(repr, choices))}, got {v!r}",
                          field=name)


def _check_positive(v: object, name: str) -> None:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) \
            or not v > 0:
        raise ConfigError(f"must be a finite number > 0, got {v!r}", field=name)


def _check_str_tuple(v: object, name: str, *, unique: bool = True, empty: bool = False,
                     ) -> None:
    if not isinstance(v, tuple):
        raise ConfigError(f"must be an array of strings, got {v!r}", field=name)
    if not empty and not v:
        raise ConfigError("must not be empty", field=name)
    for i, x in enumerate(v):
        _check_str(x, f"{name}[{i}]")
    if unique and len(set(v)) != len(v):
        dup = next(x for x in v if v.count(x) > 1)
        raise ConfigError(f"must not repeat a value, got {dup!r} twice", field=name)


def _prefixed(exc: ConfigError, prefix: str, source: str | None) -> ConfigError:
    """``exc`` with its field under ``prefix`` and the file named."""
    f = f"{prefix}.{exc.field}" if prefix and exc.field else (prefix or exc.field)
    return ConfigError(exc.reason, file=source if source is not None else exc.file, field=f)


# ------------------------------------------------------------------------ dataclasses
@dataclass(frozen=True)
class QuestionItem:
    """One questionnaire item (see the module docstring for the types and fields).

    Attributes:
        id: identifier, unique within its questionnaire (the ``answers.item`` value).
        type: one of ``ITEM_TYPES``. prompt: the question shown. required: must be answered.
        options: ``choice`` options. conditions: ``condition_*`` conditions (filled with the
            protocol's assisted conditions when not given). select: ``condition_choice``:
            ``"best"``, ``"worst"`` or None. min, max: ``integer`` / ``condition_rating``
            range. anchors: ``likert`` labels of 1..5 (or empty). max_entries, min_size:
            ``condition_sets`` limits. max_length: ``text`` limit [characters].
    """

    id: str
    type: str
    prompt: str
    required: bool = True
    options: tuple[str, ...] = ()
    conditions: tuple[str, ...] = ()
    select: str | None = None
    min: int = 0
    max: int = 10
    anchors: tuple[str, ...] = ()
    max_entries: int = 3
    min_size: int = 2
    max_length: int = 2000

    def __post_init__(self) -> None:
        if not isinstance(self.id, str) or not _ID_RE.fullmatch(self.id):
            raise ConfigError(f"must be an identifier (letters, digits, '_'), got {self.id!r}",
                              field="id")
        _check_choice(self.type, "type", ITEM_TYPES)
        _check_str(self.prompt, "prompt")
        _check_bool(self.required, "required")
        _check_str_tuple(self.options, "options", empty=True)
        _check_str_tuple(self.conditions, "conditions", empty=True)
        _check_str_tuple(self.anchors, "anchors", unique=False, empty=True)
        for name in ("min", "max", "max_entries", "min_size", "max_length"):
            _check_int(getattr(self, name), name)
        t = self.type
        if t == "choice" and len(self.options) < 2:
            raise ConfigError(f"a choice item needs at least 2 options, got {self.options!r}",
                              field="options")
        if t != "choice" and self.options:
            raise ConfigError(f"only choice items have options (this is {t!r})",
                              field="options")
        if self.select is not None:
            if t != "condition_choice":
                raise ConfigError(f"only condition_choice items have select (this is {t!r})",
                                  field="select")
            _check_choice(self.select, "select", ("best", "worst"))
        if t in ("integer", "condition_rating") and self.min >= self.max:
            raise ConfigError(f"min must be < max, got min={self.min!r}, max={self.max!r}",
                              field="max")
        if t == "likert" and self.anchors and len(self.anchors) != LIKERT_POINTS:
            raise ConfigError(f"a likert item has {LIKERT_POINTS} anchors, got "
                              f"{len(self.anchors)}", field="anchors")
        if t == "condition_sets":
            _check_int(self.max_entries, "max_entries", 1, 20)
            _check_int(self.min_size, "min_size", 1)
        _check_int(self.max_length, "max_length", 1, 100_000)

    @property
    def numeric(self) -> bool:
        """Whether the answers are numbers (integer, likert, condition_rating)."""
        return self.type in ("integer", "likert", "condition_rating")


@dataclass(frozen=True)
class Questionnaire:
    """A questionnaire: the standard demographics (pre only) and further items.

    Attributes:
        demographics: ask the demographic fields of ``vasim.study.store.DEMOGRAPHIC_FIELDS``
            (group, specialisation, laparoscopy / simulator / robotic experience).
        items: the other items, in order.
    """

    demographics: bool = False
    items: tuple[QuestionItem, ...] = ()

    def __post_init__(self) -> None:
        _check_bool(self.demographics, "demographics")
        if not isinstance(self.items, tuple) or not all(
                isinstance(i, QuestionItem) for i in self.items):
            raise ConfigError(f"must be a tuple of QuestionItem, got {self.items!r}",
                              field="items")
        seen: set[str] = set()
        for k, item in enumerate(self.items):
            if item.id in seen:
                raise ConfigError(f"duplicate item id {item.id!r}", field=f"items[{k}].id")
            if self.demographics and item.id in DEMOGRAPHIC_FIELDS:
                raise ConfigError(f"item id {item.id!r} is a demographic field (asked by "
                                  "demographics = true)", field=f"items[{k}].id")
            seen.add(item.id)

    @property
    def empty(self) -> bool:
        return not self.demographics and not self.items


@dataclass(frozen=True)
class Block:
    """A block of trials under one condition (see the module docstring).

    Attributes:
        name: unique block name. condition: schema name or teleoperation mode; the label
            questionnaires and analyses use.
        schema: the schema file the block runs, when it is not the condition's own (e.g.
            condition ``"vg"`` run as ``"vg_seed"``, the arrow the seed's subjects saw);
            None: the condition.
        variants: trajectory variants, in listed order. repetitions: rounds over variants.
        probe: the block's own trials are probe (fixture-free) trials.
        counterbalance: takes part in the block-order randomisation.
        probes_after: probe trials appended after the block's trials.
    """

    name: str
    condition: str
    variants: tuple[int, ...] = (0,)
    repetitions: int = 1
    probe: bool = False
    counterbalance: bool = True
    probes_after: int = 0
    schema: str | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME_RE.fullmatch(self.name):
            raise ConfigError(f"must be a name of letters, digits, '_', '-', '.', got "
                              f"{self.name!r}", field="name")
        _check_str(self.condition, "condition")
        if not isinstance(self.variants, tuple):
            raise ConfigError(f"must be an array of integers, got {self.variants!r}",
                              field="variants")
        if not self.variants:
            raise ConfigError("must list at least one variant (an empty block)",
                              field="variants")
        for i, v in enumerate(self.variants):
            _check_int(v, f"variants[{i}]", 0)
        if len(set(self.variants)) != len(self.variants):
            raise ConfigError(f"must not repeat a variant (use repetitions), got "
                              f"{list(self.variants)!r}", field="variants")
        _check_int(self.repetitions, "repetitions", 1, 1000)
        _check_bool(self.probe, "probe")
        _check_bool(self.counterbalance, "counterbalance")
        _check_int(self.probes_after, "probes_after", 0, 1000)
        if self.schema is not None:
            _check_str(self.schema, "schema")

    @property
    def n_trials(self) -> int:
        """Trials of the block, appended probes included."""
        return len(self.variants) * self.repetitions + self.probes_after


@dataclass(frozen=True)
class Protocol:
    """A validated study protocol (see the module docstring for the file layout).

    Attributes:
        name, description: as in the file. task: ``"trajectory"`` or ``"point"``.
        reach_radius: r_reach [m]. max_trial_time: time limit of one trial [s].
        excessive_force_n: threshold of the excessive-force metrics [N].
        path_tolerance_m: radius of the tolerance tube around the planned path [m]
            (``path_dev_out_frac``).
        poi_spacing: arc length between the trajectory task's POIs [m]; None: the task's
            default (``vasim.tasks.trajectory.POI_SPACING``).
        block_order: ``BLOCK_ORDERS``. variant_order: ``VARIANT_ORDERS``.
        probe_condition: condition of probe trials (a fixture-free schema).
        probe_variant: variant of probe trials.
        blocks: the blocks in file order. pre, post: the questionnaires.
        text: the TOML text it was parsed from (stored with each session; not compared).
        source: the file it came from (not compared).

    Raises:
        ConfigError: naming the field (dotted path) and the value; ``load_protocol`` adds
            the file.
    """

    name: str
    description: str
    task: TaskKind
    blocks: tuple[Block, ...]
    reach_radius: float = 0.005
    max_trial_time: float = 180.0
    excessive_force_n: float = 2.0
    path_tolerance_m: float = 0.002
    poi_spacing: float | None = None
    block_order: str = "fixed"
    variant_order: str = "fixed"
    probe_condition: str = "none"
    probe_variant: int = 0
    pre: Questionnaire = Questionnaire()
    post: Questionnaire = Questionnaire()
    text: str | None = field(default=None, compare=False, repr=False)
    source: str | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME_RE.fullmatch(self.name):
            raise ConfigError(f"must be a name of letters, digits, '_', '-', '.', got "
                              f"{self.name!r}", field="name")
        _check_str(self.description, "description")
        _check_choice(self.task, "task", TASKS)
        _check_positive(self.reach_radius, "reach_radius_m")
        check_trial_time(self.max_trial_time, "max_trial_time_s")
        _check_positive(self.excessive_force_n, "excessive_force_n")
        _check_positive(self.path_tolerance_m, "path_tolerance_m")
        if self.poi_spacing is not None:
            _check_positive(self.poi_spacing, "poi_spacing_m")
            if not self.poi_spacing > 2.0 * self.reach_radius:
                raise ConfigError(f"must exceed twice reach_radius_m ({self.reach_radius!r}), "
                                  f"got {self.poi_spacing!r}", field="poi_spacing_m")
        _check_choice(self.block_order, "randomisation.block_order", BLOCK_ORDERS)
        _check_choice(self.variant_order, "randomisation.variant_order", VARIANT_ORDERS)
        if not isinstance(self.blocks, tuple) or not self.blocks:
            raise ConfigError("a protocol needs at least one block", field="blocks")
        n_var = N_VARIANTS[self.task]
        _check_int(self.probe_variant, "probe.variant", 0, n_var - 1)
        _check_condition(self.probe_condition, self.task, "probe.condition")
        if _schema_has_fixtures(self.probe_condition):
            raise ConfigError(f"probe trials are fixture-free: schema "
                              f"{self.probe_condition!r} has fixtures",
                              field="probe.condition")
        names: set[str] = set()
        for i, b in enumerate(self.blocks):
            if not isinstance(b, Block):
                raise ConfigError(f"must be a Block, got {b!r}", field=f"blocks[{i}]")
            if b.name in names:
                raise ConfigError(f"duplicate block name {b.name!r}", field=f"blocks[{i}].name")
            names.add(b.name)
            _check_condition(b.condition, self.task, f"blocks[{i}].condition")
            if b.schema is not None:
                _check_condition(b.schema, self.task, f"blocks[{i}].schema")
                if b.condition in TELEOPERATION_MODES or b.schema in TELEOPERATION_MODES:
                    raise ConfigError("a teleoperation-mode block has no separate schema",
                                      field=f"blocks[{i}].schema")
            for j, v in enumerate(b.variants):
                if v >= n_var:
                    raise ConfigError(
                        f"variant {v!r} out of range: the {self.task} task has variants "
                        f"0..{n_var - 1}", field=f"blocks[{i}].variants[{j}]")
            if b.probe and b.condition != self.probe_condition:
                raise ConfigError(
                    f"a probe block runs the probe condition {self.probe_condition!r}, got "
                    f"{b.condition!r}", field=f"blocks[{i}].condition")
            if b.probes_after and b.condition in TELEOPERATION_MODES:
                raise ConfigError("teleoperation-mode blocks have no fixture-free probes",
                                  field=f"blocks[{i}].probes_after")
        for qname in ("pre", "post"):
            q = getattr(self, qname)
            if not isinstance(q, Questionnaire):
                raise ConfigError(f"must be a Questionnaire, got {q!r}",
                                  field=f"questionnaires.{qname}")
        if self.post.demographics:
            raise ConfigError("demographics are asked before the session (pre)",
                              field="questionnaires.post.demographics")
        # condition_* items default to the assisted conditions; explicit ones must exist
        assisted = self.assisted_conditions
        for qname in ("pre", "post"):
            q = getattr(self, qname)
            items = []
            for k, item in enumerate(q.items):
                path = f"questionnaires.{qname}.items[{k}]"
                if item.type.startswith("condition_"):
                    if not item.conditions:
                        if not assisted:
                            raise ConfigError("the protocol has no assisted condition to ask "
                                              "about", field=f"{path}.conditions")
                        item = _replace_item(item, conditions=assisted)
                    for c, cond in enumerate(item.conditions):
                        if cond not in self.conditions:
                            raise ConfigError(
                                f"unknown condition {cond!r} (the protocol's: "
                                f"{', '.join(self.conditions)})",
                                field=f"{path}.conditions[{c}]")
                    if item.type == "condition_sets" and item.min_size > len(item.conditions):
                        raise ConfigError(
                            f"min_size {item.min_size} exceeds the {len(item.conditions)} "
                            "conditions", field=f"{path}.min_size")
                elif item.conditions:
                    raise ConfigError(f"only condition_* items have conditions (this is "
                                      f"{item.type!r})", field=f"{path}.conditions")
                items.append(item)
            object.__setattr__(self, qname, Questionnaire(q.demographics, tuple(items)))

    # -- views --------------------------------------------------------------------------
    @property
    def conditions(self) -> tuple[str, ...]:
        """Every condition of the protocol (blocks and probes), in first-use order."""
        out: list[str] = []
        for b in self.blocks:
            for c in (b.condition, self.probe_condition if b.probes_after else None):
                if c is not None and c not in out:
                    out.append(c)
        return tuple(out)

    @property
    def assisted_conditions(self) -> tuple[str, ...]:
        """Conditions of non-probe blocks other than the probe condition (the fixtures or
        modes the questionnaires ask about), in file order."""
        out: list[str] = []
        for b in self.blocks:
            if not b.probe and b.condition != self.probe_condition and b.condition not in out:
                out.append(b.condition)
        return tuple(out)

    @property
    def teleoperation_modes(self) -> tuple[str, ...]:
        """The teleoperation-mode conditions used (empty for a fixture study)."""
        return tuple(c for c in self.conditions if c in TELEOPERATION_MODES)

    @property
    def n_trials(self) -> int:
        """Trials per session."""
        return sum(b.n_trials for b in self.blocks)

    def check_runnable(self) -> None:
        """The hook where a protocol this release cannot run would be refused.

        Nothing is refused now: every protocol that validates runs, fixture conditions
        through the trial runner (``vasim.trials.vf``) and teleoperation modes (StdT,
        MRCP, MRCP+Cam) through the MRCP slave station's needle task
        (``vasim.trials.teleop``), whatever the protocol's ``task`` names. The callers
        (session, cohort, CLI) keep calling it before anything is started.
        """


def _replace_item(item: QuestionItem, **changes: Any) -> QuestionItem:
    return replace(item, **changes)


@cache
def _schema_task(name: str) -> str:
    from vasim.fixtures.schema import load_schema

    return load_schema(name).task


@cache
def _schema_has_fixtures(name: str) -> bool:
    from vasim.fixtures.schema import load_schema

    if name in TELEOPERATION_MODES:
        return True
    return bool(load_schema(name).fixtures)


def _check_condition(cond: object, task: str, name: str) -> None:
    """A condition is a shipped schema usable for ``task`` or a teleoperation mode."""
    from vasim.fixtures.schema import available_schemas

    _check_str(cond, name)
    assert isinstance(cond, str)
    if cond in TELEOPERATION_MODES:
        return
    known = available_schemas()
    if cond not in known:
        raise ConfigError(
            f"unknown condition {cond!r}: not a schema of protocols/schemas "
            f"({', '.join(known)}) nor a teleoperation mode ({', '.join(TELEOPERATION_MODES)})",
            field=name)
    scope = _schema_task(cond)
    if scope not in ("any", task):
        raise ConfigError(f"schema {cond!r} is for {scope!r} tasks, not {task!r}", field=name)


# ------------------------------------------------------------------------- loading
_TOP = ("name", "description", "task", "reach_radius_m", "max_trial_time_s",
        "excessive_force_n", "path_tolerance_m", "poi_spacing_m", "randomisation", "probe",
        "blocks", "questionnaires")
_BLOCK = ("name", "condition", "variants", "repetitions", "probe", "counterbalance",
          "probes_after", "schema")
_ITEM = ("id", "type", "prompt", "required", "options", "conditions", "select", "min",
         "max", "anchors", "max_entries", "min_size", "max_length")


def available_protocols() -> tuple[str, ...]:
    """Names of the protocol files shipped in ``protocols/studies/``, sorted."""
    return available_files(studies_dir())


def protocol_path(ref: str | Path) -> Path:
    """The file a protocol reference names: a path, or a name in ``protocols/studies/``.

    Raises:
        ConfigError: if a bare name matches no shipped protocol.
    """
    return data_file(ref, studies_dir(), "protocol")


def load_protocol(ref: str | Path) -> Protocol:
    """Loads and validates a protocol by name (``"vf_learning_curve"``) or path.

    Raises:
        ConfigError: naming the file, the field and the value of the first problem.
    """
    path = protocol_path(ref)
    return parse_protocol(read_data_file(path, "protocol"), source=str(path))


def parse_protocol(text: str, *, source: str = "<string>") -> Protocol:
    """Parses and validates protocol TOML text; ``source`` names it in errors.

    The returned protocol keeps ``text`` (what a session stores).
    """
    if not isinstance(text, str):
        raise ConfigError(f"protocol text must be a string, got {type(text).__name__}",
                          file=source)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"invalid TOML: {exc}", file=source) from exc
    return protocol_from_dict(data, text=text, source=source)


def _unknown(table: Mapping[str, Any], known: Sequence[str], prefix: str, source: str) -> None:
    for key, value in table.items():
        if key not in known:
            path = f"{prefix}.{key}" if prefix else key
            raise ConfigError(f"unknown field (value {value!r}); expected one of "
                              f"{', '.join(known)}", file=source, field=path)


def _table(data: Mapping[str, Any], key: str, prefix: str, source: str) -> dict[str, Any]:
    v = data.get(key, {})
    if not isinstance(v, dict):
        path = f"{prefix}.{key}" if prefix else key
        raise ConfigError(f"must be a table, got {v!r}", file=source, field=path)
    return v


def _tuple(v: Any) -> Any:
    """TOML arrays become tuples; anything else is passed on for the dataclass to reject."""
    return tuple(v) if isinstance(v, list) else v


def protocol_from_dict(data: Mapping[str, Any], *, text: str | None = None,
                       source: str = "<dict>") -> Protocol:
    """Builds a protocol from parsed TOML (see the module docstring for the layout)."""
    _unknown(data, _TOP, "", source)
    for key in ("name", "description", "task", "blocks"):
        if key not in data:
            raise ConfigError("missing required field", file=source, field=key)
    rnd = _table(data, "randomisation", "", source)
    _unknown(rnd, ("block_order", "variant_order"), "randomisation", source)
    probe = _table(data, "probe", "", source)
    _unknown(probe, ("condition", "variant"), "probe", source)
    raw_blocks = data["blocks"]
    if not isinstance(raw_blocks, list) or not all(isinstance(b, dict) for b in raw_blocks):
        raise ConfigError(f"must be an array of tables ([[blocks]]), got {raw_blocks!r}",
                          file=source, field="blocks")
    blocks = []
    for i, raw in enumerate(raw_blocks):
        path = f"blocks[{i}]"
        _unknown(raw, _BLOCK, path, source)
        for key in ("name", "condition"):
            if key not in raw:
                raise ConfigError("missing required field", file=source, field=f"{path}.{key}")
        kw = {k: _tuple(v) for k, v in raw.items()}
        try:
            blocks.append(Block(**kw))
        except ConfigError as exc:
            raise _prefixed(exc, path, source) from exc
    qs = _table(data, "questionnaires", "", source)
    _unknown(qs, ("pre", "post"), "questionnaires", source)
    questionnaires = {}
    for qname in ("pre", "post"):
        qpath = f"questionnaires.{qname}"
        q = _table(qs, qname, "questionnaires", source)
        _unknown(q, ("demographics", "items"), qpath, source)
        raw_items = q.get("items", [])
        if not isinstance(raw_items, list) or not all(isinstance(x, dict) for x in raw_items):
            raise ConfigError(f"must be an array of tables ([[{qpath}.items]]), got "
                              f"{raw_items!r}", file=source, field=f"{qpath}.items")
        items = []
        for k, raw in enumerate(raw_items):
            path = f"{qpath}.items[{k}]"
            _unknown(raw, _ITEM, path, source)
            for key in ("id", "type", "prompt"):
                if key not in raw:
                    raise ConfigError("missing required field", file=source,
                                      field=f"{path}.{key}")
            try:
                items.append(QuestionItem(**{key: _tuple(v) for key, v in raw.items()}))
            except ConfigError as exc:
                raise _prefixed(exc, path, source) from exc
        try:
            questionnaires[qname] = Questionnaire(q.get("demographics", False), tuple(items))
        except ConfigError as exc:
            raise _prefixed(exc, qpath, source) from exc
    kw: dict[str, Any] = {
        "name": data["name"], "description": data["description"], "task": data["task"],
        "blocks": tuple(blocks),
        "reach_radius": data.get("reach_radius_m", 0.005),
        "max_trial_time": data.get("max_trial_time_s", 180.0),
        "excessive_force_n": data.get("excessive_force_n", 2.0),
        "path_tolerance_m": data.get("path_tolerance_m", 0.002),
        "poi_spacing": data.get("poi_spacing_m"),
        "block_order": rnd.get("block_order", "fixed"),
        "variant_order": rnd.get("variant_order", "fixed"),
        "probe_condition": probe.get("condition", "none"),
        "probe_variant": probe.get("variant", 0),
        "pre": questionnaires["pre"], "post": questionnaires["post"],
        "text": text, "source": source,
    }
    try:
        return Protocol(**kw)
    except ConfigError as exc:
        raise _prefixed(exc, "", source) from exc


# ------------------------------------------------------------------------ schedules
@dataclass(frozen=True)
class ScheduledTrial:
    """One trial of a session's schedule.

    Attributes:
        index: 0-based position in the session.
        block: block name. block_index: 0-based position of the block in this schedule.
        trial_in_block: 0-based position within the block (appended probes included).
        condition: the protocol's condition label. schema: the fixture schema to run (None
            for a teleoperation mode). task: ``"trajectory"`` or ``"point"``.
        variant: trajectory variant. probe: a fixture-free probe trial.
        probe_index: 1-based number among the session's probe trials (None if not a probe).
        repetition: 0-based round over the block's variants (or over its appended probes).
    """

    index: int
    block: str
    block_index: int
    trial_in_block: int
    condition: str
    schema: str | None
    task: str
    variant: int
    probe: bool
    probe_index: int | None
    repetition: int

    def as_row(self) -> dict[str, Any]:
        """The store's ``scheduled_trials`` columns (``index`` -> ``trial_index``)."""
        return {"trial_index": self.index, "block": self.block, "block_index": self.block_index,
                "trial_in_block": self.trial_in_block, "condition": self.condition,
                "schema": self.schema, "task": self.task, "variant": self.variant,
                "probe": self.probe, "probe_index": self.probe_index,
                "repetition": self.repetition}

    @classmethod
    def from_row(cls, row: Mapping[str, Any]) -> ScheduledTrial:
        """Inverse of ``as_row`` (e.g. a row of ``TrialStore.schedule``)."""
        def opt_int(v: Any) -> int | None:
            return None if v is None or pd.isna(v) else int(v)

        return cls(index=int(row["trial_index"]), block=str(row["block"]),
                   block_index=int(row["block_index"]), trial_in_block=int(row["trial_in_block"]),
                   condition=str(row["condition"]),
                   schema=None if pd.isna(row["schema"]) else str(row["schema"]),
                   task=str(row["task"]), variant=int(row["variant"]), probe=bool(row["probe"]),
                   probe_index=opt_int(row["probe_index"]), repetition=int(row["repetition"]))


def _rng(seed: int, *stream: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(seed), *stream]))


def williams_square(n: int) -> list[list[int]]:
    """Rows of a Williams balanced Latin square for n conditions (0..n-1).

    n rows for even n, 2n for odd n (the square and its mirror image). Every condition
    appears once per row and equally often in every position, and over all rows every
    ordered pair (a, b), a != b, appears as neighbours once (even n) or twice (odd n)
    (Williams 1949, "Experimental designs balanced for the estimation of residual effects
    of treatments").

    Example:
        >>> williams_square(4)
        [[0, 1, 3, 2], [1, 2, 0, 3], [2, 3, 1, 0], [3, 0, 2, 1]]
    """
    if not _is_int(n) or n < 1:
        raise ValueError(f"n must be an integer >= 1, got {n!r}")
    first = [0]
    lo, hi = 1, n - 1
    for k in range(1, n):
        if k % 2 == 1:
            first.append(lo)
            lo += 1
        else:
            first.append(hi)
            hi -= 1
    rows = [[(c + r) % n for c in first] for r in range(n)]
    if n % 2 == 1:
        rows += [row[::-1] for row in rows]
    return rows


def block_order(protocol: Protocol, seed: int) -> list[int]:
    """Indices into ``protocol.blocks`` in this seed's order (module docstring rules)."""
    slots = [i for i, b in enumerate(protocol.blocks) if b.counterbalance]
    order = list(range(len(protocol.blocks)))
    if len(slots) < 2 or protocol.block_order == "fixed":
        return order
    if protocol.block_order == "random":
        perm = _rng(seed, 1).permutation(len(slots)).tolist()
    else:
        rows = williams_square(len(slots))
        perm = rows[seed % len(rows)]
    for slot, k in zip(slots, perm, strict=True):
        order[slot] = slots[k]
    return order


def generate_schedule(protocol: Protocol, seed: int) -> list[ScheduledTrial]:
    """The realised schedule of one session: a pure function of protocol and seed.

    Args:
        protocol: the validated protocol.
        seed: the session's randomisation seed, an integer in [0, 2**63).

    Returns:
        ``protocol.n_trials`` scheduled trials in session order.

    Raises:
        ConfigError: a bad seed.

    Example:
        >>> p = load_protocol("vf_learning_curve")
        >>> a, b = generate_schedule(p, 1), generate_schedule(p, 1)
        >>> a == b, a[0].block, a[3].block_index
        (True, 'baseline', 1)
    """
    if not _is_int(seed) or not 0 <= seed < 2**63:
        raise ConfigError(f"seed must be an integer in [0, 2**63), got {seed!r}", field="seed")
    seed = int(seed)
    out: list[ScheduledTrial] = []
    n_probe = 0

    def schema_of(b: Block) -> str | None:
        if b.schema is not None:
            return b.schema
        return None if b.condition in TELEOPERATION_MODES else b.condition

    for pos, bi in enumerate(block_order(protocol, seed)):
        b = protocol.blocks[bi]
        rng = _rng(seed, 2, bi)
        k = 0
        for rep in range(b.repetitions):
            variants = list(b.variants)
            if protocol.variant_order == "random" and len(variants) > 1:
                variants = [variants[j] for j in rng.permutation(len(variants)).tolist()]
            for v in variants:
                if b.probe:
                    n_probe += 1
                out.append(ScheduledTrial(
                    index=len(out), block=b.name, block_index=pos, trial_in_block=k,
                    condition=b.condition, schema=schema_of(b), task=protocol.task,
                    variant=v, probe=b.probe, probe_index=n_probe if b.probe else None,
                    repetition=rep))
                k += 1
        for rep in range(b.probes_after):
            n_probe += 1
            out.append(ScheduledTrial(
                index=len(out), block=b.name, block_index=pos, trial_in_block=k,
                condition=protocol.probe_condition, schema=protocol.probe_condition,
                task=protocol.task, variant=protocol.probe_variant, probe=True,
                probe_index=n_probe, repetition=rep))
            k += 1
    return out


# ------------------------------------------------------------------------ answers
AnswerRow = tuple[str, str, str, float | None]
"""``(item, key, value, value_num)``: one row of the store's ``answers`` table."""


def validate_answers(protocol: Protocol, questionnaire: Literal["pre", "post"],
                     answers: Mapping[str, Any], *, source: str | None = None,
                     ) -> tuple[list[AnswerRow], Any]:
    """Checks one questionnaire's answers against the protocol and makes tidy rows.

    Args:
        protocol: the session's protocol. questionnaire: ``"pre"`` or ``"post"``.
        answers: item id -> answer: a string (choice, text, condition_choice, demographic
            fields), an integer (integer, likert), a mapping condition -> integer
            (condition_rating), a list of lists of conditions (condition_sets).
        source: the file the answers came from (named in errors).

    Returns:
        (rows, demographics): the answer rows (``AnswerRow``; keys: the condition for
        ratings, the 1-based entry number for sets, ``''`` otherwise; a set is stored as its
        conditions in the item's order joined by ``'+'``) and a
        ``vasim.study.store.Demographics`` when the questionnaire asks for demographics
        (else None).

    Raises:
        ConfigError: an unknown item, a missing required answer, or a bad value (field =
            the item id).
    """
    q: Questionnaire = getattr(protocol, questionnaire)
    if not isinstance(answers, Mapping):
        raise ConfigError(f"answers must be a table of item -> answer, got {answers!r}",
                          file=source, field=questionnaire)
    known = [*(DEMOGRAPHIC_FIELDS if q.demographics else ()), *(i.id for i in q.items)]
    for key in answers:
        if key not in known:
            raise ConfigError(f"unknown item (the {questionnaire} questionnaire of "
                              f"{protocol.name!r} has: {', '.join(known) or 'no items'})",
                              file=source, field=f"{questionnaire}.{key}")
    rows: list[AnswerRow] = []
    demo = None
    if q.demographics:
        try:
            demo = Demographics.from_mapping({k: answers[k] for k in DEMOGRAPHIC_FIELDS
                                              if k in answers})
        except ConfigError as exc:
            raise _prefixed(exc, questionnaire, source) from exc
        rows += [(k, "", str(answers[k]), None) for k in DEMOGRAPHIC_FIELDS]
    for item in q.items:
        path = f"{questionnaire}.{item.id}"
        if item.id not in answers:
            if item.required:
                raise ConfigError("missing answer to a required item", file=source, field=path)
            continue
        try:
            rows += _item_rows(item, answers[item.id])
        except ConfigError as exc:
            # An inner field (a condition of a rating: "rating.vg") keeps its detail.
            inner = exc.field or ""
            field = (f"{questionnaire}.{inner}" if inner.startswith(f"{item.id}.")
                     else path)
            raise ConfigError(exc.reason, file=source, field=field) from exc
    return rows, demo


def _item_rows(item: QuestionItem, a: Any) -> list[AnswerRow]:
    t = item.type
    if t == "choice":
        _check_choice(a, item.id, item.options)
        return [(item.id, "", a, None)]
    if t == "text":
        _check_str(a, item.id, one_line=False, empty=True)
        if len(a) > item.max_length:
            raise ConfigError(f"text longer than {item.max_length} characters ({len(a)})")
        return [(item.id, "", a, None)]
    if t == "integer":
        _check_int(a, item.id, item.min, item.max)
        return [(item.id, "", str(int(a)), float(a))]
    if t == "likert":
        _check_int(a, item.id, 1, LIKERT_POINTS)
        return [(item.id, "", str(int(a)), float(a))]
    if t == "condition_choice":
        _check_choice(a, item.id, item.conditions)
        return [(item.id, "", a, None)]
    if t == "condition_rating":
        if not isinstance(a, Mapping):
            raise ConfigError(f"must be a table condition -> rating, got {a!r}")
        for c in a:
            if c not in item.conditions:
                raise ConfigError(f"unknown condition {c!r} (expected "
                                  f"{', '.join(item.conditions)})")
        missing = [c for c in item.conditions if c not in a]
        if missing and item.required:
            raise ConfigError(f"missing ratings for {', '.join(missing)}")
        out: list[AnswerRow] = []
        for c in item.conditions:
            if c in a:
                _check_int(a[c], f"{item.id}.{c}", item.min, item.max)
                out.append((item.id, c, str(int(a[c])), float(a[c])))
        return out
    # condition_sets
    if not isinstance(a, list | tuple) or len(a) > item.max_entries:
        raise ConfigError(f"must be a list of at most {item.max_entries} sets of conditions, "
                          f"got {a!r}")
    out = []
    seen: set[frozenset[str]] = set()
    for e, entry in enumerate(a, start=1):
        if not isinstance(entry, list | tuple) or not all(isinstance(c, str) for c in entry):
            raise ConfigError(f"entry {e} must be a list of conditions, got {entry!r}")
        members = set(entry)
        unknown = sorted(members - set(item.conditions))
        if unknown:
            raise ConfigError(f"entry {e}: unknown condition(s) {unknown} (expected "
                              f"{', '.join(item.conditions)})")
        if len(members) != len(entry) or len(members) < item.min_size:
            raise ConfigError(f"entry {e} must list at least {item.min_size} different "
                              f"conditions, got {entry!r}")
        if frozenset(members) in seen:
            raise ConfigError(f"entry {e} repeats an earlier proposal: {entry!r}")
        seen.add(frozenset(members))
        canon = "+".join(c for c in item.conditions if c in members)
        out.append((item.id, str(e), canon, None))
    return out


__all__ = [
    "BLOCK_ORDERS",
    "ITEM_TYPES",
    "TELEOPERATION_MODES",
    "VARIANT_ORDERS",
    "Block",
    "Protocol",
    "QuestionItem",
    "Questionnaire",
    "ScheduledTrial",
    "available_protocols",
    "block_order",
    "generate_schedule",
    "load_protocol",
    "parse_protocol",
    "protocol_from_dict",
    "protocol_path",
    "validate_answers",
    "williams_square",
]
