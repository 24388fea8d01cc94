"""Parameter recovery: what the analysis estimates of the fixture effects, beside what a
synthetic cohort's scenario assumed (``summary.json``: ``assumed_effects``,
``recovered_effects``; issue #25 item 4).

**The effect** (one definition for both sides, so they are the same quantity): the
*assisted path-deviation ratio* of fixture c, the ratio of a subject's mean path deviation
while assisted by c to its path deviation without any fixture at the same practice, before
any fixture has been practised (no carry-over). A scenario assumes it as ``accuracy`` a_c
(the operator's learnable-noise factor while assisted, ``vasim.operator.learning``); the
outcome engine (``vasim.operator.outcome``) realises it exactly on the path deviation, the
scripted 1 kHz engine adds each fixture's mechanism on top (unless the scenario's
``mechanism_gain`` is 0), so there "recovered" measures mechanism and assumption together.

**Estimation** (:func:`estimate_effects`; statsmodels ``MixedLM``, REML, a random intercept
per subject)::

    ln E_ij = b0 + sum_c beta_c [trial j assisted by c] + s(ln(1 + practice_j))
              + gamma_1 carry_ij + gamma_2 after_ij [+ variant_j] + u_i + e_ij

E the trial's mean path deviation (``path_dev_mean_mm``), practice the trial's 0-based
position in its session, s a natural cubic regression spline (patsy ``cr``, 4 df, centred;
in ln(1 + practice), where a power law of practice is a line),
``carry`` the number of distinct fixtures practised before an unassisted trial (0 for an
assisted one: carry-over is estimated, not assumed away), ``after`` 1 for an unassisted
trial right after an assisted one (guidance dependence), ``variant`` the trajectory
variant as a factor when every variant runs both assisted and unassisted (else it is
confounded with the fixture and left out, and the result says so). Recovered ratio
``exp(beta_c)``, 95 % Wald interval ``exp(beta_c +- z_.975 SE)``, p of the Wald z test.

The analysis never knows whether its data are synthetic: :func:`recovery_frame` reads a
report's :class:`~vasim.study.report.data.StudyData` and :func:`estimate_effects` works on
any frame of the same columns (a real cohort gets ``recovered_effects`` too; only
``assumed_effects`` needs a stored scenario).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from vasim.core.errors import StoreError
from vasim.operator.scenario import scenario_from_text

VF_FREE = "none"
PATH_DEV = "path_dev_mean_mm"
FRAME_COLUMNS = ("subject", "trial_index", "condition", "variant", "path_dev_mean_mm")
"""Columns :func:`estimate_effects` reads."""


def design_covariates(frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` sorted by subject and practice, with ``practice``, ``carry`` and ``after``
    (module docstring) and ``assisted``."""
    df = frame.sort_values(["subject", "trial_index"]).reset_index(drop=True).copy()
    df["practice"] = df["trial_index"].astype(float)
    df["assisted"] = df["condition"] != VF_FREE
    carry, after = [], []
    for _, g in df.groupby("subject", sort=False):
        seen: set[str] = set()
        prev = VF_FREE
        for cond in g["condition"]:
            unassisted = cond == VF_FREE
            carry.append(float(len(seen)) if unassisted else 0.0)
            after.append(1.0 if unassisted and prev != VF_FREE else 0.0)
            if not unassisted:
                seen.add(str(cond))
            prev = str(cond)
    df["carry"] = carry
    df["after"] = after
    return df


def variant_confounded(df: pd.DataFrame) -> bool:
    """True when some trajectory variant never runs unassisted or never assisted (then
    the variant factor would absorb part of the fixture effect)."""
    both = df.groupby("variant")["assisted"].agg(["any", "all"])
    return bool(((~both["any"]) | both["all"]).any())


