"""The fixture-effect section, the seed's analysis design (secondary; the primary
analysis is the probe model, :mod:`vasim.study.report.sections.transfer`): subject-level
RM-ANOVAs per fixture and per probe trial, post hoc tests, the mixed model of every trial
and the seed's per-sample ANOVA as a labelled replication."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pandas as pd

from vasim.core.errors import ConfigError
from vasim.study import stats
from vasim.study.report.analysis import VfAnalysis, excluded_text
from vasim.study.report.common import (
    LABEL_PAIRED,
    LABEL_TUKEY,
    VF_DVS,
    SectionOut,
    captured,
    note_excluded,
    prov_row,
)
from vasim.study.report.data import StudyData
from vasim.study.report.html_page import (
    Block,
    Paragraph,
    Section,
    TableBlock,
    TextList,
)
from vasim.study.report.models import fixture_mixed_model
from vasim.study.report.primary import factor_anova_data
from vasim.study.report.sections.gain import gain_blocks

SEED_REPORTED: dict[tuple[str, str], str] = {
    ("eq65", "fixture"): "F(5, 98131) = 35.030", ("eq65", "trial"):
    "F(7, 98131) = 22.871", ("latency", "fixture"): "F(5, 98131) = 44.099",
    ("latency", "trial"): "F(7, 98131) = 87.344",
}
"""The seed's per-sample ANOVA results (section 6.4.4; its "error" is eq. 6.5's e), shown
beside the replication."""
SECTION_TITLE = "Effect of fixture: the seed's per-fixture RM-ANOVA (secondary)"



def _rm_block(cells: pd.DataFrame, factor: str, levels: Sequence[Any], out: SectionOut,
              cells_text: str, table_names: Sequence[str], trial_col: str,
              dvs: Sequence[tuple[str, str, str]]
              ) -> tuple[list[pd.DataFrame], list[pd.DataFrame], list[pd.DataFrame],
                         list[dict[str, str]]]:
    """RM-ANOVA and both post hoc families of one factor, for every VF dv."""
    anovas: list[pd.DataFrame] = []
    tukeys: list[pd.DataFrame] = []
    paireds: list[pd.DataFrame] = []
    prov: list[dict[str, str]] = []
    if len(levels) < 2:
        out.notes.append(f"factor {factor}: {len(levels)} level(s) with data "
                         f"({', '.join(map(str, levels)) or 'none'}); an RM-ANOVA needs 2")
        return anovas, tukeys, paireds, prov
    data, missing = factor_anova_data(cells, factor, levels)  # shared with power planning
    kept = data
    if missing:
        out.notes.append(excluded_text(factor, {
            s: [f"{factor} {v}" if v.isdigit() else v for v in m]
            for s, m in missing.items()}))
    n = kept["subject"].nunique()
    if n < 2:
        out.notes.append(f"factor {factor}: {n} subject(s) with every cell; an RM-ANOVA "
                         "needs at least 2: not computed")
        return anovas, tukeys, paireds, prov
    for r in kept.itertuples(index=False):
        ids = getattr(r, trial_col)
        ids = ids.split() if isinstance(ids, str) else [ids]
        for t in table_names:
            prov.append(prov_row(t, f"{factor}={getattr(r, factor)}", r.subject, trial_ids=ids))
    for dv, _name, unit in dvs:
        head = {"dv": dv, "unit": unit, "factor": factor}
        try:
            aov, msgs = captured(stats.rm_anova, data, dv=dv, subject="subject",
                                  within=factor)
            out.notes.extend(f"{dv}, {factor}: {m}" for m in msgs)
            aov.insert(0, "dv", dv)
            aov.insert(1, "unit", unit)
            aov.insert(2, "factor", factor)
            aov.insert(3, "n_subjects", n)
            aov.insert(4, "levels", ", ".join(str(v) for v in levels))
            aov.insert(5, "cells", cells_text)
            aov.insert(6, "excluded_subjects", " ".join(sorted(missing)))
            anovas.append(aov)
        except ConfigError as exc:
            out.notes.append(f"RM-ANOVA of {dv} by {factor} not computed: {exc.reason}")
        try:
            tk, msgs = captured(stats.tukey_hsd_rm, data, dv=dv, subject="subject",
                                 within=factor)
            out.notes.extend(f"{dv}, {factor}: {m}" for m in msgs)
            c = tk.comparisons.copy()
            for i, (k, v) in enumerate({**head, "label": LABEL_TUKEY}.items()):
                c.insert(i, k, v)
            c["ms_error"], c["df_error"], c["q_crit"] = tk.ms_error, tk.df_error, tk.q_crit
            tukeys.append(c)
        except ConfigError as exc:
            out.notes.append(f"Tukey HSD of {dv} by {factor} not computed: {exc.reason}")
        try:
            pp, msgs = captured(stats.pairwise_paired, data, dv=dv, subject="subject",
                                 within=factor)
            out.notes.extend(f"{dv}, {factor}: {m}" for m in msgs)
            for i, (k, v) in enumerate({**head, "label": LABEL_PAIRED}.items()):
                pp.insert(i, k, v)
            paireds.append(pp)
        except ConfigError as exc:
            out.notes.append(f"paired t-tests of {dv} by {factor} not computed: {exc.reason}")
    return anovas, tukeys, paireds, prov


def _p_text(p: float) -> str:
    """A p-value as reported: ``p < 0.001`` below 0.001, else three decimals.

    >>> _p_text(3e-45), _p_text(0.0123), _p_text(float("nan"))
    ('p < 0.001', 'p = 0.012', 'p undefined')
    """
    if math.isnan(p):
        return "p undefined"
    return "p < 0.001" if p < 0.001 else f"p = {p:.3f}"


def _anova_sentence(r: dict[str, Any]) -> str:
    """One RM-ANOVA row in the usual reporting form."""
    name = dict((dv, n) for dv, n, _ in VF_DVS).get(r["dv"], r["dv"])
    gg = (f"; Greenhouse-Geisser eps = {r['eps_gg']:.3f}, {_p_text(r['p_gg'])}"
          if r["df1"] > 1 and not math.isnan(r["eps_gg"]) else "")
    return (f"{name} by {r['factor']} (n = {r['n_subjects']} subjects): "
            f"F({r['df1']}, {r['df2']}) = {r['F']:.3f}, {_p_text(r['p_unc'])}{gg}; "
            f"partial eta squared = {r['np2']:.3f}")


def fixture_effect_section(data: StudyData, vf: VfAnalysis
                           ) -> tuple[Section, list[dict[str, str]]]:
    """Effect of fixture: subject-level RM-ANOVAs, post hoc tests, seed replication."""
    out = SectionOut()
    cells_fix = ("per subject: mean of the trial outcome over the subject's analysed trials "
                 "of that condition (the assisted trials of a fixture, 6 in the VF protocol; "
                 "'none' = the VF-free probe trials that follow the fixture blocks; the "
                 "baseline probes, which precede every block, never enter it)")
    cells_trial = "per subject: the probe trial of that number (one trial per cell)"
    intro: list[Block] = [Paragraph(
        "Methods. Secondary analysis, the seed's design (section 6.4.4): the primary "
        "analysis is the probe model of the section 'Transfer'. One-way repeated-measures "
        "ANOVAs on subject-level cell means (spec §3 decision, instead of the seed's "
        "per-sample ANOVA), one for the factor fixture (" + cells_fix + ") and one "
        "for the factor trial (" + cells_trial + "); the two factors are not crossed "
        "(assisted trials have no VF-free trial number), so no interaction is tested. "
        "Mauchly's test, Greenhouse-Geisser (p_gg) and Huynh-Feldt (p_hf) corrections and "
        "partial eta squared (np2) are given. Post hoc: " + LABEL_TUKEY + "; and "
        + LABEL_PAIRED + ". Only subjects with every cell of a factor enter its tests. "
        "Mauchly's p is R's mauchly.test. "
        "The 3 baseline trials always come first, so pooling them with the conditions "
        "would mix practice into the fixture factor: the VF-free level is the probe trials "
        "that follow the blocks. This compares performance *while assisted* with VF-free "
        "performance, not what practice with a fixture leaves behind. Every condition runs "
        "on the same trajectory variants (each assisted block on all six, the VF-free "
        "trials in a balanced rotation), so a cell mean does not stand for one variant. "
        "A linear mixed model over every analysed trial (statsmodels MixedLM, REML: "
        "measure ~ fixture + log(practice) + variant, random intercept per subject, "
        "practice = the trial's position in the session) gives the fixture effects "
        "(difference from 'none') adjusted for practice and variant.")]
    if vf.trials.empty:
        out.notes.append("no analysed trial of a fixture condition or a VF-free probe in the "
                         "sessions of this protocol: no fixture analysis")
        return out.section("fixture", SECTION_TITLE, intro), []
    if "none" not in set(vf.fixture_cells["condition"]):
        out.notes.append("no VF-free (probe) trial: the fixture factor lacks the level "
                         "'none' and compares the fixtures only")
    note_excluded(out, vf.excluded, probe_only=False, trials=vf.trials)
    prov: list[dict[str, str]] = []
    names = ("vf_rm_anova", "vf_posthoc_tukey", "vf_posthoc_paired")
    a1, t1, p1, pr1 = _rm_block(vf.fixture_cells, "fixture", vf.fixture_levels, out,
                                cells_fix, names, "trial_ids", vf.dvs)
    tc = vf.trial_cells
    a2, t2, p2, pr2 = _rm_block(tc, "trial", vf.trial_levels, out, cells_trial, names,
                                "trial_id", vf.dvs) if len(tc) else ([], [], [], [])
    if not len(tc):
        out.notes.append("no VF-free probe trial: the trial factor is not analysed")
    prov += pr1 + pr2
    anova = pd.concat(a1 + a2, ignore_index=True) if a1 + a2 else pd.DataFrame()
    if len(anova):
        out.blocks.append(TableBlock(
            "vf_rm_anova", "Subject-level RM-ANOVA per fixture and per probe trial (the "
            "seed's design; secondary)", anova,
            "df1, df2: degrees of freedom (p and p(n-1)); F and uncorrected p_unc; eps_gg, "
            "p_gg: Greenhouse-Geisser; mauchly_p: Mauchly's test of sphericity (p as R's "
            "mauchly.test); np2: "
            "partial eta squared. Cells: see the 'cells' column; provenance.csv lists the "
            "trial ids of every subject x level cell.",
            columns=("dv", "factor", "n_subjects", "df1", "df2", "F", "p_unc", "eps_gg",
                     "p_gg", "p_hf", "np2", "mauchly_W", "mauchly_p")))
        out.blocks.append(TextList("In words", tuple(_anova_sentence(r) for r in
                                                     anova.to_dict("records"))))
    if t1 + t2:
        out.blocks.append(TableBlock(
            "vf_posthoc_tukey", "Post hoc: " + LABEL_TUKEY, pd.concat(t1 + t2,
                                                                      ignore_index=True),
            "diff = mean2 - mean1 (unit of the dv); p_adj: studentized range; lwr/upr: "
            "simultaneous 95 % interval; both factors (fixture, trial).", display="details",
            columns=("dv", "factor", "group1", "group2", "mean1", "mean2", "diff", "lwr",
                     "upr", "p_adj")))
    if p1 + p2:
        out.blocks.append(TableBlock(
            "vf_posthoc_paired", "Post hoc: " + LABEL_PAIRED, pd.concat(p1 + p2,
                                                                       ignore_index=True),
            "mean_diff = mean(group1 - group2); p_holm: Holm-adjusted within each dv x "
            "factor family; cohen_dz; power_observed at this n; n_power90_ceil: minimum n "
            "for power 0.9.", display="details",
            columns=("dv", "factor", "group1", "group2", "n", "mean_diff", "t", "p", "p_holm",
                     "cohen_dz")))
    out.blocks.extend(gain_blocks(data, vf))  # faded and adaptive conditions (issue #18)
    prov += _mixed_model_block(vf, out)
    rep, rprov = _seed_replication(data, vf, out)
    prov += rprov
    if rep is not None:
        out.blocks.append(TableBlock(
            "vf_seed_replication", "Replication of the seed's per-sample ANOVA (not the "
            "primary result)", rep,
            stats.SEED_LABEL + ". One row per trajectory point of every analysed trial "
            "(eq. 6.5's e_i times the sample period [mm·s], or l_i [s]); factors fixture "
            "and trial (an assisted trial's trial "
            "level = the VF-free trial closing its block); additive OLS model, type II SS. "
            "df2 counts points, not subjects: the p-values are not valid inference. "
            "'seed_reported' is the seed's published figure.",
            columns=("dv", "effect", "df1", "df2", "F", "p", "seed_reported", "n_rows")))
    return out.section("fixture", SECTION_TITLE, intro), prov


def _seed_replication(data: StudyData, vf: VfAnalysis, out: SectionOut
                      ) -> tuple[pd.DataFrame | None, list[dict[str, str]]]:
    ok = vf.trials[vf.trials["latency"].notna() & vf.trials["stage"].notna()]
    if ok.empty:
        out.notes.append("seed replication not computed: no analysed trial with a stage")
        return None, []
    rows = data.points.merge(ok[["trial_id", "subject", "fixture", "stage"]], on="trial_id")
    rows["trial"] = rows["stage"].astype(np.int64)
    rows["fixture"] = pd.Categorical(rows["fixture"], categories=list(vf.fixture_levels))
    parts = []
    for dv, col in (("eq65", "error_l1_mm_s"), ("latency", "latency")):
        if col not in rows.columns:
            continue
        d = rows[rows[col].notna()]
        try:
            r, msgs = captured(stats.seed_per_sample_anova, d, dv=col,
                                factors=("fixture", "trial"))
        except ConfigError as exc:
            out.notes.append(f"seed replication of {dv} not computed: {exc.reason}")
            continue
        out.notes.extend(msgs)
        r.insert(0, "dv", dv)
        r.insert(1, "label", stats.SEED_LABEL)
        r["n_rows"] = len(d)
        r["seed_reported"] = [SEED_REPORTED.get((dv, e), "") for e in r["effect"]]
        parts.append(r)
    if not parts:
        return None, []
    prov = [prov_row("vf_seed_replication", "all points of the subject's analysed trials", s,
                  trial_ids=g["trial_id"]) for s, g in ok.groupby("subject")]
    return pd.concat(parts, ignore_index=True), prov




def _mixed_model_block(vf: VfAnalysis, out: SectionOut) -> list[dict[str, str]]:
    """The practice-adjusted mixed model of every dv: table ``vf_mixed_model``."""
    parts = []
    for dv, _name, unit in vf.dvs:
        try:
            fit, msgs = captured(fixture_mixed_model, vf.trials, dv)
        except ConfigError as exc:
            out.notes.append(f"mixed model of {dv} not computed: {exc.reason}")
            continue
        out.notes.extend(f"{dv}, mixed model: {m}" for m in msgs)
        fit.insert(0, "dv", dv)
        fit.insert(1, "unit", unit)
        fit["reference"] = fit.attrs["reference"]
        fit["n_obs"] = fit.attrs["n_obs"]
        fit["n_subjects"] = fit.attrs["n_groups"]
        parts.append(fit)
    if not parts:
        return []
    out.blocks.append(TableBlock(
        "vf_mixed_model", "Fixture effects over every trial adjusted for practice and "
        "variant (linear mixed model; secondary)",
        pd.concat(parts, ignore_index=True),
        "dv ~ C(fixture) + log_practice + C(variant), random intercept per subject (REML). "
        "coef of C(fixture)[T.x]: mean difference fixture x - 'none' (unit of the dv) at "
        "equal practice and variant; C(variant)[T.vk]: variant k - the first variant; "
        "log_practice: change per e-fold of the practice count; se, z, p (Wald, "
        "two-sided), 95 % interval. Every analysed VF trial enters (vf_trials.csv).",
        columns=("dv", "term", "coef", "se", "z", "p", "ci_low", "ci_high", "n_obs",
                 "n_subjects")))
    return [prov_row("vf_mixed_model", "all analysed VF trials", s, trial_ids=g["trial_id"])
            for s, g in vf.trials.groupby("subject")]
