"""The primary analysis section (issue #25): transfer to the VF-free probe after each
fixture block (:mod:`vasim.study.report.transfer`), and the measures section: what each
outcome measures, its unit, and how strongly eq. 6.5's e tracks latency in these data."""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
import pandas as pd
import statsmodels.formula.api as smf
from scipy import stats as sps

from vasim.core.errors import ConfigError
from vasim.study.report.analysis import VfAnalysis
from vasim.study.report.common import (
    DV_NAMES,
    EQ65_ABSENT,
    EQ65_DV,
    LATENCY_DV,
    PATH_DEV_ABSENT,
    PATH_DEV_DV,
    PATH_DEV_EXTRA,
    SectionOut,
    captured,
    prov_row,
)
from vasim.study.report.html_page import Block, Paragraph, Section, TableBlock, TextList
from vasim.study.report.transfer import transfer_model

TITLE = "Transfer: the VF-free probe after each fixture block (primary analysis)"
MEASURES_TITLE = "Measures and units"
CORRELATION_COLUMNS: tuple[str, ...] = ("x", "y", "method", "n_obs", "n_subjects", "r",
                                        "ci_low", "ci_high", "p")
"""Columns of ``vf_measure_correlations``."""


def _p_text(p: float) -> str:
    if math.isnan(p):
        return "p undefined"
    return "p < 0.001" if p < 0.001 else f"p = {p:.3f}"


def transfer_section(vf: VfAnalysis) -> tuple[Section, list[dict[str, str]]]:
    """The primary probe model of every outcome: tables ``vf_transfer_model`` (estimates)
    and ``vf_transfer_tests`` (fixture, variant and carry-over tests)."""
    out = SectionOut()
    intro: list[Block] = [Paragraph(
        "Methods (primary analysis, issue #25). The question of a VF training study is "
        "transfer: does practice with a fixture improve the next unassisted performance? "
        "Each VF-free probe trial that closes a fixture block is modelled by the fixture "
        "just practised, the block's position in the session (practice, a linear "
        "covariate) and the trajectory variant (a factor), with a random intercept per "
        "subject (statsmodels MixedLM, REML): dv ~ C(practised) + block_position + "
        "C(variant). The baseline probes (before any block) are not in the model. Fixture "
        "effects are each fixture's difference from the mean of the fixtures (95 % Wald "
        "interval). Tests are F tests of nested within-subject models (OLS with the "
        "subject as a fixed effect, exact under normal errors at any number of subjects; "
        "the mixed model's chi-square tests are anti-conservative with 5 probes per "
        "subject): the fixture just practised, the variant, and carry-over, reported "
        "rather than assumed away: adding the fixture practised in the block before "
        "(C(previous), 'none' after the baseline). Block order follows a "
        "Williams design and the probes rotate over the assisted trials' variants, so "
        "fixture, position, carry-over and variant are balanced by design "
        "(docs/study-design.md). Path deviation is the accuracy measure; latency the "
        "speed measure; eq. 6.5's e is the seed's measure, shown for comparison.")]
    probes = vf.trials[vf.trials["probe"].astype(bool)
                       & (vf.trials["practised"].astype(str) != "")] \
        if "practised" in vf.trials.columns else vf.trials.iloc[0:0]
    if probes.empty:
        out.notes.append("no analysed VF-free probe trial closing a fixture block: no "
                         "transfer analysis")
        return out.section("transfer", TITLE, intro), []
    est_parts, test_parts = [], []
    for dv, _name, unit in vf.dvs:
        try:
            (est, tests), msgs = captured(transfer_model, vf.trials, dv, unit)
        except ConfigError as exc:
            out.notes.append(f"transfer model of {dv} not computed: {exc.reason}")
            continue
        out.notes.extend(f"{dv}, transfer model: {m}" for m in msgs)
        est_parts.append(est)
        test_parts.append(tests)
    if not est_parts:
        return out.section("transfer", TITLE, intro), []
    est = pd.concat(est_parts, ignore_index=True)
    tests = pd.concat(test_parts, ignore_index=True)
    out.blocks.append(TableBlock(
        "vf_transfer_tests", "Primary: fixture practised, variant and carry-over tests",
        tests,
        "F tests of nested within-subject OLS models (subject as a fixed effect): fixture: "
        "the fixture just practised; variant: the trajectory variant; carry_over: adding "
        "the previous block's fixture. n_obs: probe trials; provenance.csv lists them.",
        columns=("dv", "unit", "test", "F", "df1", "df2", "p", "n_obs", "n_subjects",
                 "note")))
    out.blocks.append(TableBlock(
        "vf_transfer_model", "Primary: estimates of the probe model", est,
        "term fixture: the probe's mean after practising that fixture minus the mean over "
        "the fixtures (unit of the dv), at equal block position and variant; "
        "block_position: change per block of practice; variant: difference from the first "
        "variant. se, z, p: Wald; ci_low/ci_high: 95 % interval.",
        columns=("dv", "unit", "term", "condition", "coef", "ci_low", "ci_high", "p",
                 "n_obs", "n_subjects")))
    words = []
    for r in tests.to_dict("records"):
        name = DV_NAMES.get(r["dv"], r["dv"])
        if r["test"] == "fixture":
            words.append(f"{name}: fixture just practised F({r['df1']}, {r['df2']}) = "
                         f"{r['F']:.2f}, {_p_text(r['p'])} (n = {r['n_subjects']} subjects, "
                         f"{r['n_obs']} probes)")
        elif r["test"] == "carry_over":
            words.append(f"{name}: carry-over (previous block's fixture) " + (
                f"F({r['df1']}, {r['df2']}) = {r['F']:.2f}, {_p_text(r['p'])}"
                if r["df1"] else str(r["note"])))
    for r in est[est["term"] == "block_position"].to_dict("records"):
        words.append(f"{DV_NAMES.get(r['dv'], r['dv'])}: {r['coef']:+.3g} {r['unit']} per "
                     f"block of practice (95 % CI {r['ci_low']:.3g} to {r['ci_high']:.3g})")
    out.blocks.append(TextList("In words", tuple(words)))
    prov = [prov_row("vf_transfer_model", "probe trials closing a fixture block", s,
                     trial_ids=g["trial_id"]) for s, g in probes.groupby("subject")]
    prov += [{**r, "table": "vf_transfer_tests"} for r in prov]
    return out.section("transfer", TITLE, intro), prov


