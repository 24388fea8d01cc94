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
    repeat_timed_out = false            # [false] a trial that hits its time limit is run
                                        # again (a new attempt) instead of counting as done
    path_tolerance_m = 0.002            # [0.002] tolerance tube of path_dev_out_frac [m]
    poi_spacing_m = 0.0105              # [task default] arc length between trajectory POIs [m]

    [randomisation]
    block_order = "random"              # ["fixed"] | "random" | "latin_square"
    variant_order = "random"            # ["fixed"] | "random"

    [probe]                             # the fixture-free probe trials (learning curve)
    condition = "none"                  # ["none"] a schema without fixtures
    variant = 0                         # [0] all probe trials use this trajectory, or
    variants = [1, 2, 3, 4, 5, 6]       # [none] the probe trials rotate over these
                                        # (issue #25; then a probe block has no `variants`:
                                        # its `repetitions` trials take the rotation too)

    [[blocks]]                          # at least one; run in file order unless randomised
    name = "baseline"                   # required, unique
    condition = "none"                  # required: a schema name (protocols/schemas) or, in
                                        # the MRCP protocols, a mode "stdt"|"mrcp"|"mrcp_cam"
    variants = [0]                      # [[0]] trajectory variants (0..6; point task: 0)
    repetitions = 3                     # [1] every variant this many times
    probe = true                        # [false] these trials are probe trials
    counterbalance = false              # [true] takes part in the block-order randomisation
    probes_after = 0                    # [0] probe trials appended after the block's trials
    phase = "acquisition"               # ["acquisition"] | "retention" | "transfer", and
    delay_days = 0.0                    # [0] a later sitting; [blocks.gate]: a proficiency
                                        # gate (vasim.study.protocol.phases)
    # fading / adaptive fixtures (issue #18; vasim.fixtures.gain), one of the two; the block
    # then needs `schema` and its condition is a label of its own (e.g. "ff_faded"):
    gain_schedule = [1.0, 0.75, 0.5]    # [none] gains in [0, 1], equal runs of trials, in order
    adaptive = { gain_min = 0.25, gain_max = 1.0, tau_s = 2.0, deviation_full_m = 0.003,
                 initial = 0.5 }        # [none] assist-as-needed (initial: [gain_max])

    [power]                             # [none] planning effects of `vasim study power`
    effect_scale = 0.5                  # [1] (vasim.study.protocol.power); the command
    [power.effects.ff]                  # line's --effect-scale / --effects override them
    accuracy = 0.8                      # labels: the protocol's conditions

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
  ``i mod R`` of a Williams balanced Latin square, i the subject's sequence number (the
  seed unless ``generate_schedule(..., sequence=i)``; R = n rows for an even number n of
  counterbalanced blocks, 2n for odd n; each block appears equally often in every position
  and follows every other block equally often over R consecutive rows: give a cohort
  consecutive sequence numbers, as ``vasim study simulate`` does).
* Within a block the trials are ``repetitions`` rounds over ``variants``; ``"random"``
  shuffles each round independently (every variant once before any twice), ``"fixed"``
  keeps the listed order. ``probes_after`` probe trials (``probe.condition`` on
  ``probe.variant``) follow the block's trials.
* ``probe.variants`` (issue #25): every probe trial, the probe blocks' own included, runs a
  variant of the rotation: probe k of sequence number i runs ``variants[(o(i) + k - 1) mod
  m]``, o(i) = i + floor(i / lcm(R, m)) (one variant further every cycle of lcm(R, m)
  subjects) (``probe_variant_of``): the VF-free trials run on the same variants as the assisted
  ones, balanced across subjects (docs/study-design.md).
* Randomness: ``numpy.random.default_rng(SeedSequence([seed, stream, block]))``, one stream
  for the block order and one per block for its variants. numpy does not promise the same
  stream across versions: the realised schedule is what is stored and replayed.
* Probe trials are numbered 1, 2, ... in schedule order (``probe_index``: the VF study's
  8-level "trial" factor).

Example:
    >>> p = load_protocol("vf_learning_curve")
    >>> s = generate_schedule(p, seed=7)
    >>> len(s), sum(t.probe for t in s), [t.variant for t in s if t.probe]
    (38, 8, [2, 3, 4, 5, 6, 1, 2, 3])
"""

from __future__ import annotations

from vasim.study.protocol.answers import AnswerRow, validate_answers
from vasim.study.protocol.loader import (
    available_protocols,
    load_protocol,
    parse_protocol,
    protocol_from_dict,
    protocol_path,
)
from vasim.study.protocol.model import (
    BLOCK_ORDERS,
    N_VARIANTS,
    TASKS,
    VARIANT_ORDERS,
    Block,
    Protocol,
    TaskKind,
    gated_blocks,
)
from vasim.study.protocol.phases import PHASES, Gate
from vasim.study.protocol.power import PowerPlan
from vasim.study.protocol.questionnaires import (
    ITEM_TYPES,
    LIKERT_POINTS,
    QuestionItem,
    Questionnaire,
)
from vasim.study.protocol.schedule import (
    ScheduledTrial,
    block_of,
    block_order,
    day_offsets,
    extend_gated_block,
    gated_trials,
    generate_schedule,
    probe_variant_of,
    sitting_numbers,
    williams_square,
)
from vasim.trials.kinds import TELEOPERATION_MODES

__all__ = [
    "BLOCK_ORDERS",
    "ITEM_TYPES",
    "LIKERT_POINTS",
    "N_VARIANTS",
    "PHASES",
    "TASKS",
    "TELEOPERATION_MODES",
    "VARIANT_ORDERS",
    "AnswerRow",
    "Block",
    "Gate",
    "PowerPlan",
    "Protocol",
    "QuestionItem",
    "Questionnaire",
    "ScheduledTrial",
    "TaskKind",
    "available_protocols",
    "block_of",
    "block_order",
    "day_offsets",
    "extend_gated_block",
    "gated_blocks",
    "gated_trials",
    "generate_schedule",
    "load_protocol",
    "parse_protocol",
    "probe_variant_of",
    "protocol_from_dict",
    "protocol_path",
    "sitting_numbers",
    "validate_answers",
    "williams_square",
]
