"""The per-trial outcomes and per-cell data of the VF learning-curve study."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from vasim.study.report.common import (
    EQ65_DV,
    FIXTURE_ORDER,
    LATENCY_DV,
    PATH_DEV_DV,
    PATH_DEV_EXTRA,
    PATH_DEV_METRIC,
    VF_DVS,
    fixture_label,
    ids_text,
    ordered_conditions,
)
from vasim.study.report.data import StudyData
from vasim.trials.kinds import TELEOPERATION_MODES


# --------------------------------------------------------------------------- VF study
@dataclass(frozen=True)
class VfAnalysis:
    """The per-trial and per-cell data of the VF learning-curve study.

    Attributes:
        trials: one row per analysed trial of a fixture condition or a probe (columns
            ``trial_id, subject, session_id, trial_index, practice, block, block_position,
            condition, fixture, variant, probe, probe_index, baseline, stage, practised,
            previous, n_points, points_reached, completed, latency, eq65`` [+
            ``path_deviation`` and the other path-deviation summaries when stored]).
            ``block_position``: the schedule's block index (0 = baseline, 1.. the fixture
            blocks in session order); ``practised``: for a probe that closes a fixture
            block, the fixture of that block (else empty); ``previous``: the fixture
            practised in the block before it (``none`` after the baseline): the carry-over
            term of the primary probe model (:mod:`vasim.study.report.transfer`).
        excluded: trials left out (``trial_id, subject, condition, reason``).
        fixture_cells: ``subject, fixture, n_trials, <dvs>, trial_ids``: per
            subject and fixture the mean over its trials (every subject); the level
            ``none`` averages the probe trials that follow the blocks, never the baseline
            probes (**Decision** of issue #15: the baseline trials always come first, so
            pooling them would mix practice into the fixture factor).
        trial_cells: ``subject, trial, practice, trial_id, <dvs>``: the probe
            trials; ``trial`` = probe number, ``practice`` = the trial's position in the
            session (1-based: probe 4 is the 10th trial).
        fixture_levels: fixture labels present, in report order.
        trial_levels: probe numbers present.
        n_baseline: probe trials before the first assisted trial (3 in the VF protocol).
        dvs: the outcomes analysed, ``(column, name, unit)``: those of :data:`VF_DVS`
            with data (the path deviation and eq. 6.5's e in mm·s need metrics older
            stores may lack).
    """

    trials: pd.DataFrame
    excluded: pd.DataFrame
    fixture_cells: pd.DataFrame
    trial_cells: pd.DataFrame
    fixture_levels: tuple[str, ...]
    trial_levels: tuple[int, ...]
    n_baseline: int
    dvs: tuple[tuple[str, str, str], ...] = VF_DVS


def vf_trial_outcomes(analysed: pd.DataFrame, points: pd.DataFrame) -> pd.DataFrame:
    """Per-trial latency and eq. 6.5's e from the per-point metrics.

    Args:
        analysed: analysed scheduled trials (``StudyData.analysed``), any conditions.
        points: per-point metrics with ``trial_id, reached, latency`` [s] and
            ``error_l1_mm_s`` [mm·s] (optional: NaN when absent).

    Returns:
        ``analysed``'s rows of fixture conditions and probes (teleoperation modes left out)
        with ``fixture`` (display label), ``n_points``, ``points_reached``, ``completed``,
        ``latency`` = Σ l_i over reached points [s] and ``eq65`` = Σ_i e_i Δt [mm·s], the
        time-integrated Manhattan distance to the next point of interest (NaN when the
        trial has no per-point row, resp. no reached point / no stored e in mm·s).

    Example:
        >>> a = pd.DataFrame({"trial_id": [1], "condition": ["vg"], "probe": [False]})
        >>> p = pd.DataFrame({"trial_id": [1, 1], "reached": [True, False],
        ...                   "error_l1_mm_s": [0.5, 0.25], "latency": [2.0, float("nan")]})
        >>> r = vf_trial_outcomes(a, p).iloc[0]
        >>> float(r.eq65), float(r.latency), bool(r.completed)
        (0.75, 2.0, False)
    """
    vf = analysed[~analysed["condition"].isin(TELEOPERATION_MODES)].copy()
    pts = points[points["trial_id"].isin(set(vf["trial_id"]))]
    if "error_l1_mm_s" not in pts.columns:
        pts = pts.assign(error_l1_mm_s=np.nan)
    g = pts.groupby("trial_id")
    reached = pts.loc[pts["reached"].astype(bool).to_numpy()]
    agg = pd.DataFrame({
        "n_points": g.size(),
        "points_reached": g["reached"].sum(),
        "eq65": g["error_l1_mm_s"].sum(min_count=1),
    })
    agg["latency"] = reached.groupby("trial_id")["latency"].sum(min_count=1)
    vf = vf.merge(agg, how="left", left_on="trial_id", right_index=True)
    vf["n_points"] = vf["n_points"].astype("Int64")
    vf["points_reached"] = vf["points_reached"].astype("Int64")
    vf["completed"] = (vf["n_points"] == vf["points_reached"]).fillna(False).astype(bool)
    vf["fixture"] = vf["condition"].map(fixture_label)
    return vf.reset_index(drop=True)


def block_context(schedule: pd.DataFrame) -> pd.DataFrame:
    """Per scheduled trial: the fixture a probe has just practised and the one before.

    Args:
        schedule: ``session_id, trial_index, block, block_index, condition, probe`` rows
            (every scheduled trial, run or not: the design, not what was analysed).

    Returns:
        ``session_id, trial_index, practised, previous`` for the probe trials that close a
        block with assisted trials (the other rows are absent): ``practised`` the block's
        condition, ``previous`` the condition of the fixture block before it in the
        session (``none`` if it is the first: only VF-free trials came before).

    Example:
        >>> s = pd.DataFrame({"session_id": 1, "trial_index": range(6),
        ...     "block": ["b", "vg", "vg", "ff", "ff", "x"], "block_index": [0, 1, 1, 2, 2, 3],
        ...     "condition": ["none", "vg", "none", "ff", "none", "none"],
        ...     "probe": [True, False, True, False, True, True]})
        >>> c = block_context(s)
        >>> c["trial_index"].tolist(), c["practised"].tolist(), c["previous"].tolist()
        ([2, 4], ['vg', 'ff'], ['none', 'vg'])
    """
    cols = ["session_id", "trial_index", "practised", "previous"]
    if schedule.empty:
        return pd.DataFrame({c: [] for c in cols})
    sched = schedule.sort_values(["session_id", "trial_index"])
    assisted = sched[~sched["probe"].astype(bool)]
    block_cond = (assisted.groupby(["session_id", "block_index"])["condition"].first()
                  .rename("practised").reset_index())
    block_cond["previous"] = (block_cond.groupby("session_id")["practised"].shift(1)
                              .fillna("none"))
    probes = sched[sched["probe"].astype(bool)][["session_id", "trial_index", "block_index"]]
    out = probes.merge(block_cond, on=["session_id", "block_index"], how="inner")
    return out[cols].reset_index(drop=True)


def analyse_vf(data: StudyData) -> VfAnalysis:
    """Builds :class:`VfAnalysis` from the store's data (see the module decisions).

    **Decision** (issue #18 §2): the trials of retention and transfer blocks are left out
    (delayed or on untrained trajectories, they are not the learning curve's probes; the
    section "Acquisition, retention and transfer" analyses them).
    """
    analysed = data.analysed
    if data.protocol is not None:
        acquisition = {b.name for b in data.protocol.blocks if b.phase == "acquisition"}
        analysed = analysed[analysed["block"].isin(acquisition)].reset_index(drop=True)
    vf = vf_trial_outcomes(analysed, data.points)
    vf["practice"] = (vf["trial_index"].astype(np.int64) + 1) if len(vf) else \
        pd.Series(dtype=np.int64)
    vf["baseline"] = baseline_flags(vf) if len(vf) else pd.Series(dtype=bool)
    vf["block_position"] = vf["block_index"].astype(np.int64) if len(vf) else \
        pd.Series(dtype=np.int64)
    ctx = block_context(data.schedule)
    vf = vf.merge(ctx, on=["session_id", "trial_index"], how="left")
    vf["practised"] = vf["practised"].fillna("").astype(str)
    vf["previous"] = vf["previous"].fillna("").astype(str)
    bad = vf["latency"].isna()
    reasons = np.where(vf["n_points"].isna(), "no per-point metrics stored",
                       "no trajectory point reached")
    excluded = vf.loc[bad, ["trial_id", "subject", "condition"]].assign(
        reason=reasons[bad.to_numpy()]).reset_index(drop=True)
    ok = vf[~bad]
    extra_cols: list[str] = []
    for metric, col in ((PATH_DEV_METRIC, PATH_DEV_DV[0]),
                        *((m, c) for m, (c, _, _) in PATH_DEV_EXTRA.items())):
        if metric in data.metrics.columns:
            values = ok["trial_id"].map(data.metrics[metric].astype(float)).astype(float)
            if values.notna().any():
                ok = ok.assign(**{col: values})
                extra_cols.append(col)
    present = {c for c in (*extra_cols, LATENCY_DV[0]) if c in ok.columns}
    if ok["eq65"].notna().any():
        present.add(EQ65_DV[0])
    dvs = tuple(d for d in VF_DVS if d[0] in present)
    dv_cols = [dv for dv, _, _ in dvs]
    descr = [c for c in extra_cols if c not in dv_cols]
    cond_order = ordered_conditions(ok["condition"], FIXTURE_ORDER)
    fixture_levels = tuple(fixture_label(c) for c in cond_order)
    # fixture cells: never the baseline probes (they precede every block: practice, not
    # the VF-free level); the VF-free level is the probes that follow the blocks
    cells = (ok[~ok["baseline"]].groupby(["subject", "condition"], sort=False)
             .agg(n_trials=("trial_id", "size"),
                  **{dv: (dv, "mean") for dv in dv_cols},
                  trial_ids=("trial_id", ids_text))
             .reset_index())
    cells["fixture"] = pd.Categorical(cells["condition"].map(fixture_label),
                                      categories=list(fixture_levels))
    cells = cells.sort_values(["subject", "fixture"]).reset_index(drop=True)
    cells = cells[["subject", "fixture", "condition", "n_trials", *dv_cols, "trial_ids"]]
    probes = ok[ok["probe"].astype(bool) & ok["probe_index"].notna()]
    tcells = probes[["subject", "probe_index", "practice", "trial_id", *dv_cols]].rename(
        columns={"probe_index": "trial"})
    tcells["trial"] = tcells["trial"].astype(np.int64)
    tcells["practice"] = tcells["practice"].astype(np.int64)
    tcells = tcells.sort_values(["subject", "trial"]).reset_index(drop=True)
    trial_levels = tuple(int(t) for t in sorted(tcells["trial"].unique()))
    n_base = int(ok.loc[ok["baseline"]].groupby("session_id").size().mode().iloc[0]) \
        if ok["baseline"].any() else 0
    cols = ["trial_id", "subject", "session_id", "trial_index", "practice", "block",
            "block_position", "condition", "fixture", "variant", "probe", "probe_index",
            "baseline", "stage", "practised", "previous", "n_points", "points_reached",
            "completed", *dv_cols, *descr]
    return VfAnalysis(trials=ok[cols].reset_index(drop=True), excluded=excluded,
                      fixture_cells=cells, trial_cells=tcells, fixture_levels=fixture_levels,
                      trial_levels=trial_levels, n_baseline=n_base, dvs=dvs)


def baseline_flags(trials: pd.DataFrame) -> pd.Series:
    """Marks the baseline probes: probe trials before the first assisted trial of their
    session (the 3 VF-free trials that open the VF protocol).

    Args:
        trials: ``session_id, trial_index, probe`` per trial (trial_index 0-based).

    Returns:
        A boolean Series aligned with ``trials``.

    Example:
        >>> t = pd.DataFrame({"session_id": [1] * 5, "trial_index": [0, 1, 2, 3, 4],
        ...                   "probe": [True, True, False, True, False]})
        >>> baseline_flags(t).tolist()
        [True, True, False, False, False]
    """
    probe = trials["probe"].astype(bool)
    first = trials.loc[~probe].groupby("session_id")["trial_index"].min()
    limit = trials["session_id"].map(first).astype(float).fillna(np.inf)
    return (probe & (trials["trial_index"].astype(float) < limit)).astype(bool)


def complete_subjects(cells: pd.DataFrame, factor: str, levels: Sequence[Any],
                      subject: str = "subject") -> tuple[pd.DataFrame, dict[str, list[str]]]:
    """Keeps the subjects that have every level of ``factor``.

    Args:
        cells: one row per subject and level. factor: the level column.
        levels: the levels every subject must have.

    Returns:
        (the cells of the complete subjects, {excluded subject: its missing levels}).

    Example:
        >>> c = pd.DataFrame({"subject": ["a", "a", "b"], "f": ["x", "y", "x"]})
        >>> kept, gone = complete_subjects(c, "f", ["x", "y"])
        >>> sorted(kept["subject"].unique()), gone
        (['a'], {'b': ['y']})
    """
    have = cells.groupby(subject)[factor].agg(lambda s: set(s.astype(str)))
    want = [str(v) for v in levels]
    missing = {str(s): [v for v in want if v not in got] for s, got in have.items()}
    missing = {s: m for s, m in missing.items() if m}
    kept = cells[~cells[subject].astype(str).isin(set(missing))].reset_index(drop=True)
    return kept, missing


def excluded_text(factor: str, missing: dict[str, list[str]],
                   what: str = "RM-ANOVA and its post hoc tests") -> str:
    parts = [f"{s} (no {', '.join(m)})" for s, m in sorted(missing.items())]
    shown = "; ".join(parts[:30]) + (f"; and {len(parts) - 30} more" if len(parts) > 30 else "")
    return (f"{len(missing)} subject(s) without every {factor} cell are excluded from the "
            f"{factor} {what}: {shown}")


