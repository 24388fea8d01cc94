"""Proficiency gates (issue #18 §4): every trainee's gated blocks — trials needed, passed
or stopped at the cap — the benchmark each was judged against, and the trainees' curves
against the benchmark. Everything is read from the stored decisions
(``vasim.study.gates``): the report replays them and recomputes nothing.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd

from vasim.records.trial_metrics import TRIAL_METRICS
from vasim.study.report.common import SectionOut, prov_row
from vasim.study.report.data import StudyData
from vasim.study.report.figures import PALETTE, _new_figure, figure_png
from vasim.study.report.html_page import Block, FigureBlock, Paragraph, Section, TableBlock

TITLE = "Proficiency gates"


def gate_outcomes(gates: pd.DataFrame) -> pd.DataFrame:
    """Per session x gated block: trials run, the last decision, and whether it passed.

    Returns:
        Columns ``subject, session_id, block, n_trials, outcome, first_pass_trial,
        trial_ids``; ``outcome``: ``passed``, ``cap``, ``expert`` or ``running`` (no final
        decision yet).
    """
    cols = ["subject", "session_id", "block", "n_trials", "outcome", "first_pass_trial",
            "trial_ids"]
    rows = []
    for (sid, block), g in gates.groupby(["session_id", "block"], sort=True):
        g = g.sort_values("n_trials")
        last = str(g["action"].iloc[-1])
        outcome = last if last in ("passed", "cap", "expert") else "running"
        passed = g[g["passed"].astype(bool)]
        rows.append({"subject": g["subject"].iloc[0], "session_id": int(sid), "block": block,
                     "n_trials": int(g["n_trials"].max()), "outcome": outcome,
                     "first_pass_trial": int(passed["n_trials"].iloc[0]) if len(passed)
                     else None,
                     "trial_ids": ",".join(str(int(t)) for t in g["trial_id"])})
    out = pd.DataFrame(rows, columns=cols)
    out["first_pass_trial"] = pd.array(out["first_pass_trial"].tolist(), dtype="Int64")
    return out


def gate_benchmarks(gates: pd.DataFrame) -> pd.DataFrame:
    """The benchmark of each (session, block) as stored with its first decision.

    Returns:
        Columns ``subject, block, metric, mean, sd, n, k, limit, higher_is_better``.
    """
    rows = []
    for (_sid, block), g in gates.groupby(["session_id", "block"], sort=True):
        rec = json.loads(g.sort_values("n_trials")["record"].iloc[0])
        for m, b in (rec.get("benchmark") or {}).items():
            rows.append({"subject": g["subject"].iloc[0], "block": block, "metric": m,
                         **{k: b[k] for k in ("mean", "sd", "n", "k", "limit",
                                              "higher_is_better")}})
    return pd.DataFrame(rows, columns=["subject", "block", "metric", "mean", "sd", "n", "k",
                                       "limit", "higher_is_better"])


def gate_curves(gates: pd.DataFrame) -> pd.DataFrame:
    """Every trainee decision's metric values: ``subject, block, n, metric, value,
    limit, passed``."""
    rows = []
    for r in gates.itertuples():
        rec = json.loads(str(r.record))
        for m, b in (rec.get("benchmark") or {}).items():
            v = rec["values"].get(m)
            rows.append({"subject": r.subject, "block": r.block, "n": int(rec["n_trials"]),
                         "metric": m, "value": math.nan if v is None else float(v),
                         "limit": float(b["limit"]), "passed": bool(rec["passes"].get(m))})
    return pd.DataFrame(rows, columns=["subject", "block", "n", "metric", "value", "limit",
                                       "passed"])


def curves_figure(curves: pd.DataFrame) -> bytes:
    """One panel per block x metric: each trainee's values over the block's trials, the
    benchmark's limit (dashed), passes filled."""
    keys = list(curves.groupby(["block", "metric"], sort=True).groups)
    fig = _new_figure(4.2 * max(len(keys), 1), 3.4)
    axes = fig.subplots(1, max(len(keys), 1), squeeze=False)[0]
    for ax, (block, metric) in zip(axes, keys, strict=False):
        d = curves[(curves["block"] == block) & (curves["metric"] == metric)]
        for i, (_, g) in enumerate(d.groupby("subject", sort=True)):
            c = PALETTE[i % len(PALETTE)]
            ax.plot(g["n"], g["value"], color=c, lw=1)
            ok = g["passed"].astype(bool)
            ax.scatter(g.loc[ok, "n"], g.loc[ok, "value"], color=c, s=18)
            ax.scatter(g.loc[~ok, "n"], g.loc[~ok, "value"], facecolors="none",
                       edgecolors=c, s=18)
        lim = float(np.median(d["limit"])) if len(d) else math.nan
        if math.isfinite(lim):
            ax.axhline(lim, color="black", ls="--", lw=1, label="limit (mean ± k·SD)")
            ax.legend(loc="best", fontsize=8)
        ax.set_xlabel(f"trial of block {block}")
        unit = TRIAL_METRICS.get(str(metric), ("", ""))[0]
        ax.set_ylabel(f"{metric} [{unit}]" if unit else str(metric))
    return figure_png(fig)


