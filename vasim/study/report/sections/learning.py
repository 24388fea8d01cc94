"""The learning-curve section over the VF-free probe trials."""

from __future__ import annotations

import numpy as np
import pandas as pd

from vasim.core.errors import ConfigError
from vasim.study import stats
from vasim.study.report.analysis import VfAnalysis
from vasim.study.report.common import (
    PATH_DEV_ABSENT,
    PATH_DEV_DV,
    PLOT_NAMES,
    SectionOut,
    captured,
    curve_summary,
    ids_text,
    note_excluded,
    prov_row,
)
from vasim.study.report.data import StudyData
from vasim.study.report.figures import (
    CurveGroups,
    CurveText,
    figure_png,
    learning_curve_figure,
)
from vasim.study.report.html_page import (
    Block,
    FigureBlock,
    Paragraph,
    Section,
    TableBlock,
)
from vasim.study.store import GROUPS

SEED_FIGURE: dict[str, str] = {"eq65": " (the seed's Fig. 6.17 measure)",
                               "latency": " (as the seed's Fig. 6.18)"}
"""The seed figure an outcome's learning curve corresponds to."""


_TITLE = "Learning curves (VF-free trials)"


def _methods(vf: VfAnalysis) -> Paragraph:
    """The section's methods paragraph (the path deviation when it is stored)."""
    return Paragraph(
        "Methods. VF-free (probe) trials only (on the assisted trials' variants, in "
        "rotation: docs/study-design.md), plotted "
        "against the practice count n: the trial's position in the session (1-based, every "
        "trial counts, assisted ones included: probe 4 is the 10th trial), not the probe "
        "number, because practice accrues on every trial. Per practice count, the "
        "mean over subjects and the interquartile range of"
        + (" the mean path deviation (distance of the tool tip to the planned polyline, "
           "mm; the accuracy measure)," if PATH_DEV_DV in vf.dvs else "")
        + " the latency L = Σ_i l_i (time from the trial start to the last reached point: "
        "the completion time when every point is reached, s) and the seed's eq. 6.5 "
        "measure e (the Manhattan distance to the next point of interest integrated over "
        "time, mm·s; it grows with the time spent, so it is not an accuracy measure)"
        ". Fit: power law of practice y = a·n^(-b) by least squares on the subject-level "
        "points, with the 95 % pointwise confidence band of the fitted mean curve (delta "
        "method).")


def learning_curve_section(data: StudyData, vf: VfAnalysis
                           ) -> tuple[Section, list[dict[str, str]]]:
    """Learning curves over the VF-free probe trials (seed Figs. 6.17-6.18)."""
    out = SectionOut()
    intro: list[Block] = [_methods(vf)]
    tc = vf.trial_cells
    if tc.empty:
        out.notes.append("no VF-free probe trial with per-point metrics in the sessions of "
                         "this protocol: no learning curve")
        return out.section("learning", _TITLE, intro), []
    incomplete = vf.trials[vf.trials["probe"].astype(bool) & ~vf.trials["completed"]]
    if len(incomplete):
        out.notes.append(f"{len(incomplete)} probe trial(s) did not reach every point within "
                         f"the time limit (their L covers the reached points only): trial "
                         f"ids {ids_text(incomplete['trial_id'])}")
    note_excluded(out, vf.excluded, probe_only=True, trials=vf.trials)
    summaries: list[pd.DataFrame] = []
    fits: list[pd.DataFrame] = []
    prov: list[dict[str, str]] = []
    if PATH_DEV_DV not in vf.dvs:
        out.notes.append(PATH_DEV_ABSENT)
    for dv, name, unit in vf.dvs:
        summ = curve_summary(out, tc, dv=dv, trial="practice", key=("dv", dv), unit=unit)
        summ = summ.rename(columns={"trial": "practice"})
        probe_of = tc.groupby("practice")["trial"].agg(
            lambda s: " ".join(str(v) for v in sorted(set(s))))
        summ.insert(summ.columns.get_loc("practice") + 1, "probe",
                    summ["practice"].map(probe_of))
        summaries.append(summ)
        band, fit_label = _probe_fit(out, tc, dv, name, fits)
        fig = learning_curve_figure(summ.rename(columns={"practice": "trial"}),
                                    _practice_text(vf, dv, unit, " over the VF-free trials"),
                                    band=band, fit_label=fit_label)
        out.blocks.append(FigureBlock(
            f"learning_{dv}", f"Learning curve: {name}" + SEED_FIGURE.get(dv, ""),
            figure_png(fig),
            f"Mean (line) and interquartile range (shaded) over subjects per VF-free trial, "
            f"against the practice count n (the trial's position in the session); "
            f"dashed: power-law fit with its 95 % confidence band (hatched). Numbers: "
            f"tables/vf_learning_curve.csv (dv = {dv}) and tables/vf_learning_fit.csv."))
    _curve_tables(out, pd.concat(summaries, ignore_index=True), fits)
    if fits:
        for r in tc.itertuples(index=False):
            prov.append(prov_row("vf_learning_fit", f"practice={r.practice}", r.subject,
                                 trial_ids=[r.trial_id]))
    _group_curves(data, vf, out)
    out.blocks.append(TableBlock(
        "vf_trials", "Analysed trials of the VF study", vf.trials,
        "One row per analysed trial (the completed attempt of each scheduled trial): "
        "path_deviation [mm] (and its RMS, maximum [mm] and fraction outside the tube), "
        "latency = Σ l_i over reached points [s], eq65 = eq. 6.5's e integrated over time "
        "[mm·s]; variant: trajectory variant; block_position: 0 baseline, 1.. the fixture "
        "blocks; practised / previous: the fixture a probe closes / the one before; stage = "
        "probe number closing the trial's block (the seed replication's trial level).",
        display="csv"))
    return out.section("learning", _TITLE, intro), prov


