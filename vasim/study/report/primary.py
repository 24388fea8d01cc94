"""The VF study's tests as pure functions shared by the report and power planning: the
PRIMARY probe model's fixture test (:func:`probe_model_tests`, issue #25) and the
RM-ANOVAs of the seed's design (:func:`primary_tests`, secondary since issue #25; the name
is kept for its callers).

These tests (spec §3 decision, ``summary.json`` keys ``fixture`` and ``practice``; since
issue #25 a secondary analysis beside the probe model of
:mod:`vasim.study.report.transfer`) are a one-way subject-level RM-ANOVA per outcome for
the factor fixture (6
levels; VF-free level = the probes after the blocks) and one for the factor trial (the
VF-free probe trials 1..8: the practice effect), each over the subjects with every cell of
the factor. :func:`factor_anova_data` selects those subjects and orders the levels;
:func:`primary_tests` runs every test of a :class:`~vasim.study.report.analysis.VfAnalysis`
exactly as the report's fixture section does (``stats.rm_anova``), so power planning
(:mod:`vasim.study.power`) counts rejections of the very tests the report would print.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from typing import Any

import pandas as pd

from vasim.core.errors import ConfigError
from vasim.study import stats
from vasim.study.report.analysis import VfAnalysis, complete_subjects

PRIMARY_FACTORS: tuple[str, ...] = ("fixture", "trial")
"""The factors of the primary RM-ANOVAs: fixture effect, practice effect (probe trials)."""
PRIMARY_COLUMNS: tuple[str, ...] = ("dv", "factor", "n_subjects", "n_levels", "df1", "df2",
                                    "F", "p_unc", "p_gg", "np2", "reason")
"""Columns of :func:`primary_tests`."""


def factor_anova_data(cells: pd.DataFrame, factor: str, levels: Sequence[Any]
                      ) -> tuple[pd.DataFrame, dict[str, list[str]]]:
    """The cells one factor's RM-ANOVA runs on: complete subjects, levels in order.

    Args:
        cells: one row per subject and level (``VfAnalysis.fixture_cells`` or
            ``trial_cells``). factor: the level column. levels: the levels, report order.

    Returns:
        (cells of the subjects with every level, ``factor`` a categorical of ``levels``
        as text; {excluded subject: its missing levels}).

    Example:
        >>> c = pd.DataFrame({"subject": ["a", "a", "b"], "trial": [1, 2, 1]})
        >>> d, gone = factor_anova_data(c, "trial", [1, 2])
        >>> list(d["trial"].cat.categories), gone
        (['1', '2'], {'b': ['2']})
    """
    kept, missing = complete_subjects(cells, factor, levels)
    data = kept.copy()
    data[factor] = pd.Categorical(data[factor].astype(str),
                                  categories=[str(v) for v in levels])
    return data, missing


def _not_computed(dv: str, factor: str, n: int, k: int, reason: str) -> dict[str, Any]:
    nan = math.nan
    return {"dv": dv, "factor": factor, "n_subjects": n, "n_levels": k, "df1": nan,
            "df2": nan, "F": nan, "p_unc": nan, "p_gg": nan, "np2": nan, "reason": reason}


def primary_tests(vf: VfAnalysis) -> pd.DataFrame:
    """Every primary RM-ANOVA of the VF study (the report's ``vf_rm_anova`` rows).

    Args:
        vf: the analysis of one cohort (``analyse_vf``).

    Returns:
        One row per outcome of ``vf.dvs`` and factor of :data:`PRIMARY_FACTORS`
        (:data:`PRIMARY_COLUMNS`): F, uncorrected and Greenhouse-Geisser p, partial eta
        squared; a test that cannot run (fewer than 2 levels or 2 complete subjects, or
        ``rm_anova`` refusing the data) has NaN statistics and its ``reason``.

    **Decision**: warnings of ``rm_anova`` (e.g. a degenerate sphericity test) are
    silenced here; the report prints them as notes, a power run of hundreds of cohorts
    would only repeat them.
    """
    rows: list[dict[str, Any]] = []
    designs = (("fixture", vf.fixture_cells, vf.fixture_levels),
               ("trial", vf.trial_cells, vf.trial_levels))
    for factor, cells, levels in designs:
        k = len(levels)
        if k < 2 or cells.empty:
            rows += [_not_computed(dv, factor, 0, k, f"{k} level(s); an RM-ANOVA needs 2")
                     for dv, _, _ in vf.dvs]
            continue
        data, _missing = factor_anova_data(cells, factor, levels)
        n = int(data["subject"].nunique())
        for dv, _name, _unit in vf.dvs:
            if n < 2:
                rows.append(_not_computed(dv, factor, n, k, f"{n} complete subject(s); an "
                                          "RM-ANOVA needs 2"))
                continue
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    aov = stats.rm_anova(data, dv=dv, subject="subject", within=factor)
            except ConfigError as exc:
                rows.append(_not_computed(dv, factor, n, k, exc.reason))
                continue
            r = aov.iloc[0]
            rows.append({"dv": dv, "factor": factor, "n_subjects": n, "n_levels": k,
                         "df1": float(r["df1"]), "df2": float(r["df2"]), "F": float(r["F"]),
                         "p_unc": float(r["p_unc"]), "p_gg": float(r["p_gg"]),
                         "np2": float(r["np2"]), "reason": ""})
    return pd.DataFrame(rows, columns=list(PRIMARY_COLUMNS))


PROBE_MODEL_FACTOR = "practised"
"""The factor label of the primary probe model's fixture test in power tables (the fixture
practised in the block before each VF-free probe)."""


def probe_model_tests(vf: VfAnalysis) -> pd.DataFrame:
    """The PRIMARY analysis' fixture test of every outcome, as :func:`primary_tests` rows.

    The test is the report's ``vf_transfer_tests`` row ``fixture``
    (:func:`vasim.study.report.transfer.transfer_model`): the nested F test of the fixture
    just practised in the post-block probe model (block position and variant in the
    model, the subject as a fixed effect). Rows carry ``factor`` =
    :data:`PROBE_MODEL_FACTOR`, ``p_unc`` = ``p_gg`` = the F test's p (no sphericity
    correction applies to it), ``np2`` = F df1 / (F df1 + df2) (partial eta squared of
    the term), ``n_levels`` the practised fixtures; a model that cannot be fitted gives
    NaN statistics and its ``reason``.
    """
    from vasim.study.report.transfer import transfer_model

    rows: list[dict[str, Any]] = []
    n_sub = int(vf.trials["subject"].nunique()) if not vf.trials.empty else 0
    for dv, _name, unit in vf.dvs:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                est, tests = transfer_model(vf.trials, dv, unit)
        except ConfigError as exc:
            rows.append(_not_computed(dv, PROBE_MODEL_FACTOR, n_sub, 0, exc.reason))
            continue
        k = len(est.attrs.get("fixtures", ()))
        t = tests.set_index("test").loc["fixture"]
        f, df1, df2 = float(t["F"]), float(t["df1"]), float(t["df2"])
        if not math.isfinite(f):
            rows.append(_not_computed(dv, PROBE_MODEL_FACTOR, int(t["n_subjects"]), k,
                                      str(t["note"]) or "fixture test not computed"))
            continue
        rows.append({"dv": dv, "factor": PROBE_MODEL_FACTOR,
                     "n_subjects": int(t["n_subjects"]), "n_levels": k, "df1": df1,
                     "df2": df2, "F": f, "p_unc": float(t["p"]), "p_gg": float(t["p"]),
                     "np2": f * df1 / (f * df1 + df2), "reason": ""})
    return pd.DataFrame(rows, columns=list(PRIMARY_COLUMNS))


__all__ = ["PRIMARY_COLUMNS", "PRIMARY_FACTORS", "PROBE_MODEL_FACTOR", "factor_anova_data",
           "primary_tests", "probe_model_tests"]