def estimate_effects(frame: pd.DataFrame, *, level: float = 0.95) -> dict[str, Any]:
    """The recovered assisted path-deviation ratios (module docstring's model).

    Args:
        frame: one row per completed trial with :data:`FRAME_COLUMNS` (path deviation > 0).
        level: confidence level of the intervals.

    Returns:
        ``{"quantity", "model", "n_subjects", "n_trials", "variant_in_model",
        "fixtures": {c: {"ratio", "ci_low", "ci_high", "p", "coef", "se"}},
        "carry_per_fixture": {...}, "after_block": {...}}`` (ratios exp(coef)); a fixture
        the model cannot estimate gets None values; ``"not_estimated"`` when the fit fails.
    """
    from statsmodels.regression.mixed_linear_model import MixedLM

    df = frame.loc[:, list(FRAME_COLUMNS)].dropna()
    df = df[df[PATH_DEV] > 0]
    out: dict[str, Any] = {
        "quantity": "assisted path-deviation ratio: mean path deviation while assisted / "
                    "unassisted at equal practice before any fixture was practised",
        "model": "MixedLM ln(path_dev_mean_mm) ~ fixture + cr(ln(1 + practice), 4) + carry + "
                 "after "
                 "[+ C(variant)] + (1 | subject), REML, Wald CIs",
        "level": level, "n_subjects": int(df["subject"].nunique()), "n_trials": len(df),
        "fixtures": {}}
    fixtures = sorted(c for c in df["condition"].unique() if c != VF_FREE)
    if df.empty or not fixtures or (df["condition"] == VF_FREE).sum() == 0 \
            or df["subject"].nunique() < 2:
        out["not_estimated"] = "needs assisted and unassisted trials of at least 2 subjects"
        return out
    df = design_covariates(df)
    df["y"] = np.log(df[PATH_DEV].astype(float))
    use_variant = df["variant"].nunique() > 1 and not variant_confounded(df)
    out["variant_in_model"] = use_variant
    terms = ["C(condition, Treatment('none'))",
             "cr(np.log1p(practice), df=4, constraints='center')"]
    if df["carry"].nunique() > 1:
        terms.append("carry")
    if df["after"].nunique() > 1:
        terms.append("after")
    if use_variant:
        terms.append("C(variant)")
    formula = "y ~ " + " + ".join(terms)
    model = MixedLM.from_formula(formula, data=df, groups=df["subject"])
    fit = None
    errors = []
    for method in ("lbfgs", "powell"):   # powell copes with a zero subject variance
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fit = model.fit(reml=True, method=[method])
            break
        except (ValueError, np.linalg.LinAlgError) as exc:
            errors.append(f"{method}: {exc}")
    if fit is None:
        out["not_estimated"] = f"mixed model failed ({'; '.join(errors)})"
        return out
    out["optimizer"] = method
    z = float(stats.norm.ppf(0.5 + level / 2.0))
    with warnings.catch_warnings():   # a singular random-effect variance: nan in its SE
        warnings.simplefilter("ignore")
        params, bse, pv = fit.fe_params, fit.bse_fe, fit.pvalues

    def term(name: str) -> dict[str, float | None]:
        if name not in params.index or not math.isfinite(float(bse[name])):
            return dict.fromkeys(("ratio", "ci_low", "ci_high", "p", "coef", "se"))
        b, se = float(params[name]), float(bse[name])
        return {"ratio": math.exp(b), "ci_low": math.exp(b - z * se),
                "ci_high": math.exp(b + z * se), "p": float(pv[name]), "coef": b, "se": se}

    for c in fixtures:
        out["fixtures"][c] = term(f"C(condition, Treatment('none'))[T.{c}]")
    out["carry_per_fixture"] = term("carry")
    out["after_block"] = term("after")
    return out


def recovery_frame(schedule: pd.DataFrame, metrics: pd.DataFrame) -> pd.DataFrame:
    """The frame :func:`estimate_effects` reads, from a report's analysed schedule
    (``StudyData.analysed``) and wide per-trial metrics (``StudyData.metrics``)."""
    if PATH_DEV not in metrics.columns or schedule.empty:
        return pd.DataFrame(columns=list(FRAME_COLUMNS))
    pd_of = metrics[PATH_DEV]
    df = schedule.loc[:, ["subject", "trial_index", "condition", "variant", "trial_id"]].copy()
    df[PATH_DEV] = df["trial_id"].astype(np.int64).map(pd_of)
    return df.loc[:, list(FRAME_COLUMNS)]


def stored_scenarios(db: Any, session_ids: Sequence[int]) -> list[Mapping[str, Any]]:
    """The distinct scenario records (``settings.extra["scenario"]``) of the sessions."""
    from vasim.study.store import TrialStore

    seen: dict[tuple[str, float], Mapping[str, Any]] = {}
    try:
        with TrialStore(db, readonly=True) as store:
            for sid in session_ids:
                cfg = store.session(int(sid)).get("config") or {}
                rec = (cfg.get("extra") or {}).get("scenario")
                if isinstance(rec, Mapping) and "text" in rec:
                    seen.setdefault((str(rec.get("sha256")),
                                     float(rec.get("effect_scale", 1.0))), rec)
    except (StoreError, OSError):
        return []
    return list(seen.values())


def recovery_summary(data: Any) -> dict[str, Any]:
    """``assumed_effects`` and ``recovered_effects`` of a report's ``StudyData``: the
    scenario of a synthetic cohort (None when it has none or several) and the estimate."""
    analysed = data.analysed if len(data.schedule) else data.schedule
    recovered = estimate_effects(recovery_frame(analysed, data.metrics))
    assumed: dict[str, Any] | None = None
    if data.synthetic and len(data.sessions):
        recs = stored_scenarios(data.db, [int(i) for i in data.sessions["id"]])
        if len(recs) == 1:
            sc = scenario_from_text(str(recs[0]["text"]))
            assumed = sc.assumed_record(float(recs[0].get("effect_scale", 1.0)))
        elif len(recs) > 1:
            assumed = {"not_declared": f"the sessions ran {len(recs)} scenarios or effect scales"}
    return {"assumed_effects": assumed, "recovered_effects": recovered}


__all__ = ["FRAME_COLUMNS", "design_covariates", "estimate_effects", "recovery_frame",
           "recovery_summary", "stored_scenarios", "variant_confounded"]