def measure_correlations(trials: pd.DataFrame, pairs: list[tuple[str, str]]
                         ) -> pd.DataFrame:
    """How strongly one trial outcome tracks another: Pearson's r over the trials (95 %
    interval by Fisher's z, scipy) and the repeated-measures correlation (the within-subject
    correlation of Bakdash & Marusich 2017: the partial correlation of x and y given the
    subject, from the OLS fit ``y ~ C(subject) + x`` of statsmodels, r = t / sqrt(t^2 +
    df), p of that t, 95 % interval by Fisher's z with standard error 1 / sqrt(df - 1),
    df = N - subjects - 1).

    Args:
        trials: ``VfAnalysis.trials``. pairs: (x, y) outcome columns.

    Returns:
        :data:`CORRELATION_COLUMNS` rows, methods ``pearson`` and ``repeated_measures``
        (a pair or method without enough data is left out).
    """
    rows: list[dict[str, Any]] = []
    for x, y in pairs:
        if x not in trials.columns or y not in trials.columns:
            continue
        d = trials[["subject", x, y]].dropna()
        n, ns = len(d), int(d["subject"].nunique())
        if n >= 4 and d[x].nunique() > 1 and d[y].nunique() > 1:
            res = sps.pearsonr(d[x].astype(float), d[y].astype(float))
            ci = res.confidence_interval(0.95)
            rows.append({"x": x, "y": y, "method": "pearson", "n_obs": n, "n_subjects": ns,
                         "r": float(res.statistic), "ci_low": float(ci.low),
                         "ci_high": float(ci.high), "p": float(res.pvalue)})
        if ns >= 2 and n - ns - 1 >= 3:
            dd = pd.DataFrame({"s": d["subject"].astype(str), "x": d[x].astype(float),
                               "y": d[y].astype(float)})
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fit = smf.ols("y ~ C(s) + x", dd).fit()
            t, dof = float(fit.tvalues["x"]), float(fit.df_resid)
            if not math.isfinite(t):
                continue
            r = t / math.sqrt(t * t + dof)
            half = 1.959963984540054 / math.sqrt(dof - 1.0)
            z = float(np.arctanh(np.clip(r, -0.999999999, 0.999999999)))
            rows.append({"x": x, "y": y, "method": "repeated_measures", "n_obs": n,
                         "n_subjects": ns, "r": r, "ci_low": math.tanh(z - half),
                         "ci_high": math.tanh(z + half), "p": float(fit.pvalues["x"])})
    return pd.DataFrame(rows, columns=list(CORRELATION_COLUMNS))