def _practice_text(vf: VfAnalysis, dv: str, unit: str, title_tail: str) -> CurveText:
    """The axes of a curve over the practice count: the dv's plot name and unit, the
    title, and the split after the baseline probes (none without a baseline)."""
    pname = PLOT_NAMES[dv]
    return CurveText(ylabel=f"{pname} [{unit}]",
                     title=f"{pname[0].upper()}{pname[1:]}{title_tail}",
                     xlabel=PRACTICE_XLABEL,
                     split_after=vf.n_baseline + 0.5 if vf.n_baseline else None)


def _probe_fit(out: SectionOut, tc: pd.DataFrame, dv: str, name: str,
               fits: list[pd.DataFrame]) -> tuple[pd.DataFrame | None, str | None]:
    """The power-law fit of ``dv`` over the probe cells: its row added to ``fits``.

    Returns:
        The fit's confidence band and legend label, or (None, None) when not computed.
    """
    try:
        fitrow, msgs = captured(stats.fit_learning_curves, tc, dv=dv, subject="subject",
                                trial="practice")
        out.notes.extend(msgs)
        pf, _ = captured(stats.fit_power_law, tc["practice"].to_numpy(dtype=float),
                         tc[dv].to_numpy(dtype=float))
        grid = np.linspace(float(tc["practice"].min()), float(tc["practice"].max()), 60)
        band = pf.band(grid)
        r = fitrow.iloc[0]
        fit_label = f"fit ${r['a']:.3g}\\, n^{{-{r['b']:.3g}}}$"
        fitrow.insert(0, "dv", dv)
        fitrow.insert(1, "model", "a*n^(-b)")
        fits.append(fitrow)
    except ConfigError as exc:
        out.notes.append(f"{name}: power-law fit not computed: {exc.reason}")
        return None, None
    return band, fit_label


def _curve_tables(out: SectionOut, table: pd.DataFrame, fits: list[pd.DataFrame]) -> None:
    """The learning-curve table and, when any, the power-law fits' table."""
    out.blocks.append(TableBlock(
        "vf_learning_curve", "Learning curve per VF-free trial", table,
        "practice: the trial's position in the session (1-based); probe: its VF-free trial "
        "number; n subjects; mean, 25th and 75th percentiles over subjects; trial_ids: the "
        "probe trials.", columns=("dv", "unit", "practice", "probe", "n", "mean", "q25",
                                  "q75")))
    if fits:
        out.blocks.append(TableBlock(
            "vf_learning_fit", "Power-law fits y = a·n^(-b)", pd.concat(fits, ignore_index=True),
            "n = practice count; a in the unit of the dv; b dimensionless (> 0: improvement "
            "with practice); "
            "standard errors from the least-squares covariance; provenance.csv lists the "
            "probe trials fitted.", columns=("dv", "model", "n_obs", "a", "b", "se_a", "se_b",
                                             "rss", "dof")))


PRACTICE_XLABEL = "trial number in the session (practice count n)"
"""x label of the VF learning curves."""


def probe_cells_with_group(data: StudyData, vf: VfAnalysis) -> pd.DataFrame:
    """The probe-trial cells with each subject's group (``surgeon``/``resident``) from the
    demographics; subjects without demographics are left out.

    Returns:
        ``vf.trial_cells`` plus a ``group`` column.
    """
    demo = data.demographics
    group_of = dict(zip(demo["subject"], demo["subject_group"], strict=True))
    tc = vf.trial_cells.assign(group=vf.trial_cells["subject"].map(group_of))
    return tc[tc["group"].isin(GROUPS)].reset_index(drop=True)


def _group_curves(data: StudyData, vf: VfAnalysis, out: SectionOut) -> None:
    """Learning curves per group (surgeons, residents) against the practice count."""
    tc = probe_cells_with_group(data, vf)
    present = [g for g in GROUPS if g in set(tc["group"])]
    if len(present) < 2:
        out.notes.append(f"curves per group need surgeons and residents with demographics; "
                         f"present: {', '.join(present) or 'none'}")
        return
    parts = []
    for dv, name, unit in vf.dvs:
        summ = curve_summary(out, tc, dv=dv, trial="practice", key=("dv", dv), unit=unit,
                             condition="group")
        summ = summ.rename(columns={"trial": "practice"})
        parts.append(summ)
        fig = learning_curve_figure(summ.rename(columns={"practice": "trial"}),
                                    _practice_text(vf, dv, unit, ": surgeons vs residents"),
                                    groups=CurveGroups("group", order=present))
        out.blocks.append(FigureBlock(
            f"learning_group_{dv}", f"Learning curve per group: {name}", figure_png(fig),
            "Mean (line) and interquartile range (shaded) over the subjects of each group "
            "per VF-free trial, against the practice count. Numbers: "
            f"tables/vf_learning_curve_group.csv (dv = {dv}); test: section 'Surgeons vs "
            "residents'."))
    out.blocks.append(TableBlock(
        "vf_learning_curve_group", "Learning curve per group", pd.concat(parts,
                                                                        ignore_index=True),
        "Per dv, group and practice count: n subjects, mean, quartiles; trial_ids.",
        display="details", columns=("dv", "unit", "group", "practice", "n", "mean", "q25",
                                    "q75")))
