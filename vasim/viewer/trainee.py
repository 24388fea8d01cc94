"""What the trainee reads (issue #19 §4, issue #20 §1, §5): the trial's title, the one-line
instruction and start cue, the live status (points reached, time and time left), how the
trial ended, and the score card after it. Pure text builders plus the rate-limited
:class:`HudView` shell; every string reaches viser markdown escaped (viser does not
sanitise it).

**One trial number everywhere** (:func:`trial_title`): a protocol trial is named by its place
in the schedule ("trial 1 of 38") on every page and in every status line, another stored
trial by its store id ("trial 12"); a demo run, which is never stored, is "demo run 3 (not
stored)" — the server's own counter never poses as a trial id.

**Not moving never scores best** (issue #26 §6): the score card shows how much of the path
was covered and the distance from the path *along the part attempted*
(``vasim.records.path_deviation``: ``path_covered_frac``, ``path_dev_attempted_mm``); a
trial that attempted nothing has no distance ("—, nothing attempted"), and
:func:`score_key` orders trials by points reached, then the path covered, then the
distance, then the time, so a trial without motion ranks below every trial that moved.

**How a trial ended** (:data:`OUTCOME_TEXT`): the store's outcome vocabulary in words; a
trial that runs out of time says "time ran out", never "done".

**No sum of samples is shown as a length**: the score card and the HUD show distances in
mm (the current distance to the goal, the mean and maximum distance from the path) and the
path length (the Euclidean length of the tool track), never the thesis's e_i (a sum of
per-sample Manhattan errors, whose value depends on the sample rate).
"""

from __future__ import annotations

import html
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import viser

from vasim.fixtures.types import AudioCue

OUTCOME_TEXT: dict[str, str] = {
    "reached_all": "all points reached",
    "timed_out": "time ran out",
    "stopped": "stopped by the experimenter",
    "interrupted": "interrupted",
    "failed": "failed (an error stopped it)",
}
"""A trial's outcome (``vasim.study.store.vocabulary.TRIAL_OUTCOMES``) in words."""


def trial_title(trial_id: int | None, number: int, position: int | None = None,
                total: int | None = None) -> str:
    """The trial's name on every page: its place in the protocol's schedule ("trial 1 of
    38"), else its store id, else the demo run's counter.

    **Decision** (issue #26 §6): a protocol trial is named by its place in the schedule on
    both pages (the experimenter's progress line counts the same way); the store id, which
    also counts other subjects' and free trials, names only trials outside a schedule.

    >>> trial_title(12, 40), trial_title(None, 3), trial_title(57, 4, 1, 38)
    ('trial 12', 'demo run 3 (not stored)', 'trial 1 of 38')
    """
    if position is not None and total is not None:
        return f"trial {position} of {total}"
    return f"trial {trial_id}" if trial_id is not None else f"demo run {number} (not stored)"


def frame_outcome(done: bool, goal_index: int, n_points: int) -> str | None:
    """The outcome a finished frame shows by itself: every point reached, or (a trial only
    ends on its own when the last point is reached or its time is up) the time ran out."""
    if not done:
        return None
    return "reached_all" if goal_index >= n_points else "timed_out"


def instruction(task_name: str, n_points: int, input_kind: str) -> str:
    """What to do, in one sentence (shown before and during the trial).

    >>> instruction("trajectory/v3", 30, "laparoscopic")[:48]
    'Guide the instrument tip through the 30 points a'
    """
    if input_kind == "scripted":
        return "Watch: the scripted operator performs the task."
    if task_name == "needle":   # a teleoperation trial (vasim.viewer.teleop_live)
        return (f"Carry the needle through the {n_points} rings in order, touching the "
                "tissue as little as you can.")
    if task_name.startswith("point"):
        return (f"Touch each of the {n_points} targets with the instrument tip, one after "
                "the other, without pressing on the tissue.")
    return (f"Guide the instrument tip through the {n_points} points along the path, in "
            "order, as closely and smoothly as you can.")


def audio_text(audio: AudioCue | None) -> str:
    """The AG state as text: ``"off"`` (no AG), ``"silent"`` or pitch/period."""
    if audio is None:
        return "off"
    if audio.silent:
        return "silent"
    return f"{audio.pitch_hz:.0f} Hz, every {audio.period_s:.2f} s"


