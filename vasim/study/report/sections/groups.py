"""The surgeons-vs-residents section: a mixed-design ANOVA, group (between) x probe trial
(within), over the VF-free probe trials (the curves per group are in the learning-curve
section)."""

from __future__ import annotations

import pandas as pd

from vasim.core.errors import ConfigError
from vasim.study.report.analysis import VfAnalysis, excluded_text
from vasim.study.report.common import SectionOut, captured, prov_row
from vasim.study.report.data import StudyData
from vasim.study.report.html_page import Block, Paragraph, Section, TableBlock
from vasim.study.report.models import group_design, group_mixed_anova
from vasim.study.report.sections.learning import probe_cells_with_group

TITLE = "Surgeons vs residents"


def group_section(data: StudyData, vf: VfAnalysis) -> tuple[Section, list[dict[str, str]]]:
    """Mixed ANOVA group x probe trial of every VF outcome (table ``vf_group_anova``).

    Returns:
        The section and its provenance rows (the probe trials of every subject x trial cell).
    """
    out = SectionOut()
    intro: list[Block] = [Paragraph(
        "Methods. Mixed-design ANOVA per outcome: group (surgeon / resident, from the "
        "pre-questionnaire) between subjects x VF-free probe trial (1..8) within subjects, "
        "one probe trial per cell; type II sums of squares (pingouin/JASP's default); the "
        "within terms carry the Greenhouse-Geisser correction (p_gg) and Mauchly's test "
        "(p as R's mauchly.test) on the pooled within-group covariance. The group row tests "
        "surgeons vs residents, the trial row the practice effect over the probes, the "
        "interaction whether the groups learn differently. Subjects without demographics "
        "or without every probe trial are left out (listed).")]
    cells = probe_cells_with_group(data, vf)
    if cells.empty:
        out.notes.append("no probe trial of a subject with a known group: no group analysis")
        return out.section("groups", TITLE, intro), []
    kept, missing = group_design(cells, vf.trial_levels)
    if missing:
        out.notes.append(excluded_text("trial", {
            s: [f"trial {v}" for v in m] for s, m in missing.items()}, "mixed ANOVA"))
    parts = []
    for dv, _name, unit in vf.dvs:
        try:
            aov, msgs = captured(group_mixed_anova, kept, dv)
        except ConfigError as exc:
            out.notes.append(f"mixed ANOVA of {dv} not computed: {exc.reason}")
            continue
        out.notes.extend(f"{dv}, mixed ANOVA: {m}" for m in msgs)
        aov.insert(0, "dv", dv)
        aov.insert(1, "unit", unit)
        sizes = aov.attrs.get("group_sizes", {})
        aov["n_surgeon"] = int(sizes.get("surgeon", 0))
        aov["n_resident"] = int(sizes.get("resident", 0))
        parts.append(aov)
    if not parts:
        return out.section("groups", TITLE, intro), []
    out.blocks.append(TableBlock(
        "vf_group_anova", "Mixed ANOVA: group x probe trial", pd.concat(parts,
                                                                       ignore_index=True),
        "Source: group (between), trial (within) and their interaction; DF1, DF2, F, p_unc; "
        "eps, p_GG_corr: Greenhouse-Geisser (within rows); W_spher, p_spher: Mauchly (R); "
        "np2: partial eta squared; ng2: generalised eta squared. provenance.csv lists the "
        "probe trials of every subject.",
        columns=("dv", "Source", "DF1", "DF2", "F", "p_unc", "eps", "p_GG_corr", "np2",
                 "W_spher", "p_spher", "n_surgeon", "n_resident")))
    prov = [prov_row("vf_group_anova", f"group={g['group'].iloc[0]}", str(s),
                     trial_ids=g["trial_id"]) for s, g in kept.groupby("subject")]
    return out.section("groups", TITLE, intro), prov


__all__ = ["group_section"]
