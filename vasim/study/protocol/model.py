"""The protocol model: ``Block`` and ``Protocol``, frozen dataclasses validated on
construction (types, plausibility bounds of :mod:`vasim.core.bounds`, conditions that
exist for the task, questionnaire items that name the protocol's conditions).

The file layout is described in :mod:`vasim.study.protocol`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cache
from typing import Any, Literal

from vasim.core.bounds import (
    FORCE_N,
    PATH_TOLERANCE_M,
    POI_SPACING_M,
    PROBES_AFTER,
    REACH_RADIUS_M,
    REPETITIONS,
    RETENTION_DELAY_DAYS,
    TRIAL_TIME_S,
    TRIALS_PER_SESSION,
)
from vasim.core.config import (
    check_bool,
    check_choice,
    check_int,
    check_number,
    check_str,
    fail,
)
from vasim.fixtures.gain import (
    AdaptiveRule,
    GainRule,
    check_stages,
    rule_from_record,
    scheduled_gain,
)
from vasim.study.protocol.phases import PHASES, Gate
from vasim.study.protocol.power import PowerPlan
from vasim.study.protocol.questionnaires import QuestionItem, Questionnaire
from vasim.trials.kinds import TELEOPERATION_MODES

TaskKind = Literal["trajectory", "point"]
TASKS: tuple[str, ...] = ("trajectory", "point")
BLOCK_ORDERS: tuple[str, ...] = ("fixed", "random", "latin_square")
VARIANT_ORDERS: tuple[str, ...] = ("fixed", "random")
N_VARIANTS = {"trajectory": 7, "point": 1}
"""Variants per task: the trajectory's original + six mirrored/rotated; one point task."""