@dataclass(frozen=True)
class HudInfo:
    """What the trainee's HUD shows (plain values; the app builds it from a frame).

    Attributes:
        schema: schema name. fixtures: active fixture names. task: task name.
        title: :func:`trial_title`. instruction: :func:`instruction`.
        t: time in trial [s]. time_left: time limit minus ``t`` [s] (None: no limit).
        error_m: current distance from the tool tip to the goal |x - g| [m].
        goal_index, n_points: progress. last_latency: l_i of the last reached point [s].
        audio: AG cue or None. force_n: |F| [N] or None. zoom: Mag zoom or None.
        ms: (3,) MS factors or None. done: the trial ended.
        outcome: how it ended (``OUTCOME_TEXT`` key) or None while it runs.
        countdown_s: seconds until the trial starts (the start cue), or None.
        path_m: current distance from the tool tip to the planned path [m], or None (every
            point reached, or no path).
    """

    schema: str
    fixtures: tuple[str, ...]
    task: str
    title: str
    t: float
    error_m: float
    goal_index: int
    n_points: int
    last_latency: float | None
    audio: AudioCue | None
    force_n: float | None
    zoom: float | None
    ms: tuple[float, float, float] | None
    done: bool
    time_left: float | None = None
    outcome: str | None = None
    instruction: str = ""
    countdown_s: float | None = None
    path_m: float | None = None


def state_text(info: HudInfo) -> str:
    """The trial's state in words: starting, running, or how it ended."""
    if info.countdown_s is not None:
        return f"starts in {math.ceil(max(info.countdown_s, 0.0))} s"
    if info.outcome is not None:
        return f"ended: {OUTCOME_TEXT.get(info.outcome, info.outcome)}"
    if info.done:
        return "ended"
    return "running"


def hud_markdown(info: HudInfo) -> str:
    """The HUD's markdown (every string escaped: markdown is not sanitised by viser)."""
    esc = html.escape
    lat = "–" if info.last_latency is None else f"{info.last_latency:.2f} s"
    reached = min(info.goal_index, info.n_points)
    head = f"**{esc(info.title)}** — {esc(state_text(info))}"
    if info.instruction:
        head += f"  \n{esc(info.instruction)}"
    if info.countdown_s is not None:
        head += "  \n**Get ready…** the clock starts at 0."
    time_row = f"{info.t:6.1f} s"
    if info.time_left is not None and info.outcome is None and not info.done:
        time_row += f" ({max(info.time_left, 0.0):.0f} s left)"
    # **Decision** (issue #19 §4, #15 §1): the trainee sees only what a trainee understands
    # and acts on — progress, time, how far the tip is from the path and from the next
    # point. The condition's internals (schema, AG cue, FF force, MS factors, Mag zoom) are
    # on the experimenter's page; they would tell a study's trainee what is being tested.
    rows = [
        ("Points reached", f"{reached} of {info.n_points}"),
        ("Time", time_row),
        ("From the path", "–" if info.done or info.path_m is None
         else f"{info.path_m * 1e3:.1f} mm"),
        ("To the next point", "–" if info.done else f"{info.error_m * 1e3:.1f} mm"),
        ("Last latency", lat),
    ]
    # A "|" inside a cell would end it: escape it.
    body = "\n".join(f"| {k} | {v.replace('|', '&#124;')} |" for k, v in rows)
    return head + "\n\n| | |\n|---|---|\n" + body


class HudView:
    """A GUI markdown panel with the live trial state; rewritten at most ``max_rate_hz``.

    Args:
        server: the viser server.
        max_rate_hz: maximum rewrites per second (each is a message to every browser).
    """

    def __init__(self, server: viser.ViserServer, *, max_rate_hz: float = 10.0):
        self.min_interval = 1.0 / max_rate_hz
        self.handle = server.gui.add_markdown("*waiting for the first frame…*")
        self.text = ""
        self._last_t = -math.inf

    def update(self, info: HudInfo, now: float | None = None, *, force: bool = False) -> None:
        now = time.perf_counter() if now is None else now
        if not force and now - self._last_t < self.min_interval:
            return
        text = hud_markdown(info)
        self._last_t = now
        if text != self.text:
            self.text = text
            self.handle.content = text


# ---------------------------------------------------------------------------------------
# The score card


