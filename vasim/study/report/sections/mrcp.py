"""The MRCP vs standard-teleoperation section (spec §4; seed chapter 5, experiments 1-3).

Besides means, paired tests, gains and learning curves it gives the seed's Table 5.4
layout (``mrcp_table54``: mean and sd of StdT and of each other mode, and the gain
mean(StdT)/mean(mode) per measure), Table 5.5's (``mrcp_table55``: the paired t-tests
against StdT with observed power and the subjects needed for power 0.9, statsmodels'
``TTestPower`` via ``vasim.study.stats.paired``), and the per-subject comparison
(``mrcp_per_subject``: each subject's mean per mode and gain, who benefits and who does
not; issue #25 item 6). ``tables/mrcp_descriptives.csv`` keeps the columns ``metric, mode,
mean``; the metrics of experiment 3 are named ``ET``, ``EM``, ``contact_time``, ``force``,
``torque`` (issue #28 item 2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from vasim.core.errors import ConfigError
from vasim.study import stats
from vasim.study.report.analysis import complete_subjects, excluded_text
from vasim.study.report.common import (
    MODE_COLORS,
    MODE_ORDER,
    SectionOut,
    captured,
    curve_summary,
    fixture_label,
    ids_text,
    ordered_conditions,
    prov_row,
)
from vasim.study.report.data import StudyData
from vasim.study.report.figures import (
    CurveGroups,
    CurveText,
    box_figure,
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
from vasim.trials.kinds import TELEOPERATION_MODES


@dataclass(frozen=True)
class MrcpMetric:
    """One per-trial metric of the MRCP comparison (spec §4).

    Attributes:
        key: column name in the report tables. metric: name in ``trial_metrics``.
        family: ``"ET"``, ``"EM"`` (economy of movement) or ``"Q"`` (quality).
        label: what it measures. unit: its unit.
    """

    key: str
    metric: str
    family: str
    label: str
    unit: str


MRCP_METRICS: tuple[MrcpMetric, ...] = (
    MrcpMetric("ET", "completion_time", "ET", "execution time", "s"),
    MrcpMetric("EM", "path_l2", "EM", "needle path length", "m"),
    MrcpMetric("Q", "target_deformation", "Q", "target deformation by contacts", "mm s"),
    MrcpMetric("Q_target_displacement", "target_displacement_max", "Q",
               "largest target displacement", "m"),
    MrcpMetric("contact_time", "contact_time", "Q", "accumulated contact time", "s"),
    MrcpMetric("force", "accumulated_force", "Q", "accumulated force on tissue", "N s"),
    MrcpMetric("torque", "accumulated_torque", "Q", "accumulated torque on tissue", "N m s"),
)
"""The MRCP metrics, in report order (those with no stored value are left out)."""


_TITLE = "MRCP vs standard teleoperation"
_METHODS = (
    "Per trial: ET = execution time (completion_time) [s]; EM = economy of movement, "
    "the Euclidean length of the needle path (path_l2) [m]; Q = quality as the seed "
    "measures it: the rings' displacement by contacts, integrated over time and summed "
    "over the rings (target_deformation) [mm s]; and, as experiment 3, the largest "
    "target displacement [m], accumulated contact time (contact_time) [s], force "
    "(force) [N s] and torque (torque) [N m s] on tissue (when stored). Per subject and "
    "mode the cell is the mean over the mode's trials; mean and sd per mode (Table "
    "5.4's layout), paired Student t-tests per pair of modes (with observed power and "
    "the minimum n for power 0.9: Table 5.5's layout) and the seed's gain "
    "mean(StdT)/mean(mode) use the subjects with every mode; the per-subject table "
    "shows who benefits from each mode and who does not. Learning curves: mean and "
    "interquartile range per trial number within the mode (1..6). Likert items: see "
    "the Questionnaires section.")


@dataclass
class _MrcpTables:
    """The section's rows as the metrics add them (one builder per table family)."""

    out: SectionOut
    modes: list[str]
    labels: list[str]
    desc: list[dict[str, object]] = field(default_factory=list)
    paired: list[pd.DataFrame] = field(default_factory=list)
    gains: list[dict[str, object]] = field(default_factory=list)
    table54: list[dict[str, object]] = field(default_factory=list)
    per_subject: list[dict[str, object]] = field(default_factory=list)
    curves: list[pd.DataFrame] = field(default_factory=list)
    fits: list[dict[str, object]] = field(default_factory=list)
    curve_figs: list[FigureBlock] = field(default_factory=list)
    excl: dict[str, list[str]] = field(default_factory=dict)  # note -> metrics it applies to
    prov: list[dict[str, str]] = field(default_factory=list)


