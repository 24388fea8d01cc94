"""``summary.json``: the report's headline results, machine-readable.

Schema (every key always present; ``null`` where a value is undefined or not computed)::

    {"synthetic": bool, "n_subjects": int, "primary": "mixed_model",
     "measures": {"path_deviation": M, "latency": M, "eq65": M},
     "measure_correlations": {"eq65~latency": C, "path_deviation~latency": C,
                              "eq65~path_deviation": C},
     "ratings": {F: mean}, "best_share": {F: fraction}, "worst_share": {F: fraction},
     "assumed_effects": null, "recovered_effects": null}

with ``F`` each of ``vg, ag, ms, mag, ff``;

* ``M = {"unit", "fixture": T, "practice": T, "group": T, "group_x_practice": T,
  "mixed_model": P}``, ``T = {"F", "df1", "df2", "p", "p_gg"}``;
* ``P`` (the PRIMARY analysis, :mod:`vasim.study.report.transfer`) = ``{"formula",
  "n_obs", "n_subjects", "fixture_test": X, "carry_over": X, "variant_test": X,
  "block_position": E, "fixture": {F: E}}`` with ``X = {"F", "df1", "df2", "p"}`` and
  ``E = {"coef", "ci_low", "ci_high", "p"}``;
* ``C = {"pearson": R, "repeated_measures": R}``, ``R = {"r", "ci_low", "ci_high", "p",
  "n_obs"}``.

**Decisions**:

* Measures (issue #25): ``path_deviation`` = mean distance to the planned path [mm] (THE
  accuracy measure), ``latency`` = Σl_i [s], ``eq65`` = eq. 6.5's e integrated over time,
  the distance to the next point of interest times time [mm·s] (the seed's measure, for
  comparison). There is no key ``error``.
* ``mixed_model`` (primary): the probe after each fixture block, ``dv ~ C(practised) +
  block_position + C(variant)``, random intercept per subject. ``fixture[F]``: the probe's
  mean after practising F minus the mean over the fixtures (unit of the measure), 95 %
  Wald interval; ``fixture_test``: F test of the fixture term; ``carry_over``: F test of
  adding the previous block's fixture; ``variant_test``: F test of the variant term (nested
  within-subject OLS models, exact at small N); ``block_position``: the change per block
  of practice.
* ``fixture`` (secondary, the seed's design): the subject-level RM-ANOVA of the fixture
  factor (``vf_rm_anova``; VF-free level = the probes after the blocks).
* ``practice``: the RM-ANOVA of the probe-trial factor (``vf_rm_anova``, factor
  ``trial``), the practice effect over the VF-free trials.
* ``group`` and ``group_x_practice``: the between-subjects row and the group x probe
  trial interaction of the mixed-design ANOVA (``vf_group_anova``); ``p_gg`` is ``null``
  for ``group`` (no sphericity correction applies to a between-subjects effect).
* ``measure_correlations``: how strongly the measures track each other
  (``vf_measure_correlations``; e.g. ``eq65~latency``: does e measure time?).
* ``T`` is an object with its five keys even when the test is not computed (each ``null``),
  so a reader never needs a key test; ``df1``/``df2`` are integers when integral.
* ``ratings``: the mean of the first ``condition_rating`` item; ``best_share`` /
  ``worst_share``: the first ``condition_choice`` item with ``select`` best / worst, as a
  fraction (0..1) of its respondents.
* ``assumed_effects`` / ``recovered_effects``: the place where a simulated cohort's
  scenario (what the simulation assumed) and the analysis' estimates of it (with 95 % CIs)
  go: :func:`build_summary` takes them as ``simulation`` (a hook of the synthetic-operator
  scenario, issue #25 items 3-4); ``null`` for real data or when no hook filled them.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pandas as pd

FIXTURES: tuple[str, ...] = ("vg", "ag", "ms", "mag", "ff")
"""The fixture keys ``F`` of the summary."""
MEASURES: dict[str, str] = {"path_deviation": "path_deviation", "latency": "latency",
                            "eq65": "eq65"}
"""Summary measure -> the report's dv column."""
UNITS: dict[str, str] = {"path_deviation": "mm", "latency": "s", "eq65": "mm·s"}
"""Summary measure -> its unit."""
CORRELATIONS: tuple[tuple[str, str], ...] = (("eq65", "latency"), ("path_deviation", "latency"),
                                             ("eq65", "path_deviation"))
