"""Cohort simulation speed: simulated seconds per wall-clock second, 1 worker vs N workers.

Simulates the first ``TRIALS`` scheduled trials of ``SUBJECTS`` synthetic subjects of the
``vf_learning_curve`` protocol (full trials, the protocol's 180 s limit) into a temporary
database, once with 1 worker process and once with N = number of cores, through the real
cohort code (workers compute, the parent alone writes to SQLite). Prints simulated seconds,
wall seconds, the real-time ratio of each run, and the wall time projected for the full
46-subject x 38-trial cohort with N workers (from the mean simulated trial length and the
N-worker ratio). The issue asks for >= 20x real time.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from vasim.study.cohort import CohortPlan, CohortRun, simulate_cohort
from vasim.study.protocol import load_protocol

SMOKE = os.environ.get("VASIM_BENCH_SMOKE") == "1"
"""``python -m bench --smoke``: every run cut to seconds (it checks the bench runs; its
figures mean nothing)."""
SUBJECTS = 1 if SMOKE else 2
# per subject: baseline + the first block's trials (conditions vary by subject)
TRIALS = 2 if SMOKE else 8
SHORT_TRIALS = 1 if SMOKE else 2  # per subject, for the start-up share
FULL_SUBJECTS, FULL_TRIALS = 46, 38


def _run(workers: int, trials: int = TRIALS) -> tuple[float, float, int]:
    protocol = load_protocol("vf_learning_curve")
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "bench.sqlite"
        rep = simulate_cohort(
            db, protocol,
            CohortPlan(n_subjects=SUBJECTS, n_surgeons=1, seed=7,
                       max_trial_time=1.0 if SMOKE else None),
            CohortRun(workers=workers, progress=True, max_trials_per_subject=trials))
        sim, wall, n = rep.sim_seconds, rep.wall_seconds, rep.trials_run
    return sim, wall, n


def main() -> None:
    cores = os.cpu_count() or 1
    rows = []
    for workers in dict.fromkeys((1,) if SMOKE else (1, cores)):
        print(f"simulating {SUBJECTS} subjects x {TRIALS} trials with {workers} worker(s) ...",
              flush=True)
        sim, wall, n = _run(workers)
        rows.append((workers, sim, wall, n))
    print(f"simulating {SUBJECTS} subjects x {SHORT_TRIALS} trials with {cores} worker(s) "
          "(start-up share) ...", flush=True)
    short = _run(cores, SHORT_TRIALS)
    print(f"{'workers':>8} {'trials':>7} {'simulated s':>12} {'wall s':>8} {'x real time':>12}")
    for workers, sim, wall, n in [*rows, (cores, *short)]:
        print(f"{workers:>8} {n:>7} {sim:>12.1f} {wall:>8.1f} {sim / wall:>12.1f}")
    workers, sim, wall, n = rows[-1]
    # Steady state: the marginal rate between the short and the long run removes the fixed
    # start-up (spawning workers, imports, numba cache load, settling the organs once per
    # process), which a 1,748-trial cohort pays once.
    d_sim, d_wall = sim - short[0], wall - short[1]
    steady = d_sim / d_wall if d_wall > 0 else float("nan")
    startup = max(0.0, short[1] - short[0] / steady) if d_wall > 0 else float("nan")
    per_trial = sim / n
    full_sim = FULL_SUBJECTS * FULL_TRIALS * per_trial
    full_wall = startup + full_sim / steady
    print(f"mean simulated trial length: {per_trial:.1f} s")
    print(f"steady state with {workers} worker(s): {steady:.1f}x real time "
          f"(start-up {startup:.1f} s, paid once per run)")
    print(f"projected {FULL_SUBJECTS} subjects x {FULL_TRIALS} trials with {workers} worker(s): "
          f"{full_sim / 3600:.1f} h simulated in {full_wall / 60:.0f} min wall "
          f"({full_sim / full_wall:.1f}x real time; target >= 20x)")


if __name__ == "__main__":
    main()