# ---------------------------------------------------------------------------------- MRCP
def mrcp_section(data: StudyData) -> tuple[Section, list[dict[str, str]]]:
    """MRCP vs standard teleoperation (spec §4; seed Tables 5.1-5.5)."""
    out = SectionOut()
    intro: list[Block] = [Paragraph(_METHODS)]
    done = data.analysed
    mt = done[done["condition"].isin(TELEOPERATION_MODES)].copy()
    if mt.empty:
        out.notes.append("no analysed trial of the teleoperation modes (stdt, mrcp, "
                         "mrcp_cam) in the sessions of this protocol: not an MRCP study, "
                         "section not applicable")
        return out.section("mrcp", _TITLE, intro), []
    modes = ordered_conditions(mt["condition"], MODE_ORDER)
    mt["mode"] = mt["condition"].map(fixture_label)
    mt["trial_number"] = (mt.groupby(["session_id", "condition"])["trial_index"]
                          .rank(method="first").astype(np.int64))
    metrics = _stored_metrics(data, mt, out)
    if not metrics:
        out.notes.append("no MRCP metric is stored for the teleoperation trials")
        return out.section("mrcp", _TITLE, intro), []
    wide = mt.merge(data.metrics[[m.metric for m in metrics]], how="left",
                    left_on="trial_id", right_index=True)
    wide = wide.rename(columns={m.metric: m.key for m in metrics})
    tabs = _MrcpTables(out, modes, [fixture_label(m) for m in modes])
    for m in metrics:
        _add_metric(tabs, m, wide)
    out.notes.extend(f"{', '.join(keys)}: {text}" for text, keys in tabs.excl.items())
    _comparison_blocks(tabs, wide, metrics)
    _learning_blocks(tabs)
    trials_tab = wide[["trial_id", "subject", "session_id", "trial_index", "condition", "mode",
                       "trial_number", *[m.key for m in metrics]]]
    out.blocks.append(TableBlock(
        "mrcp_trials", "Analysed teleoperation trials", trials_tab,
        "One row per analysed trial with its metrics.", display="csv"))
    return out.section("mrcp", _TITLE, intro), tabs.prov


def _stored_metrics(data: StudyData, mt: pd.DataFrame, out: SectionOut) -> list[MrcpMetric]:
    """The MRCP metrics with a stored value for some teleoperation trial; notes the rest."""
    metrics = [m for m in MRCP_METRICS if m.metric in data.metrics.columns
               and data.metrics.loc[data.metrics.index.isin(set(mt["trial_id"])),
                                    m.metric].notna().any()]
    absent = [m.metric for m in MRCP_METRICS if m not in metrics]
    if absent:
        out.notes.append(f"metrics not stored for these trials (left out): {', '.join(absent)}")
    return metrics


def _add_metric(tabs: _MrcpTables, m: MrcpMetric, wide: pd.DataFrame) -> None:
    """One metric's rows: descriptives, paired tests, gains and its learning curve."""
    out = tabs.out
    d = wide[["trial_id", "subject", "condition", "mode", "trial_number", m.key]].rename(
        columns={m.key: "value"})
    bad = d[d["value"].isna()]
    if len(bad):
        out.notes.append(f"{m.key}: {len(bad)} trial(s) without a value (e.g. not "
                         f"completed) left out: trial ids {ids_text(bad['trial_id'])}")
    d = d[d["value"].notna()]
    kept = _subject_cells(tabs, m, d)
    n = kept["subject"].nunique()
    if n >= 2 and len(tabs.modes) >= 2:
        _paired_tests(tabs, m, kept)
        if "stdt" in tabs.modes:
            _stdt_gains(tabs, m, kept, n)
    elif n < 2:
        out.notes.append(f"{m.key}: {n} subject(s) with every mode; paired tests and "
                         "gains need at least 2")
    _learning_curve(tabs, m, d)