_NO_QUESTIONS = Questionnaire()
"""The empty questionnaire (frozen, shared as the default)."""
_NAME_RE = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")  # fullmatch: no trailing "\n"


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
        phase: ``"acquisition"``, ``"retention"`` or ``"transfer"``
            (:mod:`vasim.study.protocol.phases`). delay_days: the block begins a new
            sitting this many days after the previous trial [d] (0: same sitting).
        gate: the block's proficiency gate, or None.
        gain_schedule: fading (issue #18): the fixture gain of the block's own trials in
            stages, e.g. ``(1.0, 0.75, 0.5, 0.25)`` (``vasim.fixtures.gain.scheduled_gain``);
            None: gain 1. adaptive: assist-as-needed (``vasim.fixtures.gain.AdaptiveRule``;
            a TOML table is converted); None: none. A block with either names its own
            condition label (e.g. ``"ff_faded"``) and the ``schema`` it runs.
    """

    name: str
    condition: str
    variants: tuple[int, ...] = (0,)
    repetitions: int = 1
    probe: bool = False
    counterbalance: bool = True
    probes_after: int = 0
    schema: str | None = None
    phase: str = "acquisition"
    delay_days: float = 0.0
    gate: Gate | None = None
    # -- fading and adaptive fixtures (issue #18 item 1) --
    gain_schedule: tuple[float, ...] | None = None
    adaptive: AdaptiveRule | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME_RE.fullmatch(self.name):
            raise fail(self.name, "a name of letters, digits, '_', '-', '.'", field="name")
        _check_gain_fields(self)
        check_str(self.condition, "condition")
        if self.schema is not None:
            check_str(self.schema, "schema")
        if not isinstance(self.variants, tuple):
            raise fail(self.variants, "an array of integers", field="variants")
        if not self.variants:
            raise fail(self.variants, "at least one variant (an empty block)",
                       field="variants")
        for i, v in enumerate(self.variants):
            check_int(v, f"variants[{i}]", lo=0)
        if len(set(self.variants)) != len(self.variants):
            raise fail(list(self.variants), "no repeated variant (use repetitions)",
                       field="variants")
        check_int(self.repetitions, "repetitions", bound=REPETITIONS)
        check_bool(self.probe, "probe")
        check_bool(self.counterbalance, "counterbalance")
        check_int(self.probes_after, "probes_after", bound=PROBES_AFTER)
        n_own = len(self.variants) * self.repetitions
        if self.gain_schedule is not None and len(self.gain_schedule) > n_own:
            # issue #30: 4 stages on 2 trials silently ran only 2 of them
            raise fail(list(self.gain_schedule), f"at most {n_own} stage(s), one per trial of "
                       f"the block's {n_own} trial(s) (a longer schedule would skip stages; "
                       "drop stages or add variants/repetitions)", field="gain_schedule")
        check_block_phase(self)

    @property
    def n_trials(self) -> int:
        """Trials of the block, appended probes included."""
        return len(self.variants) * self.repetitions + self.probes_after

    @property
    def has_gain(self) -> bool:
        """The block fades or adapts its fixtures' gain."""
        return self.gain_schedule is not None or self.adaptive is not None

    def trial_gain(self, trial_in_block: int) -> GainRule:
        """The gain of the block's own trial ``trial_in_block`` (0-based): the adaptive
        rule, the schedule's stage, or 1.0 (appended probes are fixture-free anyway)."""
        if self.adaptive is not None:
            return self.adaptive
        if self.gain_schedule is not None:
            return scheduled_gain(self.gain_schedule, trial_in_block,
                                  len(self.variants) * self.repetitions)
        return 1.0


def _check_gain_fields(b: Block) -> None:
    """The fading/adaptive fields of a block (issue #18 item 1), converted and checked."""
    if b.gain_schedule is not None:
        object.__setattr__(b, "gain_schedule", check_stages(b.gain_schedule, "gain_schedule"))
    if b.adaptive is not None and not isinstance(b.adaptive, AdaptiveRule):
        if not isinstance(b.adaptive, Mapping):
            raise fail(b.adaptive, "a table of gain_min, gain_max, tau_s, deviation_full_m, "
                       "initial", field="adaptive")
        object.__setattr__(b, "adaptive", rule_from_record(b.adaptive, "adaptive"))
    if b.gain_schedule is not None and b.adaptive is not None:
        raise fail(b.gain_schedule, "either gain_schedule or adaptive, not both",
                   field="gain_schedule")
    if b.has_gain and b.probe:
        raise fail(True, "false (a probe block is fixture-free: it has no gain)",
                   field="probe")
    if b.has_gain and b.schema is None:
        raise fail(None, "the schema the faded/adaptive condition runs (schema = \"ff\"; "
                   f"the condition {b.condition!r} is its own label)", field="schema")


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
        repeat_timed_out: a scheduled trial whose attempt timed out (outcome
            ``'timed_out'``) is run again: ``vasim.study.session`` begins a new attempt.
        block_order: ``BLOCK_ORDERS``. variant_order: ``VARIANT_ORDERS``.
        probe_condition: condition of probe trials (a fixture-free schema).
        probe_variant: variant of probe trials (when ``probe_variants`` is None).
        probe_variants: the variants the probe trials rotate over (``[probe] variants``),
            or None: every probe trial runs ``probe_variant``. With a rotation the k-th
            probe trial (``probe_index`` k, baseline probes included) of the session with
            sequence number i runs ``probe_variants[(o(i) + k - 1) mod m]``,
            o(i) = i + i // lcm(R, m), R the number of block-order sequences (issue #25:
            the VF-free trials run on the same variants as the assisted ones, balanced
            across subjects; :func:`vasim.study.protocol.schedule.probe_variant_of`).
        blocks: the blocks in file order. pre, post: the questionnaires.
        power: the ``[power]`` table's planning effects (``vasim.study.protocol.power``),
            or None.
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
    repeat_timed_out: bool = False
    path_tolerance_m: float = 0.002
    poi_spacing: float | None = None
    block_order: str = "fixed"
    variant_order: str = "fixed"
    probe_condition: str = "none"
    probe_variant: int = 0
    probe_variants: tuple[int, ...] | None = None
    pre: Questionnaire = _NO_QUESTIONS
    post: Questionnaire = _NO_QUESTIONS
    power: PowerPlan | None = None
    text: str | None = field(default=None, compare=False, repr=False)
    source: str | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME_RE.fullmatch(self.name):
            raise fail(self.name, "a name of letters, digits, '_', '-', '.'", field="name")
        check_str(self.description, "description")
        check_choice(self.task, "task", TASKS)
        check_number(self.reach_radius, "reach_radius_m", gt=0.0, bound=REACH_RADIUS_M)
        check_number(self.max_trial_time, "max_trial_time_s", gt=0.0, bound=TRIAL_TIME_S)
        check_number(self.excessive_force_n, "excessive_force_n", gt=0.0, bound=FORCE_N)
        check_bool(self.repeat_timed_out, "repeat_timed_out")
        check_number(self.path_tolerance_m, "path_tolerance_m", gt=0.0, bound=PATH_TOLERANCE_M)
        if self.poi_spacing is not None:
            check_number(self.poi_spacing, "poi_spacing_m", gt=0.0, bound=POI_SPACING_M)
            if not self.poi_spacing > 2.0 * self.reach_radius:
                raise fail(self.poi_spacing, f"more than twice reach_radius_m "
                           f"({self.reach_radius!r})", field="poi_spacing_m")
        check_choice(self.block_order, "randomisation.block_order", BLOCK_ORDERS)
        check_choice(self.variant_order, "randomisation.variant_order", VARIANT_ORDERS)
        if not isinstance(self.blocks, tuple) or not self.blocks:
            raise fail(self.blocks, "at least one block", field="blocks")
        n_var = N_VARIANTS[self.task]
        check_int(self.probe_variant, "probe.variant", lo=0, hi=n_var - 1)
        _check_probe_variants(self.probe_variants, self.probe_variant, n_var)
        _check_condition(self.probe_condition, self.task, "probe.condition")
        if _schema_has_fixtures(self.probe_condition):
            raise fail(self.probe_condition, "a schema without fixtures (probe trials are "
                       "fixture-free)", field="probe.condition")
        self._check_blocks(n_var)
        check_protocol_phases(self)
        if self.power is not None:
            if not isinstance(self.power, PowerPlan):
                raise fail(self.power, "a PowerPlan", field="power")
            self.power.check_labels(self.conditions)
        n_trials = sum(b.n_trials for b in self.blocks)
        if n_trials > TRIALS_PER_SESSION.high:
            raise fail(n_trials, f"at most {TRIALS_PER_SESSION.high:,} trials per session "
                       f"({TRIALS_PER_SESSION.reason})", field="blocks")
        for qname in ("pre", "post"):
            q = getattr(self, qname)
            if not isinstance(q, Questionnaire):
                raise fail(q, "a Questionnaire", field=f"questionnaires.{qname}")
        if self.post.demographics:
            raise fail(True, "false (demographics are asked before the session: pre)",
                       field="questionnaires.post.demographics")
        self._resolve_items()

    def _check_blocks(self, n_var: int) -> None:
        """Each block: a unique name, known conditions and schemas, variants of the task,
        probe blocks that run the probe condition."""
        names: set[str] = set()
        for i, b in enumerate(self.blocks):
            if not isinstance(b, Block):
                raise fail(b, "a Block", field=f"blocks[{i}]")
            if b.name in names:
                raise fail(b.name, "a block name not used before (duplicate block name)",
                           field=f"blocks[{i}].name")
            names.add(b.name)
            if b.has_gain:  # its own label (e.g. ff_faded): not a schema, not a mode
                _check_gain_label(b, self.task, f"blocks[{i}]")
            else:
                _check_condition(b.condition, self.task, f"blocks[{i}].condition")
            if b.schema is not None:
                _check_condition(b.schema, self.task, f"blocks[{i}].schema")
                if b.condition in TELEOPERATION_MODES or b.schema in TELEOPERATION_MODES:
                    raise fail(b.schema, "no schema (a teleoperation-mode block runs its "
                               "mode)", field=f"blocks[{i}].schema")
            for j, v in enumerate(b.variants):
                if v >= n_var:
                    raise fail(v, f"a variant in [0, {n_var - 1}] (the {self.task} task's)",
                               field=f"blocks[{i}].variants[{j}]")
            if (b.probe and self.probe_variants is not None and b.variants != (0,)
                    and b.phase != "transfer"):
                # a transfer block keeps its own (untrained) variants: they are outside
                # the rotation by definition (vasim.study.protocol.phases)
                raise fail(list(b.variants), "no variants (a probe block's trials take "
                           "probe.variants in rotation; set its trial count with "
                           "repetitions)", field=f"blocks[{i}].variants")
            if b.probe and b.condition != self.probe_condition:
                raise fail(b.condition, f"the probe condition {self.probe_condition!r} (a "
                           "probe block runs it)", field=f"blocks[{i}].condition")
            if b.probes_after and b.condition in TELEOPERATION_MODES:
                raise fail(b.probes_after, "0 (teleoperation-mode blocks have no "
                           "fixture-free probes)", field=f"blocks[{i}].probes_after")

    def _resolve_items(self) -> None:
        """The questionnaires' condition_* items: default conditions filled in (the
        assisted ones), explicit ones checked against the protocol's."""
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
                            raise fail(item.conditions, "conditions to ask about (the protocol "
                                       "has no assisted condition)", field=f"{path}.conditions")
                        item = _replace_item(item, conditions=assisted)
                    for c, cond in enumerate(item.conditions):
                        if cond not in self.conditions:
                            raise fail(cond, f"one of the protocol's conditions "
                                       f"({', '.join(self.conditions)})",
                                       field=f"{path}.conditions[{c}]")
                    if item.type == "condition_sets" and item.min_size > len(item.conditions):
                        raise fail(item.min_size, f"at most the {len(item.conditions)} "
                                   "conditions asked about", field=f"{path}.min_size")
                elif item.conditions:
                    raise fail(item.conditions, f"no conditions (only condition_* items have "
                               f"them; this is {item.type!r})", field=f"{path}.conditions")
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


