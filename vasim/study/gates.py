"""Proficiency gates (issue #18 §4): an expert benchmark per metric, the pass of a trial,
the decision to add a trial to a gated block, and the stored record of each decision.

Pure part: :func:`expert_benchmark` (mean ± k·SD per metric), :func:`judge` (a trial's
pass per metric), :func:`decide` (continue / extend / passed / cap). Stateful shell:
:func:`apply_gates` reads a session's gated trials, decides in order the ones without a
decision, and stores each decision as a ``'gate'`` event on the trial that made it (JSON,
:func:`gate_record`); an extension inserts the new scheduled trial in the same transaction
(``TrialStore.insert_scheduled``), so resume and reports replay the stored decisions and
never recompute them.

**Decisions**:

* The benchmark of a gated block is computed from the completed trials of **the same block
  of the same protocol** (sessions of ``protocol.name``) by subjects of the gate's
  ``expert_group`` (demographics ``subject_group``; a simulated subject without
  demographics: its cohort group), the trainee excluded: like is compared with like (same
  condition, trajectories, practice before it). It is computed once, at the block's first
  trial of the session, and stored with every decision of the block (a benchmark that
  changed mid-block as experts were added would make the decisions irreproducible).
* limit = mean + k·SD for metrics where lower is better (times, errors, deviations,
  counts), mean − k·SD for :data:`HIGHER_IS_BETTER`; SD is the sample SD (ddof = 1) over
  the expert trials (at least 2; NaN values are left out). A trial passes a metric when its
  value is on the good side of the limit (equal passes); a NaN value fails. It passes the
  gate when it passes every metric.
* The block's scheduled trials are its minimum: they all run; after the last of them, a
  trial is added while the trailing run of passes is shorter than ``consecutive`` and the
  block holds fewer than ``max_trials``.
* Subjects of the expert group are not gated (they supply the benchmark): their decisions
  are stored as ``expert`` and never extend the block.

Example:
    >>> b = expert_benchmark({"duration": [10.0, 12.0, 14.0]}, ("duration",), k=1.0)
    >>> b["duration"].mean, b["duration"].sd, b["duration"].limit
    (12.0, 2.0, 14.0)
    >>> judge({"duration": 13.5}, b), decide([True, False, True, True], n_scheduled=3,
    ...                                       consecutive=2, max_trials=10).action
    ({'duration': True}, 'passed')
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any, Literal

import numpy as np
import pandas as pd

from vasim.core.config import expect
from vasim.core.errors import ConfigError
from vasim.study.protocol import Block, Protocol, gated_blocks, gated_trials
from vasim.study.protocol.schedule import extend_gated_block
from vasim.study.stored_session import read_session

GATE_EVENT = "gate"
"""``events.kind`` of a stored gate decision."""

HIGHER_IS_BETTER: frozenset[str] = frozenset({
    "points_reached", "completed", "log_dimensionless_jerk"})
"""Trial metrics where a larger value is better (the rest: lower is better)."""

Action = Literal["continue", "extend", "passed", "cap", "expert"]


@dataclass(frozen=True)
class MetricBenchmark:
    """The benchmark of one metric.

    Attributes:
        metric: trial-metric name. mean, sd: of the expert trials (stored units). n: expert
        trials used. k: width factor. higher_is_better: direction.
    """

    metric: str
    mean: float
    sd: float
    n: int
    k: float
    higher_is_better: bool

    @property
    def limit(self) -> float:
        """mean − k·SD (higher is better) or mean + k·SD."""
        return self.mean - self.k * self.sd if self.higher_is_better \
            else self.mean + self.k * self.sd

    def passes(self, value: float) -> bool:
        """Whether ``value`` is on the good side of the limit (NaN fails)."""
        if not math.isfinite(value):
            return False
        return value >= self.limit if self.higher_is_better else value <= self.limit


def expert_benchmark(values: Mapping[str, Sequence[float]], metrics: Sequence[str],
                     k: float) -> dict[str, MetricBenchmark]:
    """The benchmark of each metric from the expert trials' values (module decisions).

    Args:
        values: metric -> the expert trials' values (stored units; NaN left out).
        metrics: the gate's metrics. k: width factor (>= 0).

    Raises:
        ConfigError: a metric with fewer than 2 finite expert values.
    """
    out = {}
    for m in metrics:
        v = np.asarray(values.get(m, ()), dtype=float)
        v = v[np.isfinite(v)]
        expect(len(v) >= 2, len(v), f"at least 2 finite expert values of {m!r} (an SD "
               "needs two)", field="gate.metrics")
        out[m] = MetricBenchmark(m, float(v.mean()), float(v.std(ddof=1)), len(v),
                                 float(k), m in HIGHER_IS_BETTER)
    return out


def judge(metrics: Mapping[str, float], bench: Mapping[str, MetricBenchmark],
          ) -> dict[str, bool]:
    """A trial's pass of each benchmark metric (a missing value fails)."""
    return {m: b.passes(float(metrics.get(m, math.nan))) for m, b in bench.items()}