SCORE_METRICS: tuple[tuple[str, str, str, float, int], ...] = (
    # (trial metric name, label, unit, factor from the stored unit, decimals)
    ("duration", "Time", "s", 1.0, 1),
    ("points_reached", "Points reached", "", 1.0, 0),
    ("path_covered_frac", "Path covered", "%", 100.0, 0),
    ("path_dev_attempted_mm", "Mean distance from the path (part attempted)", "mm", 1.0, 1),
    ("path_dev_max_mm", "Maximum distance from the path", "mm", 1.0, 1),
    ("contact_count", "Tissue contacts", "", 1.0, 0),
    ("excessive_force_time", "Excessive-force time", "s", 1.0, 1),
    ("path_l2", "Path length", "mm", 1e3, 0),
)
"""The score card's rows: ``vasim.records.trial_metrics`` names (shown as "—" while absent,
e.g. a trial stored before the metric existed), in plain units."""

NOTHING_ATTEMPTED = "nothing attempted"
"""The distance rows' note when the trial covered none of the path."""

RANK_ORDER = ("points reached", "path covered", "distance from the path", "time")
"""What :func:`score_key` compares, in order."""


def score_key(metrics: Mapping[str, float]) -> tuple[float, float, float, float]:
    """A trial's rank (larger is better): points reached, then the fraction of the path
    covered, then the (negated) mean distance along the part attempted, then the (negated)
    time. A missing or undefined value ranks worst (a trial that attempted nothing has no
    distance, so it never beats one that moved).

    >>> still = {"points_reached": 0, "path_covered_frac": 0.0, "duration": 180.0}
    >>> moved = {"points_reached": 0, "path_covered_frac": 0.1,
    ...          "path_dev_attempted_mm": 9.0, "duration": 180.0}
    >>> score_key(moved) > score_key(still)
    True
    """
    def get(name: str, sign: float) -> float:
        v = _value(metrics, name, 1.0)
        return -math.inf if v is None else sign * v

    return (get("points_reached", 1.0), get("path_covered_frac", 1.0),
            get("path_dev_attempted_mm", -1.0), get("duration", -1.0))


@dataclass(frozen=True)
class ScoreRow:
    """One metric of the score card, in its display unit (None: not available)."""

    name: str
    label: str
    unit: str
    value: float | None
    earlier: float | None
    benchmark: float | None
    decimals: int


@dataclass(frozen=True)
class ScoreCard:
    """The score card of one finished trial.

    Attributes:
        title: :func:`trial_title`. outcome: ``OUTCOME_TEXT`` key. n_points: POIs.
        rows: the metrics. n_earlier: the trainee's earlier trials averaged in ``earlier``.
        n_benchmark: trials behind the benchmark (0: no benchmark).
        gate: the proficiency gate's verdict on this trial (a gated block), or None.
        attempted: False when the trial covered none of the path (its distance rows are
        "—, nothing attempted"). better_than: earlier trials it ranks above
        (:func:`score_key`).
    """

    title: str
    outcome: str | None
    n_points: int
    rows: tuple[ScoreRow, ...]
    n_earlier: int = 0
    n_benchmark: int = 0
    gate: GateCard | None = None
    attempted: bool = True
    better_than: int = 0


@dataclass(frozen=True)
class GateRow:
    """One gate metric on the score card, in its display unit.

    Attributes:
        name: trial metric. label, unit, decimals: as the score card shows it.
        value: this trial's value (None: not available). limit: the benchmark's limit
        (mean ± k·SD). mean, sd: the experts'. higher_is_better: direction. passed: this
        trial passes it.
    """

    name: str
    label: str
    unit: str
    decimals: int
    value: float | None
    limit: float
    mean: float
    sd: float
    higher_is_better: bool
    passed: bool


@dataclass(frozen=True)
class GateCard:
    """The gate's verdict after a trial of a gated block (issue #18 §4).

    Attributes:
        block: the block. rows: each gate metric against the benchmark. passed: this trial
        passes every metric. streak, consecutive: passes in a row so far and needed.
        n_trials, max_trials: the block's trials so far and its cap. action: the stored
        decision (``vasim.study.gates.GateDecision.action``). k: the benchmark's width.
        n_expert: expert trials behind the benchmark. curve: the trainee's block so far,
        ``(trial in block (1-based), passed, values by metric)`` per trial.
    """

    block: str
    rows: tuple[GateRow, ...]
    passed: bool
    streak: int
    consecutive: int
    n_trials: int
    max_trials: int
    action: str
    k: float
    n_expert: int
    curve: tuple[tuple[int, bool, tuple[float | None, ...]], ...] = ()


