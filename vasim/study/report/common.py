"""Constants and small helpers shared by the report's modules: condition order and
labels, outcome names, colours, id lists and the section builder :class:`SectionOut`."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

import pandas as pd

from vasim.study import stats
from vasim.study.report.figures import (
    PALETTE,
)
from vasim.study.report.html_page import (
    Block,
    Notes,
    Section,
)

T = TypeVar("T")

FIXTURE_ORDER: tuple[str, ...] = ("none", "vg", "ag", "ms", "mag", "ff")
"""Conditions of the VF study in report order (none first, then the seed's order)."""
FIXTURE_LABELS: dict[str, str] = {"none": "none", "vg": "VG", "ag": "AG", "ms": "MS",
                                  "mag": "Mag", "ff": "FF"}
"""Display names of the fixture conditions (other conditions show their own name)."""
MODE_ORDER: tuple[str, ...] = ("stdt", "mrcp", "mrcp_cam")
"""Teleoperation modes in report order; StdT is the reference of the gains."""
MODE_LABELS: dict[str, str] = {"stdt": "StdT", "mrcp": "MRCP", "mrcp_cam": "MRCP+Cam"}
"""Display names of the teleoperation modes."""

PATH_DEV_METRIC = "path_dev_mean_mm"
"""The per-trial metric (``trial_metrics``) read as the VF study's path deviation."""
PATH_DEV_EXTRA: dict[str, tuple[str, str, str]] = {
    "path_dev_rms_mm": ("path_dev_rms", "RMS path deviation", "mm"),
    "path_dev_max_mm": ("path_dev_max", "maximum path deviation", "mm"),
    "path_dev_out_frac": ("path_dev_out_frac", "fraction of time outside the tolerance tube",
                          "1"),
}
"""The other path-deviation summaries: trial metric -> (column, name, unit); reported
descriptively beside the mean (``vf_trials.csv``, the measures table)."""
PATH_DEV_DV: tuple[str, str, str] = ("path_deviation", "mean path deviation", "mm")
"""THE accuracy measure (issue #25): mean distance of the tool tip to the planned polyline
over the trial's samples [mm] (analysed when the store holds it)."""
LATENCY_DV: tuple[str, str, str] = ("latency", "latency Σl_i", "s")
"""Speed: Σ l_i over the reached points = the reach time of the last reached point [s]."""
EQ65_DV: tuple[str, str, str] = (
    "eq65", "eq. 6.5 e (time-integrated distance to the next point of interest)", "mm·s")
"""The seed's measure e (eq. 6.5), kept for comparison and named for what it is: per trial
``Σ_i Σ_j ||x(j) - p_i||_1 Δt_j``, the Manhattan distance to the *next* point of
interest integrated over time [mm·s] (``point_metrics.error_l1_mm_s``: eq. 6.5 times the
sample period, so it does not depend on the logging rate). It grows with the time spent,
so it is not an accuracy measure; the report states from the data how strongly it tracks
latency."""
VF_DVS: tuple[tuple[str, str, str], ...] = (PATH_DEV_DV, LATENCY_DV, EQ65_DV)
"""Per-trial outcomes of the VF study, (column, name, unit), in report order; a store
without one of them (e.g. no path deviation stored) analyses the others."""
PATH_DEV_ABSENT = (f"path deviation ({PATH_DEV_METRIC}): not stored in this database (older "
                   "store or trials recorded before the metric existed): not analysed")
"""The note of a report whose store holds no path deviation."""
EQ65_ABSENT = ("eq. 6.5 e in mm·s (point_metrics.error_l1_mm_s): not stored for these "
               "trials: not analysed")
"""The note of a report whose store holds no rate-independent e."""
DV_NAMES: dict[str, str] = {dv: name for dv, name, _ in VF_DVS}
"""Outcome column -> its name in text."""
DV_UNITS: dict[str, str] = {dv: unit for dv, _, unit in VF_DVS}
"""Outcome column -> its unit."""
PLOT_NAMES: dict[str, str] = {"path_deviation": "mean path deviation",
                              "eq65": r"eq. 6.5 $\Sigma_i\, e_i\,\Delta t$ (distance to next "
                                      "POI x time)",
                              "latency": r"latency $\Sigma_i\, l_i$"}
"""The outcomes' names in figures (matplotlib mathtext)."""
FIXTURE_COLORS: dict[str, str] = {FIXTURE_LABELS[c]: PALETTE[i]
                                  for i, c in enumerate(FIXTURE_ORDER)}
"""One colour per fixture in every figure (keyed by display name)."""
MODE_COLORS: dict[str, str] = {"StdT": PALETTE[0], "MRCP": PALETTE[1], "MRCP+Cam": PALETTE[2]}
"""One colour per teleoperation mode (keyed by display name)."""



PROVENANCE_COLUMNS: tuple[str, ...] = ("table", "group", "subject", "session_ids", "trial_ids")
"""Columns of ``tables/provenance.csv``: per table cell/group, the ids it comes from."""

LABEL_TUKEY = "Tukey HSD with the RM-ANOVA error term, as in the seed (assumes sphericity)"
LABEL_PAIRED = "paired t-tests, Holm-corrected: the within-subject-correct alternative"



# ---------------------------------------------------------------------------- helpers
def ids_text(values: Iterable[Any]) -> str:
    """Sorted distinct integer ids joined by spaces (the CSV form of an id list).

    >>> ids_text([12, 3, 3, 7])
    '3 7 12'
    """
    return " ".join(str(v) for v in sorted({int(v) for v in values if not pd.isna(v)}))


def fixture_label(condition: str) -> str:
    """Display name of a condition: ``"mag"`` -> ``"Mag"``, modes ``"mrcp_cam"`` ->
    ``"MRCP+Cam"``, a combined schema ``"ag_mag"`` -> ``"AG+Mag"``, a faded or adaptive
    condition ``"ff_faded"`` -> ``"FF faded"`` (issue #18); unknown names are returned
    unchanged.

    >>> fixture_label("mag"), fixture_label("mrcp_cam"), fixture_label("custom")
    ('Mag', 'MRCP+Cam', 'custom')
    >>> fixture_label("ag_mag"), fixture_label("mag_adaptive")
    ('AG+Mag', 'Mag adaptive')
    """
    known = FIXTURE_LABELS.get(condition, MODE_LABELS.get(condition))
    if known is not None:
        return known
    base, kind = _derived(condition)
    if kind:
        return f"{fixture_label(base)} {kind}"
    parts = condition.split("_")
    if len(parts) > 1 and all(p in FIXTURE_LABELS and p != "none" for p in parts):
        return "+".join(FIXTURE_LABELS[p] for p in parts)
    return condition


_DERIVED_KINDS: tuple[str, ...] = ("faded", "adaptive")
"""Suffixes of the faded and adaptive conditions (``ff_faded``), in report order."""


def _derived(condition: str) -> tuple[str, str]:
    """(base condition, "faded"/"adaptive") of a derived label, else (condition, "")."""
    base, _, kind = condition.rpartition("_")
    if base and kind in _DERIVED_KINDS:
        return base, kind
    return condition, ""


def ordered_conditions(present: Iterable[str], order: Sequence[str]) -> list[str]:
    """The present conditions in ``order``, unknown ones after it, sorted; a faded or
    adaptive condition follows its base condition (``ff``, ``ff_faded``, ``ff_adaptive``).

    >>> ordered_conditions(["ff", "x", "none", "vg"], FIXTURE_ORDER)
    ['none', 'vg', 'ff', 'x']
    >>> ordered_conditions(["ff_adaptive", "mag", "ff_faded", "ff", "none"], FIXTURE_ORDER)
    ['none', 'mag', 'ff', 'ff_faded', 'ff_adaptive']
    """
    def key(c: str) -> tuple[int, int, str]:
        base, kind = _derived(c)
        rank = _DERIVED_KINDS.index(kind) + 1 if kind else 0
        return (order.index(base) if base in order else len(order), rank,
                c if base not in order else "")

    return sorted(set(present), key=key)


def subjects_text(subjects: Iterable[str], limit: int = 40) -> str:
    s = sorted(set(subjects))
    shown = ", ".join(s[:limit])
    return shown + (f" and {len(s) - limit} more" if len(s) > limit else "")


def captured(fn: Callable[..., T], *args: Any, **kwargs: Any) -> tuple[T, list[str]]:
    """Calls ``fn`` and returns its result with the messages of the warnings it issued."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = fn(*args, **kwargs)
    msgs = []
    for w in caught:
        text = str(w.message)
        if text not in msgs:
            msgs.append(text)
    return out, msgs


def curve_summary(out: SectionOut, cells: pd.DataFrame, *, dv: str, trial: str,
                  key: tuple[str, str], unit: str, condition: str | None = None,
                  ) -> pd.DataFrame:
    """A learning curve's table, as every section shows one: ``learning_curve_summary`` of
    ``cells[dv]`` over subjects per ``trial`` (and ``condition``), its warnings noted in
    ``out``, each row's ``trial_ids`` (the trials it averages) added, and the key column
    (``key`` = (name, value), e.g. ``("dv", "latency")``) and ``unit`` put first.

    Returns:
        Columns ``key[0], unit, [condition,] trial, n, mean, q25, q75, trial_ids``.
    """
    grouped = {} if condition is None else {"condition": condition}
    summ, msgs = captured(stats.learning_curve_summary, cells, dv=dv, subject="subject",
                          trial=trial, **grouped)
    out.notes.extend(msgs)
    if condition is None:
        ids = cells.groupby(trial)["trial_id"].agg(ids_text)
        summ["trial_ids"] = summ["trial"].map(ids)
    else:
        pair_ids = cells.groupby([condition, trial])["trial_id"].agg(ids_text)
        summ["trial_ids"] = [pair_ids.get((r[condition], r["trial"]), "")
                             for r in summ.to_dict("records")]
    summ.insert(0, key[0], key[1])
    summ.insert(1, "unit", unit)
    return summ


def prov_row(table: str, group: str, subject: str | None = None, *,
          session_ids: Iterable[Any] = (), trial_ids: Iterable[Any] = ()) -> dict[str, str]:
    return {"table": table, "group": group, "subject": subject or "",
            "session_ids": ids_text(session_ids), "trial_ids": ids_text(trial_ids)}



# ---------------------------------------------------------------------------- results
@dataclass
class SectionOut:
    """A section under construction: its blocks and its notes (what is missing)."""

    blocks: list[Block] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def section(self, key: str, title: str, intro: Sequence[Block] = ()) -> Section:
        head: list[Block] = list(intro)
        if self.notes:
            head.append(Notes(tuple(dict.fromkeys(self.notes))))  # each note once
        return Section(key, title, tuple(head + self.blocks))



def note_excluded(out: SectionOut, excluded: pd.DataFrame, *, probe_only: bool,
                   trials: pd.DataFrame) -> None:
    ex = excluded
    if probe_only:
        probe_ids = set(trials.loc[trials["probe"].astype(bool), "trial_id"])
        ex = ex[ex["trial_id"].isin(probe_ids)]
    for reason, g in ex.groupby("reason"):
        out.notes.append(f"{len(g)} trial(s) excluded ({reason}): trial ids "
                         f"{ids_text(g['trial_id'])} of subject(s) "
                         f"{subjects_text(g['subject'])}")