# -- phases and gates (the rules of vasim.study.protocol.phases' docstring) -------------
def check_block_phase(block: Block) -> None:
    """The block-level checks of ``phase``, ``delay_days`` and ``gate``.

    Raises:
        ConfigError: naming the field (relative to the block) and the value.
    """
    check_choice(block.phase, "phase", PHASES)
    object.__setattr__(block, "delay_days",
                       check_number(block.delay_days, "delay_days",
                                    bound=RETENTION_DELAY_DAYS))
    delayed = block.delay_days > 0 or block.phase != "acquisition"
    if delayed and block.counterbalance:
        raise fail(True, "false (a delayed, retention or transfer block keeps its place in "
                   "time)", field="counterbalance")
    if block.phase != "acquisition":
        if not block.probe:
            raise fail(block.probe, f"true (a {block.phase} block is VF-free probe trials)",
                       field="probe")
        if block.probes_after:
            raise fail(block.probes_after, f"0 (a {block.phase} block is itself probes)",
                       field="probes_after")
    g = block.gate
    if g is None:
        return
    if not isinstance(g, Gate):
        raise fail(g, "a [blocks.gate] table", field="gate")
    if block.phase != "acquisition" or block.probe:
        raise fail(block.phase if block.probe is False else "probe = true",
                   "an acquisition block that is not a probe block (a gate)", field="gate")
    base = len(block.variants) * block.repetitions
    if g.max_trials < base:
        raise fail(g.max_trials, f"at least the block's {base} scheduled trials",
                   field="gate.max_trials")
    if g.consecutive > g.max_trials:
        raise fail(g.consecutive, f"at most gate.max_trials ({g.max_trials})",
                   field="gate.consecutive")


