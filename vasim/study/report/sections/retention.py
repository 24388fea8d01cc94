"""Acquisition, retention and transfer side by side (issue #18 §2): per subject the last
VF-free probe of the acquisition phase, the mean of the delayed VF-free retention probes
and the mean of the VF-free transfer probes on untrained trajectories; their summary, the
paired comparisons and a figure.

**Decisions**: the acquisition level is the *last* VF-free probe before the retention
sitting (the end of acquisition, what retention is measured against: Schmidt & Lee's
retention test compares with the end of practice, not its average); a subject enters a
paired comparison when it has both of its levels (pairs are analysed separately, so a
subject without transfer trials still counts for acquisition vs retention).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd

from vasim.core.errors import ConfigError
from vasim.study import stats
from vasim.study.protocol import Protocol
from vasim.study.report.common import SectionOut, captured, prov_row
from vasim.study.report.data import StudyData
from vasim.study.report.figures import PALETTE, _new_figure, figure_png
from vasim.study.report.html_page import Block, FigureBlock, Paragraph, Section, TableBlock

TITLE = "Acquisition, retention and transfer"
PHASE_ORDER: tuple[str, ...] = ("acquisition", "retention", "transfer")
RETENTION_DVS: tuple[tuple[str, str, str], ...] = (
    ("path_dev_mean_mm", "mean distance from the path", "mm"),
    ("duration", "trial duration", "s"),
)
"""Outcomes compared (trial metric, meaning, unit): accuracy independent of speed, time."""


def phase_cells(data: StudyData, protocol: Protocol) -> pd.DataFrame:
    """Per subject x phase x outcome: the value of the level (module docstring).

    Returns:
        Columns ``subject, phase, dv, value, n_trials, trial_ids`` (``trial_ids``: the
        trials behind the value, comma-separated).
    """
    phase_of = {b.name: b.phase for b in protocol.blocks}
    done = data.analysed
    if done.empty:
        return pd.DataFrame(columns=["subject", "phase", "dv", "value", "n_trials",
                                     "trial_ids"])
    done = done.assign(phase=done["block"].map(phase_of))
    rows = []
    for subject, g in done.groupby("subject", sort=True):
        g = g.sort_values("trial_index")
        later = g[g["phase"] != "acquisition"]
        first_later = int(later["trial_index"].min()) if len(later) else math.inf
        acq = g[(g["phase"] == "acquisition") & g["probe"].astype(bool)
                & (g["trial_index"] < first_later)]
        picks = {"acquisition": [int(acq["trial_id"].iloc[-1])] if len(acq) else [],
                 "retention": [int(i) for i in g.loc[g["phase"] == "retention", "trial_id"]],
                 "transfer": [int(i) for i in g.loc[g["phase"] == "transfer", "trial_id"]]}
        for phase, ids in picks.items():
            if not ids:
                continue
            for dv, _, _ in RETENTION_DVS:
                vals = [float(data.metrics.at[i, dv]) if (i in data.metrics.index and
                                                           dv in data.metrics.columns)
                        else math.nan for i in ids]
                finite = [v for v in vals if math.isfinite(v)]
                rows.append({"subject": subject, "phase": phase, "dv": dv,
                             "value": float(np.mean(finite)) if finite else math.nan,
                             "n_trials": len(finite),
                             "trial_ids": ",".join(map(str, ids))})
    return pd.DataFrame(rows, columns=["subject", "phase", "dv", "value", "n_trials",
                                       "trial_ids"])


def phase_summary(cells: pd.DataFrame) -> pd.DataFrame:
    """Per outcome x phase: subjects, mean, SD (ddof = 1), median."""
    rows = []
    for (dv, phase), g in cells.dropna(subset=["value"]).groupby(["dv", "phase"]):
        v = g["value"].to_numpy(float)
        rows.append({"dv": dv, "phase": phase, "n": len(v), "mean": float(v.mean()),
                     "sd": float(v.std(ddof=1)) if len(v) > 1 else math.nan,
                     "median": float(np.median(v))})
    out = pd.DataFrame(rows, columns=["dv", "phase", "n", "mean", "sd", "median"])
    order = {p: i for i, p in enumerate(PHASE_ORDER)}
    return out.sort_values(["dv", "phase"], key=lambda s: s.map(order) if s.name == "phase"
                           else s).reset_index(drop=True)


def phase_pairs(cells: pd.DataFrame) -> tuple[pd.DataFrame, list[str]]:
    """Paired t-tests acquisition vs retention, acquisition vs transfer, retention vs
    transfer per outcome (``stats.pairwise_paired`` on the subjects with both levels;
    Holm over the three pairs of an outcome, recomputed here as pairs differ in n)."""
    from statsmodels.stats.multitest import multipletests

    parts, notes = [], []
    for dv, _, unit in RETENTION_DVS:
        d = cells[(cells["dv"] == dv)].dropna(subset=["value"])
        rows = []
        for a, b in (("acquisition", "retention"), ("acquisition", "transfer"),
                     ("retention", "transfer")):
            pair = d[d["phase"].isin((a, b))]
            both = pair.groupby("subject")["phase"].nunique()
            keep = pair[pair["subject"].isin(both[both == 2].index)]
            if keep["subject"].nunique() < 2:
                if pair["phase"].nunique() == 2 or (a in set(d["phase"])
                                                    and b in set(d["phase"])):
                    notes.append(f"{dv}: {a} vs {b} needs 2 subjects with both levels")
                continue
            keep = keep.assign(phase=pd.Categorical(keep["phase"], [a, b], ordered=True))
            try:
                pp, msgs = captured(stats.pairwise_paired, keep, dv="value",
                                    subject="subject", within="phase")
            except ConfigError as exc:
                notes.append(f"{dv}: {a} vs {b} not computed: {exc.reason}")
                continue
            notes.extend(f"{dv}, {a} vs {b}: {m}" for m in msgs)
            rows.append(pp)
        if not rows:
            continue
        t = pd.concat(rows, ignore_index=True)
        ok = np.isfinite(t["p"].to_numpy(float))
        t["p_holm"] = np.nan
        if ok.any():
            t.loc[ok, "p_holm"] = multipletests(t.loc[ok, "p"].to_numpy(float),
                                                method="holm")[1]
        t.insert(0, "dv", dv)
        t.insert(1, "unit", unit)
        parts.append(t)
    if not parts:
        return pd.DataFrame(), notes
    return pd.concat(parts, ignore_index=True), notes


def phases_figure(cells: pd.DataFrame, summary: pd.DataFrame) -> bytes:
    """One panel per outcome: every subject's levels joined (thin), the mean ± SD (thick)."""
    dvs = [d for d in RETENTION_DVS if d[0] in set(cells["dv"])]
    fig = _new_figure(4.2 * max(len(dvs), 1), 3.4)
    axes = fig.subplots(1, max(len(dvs), 1), squeeze=False)[0]
    x_of = {p: i for i, p in enumerate(PHASE_ORDER)}
    for ax, (dv, meaning, unit) in zip(axes, dvs, strict=False):
        d = cells[cells["dv"] == dv].dropna(subset=["value"])
        for _, g in d.groupby("subject"):
            g = g.sort_values("phase", key=lambda s: s.map(x_of))
            ax.plot(g["phase"].map(x_of), g["value"], color="#999999", lw=0.6, alpha=0.6)
        s = summary[summary["dv"] == dv].sort_values("phase", key=lambda c: c.map(x_of))
        ax.errorbar(s["phase"].map(x_of), s["mean"], yerr=s["sd"].fillna(0.0), color=PALETTE[0],
                    lw=2, marker="o", capsize=4, label="mean ± SD")
        ax.set_xticks(range(len(PHASE_ORDER)), list(PHASE_ORDER))
        ax.set_ylabel(f"{meaning} [{unit}]")
        ax.set_title(dv)
        ax.legend(loc="best", fontsize=8)
    return figure_png(fig)