def _subject_cells(tabs: _MrcpTables, m: MrcpMetric, d: pd.DataFrame) -> pd.DataFrame:
    """The subject x mode means of the subjects with every mode; their descriptives and
    provenance rows."""
    cells = (d.groupby(["subject", "condition"]).agg(
        value=("value", "mean"), n_trials=("trial_id", "size"),
        trial_ids=("trial_id", ids_text)).reset_index())
    cells["mode"] = cells["condition"].map(fixture_label)
    kept, missing = complete_subjects(cells, "condition", tabs.modes)
    if missing:
        tabs.excl.setdefault(excluded_text("mode", {
            s: [fixture_label(x) for x in v] for s, v in missing.items()},
            "means, sds, paired tests and gains"), []).append(m.key)
    for cond in tabs.modes:
        part = kept[kept["condition"] == cond]
        tabs.desc.append({"metric": m.key, "family": m.family, "unit": m.unit, "mode":
                          fixture_label(cond), "n_subjects": len(part),
                          "n_trials": int(part["n_trials"].sum()),
                          "mean": float(part["value"].mean()) if len(part) else math.nan,
                          "sd": float(part["value"].std(ddof=1)) if len(part) > 1
                          else math.nan,
                          "trial_ids": ids_text(" ".join(part["trial_ids"]).split())})
    for r in kept.itertuples(index=False):
        for t in ("mrcp_paired", "mrcp_gains"):
            tabs.prov.append(prov_row(t, f"{m.key}|mode={r.mode}", r.subject,
                                      trial_ids=str(r.trial_ids).split()))
    return kept


def _paired_tests(tabs: _MrcpTables, m: MrcpMetric, kept: pd.DataFrame) -> None:
    """Paired t-tests per pair of modes on the subject means."""
    k = kept.copy()
    k["mode"] = pd.Categorical(k["mode"], categories=tabs.labels)
    try:
        pp, msgs = captured(stats.pairwise_paired, k, dv="value", subject="subject",
                            within="mode")
    except ConfigError as exc:
        tabs.out.notes.append(f"{m.key}: paired t-tests not computed: {exc.reason}")
        return
    tabs.out.notes.extend(f"{m.key}: {x}" for x in msgs)
    pp.insert(0, "metric", m.key)
    pp.insert(1, "unit", m.unit)
    tabs.paired.append(pp)


def _stdt_gains(tabs: _MrcpTables, m: MrcpMetric, kept: pd.DataFrame, n: int) -> None:
    """The seed's gains mean(StdT)/mean(mode): Table 5.4's rows and each subject's."""
    ref = kept[kept["condition"] == "stdt"].set_index("subject")["value"]
    for cond in tabs.modes:
        if cond == "stdt":
            continue
        cmp_ = kept[kept["condition"] == cond].set_index("subject")["value"]
        cmp_ = cmp_.reindex(ref.index)
        try:
            g = stats.gain(ref.to_numpy(), cmp_.to_numpy())
        except ConfigError as exc:
            tabs.out.notes.append(f"{m.key}: gain StdT/{fixture_label(cond)} not "
                                  f"computed: {exc.reason}")
            continue
        tabs.gains.append({"metric": m.key, "family": m.family, "unit": m.unit,
                           "reference": "StdT", "mode": fixture_label(cond),
                           "n_subjects": n, "mean_reference": float(ref.mean()),
                           "mean_mode": float(cmp_.mean()), "gain": g})
        sd_of = kept.groupby("condition")["value"].std(ddof=1)
        tabs.table54.append({"metric": m.key, "unit": m.unit, "mode": fixture_label(cond),
                             "n_subjects": n, "mean_StdT": float(ref.mean()),
                             "sd_StdT": float(sd_of.get("stdt", math.nan)),
                             "mean_mode": float(cmp_.mean()),
                             "sd_mode": float(sd_of.get(cond, math.nan)), "gain": g})
        for subj, r_v in ref.items():
            c_v, s_v = float(cmp_.loc[subj]), float(r_v)
            # gain inf: the mode's mean is 0 (e.g. no contact at all) and
            # StdT's is not; NaN: both 0 (a tie)
            sg = s_v / c_v if c_v > 0 else math.inf if s_v > 0 else math.nan
            tabs.per_subject.append({
                "subject": subj, "metric": m.key, "unit": m.unit,
                "mode": fixture_label(cond), "mean_StdT": s_v,
                "mean_mode": c_v, "gain": sg,
                "benefits": "yes" if c_v < s_v else "no" if c_v > s_v else "tie"})