def check_protocol_phases(protocol: Protocol) -> None:
    """The protocol-level rules (module docstring's decisions).

    Raises:
        ConfigError: naming the block field and the value.
    """
    blocks = protocol.blocks
    rotation = protocol.probe_variants
    probe_vs = set(rotation) if rotation is not None else {protocol.probe_variant}
    probes_variant = probe_vs if any(b.probes_after for b in blocks) else set()
    trained = {v for b in blocks if b.phase == "acquisition"
               for v in (probe_vs if b.probe and rotation is not None else b.variants)}
    trained |= probes_variant
    others: dict[str, set[int]] = {}
    for b in blocks:
        if b.phase != "transfer":
            others[b.name] = (set(probe_vs) if b.probe and rotation is not None
                              else set(b.variants))
    delay_since_acq: float | None = None
    for i, b in enumerate(blocks):
        if b.phase == "acquisition":
            delay_since_acq = b.delay_days
            continue
        if delay_since_acq is None:
            raise fail(b.phase, "an acquisition block before it (nothing to retain or "
                       "transfer)", field=f"blocks[{i}].phase")
        delay_since_acq += b.delay_days
        if b.phase == "retention":
            if delay_since_acq <= 0:
                raise fail(b.delay_days, "a delay: the delays since the last acquisition "
                           "block sum to 0 (a retention block is a later sitting)",
                           field=f"blocks[{i}].delay_days")
            # under a probe rotation a retention probe block runs the rotation's variants
            retained = (tuple(sorted(probe_vs)) if b.probe and rotation is not None
                        else b.variants)
            for j, v in enumerate(retained):
                if v not in trained:
                    raise fail(v, f"a trained variant ({sorted(trained)}; retention is "
                               "measured on what was practised)",
                               field=f"blocks[{i}].variants[{j}]")
        else:
            used = set().union(*others.values()) | probes_variant
            for j, v in enumerate(b.variants):
                if v in used:
                    where = [n for n, vs in others.items() if v in vs]
                    what = (f"block(s) {', '.join(where)}" if where
                            else "the probe variant of appended probes")
                    raise fail(v, f"an untrained variant (variant {v} is run in {what})",
                               field=f"blocks[{i}].variants[{j}]")
    if blocks and blocks[0].delay_days > 0:
        # issue #30: accepted, exported as a later sitting, yet everything ran at once
        raise fail(blocks[0].delay_days, "0 on the first block (a delay counts from the "
                   "previous trial; the first block has none: give the delay to the block "
                   "that begins the later sitting)", field="blocks[0].delay_days")
    worst = sum(max_trials(b) for b in blocks)
    if worst > TRIALS_PER_SESSION.high:
        raise fail(worst, f"at most {TRIALS_PER_SESSION.high:,} trials per session with "
                   f"every gate at its cap ({TRIALS_PER_SESSION.reason})", field="blocks")