@dataclass(frozen=True)
class GateDecision:
    """What happens after a gated trial.

    Attributes:
        streak: trailing passes in a row. n_trials: the block's trials so far.
        action: ``continue`` (scheduled trials remain), ``extend`` (a trial is added),
            ``passed`` (the gate is passed: the block ends), ``cap`` (the block is at its
            cap without a pass), ``expert`` (not gated).
    """

    streak: int
    n_trials: int
    action: Action


def decide(passes: Sequence[bool], *, n_scheduled: int, consecutive: int,
           max_trials: int) -> GateDecision:
    """The decision after the block's trials so far (module decisions).

    Args:
        passes: each done trial's gate pass, in order.
        n_scheduled: the block's trials in the schedule (done and pending).
        consecutive: passes in a row needed. max_trials: the block's cap.
    """
    streak = 0
    for p in reversed(passes):
        if not p:
            break
        streak += 1
    n = len(passes)
    action: Action
    if n < n_scheduled:
        action = "continue"
    elif streak >= consecutive:
        action = "passed"
    elif n >= max_trials:
        action = "cap"
    else:
        action = "extend"
    return GateDecision(streak, n, action)


# ------------------------------------------------------------------------ the store shell
def gate_record(block: Block, trial_index: int, values: Mapping[str, float],
                bench: Mapping[str, MetricBenchmark] | None, passes: Mapping[str, bool],
                decision: GateDecision, expert_trials: int) -> dict[str, Any]:
    """The JSON record of one decision (the ``'gate'`` event's detail)."""
    assert block.gate is not None
    return {
        "block": block.name, "trial_index": int(trial_index),
        "values": {m: (None if not math.isfinite(v) else float(v)) for m, v in values.items()},
        "benchmark": None if bench is None else {m: asdict(b) | {"limit": b.limit}
                                                 for m, b in bench.items()},
        "expert_trials": int(expert_trials),
        "passes": dict(passes), "passed": bool(passes) and all(passes.values()),
        "streak": decision.streak, "n_trials": decision.n_trials, "action": decision.action,
        "consecutive": block.gate.consecutive, "max_trials": block.gate.max_trials,
        "k": block.gate.k,
    }


def benchmark_of(record: Mapping[str, Any]) -> dict[str, MetricBenchmark] | None:
    """The benchmark stored in a decision record (None: an expert's, no benchmark)."""
    raw = record.get("benchmark")
    if raw is None:
        return None
    return {m: MetricBenchmark(metric=b["metric"], mean=float(b["mean"]), sd=float(b["sd"]),
                               n=int(b["n"]), k=float(b["k"]),
                               higher_is_better=bool(b["higher_is_better"]))
            for m, b in raw.items()}


def subject_group(store: Any, subject: str, config: Mapping[str, Any] | None) -> str | None:
    """The subject's group: demographics ``subject_group``, else the simulated cohort's
    group stored with the session, else None."""
    demo = store.demographics()
    row = demo[demo["subject"] == subject]
    if len(row):
        return str(row["subject_group"].iloc[0])
    cohort = ((config or {}).get("extra") or {}).get("cohort") or {}
    g = cohort.get("group")
    return None if g is None else str(g)


def expert_trials(store: Any, protocol: Protocol, block: Block, exclude: str,
                  ) -> list[int]:
    """Completed trial ids of the gate's expert group in ``block`` of ``protocol``'s
    sessions (the trainee ``exclude`` left out)."""
    assert block.gate is not None
    rows = store.con.execute(
        "SELECT q.trial_id, s.subject, s.config_json FROM scheduled_trials q JOIN sessions s "
        "ON s.id = q.session_id WHERE s.protocol = ? AND q.block = ? AND q.trial_id IS NOT "
        "NULL AND q.probe = 0 ORDER BY q.trial_id", (protocol.name, block.name)).fetchall()
    groups: dict[str, str | None] = {}
    out = []
    for tid, subj, cfg in rows:
        if subj == exclude:
            continue
        if subj not in groups:
            groups[subj] = subject_group(store, subj, json.loads(cfg) if cfg else None)
        if groups[subj] == block.gate.expert_group:
            out.append(int(tid))
    return out


def expert_groups(protocol: Protocol) -> frozenset[str]:
    """The groups whose trials are a benchmark of the protocol's gates: a simulated cohort
    runs their sessions first (empty without a gate)."""
    return frozenset(b.gate.expert_group for b in gated_blocks(protocol)
                     if b.gate is not None)


def gate_records(store: Any, session_id: int) -> list[tuple[int, dict[str, Any]]]:
    """The stored decisions of a session: ``(trial id, record)`` in trial order."""
    rows = store.con.execute(
        "SELECT e.trial_id, e.detail FROM events e JOIN scheduled_trials q ON q.trial_id = "
        "e.trial_id WHERE q.session_id = ? AND e.kind = ? ORDER BY q.trial_index, e.id",
        (int(session_id), GATE_EVENT)).fetchall()
    return [(int(t), json.loads(d)) for t, d in rows]