def proficiency_section(data: StudyData) -> tuple[Section, list[dict[str, str]]]:
    """The section (tables ``gate_outcomes``, ``gate_benchmarks``, ``gate_curves``);
    a sentence when the protocol has no gate."""
    out = SectionOut()
    protocol = data.protocol
    gated = [b for b in protocol.blocks if b.gate is not None] if protocol else []
    if not gated:
        return out.section("proficiency", TITLE, [Paragraph(
            "The protocol has no proficiency gate.")]), []
    desc = "; ".join(
        f"block {b.name}: {', '.join(b.gate.metrics)} within mean ± {b.gate.k:g} SD of "
        f"group {b.gate.expert_group!r}, {b.gate.consecutive} passes in a row, at least "
        f"{len(b.variants) * b.repetitions} and at most {b.gate.max_trials} trials"
        for b in gated if b.gate is not None)
    intro: list[Block] = [Paragraph(
        "Methods. A gated block's trials are judged against a benchmark from the expert "
        "group's trials of the same block (limit = mean + k·SD, or mean − k·SD where "
        "higher is better; sample SD), computed once per trainee at the block's first trial "
        "and stored with every decision; a trial passes when it passes every metric; trials "
        "are added one at a time after the block's scheduled ones until the last passes "
        "are consecutive enough or the cap is reached. Experts run the block ungated. The "
        f"decisions are read as stored. {desc}.")]
    gates = data.gates
    if gates.empty:
        out.notes.append("no stored gate decision")
        return out.section("proficiency", TITLE, intro), []
    outcomes = gate_outcomes(gates)
    trainees = outcomes[outcomes["outcome"] != "expert"]
    summary = (trainees.groupby(["block", "outcome"]).agg(
        subjects=("subject", "nunique"), mean_trials=("n_trials", "mean"),
        min_trials=("n_trials", "min"), max_trials=("n_trials", "max")).reset_index()
        if len(trainees) else pd.DataFrame(columns=["block", "outcome", "subjects"]))
    out.blocks.append(TableBlock(
        "gate_summary", "Gate outcomes", summary,
        "Trainees per gated block and outcome (passed / cap / running) with the trials "
        "they needed (mean, min, max)."))
    out.blocks.append(TableBlock(
        "gate_outcomes", "Gate outcome of every session", outcomes,
        "One row per session x gated block; first_pass_trial: the first trial that passed."))
    bench = gate_benchmarks(gates)
    if len(bench):
        out.blocks.append(TableBlock(
            "gate_benchmarks", "Benchmarks", bench,
            "The benchmark each trainee was judged against (stored units; n expert trials).",
            display="details"))
    curves = gate_curves(gates)
    if len(curves):
        out.blocks.append(TableBlock("gate_curves", "Trainee curves", curves,
                                     "Every judged trial's values and limits.", display="csv"))
        out.blocks.append(FigureBlock(
            "gate_figure", "Trainees against the benchmark", curves_figure(curves),
            "Each trainee's values over the gated block (filled: passed, open: not); dashed: "
            "the limit (table gate_curves)."))
    prov = [prov_row("gate_outcomes", str(r.block), str(r.subject),
                     session_ids=[r.session_id], trial_ids=str(r.trial_ids).split(","))
            for r in outcomes.itertuples()]
    return out.section("proficiency", TITLE, intro), prov


__all__ = ["curves_figure", "gate_benchmarks", "gate_curves", "gate_outcomes",
           "proficiency_section"]