def _delays_text(data: StudyData, protocol: Protocol) -> str:
    delays = [f"{b.name} {b.delay_days:g} d" for b in protocol.blocks if b.delay_days > 0]
    n_sim = n_real = 0
    for rec in data.sittings.get("record", pd.Series(dtype=str)):
        r = json.loads(rec)
        n_sim += bool(r.get("simulated"))
        n_real += not r.get("simulated")
    return (f"Delays before a later sitting (protocol): {', '.join(delays) or 'none'}; "
            f"stored sittings: {n_sim} simulated (a recorded date offset, no real waiting), "
            f"{n_real} after a real delay.")


def retention_section(data: StudyData) -> tuple[Section, list[dict[str, str]]]:
    """The section (tables ``retention_phases``, ``retention_pairs``,
    ``retention_cells``); empty when the protocol has no retention or transfer block."""
    out = SectionOut()
    protocol = data.protocol
    if protocol is None or not any(b.phase != "acquisition" for b in protocol.blocks):
        return out.section("retention", TITLE, [Paragraph(
            "The protocol has no retention or transfer block.")]), []
    intro: list[Block] = [Paragraph(
        "Methods. Per subject, three levels of each outcome: acquisition = the last VF-free "
        "probe trial before the retention sitting (the end of practice), retention = the "
        "mean of the VF-free retention probes after the delay (a later sitting, on the "
        "trained trajectory), transfer = the mean of the VF-free probes on trajectories no "
        "block trained (checked when the protocol loads). Paired Student t-tests "
        "acquisition vs retention (forgetting), acquisition vs transfer and retention vs "
        "transfer (what carries to a new path), each on the subjects with both levels; "
        "mean difference = first minus second level with its 95 % CI, Cohen's d_z; Holm "
        "adjustment over the three pairs of an outcome. " + _delays_text(data, protocol))]
    cells = phase_cells(data, protocol)
    if cells.empty:
        out.notes.append("no completed trial: nothing to compare")
        return out.section("retention", TITLE, intro), []
    summary = phase_summary(cells)
    pairs, notes = phase_pairs(cells)
    out.notes.extend(notes)
    out.blocks.append(TableBlock(
        "retention_phases", "Acquisition, retention and transfer: summary", summary,
        "Per outcome and level: subjects (n), mean, SD (ddof 1) and median of the "
        "per-subject values; retention_cells.csv lists every subject's value and trials."))
    if not pairs.empty:
        out.blocks.append(TableBlock(
            "retention_pairs", "Paired comparisons of the levels", pairs,
            "group1 - group2: mean_diff with ci_low..ci_high (95 %), t, df, p, cohen_dz; "
            "p_holm over the pairs of an outcome.",
            columns=("dv", "unit", "group1", "group2", "n", "mean_diff", "ci_low",
                     "ci_high", "t", "df", "p", "p_holm", "cohen_dz")))
    out.blocks.append(TableBlock(
        "retention_cells", "Per-subject levels", cells,
        "The value of every subject, level and outcome, with the trials behind it.",
        display="csv"))
    out.blocks.append(FigureBlock(
        "retention_figure", "Acquisition, retention and transfer",
        phases_figure(cells, summary),
        "Grey: each subject's levels; blue: mean ± SD (table retention_phases)."))
    prov = [prov_row("retention_cells", f"{r.phase}/{r.dv}", str(r.subject),
                     trial_ids=str(r.trial_ids).split(","))
            for r in cells.itertuples()]
    return out.section("retention", TITLE, intro), prov


__all__ = ["PHASE_ORDER", "RETENTION_DVS", "phase_cells", "phase_pairs", "phase_summary",
           "phases_figure", "retention_section"]
