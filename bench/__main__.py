"""Runs every benchmark and prints its figures: ``python -m bench [NAME ...]``."""

from __future__ import annotations

import importlib
import sys

BENCHES = ["bench.fixtures_pipeline", "bench.store", "bench.study_simulate", "bench.haptics",
           "bench.report", "bench.abdomen", "bench.contact",
           "bench.mrcp_rpq", "bench.viewer"]
BENCHES += ["bench.mrcp"]  # the MRCP control cycle vs the 18 ms budget
BENCHES += ["bench.mrcp_profile"]  # where the 8-robot MRCP cycle's time goes, by part
BENCHES += ["bench.power"]  # power planning: cohorts/s on 1 and 2 local Ray workers


def main(argv: list[str]) -> int:
    names = [f"bench.{n}" for n in argv] if argv else BENCHES
    for name in names:
        mod = importlib.import_module(name)
        print(f"\n=== {name} ===", flush=True)
        mod.main()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