"""The measure pairs of ``measure_correlations`` (keys ``"x~y"``)."""
SIMULATION_KEYS: tuple[str, ...] = ("assumed_effects", "recovered_effects")
"""Top-level keys a simulated cohort's scenario hook fills (null otherwise)."""
TEST_KEYS: tuple[str, ...] = ("F", "df1", "df2", "p", "p_gg")


def _num(v: Any) -> float | None:
    """A JSON number (float), or None for a missing / non-finite value.

    >>> _num(float("nan")), _num(3), _num(2.5), _num(None), _num("x")
    (None, 3.0, 2.5, None, None)
    """
    if v is None or isinstance(v, str | bool):
        return None
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _df(v: Any) -> float | int | None:
    """Degrees of freedom: an integer when integral.

    >>> _df(5.0), _df(4.2), _df(float("nan"))
    (5, 4.2, None)
    """
    f = _num(v)
    return int(f) if f is not None and f.is_integer() else f


def _test(row: Mapping[str, Any] | None, cols: tuple[str, str, str, str, str]
          ) -> dict[str, Any]:
    """``T`` from one table row and its column names for F, df1, df2, p, p_gg."""
    if row is None:
        return dict.fromkeys(TEST_KEYS)
    f, d1, d2, p, pgg = cols
    return {"F": _num(row.get(f)), "df1": _df(row.get(d1)), "df2": _df(row.get(d2)),
            "p": _num(row.get(p)), "p_gg": _num(row.get(pgg)) if pgg else None}


def _first(table: pd.DataFrame | None, **match: Any) -> dict[str, Any] | None:
    if table is None or table.empty:
        return None
    sel = table
    for k, v in match.items():
        if k not in sel.columns:
            return None
        sel = sel[sel[k].astype(str) == str(v)]
    return None if sel.empty else sel.iloc[0].to_dict()


def _x(row: Mapping[str, Any] | None) -> dict[str, Any]:
    if row is None or _num(row.get("F")) is None:
        return {"F": None, "df1": None, "df2": None, "p": None}
    return {"F": _num(row.get("F")), "df1": _df(row.get("df1")), "df2": _df(row.get("df2")),
            "p": _num(row.get("p"))}


def _e(row: Mapping[str, Any] | None) -> dict[str, Any] | None:
    if row is None:
        return None
    return {k: _num(row.get(k)) for k in ("coef", "ci_low", "ci_high", "p")}


def _primary(est: pd.DataFrame | None, tests: pd.DataFrame | None, dv: str) -> dict[str, Any]:
    """``P`` of one measure from ``vf_transfer_model`` / ``vf_transfer_tests``."""
    from vasim.study.report.transfer import FORMULA

    first = _first(tests, dv=dv, test="fixture")
    return {
        "formula": FORMULA.format(dv=dv) + " + (1 | subject)",
        "n_obs": int(first["n_obs"]) if first is not None else None,
        "n_subjects": int(first["n_subjects"]) if first is not None else None,
        "fixture_test": _x(first),
        "carry_over": _x(_first(tests, dv=dv, test="carry_over")),
        "variant_test": _x(_first(tests, dv=dv, test="variant")),
        "block_position": _e(_first(est, dv=dv, term="block_position")),
        "fixture": {f: _e(_first(est, dv=dv, term="fixture", condition=f))
                    for f in FIXTURES},
    }