def _value(metrics: Mapping[str, float], name: str, factor: float) -> float | None:
    v = metrics.get(name)
    if v is None:
        return None
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f * factor if math.isfinite(f) else None


def _mean(rows: Sequence[Mapping[str, float]], name: str, factor: float) -> float | None:
    vals = [v for r in rows if (v := _value(r, name, factor)) is not None]
    return sum(vals) / len(vals) if vals else None


def score_card(metrics: Mapping[str, float], *, title: str, outcome: str | None,
               n_points: int, earlier: Sequence[Mapping[str, float]] = (),
               benchmark: Sequence[Mapping[str, float]] = (),
               gate: GateCard | None = None) -> ScoreCard:
    """The score card of a trial from its ``trial_metrics``.

    Args:
        metrics: the trial's metrics by name (stored units: s, m, counts).
        title, outcome, n_points: the trial.
        earlier: the trainee's earlier comparable trials' metrics; each row shows their mean.
        benchmark: the benchmark trials' metrics; each row shows their mean (none: no
            benchmark column).
        gate: the proficiency gate's verdict (:func:`gate_card`), shown under the rows.
    """
    still = _value(metrics, "path_covered_frac", 1.0) == 0.0
    rows = tuple(
        ScoreRow(name, label, unit,
                 None if still and name.startswith("path_dev") else _value(metrics, name, f),
                 _mean(earlier, name, f), _mean(benchmark, name, f), dec)
        for name, label, unit, f, dec in SCORE_METRICS)
    mine = score_key(metrics)
    return ScoreCard(title=title, outcome=outcome, n_points=int(n_points), rows=rows,
                     n_earlier=len(earlier), n_benchmark=len(benchmark), gate=gate,
                     attempted=not still,
                     better_than=sum(mine > score_key(e) for e in earlier))


_GATE_ACTION_TEXT = {
    "continue": "keep going: the block's planned trials continue",
    "extend": "one more trial added: the gate asks for {need} passes in a row",
    "passed": "gate passed: {need} passes in a row — the block is done",
    "cap": "the block reached its cap of {cap} trials without passing the gate",
    "expert": "expert: not gated (your trials are part of the benchmark)",
}
"""The stored decision in words (``{need}``: passes in a row, ``{cap}``: the cap)."""


def _display(name: str) -> tuple[str, str, float, int]:
    """Label, unit, factor and decimals of a trial metric as the score card shows it."""
    for n, label, unit, factor, dec in SCORE_METRICS:
        if n == name:
            return label, unit, factor, dec
    return name.replace("_", " "), "", 1.0, 2


def gate_card(record: Mapping[str, object],
              earlier: Sequence[Mapping[str, object]] = ()) -> GateCard | None:
    """The score card's gate part from a stored decision (``vasim.study.gates``'
    ``gate_record``) and the block's earlier decisions (the trainee's curve).

    Returns:
        None for an expert's trial (no benchmark).
    """
    bench = record.get("benchmark")
    if not isinstance(bench, Mapping):
        return None
    values = record.get("values")
    passes = record.get("passes")
    assert isinstance(values, Mapping) and isinstance(passes, Mapping)
    rows = []
    for m, b in bench.items():
        assert isinstance(b, Mapping)
        label, unit, f, dec = _display(str(m))
        v = values.get(m)
        rows.append(GateRow(
            name=str(m), label=label, unit=unit, decimals=dec,
            value=None if v is None else float(v) * f,
            limit=float(b["limit"]) * f, mean=float(b["mean"]) * f,
            sd=float(b["sd"]) * f, higher_is_better=bool(b["higher_is_better"]),
            passed=bool(passes.get(m, False))))
    curve = []
    for i, r in enumerate([*earlier, record], start=1):
        vals = r.get("values")
        assert isinstance(vals, Mapping)
        curve.append((i, bool(r.get("passed")),
                      tuple(None if vals.get(row.name) is None
                            else float(vals[row.name]) * _display(row.name)[2]
                            for row in rows)))

    def num(key: str) -> int:
        v = record.get(key)
        return int(v) if isinstance(v, int | float) else 0

    k = record.get("k")
    return GateCard(block=str(record.get("block")), rows=tuple(rows),
                    passed=bool(record.get("passed")), streak=num("streak"),
                    consecutive=num("consecutive"), n_trials=num("n_trials"),
                    max_trials=num("max_trials"), action=str(record.get("action")),
                    k=float(k) if isinstance(k, int | float) else 0.0,
                    n_expert=num("expert_trials"), curve=tuple(curve))


