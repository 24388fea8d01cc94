"""Runs every benchmark and prints its figures: ``python -m bench [--smoke] [NAME ...]``.

``make bench`` (no ``--smoke``) runs the modules of :data:`BENCHES` in this process, one after
the other, and prints their figures.

``--smoke`` (``make test`` runs it) checks that every benchmark still runs, so none can rot
unnoticed: each module of :data:`BENCHES` and :data:`SMOKE_EXTRA` runs in its own process
(``python -m bench.NAME``, a crash or a leaked thread stays there) with
``VASIM_BENCH_SMOKE=1``, under which every module cuts its runs to seconds (fewer steps,
cycles, subjects; the figures it prints then mean nothing), ``--jobs`` at a time (default:
one per core). One line per benchmark as it ends; a failure prints the tail of its output;
the exit status is 1 if any failed.
:data:`NOT_SMOKED` names the modules left out, each with the reason
(``tests/test_bench_smoke.py`` checks every ``bench/*.py`` is in one of the three lists).
"""

from __future__ import annotations

import argparse
import importlib
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

BENCHES = ["bench.fixtures_pipeline", "bench.store", "bench.study_simulate", "bench.haptics",
           "bench.report", "bench.abdomen", "bench.contact",
           "bench.mrcp_rpq", "bench.viewer"]
BENCHES += ["bench.mrcp"]  # the MRCP control cycle vs the 18 ms budget
BENCHES += ["bench.mrcp_profile"]  # where the 8-robot MRCP cycle's time goes, by part
BENCHES += ["bench.power"]  # power planning: cohorts/s on 1 and 2 local Ray workers
BENCHES += ["bench.viewer_pixels"]  # the software renderer's cost per frame, per render scale

SMOKE_EXTRA = ["bench.bad_inputs", "bench.house"]
"""Benchmarks ``make bench`` leaves out (run on their own) that the smoke run checks too."""

NOT_SMOKED = {
    "bench.equivalence": "compares the tree with a git revision over minutes of simulation: "
                         "a refactoring's check, run by hand against its parent commit",
    "bench.calibration": "its statistics need a whole simulated cohort (46 subjects x 38 "
                         "trials, ~12 min); vasim study simulate and report are tested",
    "bench.chapter5": "its paired tests need a whole simulated cohort (4 subjects x 18 "
                      "trials, ~9 min); the MRCP study path is tested in tests/mrcp",
}
"""Modules in bench/ that are not smoke-run, and why."""

SMOKE_TIMEOUT_S = 900.0
"""Per benchmark, generous: a loaded 2-core machine stretches seconds into minutes."""

ROOT = Path(__file__).resolve().parent.parent


def _smoke_one(name: str, env: dict[str, str]) -> tuple[int | None, str, float]:
    """(exit status or None on timeout, its output, seconds) of one benchmark's smoke run."""
    t0 = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, "-m", name], cwd=ROOT, env=env,
                              stdin=subprocess.DEVNULL, capture_output=True, text=True,
                              timeout=SMOKE_TIMEOUT_S, check=False)
        return proc.returncode, proc.stdout + proc.stderr, time.perf_counter() - t0
    except subprocess.TimeoutExpired as exc:
        out = "".join(b.decode(errors="replace") if isinstance(b, bytes) else (b or "")
                      for b in (exc.stdout, exc.stderr))
        return None, out, time.perf_counter() - t0


def smoke(names: list[str], jobs: int = 1) -> int:
    """Runs ``names`` (module names) in smoke mode, ``jobs`` at a time; returns the exit
    status (0: all ran). **Decision**: several at a time is fine here (the figures of a smoke
    run mean nothing, only whether it ends cleanly), so ``make test`` uses one per core."""
    env = {**os.environ, "VASIM_BENCH_SMOKE": "1"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    failed = []
    t_all = time.perf_counter()
    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        runs = {pool.submit(_smoke_one, name, env): name for name in names}
        for i, done in enumerate(as_completed(runs), 1):
            name = runs[done]
            code, out, took = done.result()
            if code == 0:
                print(f"[{i}/{len(names)}] {name}: ok ({took:.1f} s)", flush=True)
                continue
            why = f"timed out after {SMOKE_TIMEOUT_S:g} s" if code is None else f"exit {code}"
            print(f"[{i}/{len(names)}] {name}: FAILED ({why}, {took:.1f} s)", flush=True)
            tail = out.strip().splitlines()[-25:]
            print("\n".join(f"    {line}" for line in tail), flush=True)
            failed.append(name)
    status = f"{len(names) - len(failed)} of {len(names)} benchmarks ran in smoke mode"
    print(f"{status} ({time.perf_counter() - t_all:.0f} s, {jobs} at a time)"
          + (f"; failed: {', '.join(failed)}" if failed else ""), flush=True)
    return 1 if failed else 0


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench", description=__doc__.splitlines()[0])
    parser.add_argument("--smoke", action="store_true",
                        help="every benchmark in a seconds-long mode, in its own process; "
                             "exit 1 if any fails")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                        help="smoke runs at a time (default: one per core)")
    parser.add_argument("names", nargs="*", metavar="NAME", help="e.g. abdomen (default: all)")
    ns = parser.parse_args(argv)
    args: list[str] = ns.names
    if not 1 <= ns.jobs <= 64:
        parser.error(f"--jobs: got {ns.jobs}, expected an integer in [1, 64]")
    if ns.smoke:
        return smoke([f"bench.{n}" for n in args] if args else BENCHES + SMOKE_EXTRA, ns.jobs)
    names = [f"bench.{n}" for n in args] if args else BENCHES
    for name in names:
        mod = importlib.import_module(name)
        print(f"\n=== {name} ===", flush=True)
        mod.main()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
