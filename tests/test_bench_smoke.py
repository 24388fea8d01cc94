"""bench/__main__.py: ``python -m bench --smoke`` covers every benchmark module and fails
when one fails (issue #27 §3; ``make test`` runs the smoke run itself)."""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
bench_main = importlib.import_module("bench.__main__")


def test_every_bench_module_is_smoke_run_or_says_why_not() -> None:
    modules = {f"bench.{p.stem}" for p in (ROOT / "bench").glob("*.py")
               if not p.stem.startswith("_")}
    smoked = bench_main.BENCHES + bench_main.SMOKE_EXTRA
    assert len(set(smoked)) == len(smoked)
    assert not set(smoked) & set(bench_main.NOT_SMOKED)
    assert modules == set(smoked) | set(bench_main.NOT_SMOKED)
    for name in smoked:   # each one cuts its runs to seconds under VASIM_BENCH_SMOKE
        src = (ROOT / "bench" / f"{name.split('.')[1]}.py").read_text(encoding="utf-8")
        assert "VASIM_BENCH_SMOKE" in src, name


def test_a_failing_benchmark_fails_the_smoke_run(capsys: pytest.CaptureFixture[str]) -> None:
    assert bench_main.smoke(["bench.no_such_benchmark"]) == 1
    out = capsys.readouterr().out
    assert "[1/1] bench.no_such_benchmark: FAILED (exit 1" in out
    assert "No module named bench.no_such_benchmark" in out
    assert "0 of 1 benchmarks ran in smoke mode" in out and "failed: bench.no_such_benchmark" in out


@pytest.mark.parametrize(("args", "needle"), [(["--smokey"], "--smokey"),
                                               (["--smoke", "--jobs", "0"], "--jobs: got 0")])
def test_bad_options_are_a_one_line_error(args: list[str], needle: str) -> None:
    p = subprocess.run([sys.executable, "-m", "bench", *args], cwd=ROOT,
                       capture_output=True, text=True, timeout=120)
    err = p.stderr.strip().splitlines()
    assert p.returncode == 2 and needle in err[-1] and "Traceback" not in p.stderr