def gate_markdown(g: GateCard) -> str:
    """The gate part of the score card: each metric against the benchmark with its
    verdict, the streak, the decision and the trainee's curve over the block (escaped)."""
    esc = html.escape
    lines = [f"#### Proficiency gate — {esc(g.block)}",
             f"**{'PASSED' if g.passed else 'not passed'}** this trial · {g.streak} in a row "
             f"({g.consecutive} needed) · trial {g.n_trials} of at most {g.max_trials}", "",
             "| Metric | This trial | Benchmark (experts) | Limit | Passed |",
             "|---|---|---|---|---|"]
    for r in g.rows:
        side = "≥" if r.higher_is_better else "≤"
        bench = f"{_fmt(r.mean, r.decimals, r.unit)} ± {_fmt(r.sd, r.decimals, r.unit)}"
        lines.append(f"| {esc(r.label)} | {esc(_fmt(r.value, r.decimals, r.unit))} | "
                     f"{esc(bench)} | {side} {esc(_fmt(r.limit, r.decimals, r.unit))} | "
                     f"{'yes' if r.passed else 'no'} |")
    text = _GATE_ACTION_TEXT.get(g.action, g.action).format(need=g.consecutive,
                                                            cap=g.max_trials)
    lines += ["", f"*{esc(text)}* (benchmark: {g.n_expert} expert trials, mean "
                  f"± {g.k:g} SD)", "", "Your curve in this block:", "",
              "| Trial | " + " | ".join(esc(r.label) for r in g.rows) + " | Passed |",
              "|---|" + "---|" * len(g.rows) + "---|"]
    for n, ok, vals in g.curve:
        cells = [esc(_fmt(v, r.decimals, r.unit)) for v, r in zip(vals, g.rows, strict=True)]
        lines.append(f"| {n} | " + " | ".join(cells) + f" | {'yes' if ok else 'no'} |")
    return "\n".join(lines)


def _fmt(v: float | None, decimals: int, unit: str) -> str:
    if v is None:
        return "—"
    return f"{v:.{decimals}f} {unit}".rstrip()


def score_card_markdown(card: ScoreCard | None) -> str:
    """The score card as markdown (escaped): a header with how the trial ended, then one row
    per metric with this trial, the mean of the earlier trials and the benchmark."""
    if card is None:
        return ""
    esc = html.escape
    ended = OUTCOME_TEXT.get(card.outcome or "", card.outcome or "ended")
    cols = ["This trial"]
    if card.n_earlier:
        cols.append(f"Your earlier {card.n_earlier} (mean)")
    if card.n_benchmark:
        cols.append(f"Benchmark ({card.n_benchmark} expert trials)")
    lines = [f"### Score card — {esc(card.title)}", f"**{esc(ended)}**", "",
             "| Metric | " + " | ".join(cols) + " |",
             "|---|" + "---|" * len(cols)]
    for r in card.rows:
        this = _fmt(r.value, r.decimals, r.unit)
        if r.name == "points_reached" and r.value is not None:
            this = f"{r.value:.0f} of {card.n_points}"
        if r.name.startswith("path_dev") and not card.attempted:
            this = f"— ({NOTHING_ATTEMPTED})"
        cells = [this]
        if card.n_earlier:
            cells.append(_fmt(r.earlier, r.decimals, r.unit))
        if card.n_benchmark:
            cells.append(_fmt(r.benchmark, r.decimals, r.unit))
        lines.append(f"| {esc(r.label)} | " + " | ".join(esc(c) for c in cells) + " |")
    if not card.n_earlier:
        lines.append("\n*Your first trial of this kind: later trials are compared with it.*")
    else:
        lines.append(f"\nBetter than {card.better_than} of your {card.n_earlier} earlier "
                     f"trials (by {', then '.join(RANK_ORDER)}).")
    if card.gate is not None:
        lines += ["", gate_markdown(card.gate)]
    return "\n".join(lines)


__all__ = ["NOTHING_ATTEMPTED", "OUTCOME_TEXT", "RANK_ORDER", "SCORE_METRICS", "GateCard",
           "GateRow", "HudInfo", "HudView",
           "ScoreCard", "ScoreRow", "audio_text", "frame_outcome", "gate_card",
           "gate_markdown", "hud_markdown", "instruction", "score_card",
           "score_card_markdown", "score_key", "state_text", "trial_title"]
