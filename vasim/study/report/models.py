"""The VF study's secondary model-based analyses: fixture effects over every trial adjusted
for practice and variant (linear mixed model) and surgeons vs residents over the probe
trials (mixed-design ANOVA: group, practice and their interaction). The primary analysis
is :mod:`vasim.study.report.transfer`.

Both are pure functions of :class:`~vasim.study.report.analysis.VfAnalysis` tables; the
statistics themselves are :func:`vasim.study.stats.mixed_model` (statsmodels ``MixedLM``)
and :func:`vasim.study.stats.mixed_anova`.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from vasim.study import stats
from vasim.study.report.analysis import complete_subjects
from vasim.study.report.common import FIXTURE_ORDER, ordered_conditions
from vasim.study.store import GROUPS

REFERENCE = "none"
"""The reference level of the mixed model's fixture contrasts (VF-free trials)."""

_TERM = re.compile(r"^C\(fixture\)\[T\.(.+)\]$")
_VARIANT = re.compile(r"^C\(variant\)\[T\.(v\d+)\]$")


def mixed_model_data(trials: pd.DataFrame, dv: str) -> pd.DataFrame:
    """The rows of the practice-adjusted mixed model: every analysed VF trial with a value.

    Args:
        trials: ``VfAnalysis.trials`` (``subject, condition, practice`` and ``dv``).
        dv: the outcome column.

    Returns:
        ``trial_id, subject, fixture, variant, practice, log_practice, <dv>``
        (``variant`` text ``v<k>``, issue #25); ``fixture`` is the
        condition code as a categorical whose first level is ``none`` when present (the
        model's reference), ``log_practice = ln(practice)`` (practice: 1-based position of
        the trial in its session).

    **Decision**: the model uses every analysed trial, the baseline probes included,
    because practice is a covariate here: the baseline trials inform the practice slope
    and the VF-free level, and the fixture contrasts are adjusted for it.

    Example:
        >>> t = pd.DataFrame({"trial_id": [1, 2], "subject": ["a", "a"],
        ...                   "condition": ["vg", "none"], "practice": [1, 4],
        ...                   "latency": [2.0, 3.0]})
        >>> d = mixed_model_data(t, "latency")
        >>> list(d["fixture"].cat.categories), d["log_practice"].round(3).tolist()
        (['none', 'vg'], [0.0, 1.386])
    """
    d = trials[trials[dv].notna()]
    d = pd.DataFrame({"trial_id": d["trial_id"].to_numpy(), "subject": d["subject"].astype(str)
                      .to_numpy(), "fixture": d["condition"].astype(str).to_numpy(),
                      "variant": ["v" + str(int(v)) for v in d["variant"]]
                      if "variant" in d.columns else "v0",
                      "practice": d["practice"].astype(np.int64).to_numpy(),
                      dv: d[dv].astype(float).to_numpy()})
    levels = ordered_conditions(d["fixture"], FIXTURE_ORDER)
    d["fixture"] = pd.Categorical(d["fixture"], categories=levels)
    d["log_practice"] = np.log(d["practice"].astype(float))
    return d


def fixture_mixed_model(trials: pd.DataFrame, dv: str) -> pd.DataFrame:
    """Fixture effects adjusted for practice and variant: ``dv ~ fixture + log(practice) +
    variant``, random intercept per subject (REML, statsmodels ``MixedLM`` via
    :func:`vasim.study.stats.mixed_model`); the variant term is left out when every trial
    ran one variant. A secondary analysis of every trial (assisted and VF-free); the
    primary one is the probe model of :mod:`vasim.study.report.transfer`.

    Args:
        trials: ``VfAnalysis.trials``. dv: the outcome column.

    Returns:
        :func:`vasim.study.stats.mixed_model`'s table (``term, coef, se, z, p, ci_low,
        ci_high, note``) with ``condition`` added: the fixture code of a
        ``C(fixture)[T.x]`` term (its difference from ``none`` in the unit of the dv),
        ``"log_practice"`` for the practice slope (unit of the dv per e-fold of practice),
        ``""`` for the intercept. ``attrs`` as the stats function's plus ``reference``.

    Raises:
        ConfigError: from :func:`vasim.study.stats.mixed_model` (e.g. fewer than 2
            subjects, a single fixture level).
    """
    d = mixed_model_data(trials, dv)
    variant = " + C(variant)" if d["variant"].nunique() > 1 else ""
    fit = stats.mixed_model(d, f"{dv} ~ C(fixture) + log_practice{variant}", groups="subject")
    cond = []
    for term in fit["term"]:
        m = _TERM.match(str(term))
        v = _VARIANT.match(str(term))
        cond.append(m.group(1) if m else v.group(1) if v else
                    ("log_practice" if term == "log_practice" else ""))
    fit.insert(1, "condition", cond)
    fit.attrs["reference"] = str(d["fixture"].cat.categories[0])
    return fit


def group_design(cells: pd.DataFrame, levels: tuple[int, ...]
                 ) -> tuple[pd.DataFrame, dict[str, list[str]]]:
    """The subjects of the surgeons-vs-residents test: a known group and every probe trial.

    Args:
        cells: probe-trial cells with ``subject, trial, group``.
        levels: the probe numbers every subject must have.

    Returns:
        (their cells, {excluded subject: missing probe numbers}).
    """
    known = cells[cells["group"].isin(GROUPS)]
    return complete_subjects(known, "trial", levels)


def group_mixed_anova(cells: pd.DataFrame, dv: str) -> pd.DataFrame:
    """Surgeons vs residents: mixed-design ANOVA, group (between) x probe trial (within).

    Args:
        cells: the complete subjects' probe cells (:func:`group_design`).
        dv: the outcome column.

    Returns:
        :func:`vasim.study.stats.mixed_anova`'s table: rows ``group``, ``trial`` and
        ``Interaction``; F, p_unc, Greenhouse-Geisser ``eps``/``p_GG_corr`` and R's
        Mauchly test (``W_spher``, ``p_spher``) on the within rows.

    Raises:
        ConfigError: from :func:`vasim.study.stats.mixed_anova` (e.g. one group only).
    """
    d = cells[["subject", "group", "trial", dv]].copy()
    d["trial"] = d["trial"].astype(str)
    return stats.mixed_anova(d, dv=dv, within="trial", between="group", subject="subject")


__all__ = ["REFERENCE", "fixture_mixed_model", "group_design", "group_mixed_anova",
           "mixed_model_data"]
