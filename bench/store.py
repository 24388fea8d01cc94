"""The study store: per-sample append cost in the 1 kHz loop, and the one-transaction commit.

Prints µs per ``SampleBuffer.append`` (the only storage work inside the control loop) and the
time ``TrialStore.finish_trial`` takes to make a 100,000-sample trial durable (WAL,
synchronous=FULL), plus rows per second.
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from vasim.records.point_metrics import evaluate_trial
from vasim.records.samples import SampleBuffer
from vasim.records.trial_meta import TrialMeta
from vasim.study.store import TrialStore

SMOKE = os.environ.get("VASIM_BENCH_SMOKE") == "1"
"""``python -m bench --smoke``: every run cut to seconds (it checks the bench runs; its
figures mean nothing)."""
FINISH_N = 5000 if SMOKE else 100_000


def _append_cost(n: int = 1000 if SMOKE else 20_000, repeats: int = 1 if SMOKE else 5) -> float:
    buf = SampleBuffer(capacity=n)
    x, g, f = np.array([0.1, 0.2, 0.3]), np.array([0.0, 0.0, 0.01]), np.array([1.0, 0, 0])
    ms = np.ones(3)
    runs = []
    for _ in range(repeats):
        buf.clear()
        t0 = time.perf_counter()
        for k in range(n):
            buf.append(k, k * 1e-3, x, g, 0, f, ms, 1.0, 440.0, 0.5, 0.2, 0)
        runs.append((time.perf_counter() - t0) / n * 1e6)
    return statistics.median(runs)


def _finish_cost(n: int = FINISH_N, repeats: int = 1 if SMOKE else 3) -> float:
    rng = np.random.default_rng(0)
    buf = SampleBuffer(capacity=n)
    buf.extend(k=np.arange(n), t=np.arange(n) * 1e-3, x=rng.normal(size=(n, 3)),
               g=rng.normal(size=(n, 3)), goal_index=(np.arange(n) * 30) // n)
    v = buf.view()
    pm, summary = evaluate_trial(v["t"], v["x"], v["g"], v["goal_index"], 30)
    runs = []
    with tempfile.TemporaryDirectory() as tmp, TrialStore(Path(tmp) / "b.sqlite") as store:
        for _ in tqdm(range(repeats), desc="finish_trial", leave=False):
            tid = store.begin_trial(TrialMeta(subject="B01", task="trajectory"))
            t0 = time.perf_counter()
            store.finish_trial(tid, buf, pm, summary)
            runs.append(time.perf_counter() - t0)
    return statistics.median(runs)


def main() -> None:
    app = _append_cost()
    fin = _finish_cost()
    print(f"{'SampleBuffer.append (in the 1 kHz loop)':<52} {app:8.2f} µs/sample")
    print(f"{'  share of the 1 ms haptic budget':<52} {app / 10:8.2f} %")
    print(f"{f'finish_trial, {FINISH_N:,} samples, one transaction':<52} {fin:8.3f} s")
    print(f"{'  rows made durable per second':<52} {FINISH_N / fin:8.0f}")


if __name__ == "__main__":
    main()
