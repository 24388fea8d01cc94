"""Chapter 5 reproduced: a simulated StdT / MRCP / MRCP+Cam cohort beside the seed's Table 5.1.

Runs the protocol ``mrcp_vs_stdt`` (6 trials per mode, mode order randomised per subject by
the protocol's own schedule) for a simulated cohort, the trials exactly as a session runs
them (``Session.trial_config``: session practice, the mode's practice, trial seeds), and
prints per measure (ET [s], EM = needle path [m], Q = target deformation [mm s]):

* mean, sd (of the subject means, as Table 5.1) and interquartile range (of every trial, as
  Fig. 5.12) per mode, beside the seed's mean and sd;
* the %-differences between modes (MRCP and MRCP+Cam vs StdT, MRCP+Cam vs MRCP), simulated
  and seed;
* paired t-tests per pair of modes on the subject means (``vasim.study.stats
  .pairwise_paired``, the report's), beside the seed's Table 5.2 (t and p as printed there);
* the hand-over counts (StdT re-grasps and misaligned transfers, MRCP transfers) and the
  needle path split by what moved it (``em_to_ring``, ``em_to_via``, ``em_transfer``).

``--fit`` first runs the calibration of ``vasim.operator.teleop_profile`` (method of
simulated moments, secant rule between two pilot cohorts with the same subjects and seeds:
``NEUTRAL`` and ``PILOT``) and prints the fitted ``TeleopEffects``; the cohort then runs
with them. Without ``--fit`` it runs with ``SEED_TELEOP`` (the committed calibration).

The numbers are synthetic: the model is calibrated to the seed, so what it was fitted to
it reproduces by construction (ET of MRCP, EM StdT/MRCP, ET MRCP+Cam/MRCP); the rest are
its predictions. The same cohort through the study store: ``python -m vasim study simulate
--protocol mrcp_vs_stdt --subjects 20 ...`` and ``vasim study report`` (its
``tables/mrcp_descriptives.csv``).

Usage: ``python -m bench.chapter5 [--subjects N] [--seed S] [--workers W] [--fit]
[--fit-subjects N] [--effects K,THETA,C] [--csv PATH]``; the default, 4 subjects (72
trials, about 7900 s simulated), takes 9 min on one core at 15x real time (26 min on a
loaded machine); the seed's 20 subjects (``--subjects 20``, 360 trials) about 45 min.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict
from typing import Any

import pandas as pd

from vasim.core.progress import progress_bar
from vasim.operator.teleop_profile import NEUTRAL, SEED_TELEOP, TeleopEffects, secant_fit

MODES = ("stdt", "mrcp", "mrcp_cam")
LABEL = {"stdt": "StdT", "mrcp": "MRCP", "mrcp_cam": "MRCP+Cam"}
MEASURES = (("ET", "completion_time", "s"), ("EM", "path_l2", "m"),
            ("Q", "target_deformation", "mm s"))

SEED_TABLE_5_1: dict[str, dict[str, tuple[float, float]]] = {
    "ET": {"stdt": (142.51, 46.97), "mrcp": (101.13, 42.31), "mrcp_cam": (105.29, 41.16)},
    "EM": {"stdt": (2580.13, 505.05), "mrcp": (2195.05, 373.37),
           "mrcp_cam": (2185.89, 308.56)},
    "Q": {"stdt": (8477.62, 4218.93), "mrcp": (2849.91, 1463.68),
          "mrcp_cam": (3060.19, 1689.73)},
}
"""Table 5.1 (seed l. 3935-3960): mean and sd per mode (the seed's own units: s for ET; EM
and Q in the units of its tracking, not stated)."""

SEED_TABLE_5_2: dict[str, dict[tuple[str, str], tuple[float, str]]] = {
    "ET": {("stdt", "mrcp"): (6.69, "2.14E-06"), ("stdt", "mrcp_cam"): (6.43, "3.60E-02"),
           ("mrcp", "mrcp_cam"): (-0.84, "0.41")},
    "EM": {("stdt", "mrcp"): (5.76, "1.48E-01"), ("stdt", "mrcp_cam"): (5.95, "9.85E-02"),
           ("mrcp", "mrcp_cam"): (0.14, "0.89")},
    "Q": {("stdt", "mrcp"): (7.49, "4.39E-03"), ("stdt", "mrcp_cam"): (5.68, "1.79E-01"),
          ("mrcp", "mrcp_cam"): (-49.00, "0.62")},
}
"""Table 5.2 (seed l. 4055-4170): paired t and p as printed (the seed's text: StdT differs
significantly from both MRCP modes, MRCP and MRCP+Cam do not differ)."""

PILOT = TeleopEffects(thread_time=2.0, stdt_noise=1.0, camera_cost=0.5)
"""The second pilot of the fit (the first is ``NEUTRAL``)."""


def _run_trial(job: dict[str, Any]) -> dict[str, Any]:
    from vasim.trials.teleop import TeleopTrial
    from vasim.trials.vf import TrialConfig

    cfg = TrialConfig(**job["config"])
    trial = TeleopTrial(cfg, effects=TeleopEffects(**job["effects"]), n_rings=job["n_rings"])
    try:
        res = trial.run()
    finally:
        trial.station.close()
    tm = res.trial_metrics
    row = {k: job[k] for k in ("subject", "mode", "trial_number", "index")}
    row.update({name: float(tm[metric]) for name, metric, _ in MEASURES})
    row.update({k: float(tm[k]) for k in ("transfers", "regrasps", "misaligned_transfers",
                                          "em_to_ring", "em_to_via", "em_transfer",
                                          "contact_time", "safety_stops")})
    row["completed"] = bool(res.summary["finished"])
    row["sim_time"] = float(res.summary["sim_time"])
    return row


def cohort_jobs(n_subjects: int, seed: int, effects: TeleopEffects, *,
                trials_per_mode: int | None = None, n_rings: int | None = None,
                max_time: float | None = None) -> list[dict[str, Any]]:
    """Every trial of the cohort, configured as ``Session.trial_config`` configures it
    (``trials_per_mode``, ``n_rings``, ``max_time``: smaller cohorts for tests)."""
    from vasim.study.cohort import cohort_subjects
    from vasim.study.protocol import generate_schedule, load_protocol
    from vasim.study.session import trial_seed

    protocol = load_protocol("mrcp_vs_stdt")
    jobs = []
    for subj in cohort_subjects(n_subjects, n_subjects // 2, seed):
        schedule = generate_schedule(protocol, subj.session_seed)
        for t in schedule:
            m = sum(s.condition == t.condition for s in schedule[:t.index])
            if trials_per_mode is not None and m >= trials_per_mode:
                continue
            jobs.append({
                "subject": subj.code, "mode": t.condition, "trial_number": m + 1,
                "index": t.index, "effects": asdict(effects), "n_rings": n_rings,
                "config": {"mode": t.condition, "seed": trial_seed(subj.session_seed, t.index),
                           "practice": t.index, "mode_practice": m, "profile": subj.profile,
                           "max_time": protocol.max_trial_time if max_time is None
                           else max_time, "subject": subj.code}})
    return jobs


def simulate(n_subjects: int, seed: int, effects: TeleopEffects, workers: int,
             **small: Any) -> pd.DataFrame:
    """The cohort's trials, one row each (``small``: ``cohort_jobs``'s test sizes)."""
    jobs = cohort_jobs(n_subjects, seed, effects, **small)
    t0 = time.perf_counter()
    with progress_bar(len(jobs), f"chapter 5 ({n_subjects} subjects)", "trial") as bar:
        if workers <= 1:
            rows = []
            for j in jobs:
                rows.append(_run_trial(j))
                bar.update(1)
        else:
            with ProcessPoolExecutor(workers,
                                     mp_context=multiprocessing.get_context("spawn")) as ex:
                rows = []
                for r in ex.map(_run_trial, jobs):   # in order: the bar moves as they end
                    rows.append(r)
                    bar.update(1)
    df = pd.DataFrame(rows)
    wall = time.perf_counter() - t0
    print(f"  {len(df)} trials of {n_subjects} subjects, {df['sim_time'].sum():.0f} s simulated "
          f"in {wall:.0f} s wall ({df['sim_time'].sum() / wall:.1f}x real time); "
          f"{int((~df['completed']).sum())} not completed", flush=True)
    return df


def moments(df: pd.DataFrame) -> dict[str, float]:
    """The fitted moments: ET of MRCP, EM StdT/MRCP, ET MRCP+Cam/MRCP (of the mode means)."""
    m = df.groupby("mode")[["ET", "EM"]].mean()
    return {"et_mrcp": float(m.loc["mrcp", "ET"]),
            "em_stdt_mrcp": float(m.loc["stdt", "EM"] / m.loc["mrcp", "EM"]),
            "et_cam_mrcp": float(m.loc["mrcp_cam", "ET"] / m.loc["mrcp", "ET"])}


def seed_moments() -> dict[str, float]:
    t = SEED_TABLE_5_1
    return {"et_mrcp": t["ET"]["mrcp"][0],
            "em_stdt_mrcp": t["EM"]["stdt"][0] / t["EM"]["mrcp"][0],
            "et_cam_mrcp": t["ET"]["mrcp_cam"][0] / t["ET"]["mrcp"][0]}


def fit(n_subjects: int, seed: int, workers: int) -> TeleopEffects:
    """The calibration (``vasim.operator.teleop_profile``): two pilots, one secant step per
    parameter on its moment."""
    target = seed_moments()
    print(f"fit: pilot 1 ({NEUTRAL})", flush=True)
    a = moments(simulate(n_subjects, seed, NEUTRAL, workers))
    print(f"fit: pilot 2 ({PILOT})", flush=True)
    b = moments(simulate(n_subjects, seed, PILOT, workers))
    for k in target:
        print(f"  {k:13s} pilot 1 {a[k]:8.3f}  pilot 2 {b[k]:8.3f}  seed {target[k]:8.3f}")
    fitted = TeleopEffects(
        thread_time=round(secant_fit(NEUTRAL.thread_time, a["et_mrcp"], PILOT.thread_time,
                                     b["et_mrcp"], target["et_mrcp"], lo=0.1, hi=10.0), 2),
        stdt_noise=round(secant_fit(NEUTRAL.stdt_noise, a["em_stdt_mrcp"], PILOT.stdt_noise,
                                    b["em_stdt_mrcp"], target["em_stdt_mrcp"], lo=0.0,
                                    hi=5.0), 2),
        camera_cost=round(secant_fit(NEUTRAL.camera_cost, a["et_cam_mrcp"],
                                     PILOT.camera_cost, b["et_cam_mrcp"],
                                     target["et_cam_mrcp"], lo=0.0, hi=5.0), 2))
    print(f"fitted: {fitted}", flush=True)
    return fitted


def _pct(a: float, b: float) -> str:
    """``(a - b) / b`` in %, or ``n/a`` when b is 0 (e.g. no contact at all)."""
    return f"{100.0 * (a - b) / b:+.1f} %" if b != 0 else "n/a (reference 0)"


def side_by_side(df: pd.DataFrame) -> list[str]:
    """The printed table (module docstring)."""
    from vasim.study import stats

    lines = []
    cells = df.groupby(["subject", "mode"])[[m for m, _, _ in MEASURES]].mean().reset_index()
    for name, _, unit in MEASURES:
        seed = SEED_TABLE_5_1[name]
        lines.append(f"\n{name} [{unit}]   simulated mean (sd) IQR  |  seed mean (sd)")
        for mode in MODES:
            v = cells.loc[cells["mode"] == mode, name]
            q = df.loc[df["mode"] == mode, name].quantile([0.25, 0.75])
            lines.append(f"  {LABEL[mode]:9s} {v.mean():10.3f} ({v.std(ddof=1):8.3f}) "
                         f"IQR {q.iloc[1] - q.iloc[0]:8.3f}  |  {seed[mode][0]:9.2f} "
                         f"({seed[mode][1]:.2f})")
        mean = {mode: float(cells.loc[cells["mode"] == mode, name].mean()) for mode in MODES}
        for x, ref in (("mrcp", "stdt"), ("mrcp_cam", "stdt"), ("mrcp_cam", "mrcp")):
            lines.append(f"  {LABEL[x]} vs {LABEL[ref]}: simulated {_pct(mean[x], mean[ref])}, "
                         f"seed {_pct(seed[x][0], seed[ref][0])}")
        c = cells.copy()
        c["mode"] = pd.Categorical(c["mode"].map(LABEL), categories=[LABEL[m] for m in MODES])
        c = c.rename(columns={name: "value"})
        try:
            pp = stats.pairwise_paired(c[["subject", "mode", "value"]], dv="value",
                                       subject="subject", within="mode")
        except Exception as exc:   # too few subjects: say so, keep the table
            lines.append(f"  paired t-tests not computed: {exc}")
            continue
        inv = {v: k for k, v in LABEL.items()}
        for r in pp.itertuples(index=False):
            key = (inv[str(r.group1)], inv[str(r.group2)])
            st, sp = SEED_TABLE_5_2[name].get(key, (math.nan, "?"))
            lines.append(f"  paired t {r.group1} vs {r.group2}: simulated t = {r.t:6.2f}, "
                         f"p = {r.p:.3g}  |  seed t = {st}, p = {sp}")
    extra = df.groupby("mode")[["transfers", "regrasps", "misaligned_transfers", "em_to_ring",
                                "em_to_via", "em_transfer", "contact_time"]].mean()
    lines.append("\nper trial (means): " + extra.rename(index=LABEL).round(3).to_string())
    curve = df.groupby(["mode", "trial_number"])["ET"].mean().unstack().rename(index=LABEL)
    lines.append("\nET learning curve [s] (trial number within the mode):\n"
                 + curve.round(1).to_string())
    return lines


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--subjects", type=int, default=4)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--fit", action="store_true", help="fit the calibration first")
    ap.add_argument("--fit-subjects", type=int, default=3)
    ap.add_argument("--csv", default=None, help="also write the trials to this CSV")
    ap.add_argument("--effects", default=None, metavar="K,THETA,C",
                    help="run with these thread_time, stdt_noise, camera_cost instead")
    args = ap.parse_args(argv)
    effects = fit(args.fit_subjects, args.seed, args.workers) if args.fit else SEED_TELEOP
    if args.effects:
        try:
            k, theta, c = (float(v) for v in args.effects.split(","))
            effects = TeleopEffects(thread_time=k, stdt_noise=theta, camera_cost=c)
        except ValueError as exc:
            ap.error(f"--effects: expected three numbers K,THETA,C, got {args.effects!r} "
                     f"({exc})")
    print(f"cohort: {args.subjects} subjects, seed {args.seed}, {effects}", flush=True)
    df = simulate(args.subjects, args.seed, effects, args.workers)
    if args.csv:
        df.to_csv(args.csv, index=False)
    print("\n".join(side_by_side(df)))
    print("\nsynthetic data: scripted operator calibrated to the seed (not evidence)")


if __name__ == "__main__":
    main()