def _learning_curve(tabs: _MrcpTables, m: MrcpMetric, d: pd.DataFrame) -> None:
    """The metric's learning curve per mode, its power-law fits and its figure."""
    summ = curve_summary(tabs.out, d, dv="value", trial="trial_number",
                         key=("metric", m.key), unit=m.unit, condition="mode")
    tabs.curves.append(summ)
    bands = {}
    for lab in tabs.labels:
        part = d[d["mode"] == lab]
        try:
            pf, _ = captured(stats.fit_power_law, part["trial_number"].to_numpy(float),
                             part["value"].to_numpy(float))
        except ConfigError as exc:
            tabs.out.notes.append(f"{m.key}, {lab}: learning-curve fit not computed: "
                                  f"{exc.reason}")
            continue
        bands[lab] = pf.band(np.linspace(1, float(part["trial_number"].max()), 40))
        tabs.fits.append({"metric": m.key, "unit": m.unit, "mode": lab, "model": "a*n^(-b)",
                          "n_obs": pf.n_obs, "a": pf.a, "b": pf.b, "se_a": pf.se_a,
                          "se_b": pf.se_b, "rss": pf.rss, "dof": pf.dof})
        for r in part.itertuples(index=False):
            tabs.prov.append(prov_row("mrcp_learning_fit", f"{m.key}|mode={lab}", r.subject,
                                      trial_ids=[r.trial_id]))
    fig = learning_curve_figure(
        summ, CurveText(ylabel=f"{m.family}: {m.label} [{m.unit}]",
                        title=f"Learning curve: {m.key} ({m.label})",
                        xlabel="trial number within the mode"),
        groups=CurveGroups("mode", order=tabs.labels, bands=bands, colors=MODE_COLORS))
    tabs.curve_figs.append(FigureBlock(
        f"mrcp_learning_{m.key}", f"Learning curve: {m.key} ({m.label})", figure_png(fig),
        "Mean (line) and interquartile range (shaded) over subjects per trial number, "
        "one colour per mode; dashed: power-law fit per mode. Numbers: "
        f"tables/mrcp_learning_curve.csv (metric = {m.key})."))


def _comparison_blocks(tabs: _MrcpTables, wide: pd.DataFrame,
                       metrics: list[MrcpMetric]) -> None:
    """The per-mode tables (descriptives, gains, Tables 5.4/5.5, per subject, paired
    tests) and the per-mode box figure."""
    blocks = tabs.out.blocks
    fig = box_figure(wide, group="mode", colors=MODE_COLORS,
                     values=[(m.key, f"{m.family}: {m.label} [{m.unit}]") for m in metrics],
                     order=tabs.labels,
                     xlabel="mode", title="Per mode: every trial")
    blocks.append(TableBlock(
        "mrcp_descriptives", "Mean and sd per mode (as the seed's Tables 5.1-5.5)",
        pd.DataFrame(tabs.desc), "Over the subject means (subjects with every mode); "
        "trial_ids: the trials averaged.", columns=("metric", "unit", "mode", "n_subjects",
                                                    "n_trials", "mean", "sd")))
    if tabs.gains:
        blocks.append(TableBlock(
            "mrcp_gains", "Gains mean(StdT) / mean(mode)", pd.DataFrame(tabs.gains),
            "gain > 1: the mode has the smaller mean (shorter, more economical, fewer "
            "contacts). provenance.csv lists the trials of every subject x mode cell."))
    if tabs.table54:
        blocks.append(TableBlock(
            "mrcp_table54", "Table 5.4 layout: mean, sd and gain StdT / mode",
            pd.DataFrame(tabs.table54), "Over the subject means (subjects with every mode); "
            "gain = mean(StdT) / mean(mode), > 1: the mode has the smaller mean.",
            columns=("metric", "unit", "mode", "n_subjects", "mean_StdT", "sd_StdT",
                     "mean_mode", "sd_mode", "gain")))
    if tabs.paired:
        _table55(tabs)
    if tabs.per_subject:
        _per_subject_blocks(tabs)
    if tabs.paired:
        blocks.append(TableBlock(
            "mrcp_paired", "Paired t-tests per pair of modes", pd.concat(tabs.paired,
                                                                         ignore_index=True),
            "mean_diff = mean(group1 - group2); p two-sided; p_holm over the pairs of a "
            "metric; power_observed: power at this n; n_power90_ceil: minimum n for power "
            "0.9 at the observed effect cohen_dz.",
            columns=("metric", "group1", "group2", "n", "mean_diff", "t", "p", "p_holm",
                     "cohen_dz", "power_observed", "n_power90_ceil")))
    blocks.append(FigureBlock(
        "mrcp_box", "Per mode", figure_png(fig),
        "Every trial of every subject (one dot per trial); box = quartiles, line = median, "
        "diamond = mean. Numbers: tables/mrcp_trials.csv."))