def max_trials(block: Block) -> int:
    """The block's trials at most: its gate's cap (if any) plus its appended probes."""
    if block.gate is None:
        return block.n_trials
    return block.gate.max_trials + block.probes_after


def gated_blocks(protocol: Protocol) -> tuple[Block, ...]:
    """The protocol's blocks with a gate, in file order."""
    return tuple(b for b in protocol.blocks if b.gate is not None)


def sitting_starts(blocks: Sequence[Block]) -> dict[str, float]:
    """Block name -> its delay [days] (for blocks that start a later sitting)."""
    return {b.name: b.delay_days for b in blocks if b.delay_days > 0}



def _check_probe_variants(variants: object, single: int, n_var: int) -> None:
    """``probe.variants``: None, or distinct variants of the task, not with ``probe.variant``."""
    if variants is None:
        return
    if not isinstance(variants, tuple) or not variants:
        raise fail(list(variants) if isinstance(variants, tuple) else variants,
                   "a non-empty array of trajectory variants", field="probe.variants")
    for j, v in enumerate(variants):
        check_int(v, f"probe.variants[{j}]", lo=0, hi=n_var - 1)
    if len(set(variants)) != len(variants):
        raise fail(list(variants), "distinct variants (no repeats)", field="probe.variants")
    if single != 0:
        raise fail(single, "no probe.variant beside probe.variants (one or the other)",
                   field="probe.variant")


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


def _check_gain_label(b: Block, task: str, path: str) -> None:
    """A faded/adaptive block's condition is a label of its own (neither a schema nor a
    teleoperation mode: its trials must not mix with the constant schema's in analyses)
    and its schema has fixtures to scale."""
    from vasim.fixtures.schema import available_schemas

    if not _NAME_RE.fullmatch(b.condition):
        raise fail(b.condition, "a label of letters, digits, '_', '-', '.'",
                   field=f"{path}.condition")
    if b.condition in available_schemas() or b.condition in TELEOPERATION_MODES:
        raise fail(b.condition, "a label of its own for a faded/adaptive condition, not a "
                   "schema or mode name (e.g. 'ff_faded')", field=f"{path}.condition")
    assert b.schema is not None
    _check_condition(b.schema, task, f"{path}.schema")
    if not _schema_has_fixtures(b.schema) or b.schema in TELEOPERATION_MODES:
        raise fail(b.schema, "a schema with fixtures (a gain scales them)",
                   field=f"{path}.schema")


def _check_condition(cond: object, task: str, name: str) -> None:
    """A condition is a shipped schema usable for ``task`` or a teleoperation mode."""
    from vasim.fixtures.schema import available_schemas

    check_str(cond, name)
    assert isinstance(cond, str)
    if cond in TELEOPERATION_MODES:
        return
    known = available_schemas()
    if cond not in known:
        raise fail(cond, f"a schema of protocols/schemas ({', '.join(known)}) or a "
                   f"teleoperation mode ({', '.join(TELEOPERATION_MODES)}) (unknown condition)",
                   field=name)
    scope = _schema_task(cond)
    if scope not in ("any", task):
        raise fail(cond, f"a schema for {task!r} tasks (schema {cond!r} is for {scope!r} tasks, "
                   f"not {task!r})", field=name)
