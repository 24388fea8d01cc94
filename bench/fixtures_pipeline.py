"""Cost of the fixture pipeline per 1 kHz control step, and trial throughput.

Figures printed (one run, same process, so ratios are comparable on a noisy 2-core host):
* per-step cost of ``SchemaRuntime.scale_motion + render`` with all five fixtures active
  (schema ``trajectory_following``: MS, FF, AG, VG, Mag) vs. the empty schema ``none``;
* per-step cost of the whole control step (operator + fixtures + task + sample buffer);
* trial throughput: simulated seconds per wall second for complete scripted trials;
* the share of the 1 ms haptic budget the fixtures use.
"""

from __future__ import annotations

import statistics
import time

import numpy as np
from tqdm import tqdm

from vasim.fixtures.runtime import SchemaRuntime
from vasim.fixtures.schema import load_schema
from vasim.fixtures.types import TaskState
from vasim.study.trial import TrialConfig, TrialRunner
from vasim.tasks import trajectory_task


def _fixture_step_cost(schema_name: str, n: int = 5000, repeats: int = 5) -> float:
    """Median µs per (scale_motion + render) over ``repeats`` runs of ``n`` steps."""
    task = trajectory_task(0)
    rt = SchemaRuntime(load_schema(schema_name))
    rng = np.random.default_rng(0)
    tcps = task.points[0] + rng.normal(0.0, 0.01, size=(n, 3))
    dxs = rng.normal(0.0, 1e-4, size=(n, 3))
    states = [
        TaskState(tcp=tcps[i], goal=task.points[i % len(task.points)],
                  tcp_velocity=dxs[i] * 1e3, dx_master=dxs[i], scale=task.scale,
                  t=i * 1e-3, kind=task.kind, lookahead=task.lookahead(i % len(task.points)))
        for i in range(n)
    ]
    rt.reset(tcps[0])
    per_run = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for s in states:
            rt.scale_motion(s)
            rt.render(s)
        per_run.append((time.perf_counter() - t0) / n * 1e6)
    return statistics.median(per_run)


def _trial_throughput(n_trials: int = 3) -> tuple[float, float, float]:
    """(simulated s per wall s, µs per control step, simulated s per trial), median."""
    ratios, step_us, sim = [], [], []
    for seed in tqdm(range(n_trials), desc="scripted trials", leave=False):
        runner = TrialRunner(TrialConfig(schema="trajectory_following", seed=seed))
        t0 = time.perf_counter()
        while not runner.done:
            runner.advance(1.0)
        wall = time.perf_counter() - t0
        ratios.append(runner.frame.t / wall)
        step_us.append(wall / (runner.frame.k + 1) * 1e6)
        sim.append(runner.frame.t)
    return statistics.median(ratios), statistics.median(step_us), statistics.median(sim)


def main() -> None:
    none_us = _fixture_step_cost("none")
    all_us = _fixture_step_cost("trajectory_following")
    ratio, step_us, sim_s = _trial_throughput()
    print(f"{'fixture pipeline, no fixtures (none)':<52} {none_us:8.1f} µs/step")
    print(f"{'fixture pipeline, all five (trajectory_following)':<52} {all_us:8.1f} µs/step")
    print(f"{'  share of the 1 ms haptic budget':<52} {all_us / 10:8.1f} %")
    print(f"{'  cost ratio all five / none':<52} {all_us / max(none_us, 1e-9):8.1f} x")
    print(f"{'full control step (operator+fixtures+task+log)':<52} {step_us:8.1f} µs/step")
    print(f"{'trial throughput (simulated s per wall s)':<52} {ratio:8.1f} x real time")
    print(f"{'  median simulated trial length':<52} {sim_s:8.1f} s")


if __name__ == "__main__":
    main()
