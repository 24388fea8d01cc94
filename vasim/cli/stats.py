"""``vasim stats``: run the study statistics on a long-format CSV file.

``register(subparsers)`` adds ``vasim stats {rm-anova,mixed-anova,mixed-model,tukey,paired,
spearman}``. Each prints a readable table, or with ``--json`` a strict JSON object
(undefined values ``null``, numbers unrounded) with a fixed set of keys. Bad input (missing
file or column, a duplicated column name, non-numeric values, unbalanced design) raises
``ConfigError``, which ``vasim.cli`` prints as one line with exit code 2. Subject, factor,
group and item columns are read as text (``01`` and ``1`` are two subjects).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import warnings
from collections.abc import Callable, Sequence
from typing import Any, TextIO

import pandas as pd

from vasim.core.config import expect
from vasim.core.errors import InputError

_EPILOG = """\
Input is a long-format CSV: one row per observation, with the dependent variable, the
subject and the factor(s) as columns. Several rows per subject and cell (e.g. per trial or
per sample) are averaged into one cell mean per subject before the repeated-measures tests.

analyses (spec/study.md section 3):
  rm-anova   primary analysis: subject-level repeated-measures ANOVA, Mauchly's test,
             Greenhouse-Geisser / Huynh-Feldt corrections, partial and generalised eta^2
  mixed-anova  between-subjects group x within factor (mixed design), GG-corrected
  mixed-model  linear mixed model, random intercept per subject (statsmodels MixedLM, REML)
  tukey      Tukey HSD post hoc (the seed's): between groups (Tukey-Kramer), or repeated
             measures with the RM-ANOVA error term (assumes sphericity)
  paired     paired t-tests for all pairs, Holm/Bonferroni adjusted (the within-subject-
             correct post hoc), with power at N and minimum N for power 0.9
  spearman   Spearman's rho between all pairs of questionnaire items

examples:
  vasim stats rm-anova --csv trials.csv --dv error --subject subject --within fixture,trial
  vasim stats mixed-anova --csv probes.csv --dv error --subject subject --within trial \
      --between group
  vasim stats mixed-model --csv trials.csv --formula "error ~ C(fixture) + trial" \
      --groups subject --factors fixture
  vasim stats tukey --csv trials.csv --dv error --subject subject --within fixture
  vasim stats tukey --csv plants.csv --dv weight --between group
  vasim stats paired --csv modes.csv --dv ET --subject subject --within mode --json
  vasim stats spearman --csv likert.csv --subject subject --item question --value answer
"""


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds ``vasim stats {rm-anova,mixed-anova,mixed-model,tukey,paired,spearman}``."""
    p = subparsers.add_parser(
        "stats",
        help="statistics of a study CSV: RM-ANOVA, mixed ANOVA/model, Tukey, paired, Spearman",
        description="Statistics of the user studies on a long-format CSV file: the "
                    "subject-level repeated-measures ANOVA and its post hoc tests, the "
                    "mixed-design ANOVA (groups x within factor), a linear mixed model with "
                    "a random intercept per subject, paired t-tests with power analysis, "
                    "and Spearman correlations of questionnaire items.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = p.add_subparsers(dest="stats_command", metavar="TEST", required=True)

    q = sub.add_parser("rm-anova", help="repeated-measures ANOVA (one- or two-way within)",
                       description="Subject-level repeated-measures ANOVA with Mauchly's test "
                                   "of sphericity and GG/HF/lower-bound corrections.")
    _common(q, dv=True)
    q.add_argument("--subject", required=True, metavar="COL", help="subject-identifier column")
    q.add_argument("--within", required=True, metavar="A[,B]",
                   help="one within factor column, or two separated by a comma")
    q.set_defaults(func=cmd_rm_anova)

    q = sub.add_parser("mixed-anova", help="mixed-design ANOVA: one between x one within factor",
                       description="Mixed-design (split-plot) ANOVA on subject-level cell "
                                   "means: between-subjects factor, within factor and their "
                                   "interaction, Greenhouse-Geisser correction and Mauchly's "
                                   "test on the within terms, partial and generalised eta^2.")
    _common(q, dv=True)
    q.add_argument("--subject", required=True, metavar="COL", help="subject-identifier column")
    q.add_argument("--within", required=True, metavar="COL", help="within factor column")
    q.add_argument("--between", required=True, metavar="COL",
                   help="between-subjects factor column (one group per subject)")
    q.set_defaults(func=cmd_mixed_anova)

    q = sub.add_parser("mixed-model", help="linear mixed model, random intercept per subject",
                       description="Linear mixed model fitted by REML (statsmodels MixedLM) "
                                   "with one random intercept per level of --groups; fixed "
                                   "effects with Wald 95 % CI. Fit warnings (non-convergence, "
                                   "boundary) are printed as notes.")
    _common(q, dv=False)
    q.add_argument("--formula", required=True, metavar="F",
                   help='fixed effects, patsy syntax, e.g. "error ~ C(fixture) + trial"')
    q.add_argument("--groups", required=True, metavar="COL",
                   help="column with one random intercept per level (the subject column)")
    q.add_argument("--factors", default="", metavar="A[,B...]",
                   help="columns to read as text labels (categorical in the formula); other "
                        "columns of numbers are numeric")
    q.set_defaults(func=cmd_mixed_model)

    q = sub.add_parser("tukey", help="Tukey HSD: --between G, or --subject S --within A",
                       description="Tukey HSD post hoc comparisons. With --between: "
                                   "independent groups (Tukey-Kramer for unequal n). With "
                                   "--subject and --within: repeated measures, per-subject "
                                   "level means and the RM-ANOVA error term.")
    _common(q, dv=True)
    q.add_argument("--between", metavar="COL", help="grouping column (independent groups)")
    q.add_argument("--subject", metavar="COL", help="subject column (repeated measures)")
    q.add_argument("--within", metavar="COL", help="within factor column (repeated measures)")
    q.set_defaults(func=cmd_tukey)

    q = sub.add_parser("paired", help="paired t-tests between all levels, with power",
                       description="Paired Student t-tests between every pair of levels of a "
                                   "within factor, 95 % CI, Cohen's dz, observed power, "
                                   "minimum N for power 0.9, Holm and Bonferroni p.")
    _common(q, dv=True)
    q.add_argument("--subject", required=True, metavar="COL", help="subject-identifier column")
    q.add_argument("--within", required=True, metavar="COL", help="within factor column")
    q.set_defaults(func=cmd_paired)

    q = sub.add_parser("spearman", help="Spearman's rho between all questionnaire items",
                       description="Spearman rank correlation between every pair of items "
                                   "(pairwise deletion of missing answers).")
    _common(q, dv=False)
    q.add_argument("--subject", required=True, metavar="COL", help="respondent column")
    q.add_argument("--item", required=True, metavar="COL", help="item (question) column")
    q.add_argument("--value", required=True, metavar="COL", help="answer column (numbers)")
    q.set_defaults(func=cmd_spearman)


def _common(q: argparse.ArgumentParser, *, dv: bool) -> None:
    q.add_argument("--csv", required=True, metavar="FILE", help="long-format CSV file")
    if dv:
        q.add_argument("--dv", required=True, metavar="COL", help="dependent-variable column")
    q.add_argument("--json", action="store_true",
                   help="print strict JSON (unrounded values, null where undefined)")


def _run(fn: Callable[[], Any]) -> tuple[Any, list[str]]:
    """Runs a statistic, collecting its StatsWarnings as note lines."""
    from vasim.study.stats import StatsWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", StatsWarning)
        result = fn()
    return result, [str(w.message) for w in caught if issubclass(w.category, StatsWarning)]


def cmd_rm_anova(args: argparse.Namespace) -> int:
    """``vasim stats rm-anova``."""
    from vasim.study.stats import RM_ANOVA_COLUMNS, read_long_csv, rm_anova

    within = [w.strip() for w in str(args.within).split(",")]
    expect(1 <= len(within) <= 2 and all(within), args.within,
           "one factor or two separated by a comma", field="--within", error=InputError)
    data = read_long_csv(args.csv, text_columns=[args.subject, *within])
    aov, notes = _run(lambda: rm_anova(data, args.dv, args.subject, within))
    out = sys.stdout
    if args.json:
        keys = [c for c in RM_ANOVA_COLUMNS if c not in ("effect", "note")]
        body = {str(r["effect"]): {k: _json_value(r[k]) for k in keys}
                for r in aov.to_dict("records")}
        _print_json({"rm_anova": body}, out)
        _print_notes(notes, sys.stderr)
        return 0
    n_min, n_max = aov.attrs["n_obs_per_cell"]
    rows_per_cell = f"{n_min}" if n_min == n_max else f"{n_min}-{n_max}"
    print("Repeated-measures ANOVA on subject-level cell means (primary analysis)", file=out)
    print(f"data: {args.csv}; dv {args.dv!r}, subject {args.subject!r}, within "
          f"{', '.join(repr(w) for w in within)}; {aov.attrs['n_subjects']} subjects, "
          f"{rows_per_cell} row(s) averaged per subject x cell", file=out)
    print(file=out)
    _print_table(aov, ["effect", "df1", "df2", "SS", "MS", "F", "p_unc", "np2", "ges"], out)
    print(file=out)
    print("Sphericity (Mauchly's test) and epsilon-corrected p-values", file=out)
    sph = aov.rename(columns={"mauchly_W": "W", "mauchly_chi2": "chi2", "mauchly_df": "df",
                              "mauchly_p": "p_mauchly"})
    sph["df"] = sph["df"].astype("Int64")  # an integer count, or <NA> where undefined
    _print_table(sph, ["effect", "W", "chi2", "df", "p_mauchly", "eps_gg", "eps_hf", "eps_lb",
                       "p_gg", "p_hf", "p_lb"], out)
    # The StatsWarnings of rm_anova repeat the note column, which is printed instead.
    _print_notes([f"{r['effect']}: {r['note']}" for r in aov.to_dict("records") if r["note"]],
                 out)
    return 0


def cmd_mixed_anova(args: argparse.Namespace) -> int:
    """``vasim stats mixed-anova``."""
    from vasim.study.stats import MIXED_ANOVA_COLUMNS, mixed_anova, read_long_csv

    data = read_long_csv(args.csv, text_columns=[args.subject, args.within, args.between])
    aov, notes = _run(lambda: mixed_anova(data, args.dv, args.within, args.between,
                                          args.subject))
    out = sys.stdout
    if args.json:
        keys = [c for c in MIXED_ANOVA_COLUMNS if c not in ("Source", "note")]
        body = {str(r["Source"]): {k: _json_value(r[k]) for k in keys}
                for r in aov.to_dict("records")}
        _print_json({"mixed_anova": body}, out)
        _print_notes(notes, sys.stderr)
        return 0
    sizes = ", ".join(f"{g} {n}" for g, n in aov.attrs["group_sizes"].items())
    print("Mixed-design ANOVA on subject-level cell means (between x within)", file=out)
    print(f"data: {args.csv}; dv {args.dv!r}, subject {args.subject!r}, within "
          f"{args.within!r}, between {args.between!r}; {aov.attrs['n_subjects']} subjects "
          f"({sizes})", file=out)
    print(file=out)
    _print_table(aov, ["Source", "DF1", "DF2", "SS", "MS", "F", "p_unc", "np2", "ng2"], out)
    print(file=out)
    print("Sphericity of the within terms (Mauchly, R's mauchly.test) and GG correction",
          file=out)
    _print_table(aov.iloc[1:], ["Source", "W_spher", "p_spher", "eps", "p_GG_corr"], out)
    _print_notes([f"{r['Source']}: {r['note']}" for r in aov.to_dict("records") if r["note"]],
                 out)
    return 0


def cmd_mixed_model(args: argparse.Namespace) -> int:
    """``vasim stats mixed-model``."""
    from vasim.study.stats import MIXED_MODEL_COLUMNS, mixed_model, read_long_csv

    factors = [f.strip() for f in str(args.factors).split(",") if f.strip()]
    data = read_long_csv(args.csv, text_columns=[args.groups, *factors])
    _check_factors(data, factors, args.formula, str(args.csv))
    fit, notes = _run(lambda: mixed_model(data, args.formula, args.groups))
    out = sys.stdout
    attrs = fit.attrs
    if args.json:
        keys = [c for c in MIXED_MODEL_COLUMNS if c not in ("term", "note")]
        body = {
            "formula": args.formula, "groups": args.groups, "n_obs": attrs["n_obs"],
            "n_groups": attrs["n_groups"], "group_var": _json_value(attrs["group_var"]),
            "resid_var": _json_value(attrs["resid_var"]), "converged": attrs["converged"],
            "llf": _json_value(attrs["llf"]),
            "fixed": {str(r["term"]): {k: _json_value(r[k]) for k in keys}
                      for r in fit.to_dict("records")},
            "note": str(fit["note"].iloc[0]),
        }
        _print_json({"mixed_model": body}, out)
        _print_notes(notes, sys.stderr)
        return 0
    print("Linear mixed model, random intercept per group (statsmodels MixedLM, REML)",
          file=out)
    print(f"data: {args.csv}; {args.formula}; groups {args.groups!r}: {attrs['n_groups']} "
          f"groups, {attrs['n_obs']} observations", file=out)
    print(f"random-intercept variance {_num(attrs['group_var'])}, residual variance "
          f"{_num(attrs['resid_var'])}, converged {attrs['converged']}", file=out)
    print(file=out)
    _print_table(fit, ["term", "coef", "se", "z", "p", "ci_low", "ci_high"], out)
    # The StatsWarning repeats the note column, which is printed instead.
    _print_notes([str(fit["note"].iloc[0])] if fit["note"].iloc[0] else [], out)
    return 0


def _check_factors(data: pd.DataFrame, factors: list[str], formula: str, source: str) -> None:
    """``--factors``: each a column of the file and of the formula (issue #30 item 6: an
    unknown factor was silently ignored, its column then read as numbers)."""
    from vasim.study.stats.mixed_model import check_formula, formula_columns

    columns = [str(c) for c in data.columns]
    check_formula(formula, columns, source=source)
    used = formula_columns(formula, columns)
    for f in factors:
        expect(f in columns, f, f"a column of the file ({', '.join(columns)})", file=source,
               field="--factors", error=InputError)
        expect(f in used, f, f"a column the formula {formula!r} uses ({', '.join(used)})",
               file=source, field="--factors", error=InputError)


def cmd_tukey(args: argparse.Namespace) -> int:
    """``vasim stats tukey``."""
    from vasim.study.stats import TUKEY_COLUMNS, read_long_csv, tukey_hsd, tukey_hsd_rm

    rm_given = args.subject is not None or args.within is not None
    if args.between is not None and rm_given:
        raise InputError("give either --between COL (independent groups) or --subject COL "
                         "--within COL (repeated measures), not both")
    if args.between is None and (args.subject is None or args.within is None):
        raise InputError("tukey needs --between COL, or both --subject COL and --within COL")
    labels = [args.between] if args.between is not None else [args.subject, args.within]
    data = read_long_csv(args.csv, text_columns=labels)
    if args.between is not None:
        res, notes = _run(lambda: tukey_hsd(data, args.dv, args.between))
        title = ("Tukey HSD, independent groups (Tukey-Kramer for unequal n), pooled "
                 "within-group error")
    else:
        res, notes = _run(lambda: tukey_hsd_rm(data, args.dv, args.subject, args.within))
        title = ("Tukey HSD, repeated measures (the seed's post hoc): per-subject level means, "
                 "RM-ANOVA error term, assumes sphericity; see `vasim stats paired` for the "
                 "Holm-corrected paired tests")
    out = sys.stdout
    if args.json:
        _print_json({"tukey": res.to_dict()}, out)
        _print_notes(notes, sys.stderr)
        return 0
    print(title, file=out)
    print(f"data: {args.csv}; dv {args.dv!r}, factor {res.factor!r}; k = {res.k} means, "
          f"MS_error = {_num(res.ms_error)}, df_error = {_num(res.df_error)}, "
          f"q_crit(0.95) = {_num(res.q_crit)}", file=out)
    print("diff = mean2 - mean1; lwr/upr: 95 % family-wise interval", file=out)
    print(file=out)
    _print_table(res.comparisons, list(TUKEY_COLUMNS), out)
    _print_notes(notes, out)
    return 0


def cmd_paired(args: argparse.Namespace) -> int:
    """``vasim stats paired``."""
    from vasim.study.stats import PAIRED_COLUMNS, pairwise_paired, read_long_csv

    data = read_long_csv(args.csv, text_columns=[args.subject, args.within])
    res, notes = _run(lambda: pairwise_paired(data, args.dv, args.subject, args.within))
    out = sys.stdout
    if args.json:
        tests = [{k: _json_value(r[k]) for k in PAIRED_COLUMNS} for r in res.to_dict("records")]
        _print_json({"paired": {"tests": tests}}, out)
        _print_notes(notes, sys.stderr)
        return 0
    print("Paired t-tests between all levels, Holm and Bonferroni adjusted "
          "(within-subject-correct post hoc)", file=out)
    print(f"data: {args.csv}; dv {args.dv!r}, subject {args.subject!r}, within "
          f"{args.within!r}; mean_diff = group1 - group2, 95 % CI", file=out)
    print(file=out)
    _print_table(res, ["group1", "group2", "n", "mean_diff", "t", "df", "p", "p_holm",
                       "p_bonf", "ci_low", "ci_high"], out)
    print(file=out)
    print("Effect size and power (two-sided, alpha = 0.05)", file=out)
    _print_table(res, ["group1", "group2", "cohen_dz", "power_observed", "n_power90",
                       "n_power90_ceil"], out)
    _print_notes(notes, out)
    return 0


def cmd_spearman(args: argparse.Namespace) -> int:
    """``vasim stats spearman``."""
    from vasim.study.stats import SPEARMAN_COLUMNS, read_long_csv, spearman_items

    data = read_long_csv(args.csv, text_columns=[args.subject, args.item])
    res, notes = _run(lambda: spearman_items(data, args.subject, args.item, args.value))
    out = sys.stdout
    if args.json:
        tests = [{k: _json_value(r[k]) for k in SPEARMAN_COLUMNS}
                 for r in res.to_dict("records")]
        _print_json({"spearman": {"tests": tests}}, out)
        _print_notes(notes, sys.stderr)
        return 0
    print("Spearman rank correlations between items (pairwise deletion of missing answers; "
          "p from the t approximation)", file=out)
    print(f"data: {args.csv}; respondent {args.subject!r}, item {args.item!r}, value "
          f"{args.value!r}", file=out)
    print(file=out)
    _print_table(res, list(SPEARMAN_COLUMNS), out)
    _print_notes(notes, out)
    return 0


def _json_value(value: Any) -> Any:
    from vasim.study.stats import nan_to_none

    return nan_to_none(value)


def _print_json(obj: dict[str, Any], out: TextIO) -> None:
    # allow_nan=False: strict JSON; every NaN was turned into None (null) before.
    print(json.dumps(obj, indent=2, allow_nan=False), file=out)


def _print_notes(notes: Sequence[str], out: TextIO) -> None:
    if notes:
        print(file=out)
        for note in dict.fromkeys(notes):
            print(f"note: {note}", file=out)


def _num(value: Any) -> str:
    """A readable number: NaN/None as '-', integers as is, 4 decimals or 3-digit scientific."""
    if value is None or value is pd.NA:
        return "-"
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "-"
        if value == 0.0:
            return "0"
        if 1e-4 <= abs(value) < 1e6:
            return f"{value:.4f}"
        return f"{value:.3e}"
    return str(value)


def _print_table(frame: pd.DataFrame, columns: Sequence[str], out: TextIO) -> None:
    """Fixed-width table: text left-aligned, numbers right-aligned."""
    records = frame.to_dict("records")
    cells = [[_num(_plain(r[c])) for c in columns] for r in records]
    numeric = [all(_is_number(r[c]) for r in records) for c in columns]
    widths = [max([len(c)] + [len(row[i]) for row in cells]) for i, c in enumerate(columns)]

    def line(values: Sequence[str]) -> str:
        parts = [v.rjust(w) if num else v.ljust(w)
                 for v, w, num in zip(values, widths, numeric, strict=True)]
        return "  ".join(parts).rstrip()

    print(line(list(columns)), file=out)
    print(line(["-" * w for w in widths]), file=out)
    for row in cells:
        print(line(row), file=out)


def _plain(value: Any) -> Any:
    from vasim.study.stats import python_scalar

    return None if value is pd.NA else python_scalar(value)


def _is_number(value: Any) -> bool:
    value = _plain(value)
    return value is None or (isinstance(value, int | float) and not isinstance(value, bool))