def measures_section(vf: VfAnalysis) -> tuple[Section, list[dict[str, str]]]:
    """What each outcome is (``vf_measures``) and how they correlate
    (``vf_measure_correlations``), the e-latency correlation stated in words."""
    out = SectionOut()
    have = {dv for dv, _, _ in vf.dvs}
    rows = [
        {"measure": PATH_DEV_DV[0], "unit": PATH_DEV_DV[2], "role": "accuracy (THE accuracy "
         "measure)", "definition": "time mean of the distance from the tool tip to the "
         "planned path (polyline through the points of interest) over the trial's samples"},
        *({"measure": col, "unit": unit, "role": "accuracy (descriptive)",
           "definition": name} for col, name, unit in PATH_DEV_EXTRA.values()),
        {"measure": LATENCY_DV[0], "unit": LATENCY_DV[2], "role": "speed", "definition":
         "Σ l_i over the reached points: the reach time of the last reached point"},
        {"measure": EQ65_DV[0], "unit": EQ65_DV[2], "role": "the seed's measure (eq. 6.5), "
         "for comparison", "definition": "Σ_i Σ_j ||x(j) - p_i||_1 Δt_j: the Manhattan "
         "distance to the next point of interest integrated over time; it grows with the "
         "time spent, so it is not an accuracy measure"},
    ]
    table = pd.DataFrame(rows)
    table["analysed"] = [m in have or m in vf.trials.columns for m in table["measure"]]
    intro: list[Block] = [Paragraph(
        "Path deviation is the accuracy measure; latency the speed measure. Eq. 6.5's e "
        "keeps the seed's formula (Manhattan distance to the next point of interest, summed "
        "over the logged samples) and is reported per trial times the sample period, i.e. "
        "in mm·s: a time integral of a distance, not a length. The correlations below say "
        "from these data how strongly e tracks latency.")]
    if vf.trials.empty:
        out.notes.append("no analysed trial of a fixture condition or a VF-free probe: no "
                         "measures")
        return out.section("measures", MEASURES_TITLE, intro), []
    if PATH_DEV_DV[0] not in have:
        out.notes.append(PATH_DEV_ABSENT)
    if EQ65_DV[0] not in have:
        out.notes.append(EQ65_ABSENT)
    out.blocks.append(TableBlock("vf_measures", "The VF study's measures", table,
                                 "unit '1': a fraction (0..1).",
                                 columns=("measure", "unit", "role", "definition",
                                          "analysed")))
    # the measures table's 'analysed' column comes from every analysed VF trial
    prov = [prov_row("vf_measures", "all analysed VF trials", s, trial_ids=g["trial_id"])
            for s, g in vf.trials.groupby("subject")]
    cor = measure_correlations(vf.trials, [("eq65", "latency"), ("path_deviation", "latency"),
                                           ("eq65", "path_deviation")])
    if cor.empty:
        out.notes.append("too few analysed trials for the correlations between measures")
        return out.section("measures", MEASURES_TITLE, intro), prov
    out.blocks.append(TableBlock(
        "vf_measure_correlations", "How strongly the measures track each other", cor,
        "pearson: over every analysed VF trial (95 % interval by Fisher's z; trials of a "
        "subject are not independent, so read it as descriptive); repeated_measures: the "
        "within-subject correlation (partial r given the subject, OLS y ~ subject + x; "
        "95 % interval by Fisher's z).",
        columns=CORRELATION_COLUMNS))
    words = []
    for r in cor.to_dict("records"):
        words.append(f"{DV_NAMES.get(r['x'], r['x'])} vs {DV_NAMES.get(r['y'], r['y'])} "
                     f"({r['method'].replace('_', ' ')}): r = {r['r']:.3f} (95 % CI "
                     f"{r['ci_low']:.3f} to {r['ci_high']:.3f}), n = {r['n_obs']} trials")
    out.blocks.append(TextList("In words", tuple(words)))
    prov += [prov_row("vf_measure_correlations", "all analysed VF trials", s,
                      trial_ids=g["trial_id"]) for s, g in vf.trials.groupby("subject")]
    return out.section("measures", MEASURES_TITLE, intro), prov


__all__ = ["CORRELATION_COLUMNS", "measure_correlations", "measures_section",
           "transfer_section"]