def _table55(tabs: _MrcpTables) -> None:
    """Table 5.5's layout: the paired t-tests against StdT with their power."""
    allp = pd.concat(tabs.paired, ignore_index=True)
    t55 = allp[allp["group1"] == "StdT"]
    if t55.empty:
        return
    tabs.out.blocks.append(TableBlock(
        "mrcp_table55", "Table 5.5 layout: paired t-tests against StdT and power",
        t55.reset_index(drop=True), "Paired Student t-test on the subject means "
        "(two-sided); power_observed: power at this n and the observed effect "
        "cohen_dz; n_power90_ceil: subjects needed for power 0.9 at that effect "
        "(statsmodels TTestPower, alpha .05).",
        columns=("metric", "unit", "group1", "group2", "n", "mean_diff", "t", "p",
                 "cohen_dz", "power_observed", "n_power90_ceil")))


def _per_subject_blocks(tabs: _MrcpTables) -> None:
    """Who benefits from each mode: a sentence per measure and mode, and the table."""
    ps = pd.DataFrame(tabs.per_subject)
    lines = []
    for (metric, mode), part in ps.groupby(["metric", "mode"], sort=False):
        yes = part.loc[part["benefits"] == "yes", "subject"].astype(str).tolist()
        no = part.loc[part["benefits"] != "yes", "subject"].astype(str).tolist()
        lines.append(f"{metric}, {mode} vs StdT: smaller for {len(yes)} of {len(part)} "
                     f"subjects" + (f" (not for {', '.join(no)})" if no else ""))
    tabs.out.blocks.append(Paragraph("Per subject (who benefits, who does not): "
                                     + "; ".join(lines) + "."))
    tabs.out.blocks.append(TableBlock(
        "mrcp_per_subject", "Per subject: mean per mode and gain StdT / mode", ps,
        "One row per subject, measure and mode: the subject's mean over the mode's "
        "trials beside its StdT mean; benefits = yes when the mode's mean is smaller "
        "(gain > 1; inf when the mode's mean is 0), tie when equal.",
        display="details"))


def _learning_blocks(tabs: _MrcpTables) -> None:
    """The learning-curve figures, their table and the power-law fits."""
    tabs.out.blocks.extend(tabs.curve_figs)
    if tabs.curves:
        tabs.out.blocks.append(TableBlock(
            "mrcp_learning_curve", "Learning curves per mode", pd.concat(tabs.curves,
                                                                         ignore_index=True),
            "Per metric, mode and trial number: n subjects, mean, quartiles; trial_ids.",
            display="details",
            columns=("metric", "mode", "trial", "n", "mean", "q25", "q75")))
    if tabs.fits:
        tabs.out.blocks.append(TableBlock(
            "mrcp_learning_fit", "Power-law fits per mode", pd.DataFrame(tabs.fits),
            "y = a·n^(-b) on the trials of every subject.", display="details"))
