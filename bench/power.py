"""Power planning speed: cohorts per second on 1 and 2 local Ray workers and on 1 and 2
processes of the local pool (the backend without the ``cluster`` extra), what the store
would cost, and (``--validate K``) the coarse step's validation.

Default run (a few minutes on 2 cores; ``nice`` it on a shared machine):

1. *Where time goes in one cohort*: one small cohort of ``vf_learning_curve`` (``SUBJECTS``
   subjects, trials cut at ``MAX_TIME`` s) run in this process three ways: in memory at the
   1 ms step (what ``vasim study power`` does), written to a study database (what
   ``--keep-cohorts`` and ``vasim study simulate`` do), and in memory at the coarse 2 ms
   step; prints wall seconds and the ratios.
2. *Cohorts per second on Ray and on the process pool*: ``COHORTS`` such cohorts (coarse
   step) on a local Ray (when installed) and on the local process pool, each with 1 and with
   2 workers; prints wall time, the backend's start-up, cohorts/s (with and without the
   start-up) and the 2-vs-1 ratio. The pool starts its processes with the first tasks, so
   its start-up prints as ~0 s and counts in the tasks' time.

``--validate K``: the coarse step's validation (:mod:`vasim.study.power.coarse`) over the
six VF conditions x seeds 0..K-1 (full trials at 1 ms and 2 ms; ~1 s per trial pair):
the relative change of each measure's mean, overall and per condition, and each
condition's mean relative to VF-free at both steps (are the fixture effects kept?).

``python bench/power.py [--validate K]`` or ``python -m bench power``.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import pandas as pd

from vasim.core.extras import installed
from vasim.study.power.coarse import MEASURES, validate_coarse
from vasim.study.power.cohort import cohort_tests
from vasim.study.power.design import COARSE_DT, FULL_DT, PowerDesign
from vasim.study.power.driver import run_power
from vasim.study.protocol import load_protocol

PROTOCOL = "vf_learning_curve"
SMOKE = os.environ.get("VASIM_BENCH_SMOKE") == "1"
"""``python -m bench --smoke``: every run cut to seconds (it checks the bench runs; its
figures mean nothing)."""
SUBJECTS = 2 if SMOKE else 3
MAX_TIME = 0.3 if SMOKE else 3.0  # s per trial: the cohort's 114 trials stay short
COHORTS = 1 if SMOKE else 4
WORKERS = (1,) if SMOKE else (1, 2)


def where_time_goes() -> None:
    protocol = load_protocol(PROTOCOL)
    rows = []
    for label, dt, keep in (("in memory, 1 ms", FULL_DT, False),
                            ("study database, 1 ms", FULL_DT, True),
                            ("in memory, 2 ms (coarse)", COARSE_DT, False)):
        design = PowerDesign(subjects=(SUBJECTS,), cohorts=1, dt=dt, max_trial_time=MAX_TIME)
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            out = cohort_tests(protocol, design, SUBJECTS, 0, keep_dir=tmp if keep else None)
            wall = time.perf_counter() - t0
        rows.append((label, out.n_trials, out.sim_seconds, wall))
        print(f"  {label:<26} {out.n_trials:>4} trials {out.sim_seconds:>7.1f} s simulated "
              f"{wall:>7.2f} s wall", flush=True)
    mem, store, coarse = (r[3] for r in rows)
    print(f"  the study database costs {store / mem:.2f}x the in-memory cohort "
          f"({(store - mem) / rows[0][1] * 1e3:.0f} ms per trial); the coarse step runs "
          f"{mem / coarse:.2f}x faster than 1 ms")


def ray_throughput(backend: str = "ray") -> None:
    protocol = load_protocol(PROTOCOL)
    design = PowerDesign(subjects=(SUBJECTS,), cohorts=COHORTS, dt=COARSE_DT,
                         max_trial_time=MAX_TIME)
    rates = {}
    for workers in WORKERS:
        res = run_power(protocol, design, workers=workers, progress=False, backend=backend)
        n = design.n_cohorts
        steady = n / max(res.wall_seconds - res.ray_seconds, 1e-9)
        rates[workers] = (n / res.wall_seconds, steady)
        print(f"  {workers} worker(s): {n} cohorts ({res.n_trials} trials) in "
              f"{res.wall_seconds:.1f} s wall (start {res.ray_seconds:.1f} s, tasks "
              f"{res.task_seconds:.1f} s wall / {res.cpu_seconds:.1f} s CPU): "
              f"{n / res.wall_seconds:.4f} cohorts/s, "
              f"{steady:.4f} without the start, {n / res.cpu_seconds:.4f} per task CPU s",
              flush=True)
    if 2 not in rates:
        return
    print(f"  2 vs 1 workers: {rates[2][0] / rates[1][0]:.2f}x "
          f"({rates[2][1] / rates[1][1]:.2f}x without the start); tasks' wall >> CPU means "
          "they waited for cores other processes held")


def validate(k: int) -> None:
    t0 = time.perf_counter()
    change, trials = validate_coarse(list(range(k)))
    print(f"  {len(trials) // 2} trials at 1 ms and 2 ms in {time.perf_counter() - t0:.0f} s")
    print("  change of the mean, 2 ms vs 1 ms: " + ", ".join(
        f"{m} {100 * v:+.1f} %" for m, v in change.items()))
    means = trials.groupby(["schema", "dt"])[list(MEASURES)].mean()
    per = (means.xs(COARSE_DT, level="dt") / means.xs(FULL_DT, level="dt") - 1) * 100
    print("  per condition (%):")
    print(per.round(1).to_string())
    ratio = {}
    for dt in (FULL_DT, COARSE_DT):
        m = means.xs(dt, level="dt")
        ratio[f"{dt * 1e3:g} ms"] = (m / m.loc["none"]).stack()
    print("  condition mean / VF-free mean at each step (the fixture effects):")
    print(pd.DataFrame(ratio).round(3).to_string())


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--validate", type=int, default=0, metavar="K",
                    help="also validate the coarse step on seeds 0..K-1 (default: no)")
    args = ap.parse_args(argv or [])
    print(f"where time goes in one cohort ({PROTOCOL}, {SUBJECTS} subjects, trials cut at "
          f"{MAX_TIME:g} s, in this process):", flush=True)
    where_time_goes()
    for backend, where in (("ray", "a local Ray"), ("processes", "the local process pool")):
        if backend == "ray" and not installed("ray"):
            print("cohorts per second on a local Ray: skipped (no cluster extra)")
            continue
        print(f"cohorts per second on {where} ({COHORTS} cohorts of {SUBJECTS} subjects, "
              "coarse step):", flush=True)
        ray_throughput(backend)
    if args.validate:
        print(f"coarse step validation (six conditions x {args.validate} seeds):", flush=True)
        validate(args.validate)


if __name__ == "__main__":
    main(sys.argv[1:])
