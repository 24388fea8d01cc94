"""Runs every benchmark and prints its figures: ``python -m bench [--smoke] [NAME ...]``.

``make bench`` (no ``--smoke``) runs the modules of :data:`BENCHES` in this process, one after
the other, and prints their figures.

``--smoke`` (``make test`` runs it) checks that every benchmark still runs, so none can rot
unnoticed: each module of :data:`BENCHES` and :data:`SMOKE_EXTRA` runs in its own process
(``python -m bench.NAME``, a crash or a leaked thread stays there) with
``VASIM_BENCH_SMOKE=1``, under which every module cuts its runs to seconds (fewer steps,
cycles, subjects; the figures it prints then mean nothing). One line per benchmark as it
ends; a failure prints the tail of its output; the exit status is 1 if any failed.
:data:`NOT_SMOKED` names the modules left out, each with the reason
(``tests/test_bench_smoke.py`` checks every ``bench/*.py`` is in one of the three lists).
"""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
import time
from pathlib import Path

BENCHES = ["bench.fixtures_pipeline", "bench.store", "bench.study_simulate", "bench.haptics",
           "bench.report", "bench.abdomen", "bench.contact",
           "bench.mrcp_rpq", "bench.viewer"]
BENCHES += ["bench.mrcp"]  # the MRCP control cycle vs the 18 ms budget
BENCHES += ["bench.mrcp_profile"]  # where the 8-robot MRCP cycle's time goes, by part
BENCHES += ["bench.power"]  # power planning: cohorts/s on 1 and 2 local Ray workers

SMOKE_EXTRA = ["bench.bad_inputs"]
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


def smoke(names: list[str]) -> int:
    """Runs ``names`` (module names) in smoke mode; returns the exit status (0: all ran)."""
    env = {**os.environ, "VASIM_BENCH_SMOKE": "1"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    failed = []
    t_all = time.perf_counter()
    for i, name in enumerate(names, 1):
        print(f"[{i}/{len(names)}] {name} ...", end=" ", flush=True)
        t0 = time.perf_counter()
        try:
            proc = subprocess.run([sys.executable, "-m", name], cwd=ROOT, env=env,
                                  stdin=subprocess.DEVNULL, capture_output=True, text=True,
                                  timeout=SMOKE_TIMEOUT_S, check=False)
            code, out = proc.returncode, proc.stdout + proc.stderr
        except subprocess.TimeoutExpired as exc:
            code = None
            out = "".join(b.decode(errors="replace") if isinstance(b, bytes) else (b or "")
                          for b in (exc.stdout, exc.stderr))
        took = time.perf_counter() - t0
        if code == 0:
            print(f"ok ({took:.1f} s)", flush=True)
            continue
        why = f"timed out after {SMOKE_TIMEOUT_S:g} s" if code is None else f"exit {code}"
        print(f"FAILED ({why}, {took:.1f} s)", flush=True)
        tail = out.strip().splitlines()[-25:]
        print("\n".join(f"    {line}" for line in tail), flush=True)
        failed.append(name)
    status = f"{len(names) - len(failed)} of {len(names)} benchmarks ran in smoke mode"
    print(f"{status} ({time.perf_counter() - t_all:.0f} s)"
          + (f"; failed: {', '.join(failed)}" if failed else ""), flush=True)
    return 1 if failed else 0


def main(argv: list[str]) -> int:
    smoke_mode = "--smoke" in argv
    args = [a for a in argv if a != "--smoke"]
    bad = [a for a in args if a.startswith("-")]
    if bad:
        print(f"python -m bench: error: unknown option {bad[0]} (usage: python -m bench "
              "[--smoke] [NAME ...])", file=sys.stderr)
        return 2
    if smoke_mode:
        return smoke([f"bench.{n}" for n in args] if args else BENCHES + SMOKE_EXTRA)
    names = [f"bench.{n}" for n in args] if args else BENCHES
    for name in names:
        mod = importlib.import_module(name)
        print(f"\n=== {name} ===", flush=True)
        mod.main()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