def build_summary(tables: Mapping[str, pd.DataFrame], *, synthetic: bool,
                  n_subjects: int, simulation: Mapping[str, Any] | None = None
                  ) -> dict[str, Any]:
    """The summary dictionary from the report's tables (by name, as written to CSV).

    Args:
        tables: table name -> frame (``vf_transfer_model``, ``vf_transfer_tests``,
            ``vf_rm_anova``, ``vf_group_anova``, ``vf_measure_correlations``,
            ``questionnaire_ratings``, ``questionnaire_choices``; any may be missing).
        synthetic: the cohort is simulated (``StudyData.synthetic``).
        n_subjects: subjects with a session of the protocol.
        simulation: ``{"assumed_effects": ..., "recovered_effects": ...}`` from a
            simulated cohort's scenario hook (JSON-ready values), or None.

    Returns:
        The dictionary of the module's schema.

    Raises:
        ValueError: ``simulation`` has a key other than :data:`SIMULATION_KEYS`.
    """
    rm = tables.get("vf_rm_anova")
    grp = tables.get("vf_group_anova")
    est = tables.get("vf_transfer_model")
    tests = tables.get("vf_transfer_tests")
    measures: dict[str, Any] = {}
    for key, dv in MEASURES.items():
        measures[key] = {
            "unit": UNITS[key],
            "fixture": _test(_first(rm, dv=dv, factor="fixture"),
                             ("F", "df1", "df2", "p_unc", "p_gg")),
            "practice": _test(_first(rm, dv=dv, factor="trial"),
                              ("F", "df1", "df2", "p_unc", "p_gg")),
            "group": _test(_first(grp, dv=dv, Source="group"),
                           ("F", "DF1", "DF2", "p_unc", "")),
            "group_x_practice": _test(_first(grp, dv=dv, Source="Interaction"),
                                      ("F", "DF1", "DF2", "p_unc", "p_GG_corr")),
            "mixed_model": _primary(est, tests, dv),
        }
    cor = tables.get("vf_measure_correlations")
    correlations: dict[str, Any] = {}
    for x, y in CORRELATIONS:
        entry: dict[str, Any] = {}
        for method in ("pearson", "repeated_measures"):
            r = _first(cor, x=x, y=y, method=method)
            entry[method] = None if r is None else {
                **{k: _num(r.get(k)) for k in ("r", "ci_low", "ci_high", "p")},
                "n_obs": int(r["n_obs"])}
        correlations[f"{x}~{y}"] = entry
    ratings = tables.get("questionnaire_ratings")
    if ratings is not None and len(ratings):
        ratings = ratings[ratings["item"] == ratings["item"].iloc[0]]
    rating_of = {f: (_num(r["mean"]) if (r := _first(ratings, condition=f)) else None)
                 for f in FIXTURES}
    choices = tables.get("questionnaire_choices")

    def share(select: str) -> dict[str, float | None]:
        c = None
        if choices is not None and len(choices) and "select" in choices.columns:
            c = choices[choices["select"] == select]
            c = c[c["item"] == c["item"].iloc[0]] if len(c) else c
        out: dict[str, float | None] = {}
        for f in FIXTURES:
            r = _first(c, value=f)
            pct = _num(r["percent"]) if r is not None else None
            out[f] = None if pct is None else pct / 100.0
        return out

    sim = dict(simulation or {})
    unknown = sorted(set(sim) - set(SIMULATION_KEYS))
    if unknown:
        raise ValueError(f"simulation keys must be among {SIMULATION_KEYS}, got {unknown}")
    return {"synthetic": bool(synthetic), "n_subjects": int(n_subjects),
            "primary": "mixed_model", "measures": measures,
            "measure_correlations": correlations, "ratings": rating_of,
            "best_share": share("best"), "worst_share": share("worst"),
            **{k: sim.get(k) for k in SIMULATION_KEYS}}


def write_summary(path: Path, summary: Mapping[str, Any]) -> None:
    """Writes ``summary.json`` (strict JSON: no NaN)."""
    path.write_text(json.dumps(summary, indent=1, allow_nan=False) + "\n", encoding="utf-8")


__all__ = ["CORRELATIONS", "FIXTURES", "MEASURES", "SIMULATION_KEYS", "TEST_KEYS", "UNITS",
           "build_summary", "write_summary"]