GATE_FRAME_COLUMNS: tuple[str, ...] = (
    "session_id", "subject", "trial_id", "block", "trial_index", "n_trials", "passed",
    "streak", "action", "record")
"""Columns of :func:`gate_frame` (``record``: the decision's JSON)."""


def gate_frame(store: Any, session_ids: Sequence[int]) -> pd.DataFrame:
    """Every stored gate decision of the sessions, one row each (``GATE_FRAME_COLUMNS``),
    in session and schedule order (for the report)."""
    rows = []
    for sid in session_ids:
        subject = store.session(int(sid))["subject"]
        for tid, rec in gate_records(store, int(sid)):
            rows.append((int(sid), subject, tid, rec["block"], rec["trial_index"],
                         rec["n_trials"], bool(rec["passed"]), rec["streak"], rec["action"],
                         json.dumps(rec, sort_keys=True)))
    return pd.DataFrame(rows, columns=list(GATE_FRAME_COLUMNS))


def _metrics_of(store: Any, ids: Sequence[int], metrics: Sequence[str]) -> pd.DataFrame:
    if not ids:
        return pd.DataFrame(columns=list(metrics), dtype=float)
    wide = store.trial_metrics(wide=True)
    wide = wide[wide.index.isin(list(ids))]
    return wide.reindex(columns=list(metrics))


def apply_gates(store: Any, session_id: int) -> int:
    """Decides and stores every gated trial of a session that has no decision yet, in
    schedule order; returns the number of trials added.

    Raises:
        ConfigError: a trainee's gate without a benchmark (fewer than 2 expert trials of
            the block in the store).
    """
    session = read_session(store, session_id)
    protocol = session.protocol
    if session.status != "running" or not gated_blocks(protocol):
        return 0
    done = dict(gate_records(store, session.id))
    added = 0
    config = store.session(session.id)["config"]
    group = subject_group(store, session.subject, config)
    for block in gated_blocks(protocol):
        assert block.gate is not None
        gate = block.gate
        while True:
            session = read_session(store, session.id)
            own = gated_trials(session.schedule, block)
            ids = [session.completed[t.index] for t in own]
            todo = next((i for i, tid in enumerate(ids) if tid is not None
                         and tid not in done), None)
            if todo is None:
                break
            tid = ids[todo]
            assert tid is not None
            earlier = [done[t] for t in ids[:todo] if t is not None and t in done]
            vals = _metrics_of(store, [tid], gate.metrics)
            values = {m: float(vals[m].iloc[0]) if len(vals) else math.nan
                      for m in gate.metrics}
            if group == gate.expert_group:
                rec = gate_record(block, own[todo].index, values, None, {},
                                  GateDecision(0, todo + 1, "expert"), 0)
            else:
                bench = benchmark_of(earlier[0]) if earlier else None
                n_exp = earlier[0]["expert_trials"] if earlier else 0
                if bench is None:
                    exp_ids = expert_trials(store, protocol, block, session.subject)
                    table = _metrics_of(store, exp_ids, gate.metrics)
                    try:
                        bench = expert_benchmark({m: table[m].tolist() for m in gate.metrics},
                                                 gate.metrics, gate.k)
                    except ConfigError as exc:
                        raise ConfigError(
                            f"the gate of block {block.name!r} (protocol {protocol.name!r}) "
                            f"has no benchmark for subject {session.subject!r}: "
                            f"{exc.reason}; {len(exp_ids)} completed trial(s) of group "
                            f"{gate.expert_group!r} in this block in {store.path}. Run the "
                            "experts' sessions first", field=f"blocks.{block.name}.gate"
                        ) from exc
                    n_exp = len(exp_ids)
                passes = judge(values, bench)
                history = [bool(r["passed"]) for r in earlier] + [all(passes.values())]
                dec = decide(history, n_scheduled=len(own), consecutive=gate.consecutive,
                             max_trials=gate.max_trials)
                rec = gate_record(block, own[todo].index, values, bench, passes, dec, n_exp)
            detail = json.dumps(rec, sort_keys=True)
            if rec["action"] == "extend":
                new = extend_gated_block(protocol, session.schedule, block.name)
                row = next(t for t in new if t.block == block.name
                           and t.trial_in_block == len(own) and not t.probe)
                store.insert_scheduled(session.id, row.as_row(), event_trial_id=tid,
                                       kind=GATE_EVENT, detail=detail)
                added += 1
            else:
                store.add_event(tid, GATE_EVENT, detail)
            done[tid] = rec
    return added


__all__ = ["GATE_EVENT", "GATE_FRAME_COLUMNS", "HIGHER_IS_BETTER", "GateDecision",
           "MetricBenchmark", "apply_gates", "benchmark_of", "decide", "expert_benchmark",
           "expert_groups", "expert_trials", "gate_frame", "gate_record", "gate_records", "judge",
           "subject_group"]
