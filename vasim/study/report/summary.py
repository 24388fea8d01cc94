"""``summary.json``: the report's headline results, machine-readable.

Schema (every key always present; ``null`` where a value is undefined or not computed)::

    {"synthetic": bool, "n_subjects": int,
     "measures": {"error": M, "latency": M, "path_deviation": M},
     "ratings": {F: mean}, "best_share": {F: fraction}, "worst_share": {F: fraction}}

with ``F`` each of ``vg, ag, ms, mag, ff``, ``M = {"fixture": T, "practice": T, "group": T,
"mixed_model": {F: {"coef", "p"}}}`` and ``T = {"F", "df1", "df2", "p", "p_gg"}``.

**Decisions**:

* ``fixture``: the primary fixture test, the subject-level RM-ANOVA of the fixture factor
  (``vf_rm_anova``, factor ``fixture``; VF-free level = the probes after the blocks).
* ``practice``: the RM-ANOVA of the probe-trial factor (``vf_rm_anova``, factor
  ``trial``), i.e. the practice effect over the VF-free trials.
* ``group``: the between-subjects row of the mixed ANOVA group x probe trial
  (``vf_group_anova``); ``p_gg`` is ``null`` there (no sphericity correction applies to a
  between-subjects effect).
* ``mixed_model[F]``: the fixture's coefficient (difference from ``none`` at equal
  practice, unit of the measure) and its Wald p; ``null`` when the model's reference is not
  ``none`` (no VF-free trial) or the fixture is absent.
* ``T`` is an object with its five keys even when the test is not computed (each ``null``),
  so a reader never needs a key test; ``df1``/``df2`` are integers when integral.
* ``ratings``: the mean of the first ``condition_rating`` item; ``best_share`` /
  ``worst_share``: the first ``condition_choice`` item with ``select`` best / worst, as a
  fraction (0..1) of its respondents.
* Measures: ``error`` = cumulative error Σe_i [m], ``latency`` = Σl_i [s],
  ``path_deviation`` = ``path_dev_mean_mm`` [mm] (all ``null`` when not stored).
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
MEASURES: dict[str, str] = {"error": "cum_error", "latency": "latency",
                            "path_deviation": "path_deviation"}
"""Summary measure -> the report's dv column."""
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


def build_summary(tables: Mapping[str, pd.DataFrame], *, synthetic: bool,
                  n_subjects: int) -> dict[str, Any]:
    """The summary dictionary from the report's tables (by name, as written to CSV).

    Args:
        tables: table name -> frame (``vf_rm_anova``, ``vf_group_anova``,
            ``vf_mixed_model``, ``questionnaire_ratings``, ``questionnaire_choices``; any
            may be missing).
        synthetic: the cohort is simulated (``StudyData.synthetic``).
        n_subjects: subjects with a session of the protocol.

    Returns:
        The dictionary of the module's schema.
    """
    rm = tables.get("vf_rm_anova")
    grp = tables.get("vf_group_anova")
    mm = tables.get("vf_mixed_model")
    measures: dict[str, Any] = {}
    for key, dv in MEASURES.items():
        model: dict[str, Any] = {}
        for f in FIXTURES:
            r = _first(mm, dv=dv, condition=f)
            ok = r is not None and str(r.get("reference")) == "none"
            model[f] = ({"coef": _num(r["coef"]), "p": _num(r["p"])}
                        if ok and r is not None else None)
        measures[key] = {
            "fixture": _test(_first(rm, dv=dv, factor="fixture"),
                             ("F", "df1", "df2", "p_unc", "p_gg")),
            "practice": _test(_first(rm, dv=dv, factor="trial"),
                              ("F", "df1", "df2", "p_unc", "p_gg")),
            "group": _test(_first(grp, dv=dv, Source="group"),
                           ("F", "DF1", "DF2", "p_unc", "")),
            "mixed_model": model,
        }
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

    return {"synthetic": bool(synthetic), "n_subjects": int(n_subjects),
            "measures": measures, "ratings": rating_of, "best_share": share("best"),
            "worst_share": share("worst")}


def write_summary(path: Path, summary: Mapping[str, Any]) -> None:
    """Writes ``summary.json`` (strict JSON: no NaN)."""
    path.write_text(json.dumps(summary, indent=1, allow_nan=False) + "\n", encoding="utf-8")


__all__ = ["FIXTURES", "MEASURES", "TEST_KEYS", "build_summary", "write_summary"]
