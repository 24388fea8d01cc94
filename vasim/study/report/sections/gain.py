"""The fixture gain of faded and adaptive conditions (issue #18 item 1), in the report's
"Effect of fixture" section: shown only when the protocol has a faded or adaptive block.

Two tables:

* ``vf_gain_stages``: per faded/adaptive condition and trial of its block, the planned gain
  (the schedule's stage, or "adaptive"), the realised mean gain in force (the trials'
  ``gain_mean``; a trial at gain 1 ran the plain schema and has none: 1.0), and the mean
  outcomes of those trials: how accuracy follows the withdrawn assistance;
* ``vf_probe_after_block``: per block condition (constant ones included, as the
  reference), the VF-free probe trials that close the block: what the block left behind
  once the assistance was gone (the guidance hypothesis).
"""

from __future__ import annotations

import json

import pandas as pd

from vasim.study.report.analysis import VfAnalysis
from vasim.study.report.common import FIXTURE_ORDER, fixture_label, ids_text, ordered_conditions
from vasim.study.report.data import StudyData
from vasim.study.report.html_page import Block, Paragraph, TableBlock


def _gain_mean(summary_json: object) -> float:
    """A trial's realised mean gain: ``gain_mean`` of its summary, 1.0 when absent (the
    trial ran the schema as written)."""
    if not isinstance(summary_json, str):
        return 1.0
    g = json.loads(summary_json).get("gain_mean")
    return 1.0 if g is None else float(g)


def gain_blocks(data: StudyData, vf: VfAnalysis) -> list[Block]:
    """The gain tables (module docstring), or nothing when no block fades or adapts."""
    p = data.protocol
    if p is None or vf.trials.empty:
        return []
    blocks = {b.name: b for b in p.blocks}
    gained = {b.condition for b in p.blocks if b.has_gain}
    if not gained:
        return []
    t = vf.trials.merge(data.schedule[["trial_id", "trial_in_block"]], on="trial_id",
                        how="left")
    summaries = dict(zip(data.trials["id"], data.trials["summary_json"], strict=True))
    t["gain_mean"] = [_gain_mean(summaries.get(i)) for i in t["trial_id"]]
    dvs = [c for c in ("path_deviation", "latency", "eq65") if c in t.columns]
    rows = []
    assisted = t[t["condition"].isin(gained) & ~t["probe"].astype(bool)]
    for cond in ordered_conditions(assisted["condition"], FIXTURE_ORDER):
        part = assisted[assisted["condition"] == cond]
        for k, g in part.groupby("trial_in_block", sort=True):
            rule = blocks[str(g["block"].iloc[0])].trial_gain(int(k))
            rows.append({"condition": fixture_label(cond), "trial_in_block": int(k) + 1,
                         "planned_gain": rule if isinstance(rule, float) else "adaptive",
                         "n": len(g), "gain_mean": float(g["gain_mean"].mean()),
                         **{dv: float(g[dv].mean()) for dv in dvs},
                         "trial_ids": ids_text(g["trial_id"])})
    out: list[Block] = [Paragraph(
        "Fixture gain (issue #18): a faded condition runs its block's trials at the "
        "schedule's gains in order, an adaptive one lets the gain follow the trainee's path "
        "deviation within its bounds (vasim.fixtures.gain). gain_mean: the realised mean "
        "gain in force over the trials' samples (stored per sample, samples.gain).")]
    if rows:
        out.append(TableBlock(
            "vf_gain_stages", "Faded and adaptive conditions by trial of the block",
            pd.DataFrame(rows),
            "trial_in_block: 1-based; planned_gain: the schedule's stage or 'adaptive'; n: "
            "trials (one per subject); outcomes: mean over those trials (units as in the "
            "tables above)."))
    probes = t[t["probe"].astype(bool) & ~t["baseline"].astype(bool)]
    prow = []
    for name, g in probes.groupby("block", sort=False):
        cond = blocks[str(name)].condition if str(name) in blocks else str(name)
        prow.append({"block_condition": cond, "n": len(g),
                     **{dv: float(g[dv].mean()) for dv in dvs},
                     "trial_ids": ids_text(g["trial_id"])})
    if prow:
        pr = pd.DataFrame(prow)
        order = ordered_conditions(pr["block_condition"], FIXTURE_ORDER)
        pr = pr.set_index("block_condition").loc[order].reset_index()
        pr["block_condition"] = pr["block_condition"].map(fixture_label)
        out.append(TableBlock(
            "vf_probe_after_block", "VF-free probe trials after each block", pr,
            "The VF-free trials that close each block, by the block's condition: lower "
            "values after a faded or adaptive block than after the constant one mean less "
            "reliance on the assistance (the guidance hypothesis); mean over the probes."))
    return out


__all__ = ["gain_blocks"]
