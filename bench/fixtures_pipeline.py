"""Cost of the fixture pipeline per 1 kHz control step, and trial throughput.

Figures printed (one run, same process, so ratios are comparable on a noisy 2-core host):
* per-step cost of ``SchemaRuntime.scale_motion + render`` (the public API: ``TaskState`` in,
  effect objects out) with all five fixtures active (schema ``trajectory_following``: MS, FF,
  AG, VG, Mag) vs. the empty schema ``none``;
* the same pipeline on floats, ``scale_motion_xyz + render_xyz``, which is what the trial
  loop runs per step (it builds the ``FixtureOutputs`` only when it publishes a frame; the
  cost of one ``outputs()`` is printed too);
* per fixture: one call of the pure public function (``TaskState`` in, effect out), and of
  its registered ``evaluate`` on a prepared ``Step`` (the one implementation both run);
* per-step cost of the whole control step (operator + fixtures + task + sample buffer), and
  its ratio to the fixture pipeline;
* trial throughput: simulated seconds per wall second for complete scripted trials;
* the share of the 1 ms haptic budget the fixtures use.

Each figure is the median of a few runs; the host is shared, so compare figures within one
run rather than across runs.
"""

from __future__ import annotations

import os
import statistics
import time
from collections.abc import Callable
from functools import partial

import numpy as np
from tqdm import tqdm

from vasim.fixtures import FIXTURES, Step, ag, ff, mag, ms, vg
from vasim.fixtures.runtime import SchemaRuntime
from vasim.fixtures.schema import load_schema
from vasim.fixtures.types import TaskState
from vasim.tasks import trajectory_task
from vasim.trials.vf import TrialConfig, TrialRunner

SMOKE = os.environ.get("VASIM_BENCH_SMOKE") == "1"
"""``python -m bench --smoke``: every run cut to seconds (it checks the bench runs; its
figures mean nothing)."""


def _states(n: int) -> list[TaskState]:
    """``n`` states around the start of the original trajectory (fixed seed)."""
    task = trajectory_task(0)
    rng = np.random.default_rng(0)
    tcps = task.points[0] + rng.normal(0.0, 0.01, size=(n, 3))
    dxs = rng.normal(0.0, 1e-4, size=(n, 3))
    return [
        TaskState(tcp=tcps[i], goal=task.points[i % len(task.points)],
                  tcp_velocity=dxs[i] * 1e3, dx_master=dxs[i], scale=task.scale,
                  t=i * 1e-3, kind=task.kind, lookahead=task.lookahead(i % len(task.points)))
        for i in range(n)
    ]


def _median_us(run: Callable[[], None], n: int, repeats: int = 1 if SMOKE else 5) -> float:
    """Median over ``repeats`` runs of ``run`` (``n`` steps each), in µs per step."""
    per_run = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        run()
        per_run.append((time.perf_counter() - t0) / n * 1e6)
    return statistics.median(per_run)


def _fixture_step_cost(schema_name: str,
                       n: int = 200 if SMOKE else 5000) -> tuple[float, float, float]:
    """µs per step of (public scale_motion + render, float-level scale_motion_xyz +
    render_xyz) and µs per ``outputs()``."""
    states = _states(n)
    rt = SchemaRuntime(load_schema(schema_name))

    def public() -> None:
        rt.reset(states[0].tcp)
        for s in states:
            rt.scale_motion(s)
            rt.render(s)

    # the trial loop's inputs: tuples of floats (the goals are static: v = tcp_velocity)
    rows = [(tuple(s.tcp.tolist()), tuple(s.goal.tolist()), tuple(s.dx_master.tolist()),
             tuple(s.tcp_velocity.tolist()), s.t, tuple(s.lookahead.tolist()))
            for s in states]
    scale, kind = states[0].scale, states[0].kind

    def floats() -> None:
        rt.reset(states[0].tcp)
        for x, g, dxm, v, t, la in rows:
            rt.scale_motion_xyz(x, g, dxm, scale)
            rt.render_xyz(x, g, v, t, scale, kind, la, None)

    def outputs() -> None:
        for _ in range(n):
            rt._outputs = None  # rebuild the last render's outputs (what a publish costs)
            rt.outputs()

    return _median_us(public, n), _median_us(floats, n), _median_us(outputs, n)


def _per_fixture_costs(n: int = 50 if SMOKE else 2000) -> list[tuple[str, float, float]]:
    """(fixture, µs per public call, µs per float-level core call), schema parameters."""
    states = _states(n)
    params = {f.kind: f.params for f in load_schema("trajectory_following").fixtures}
    scale, kind = states[0].scale, states[0].kind
    # the float-level evaluate of each fixture (its one implementation) on a prepared Step,
    # as the trial loop calls it
    steps = [Step(tuple(s.tcp.tolist()), tuple(s.goal.tolist()), dx=tuple(s.dx_master.tolist()),
                  v=tuple(s.tcp_velocity.tolist()), lookahead=tuple(s.lookahead.tolist()),
                  kind=kind, scale=scale, t=s.t) for s in states]
    publics = {"ms": ms.motion_scaling, "ff": ff.force_feedback, "ag": ag.audio_guidance,
               "vg": vg.visual_guidance, "mag": mag.magnification}

    def run_core(name: str) -> None:
        evaluate, p = FIXTURES[name].evaluate, params[name]
        for st in steps:
            evaluate(st, p)

    def run_public(name: str) -> None:
        fn, p = publics[name], params[name]
        for s in states:
            fn(s, p)

    return [(name, _median_us(partial(run_public, name), n), _median_us(partial(run_core, name), n))
            for name in publics]


def _trial_throughput(n_trials: int = 1 if SMOKE else 3) -> tuple[float, float, float]:
    """(simulated s per wall s, µs per control step, simulated s per trial), median."""
    ratios, step_us, sim = [], [], []
    for seed in tqdm(range(n_trials), desc="scripted trials", leave=False):
        cut = {"max_time": 1.0} if SMOKE else {}
        runner = TrialRunner(TrialConfig(schema="trajectory_following", seed=seed, **cut))
        t0 = time.perf_counter()
        while not runner.done:
            runner.advance(1.0)
        wall = time.perf_counter() - t0
        ratios.append(runner.frame.t / wall)
        step_us.append(wall / (runner.frame.k + 1) * 1e6)
        sim.append(runner.frame.t)
    return statistics.median(ratios), statistics.median(step_us), statistics.median(sim)


def main() -> None:
    none_us, none_xyz_us, _ = _fixture_step_cost("none")
    all_us, all_xyz_us, outputs_us = _fixture_step_cost("trajectory_following")
    per_fixture = _per_fixture_costs()
    ratio, step_us, sim_s = _trial_throughput()
    w = 52
    print(f"{'fixture pipeline, no fixtures (none)':<{w}} {none_us:8.1f} µs/step")
    print(f"{'fixture pipeline, all five (trajectory_following)':<{w}} {all_us:8.1f} µs/step")
    print(f"{'  share of the 1 ms haptic budget':<{w}} {all_us / 10:8.1f} %")
    print(f"{'  cost ratio all five / none':<{w}} {all_us / max(none_us, 1e-9):8.1f} x")
    print(f"{'float-level pipeline (trial loop), none':<{w}} {none_xyz_us:8.1f} µs/step")
    print(f"{'float-level pipeline (trial loop), all five':<{w}} {all_xyz_us:8.1f} µs/step")
    print(f"{'  + FixtureOutputs, built once per published frame':<{w}} {outputs_us:8.1f} µs")
    for name, public_us, core_us in per_fixture:
        label = f"  {name}: pure fixture call / float-level core"
        print(f"{label:<{w}} {public_us:8.2f} / {core_us:.2f} µs")
    print(f"{'full control step (operator+fixtures+task+abdomen+log)':<{w}} {step_us:8.1f} µs/step")
    print(f"{'  ratio full step / float-level pipeline':<{w}} "
          f"{step_us / max(all_xyz_us, 1e-9):8.1f} x")
    print(f"{'trial throughput (simulated s per wall s)':<{w}} {ratio:8.1f} x real time")
    print(f"{'  median simulated trial length':<{w}} {sim_s:8.1f} s")


if __name__ == "__main__":
    main()
