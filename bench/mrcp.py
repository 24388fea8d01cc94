"""One complete MRCP control cycle against the seed's 18 ms budget (issue #7 §5).

A cycle is everything :meth:`vasim.mrcp.kernel.MRCPKernel.step` does in TOp: predict the
task, evaluate RSel at CuTP and every candidate at every other task point with every index,
texec / ttransf* / tus, RCnt and NTT, RSel's follow step and the candidates' guided moves.
The figure is for ``n`` robots x 6 indices (RJ, Θ, CR, tool cone, visibility, force-torque)
x 6 task points with the kernel's default sampling, for n = 2, 4, 8 and 16 (issue #17 §4:
8 RX60B within the 18 ms cycle, 16 to show how it scales), on a task moving along a smooth
closed path. Transfers are disabled (NTT threshold out of reach) so every
timed cycle is a full evaluation cycle.

Stations (the arm factory is pluggable, ``STATIONS``):

* ``planar``: the analytic planar arms of ``tests/mrcp/planar.py`` (numpy kinematics and
  capsule distances) — the kernel's own cost with a cheap world;
* ``rx60b``: Stäubli RX60B arms of ``vasim.mrcp.backend`` (compiled DH kinematics, pybullet
  distance queries), used when that module is importable.

Two kernel variants per station: ``default`` (IK at every predicted point, distance queries
at every point) and ``fast`` (``KernelConfig(trajectory_ik="linear",
distance_points="ends")``: first-order steps along the prediction, distances at its two
ends).

Prints wall-clock median and p99 per configuration, the same for the CPU time of the thread
running the cycle (``time.thread_time``: on a shared machine the wall time includes waiting
for a core, the thread's CPU time does not), the wall / CPU ratio of the medians (how much
the other load stretched the cycle) and both p99s over the 18 ms budget; wall time is the
figure that counts on an unloaded host (the header prints the load average: run it when
``uptime`` shows < 0.5).
``VASIM_BENCH_MRCP_N`` sets the timed cycles per configuration (default 150).

Then (issue #17 §4-5):

* for 2, 4, 8 and 16 RX60B, the cycle with the evaluation's distances and Θ of all robots
  in one compiled call a cycle (``KernelConfig`` defaults) against one distance call per
  robot and one Θ call per (robot, point) (``batch_distances=False, batch_indices=False``:
  the same cycles, alternating runs): CPU and wall p50 / p99 and their ratios;
* the speed-up of batching the trajectory IK across robots (8 RX60B, default variant,
  ``KernelConfig(batch_ik=...)``: the same cycles, alternating runs);
* the ``eight_robots`` scenario's whole cycle as ``vasim mrcp run`` and the browser run it
  (full-pose grasps: the pose IK dominates), now and with the pose IK of before issue #17
  §5 (the Python loop, the search also out of reach, no batch; the same run), and its
  real-time factor (simulated s per wall s and per CPU s);
* the browser panel's real-time factor: ``vasim serve --scene mrcp:eight_robots`` (viser
  server, view thread at 30 Hz, no page attached) over a few seconds.

**Decision** (GPU, issue #17 §4): no GPU path. The machine has none, and the work left per
cycle is a few hundred small, branchy problems (link-pair branch and bound, 6 x 6 DLS
steps, 4-point trajectories) whose cost is dominated by the Python between them, not by
arithmetic a GPU would speed up; the transfer latency of a GPU call (tens of µs) would
exceed most of the compiled calls it replaced.
"""

from __future__ import annotations

import math
import os
import statistics
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from vasim.mrcp.indices.cone import ToolCone
from vasim.mrcp.interfaces import ArmKinematics, ProximityWorld
from vasim.mrcp.kernel import IndexSpec, KernelConfig, MRCPKernel, TaskPoint

BUDGET_MS = 18.0
SMOKE = os.environ.get("VASIM_BENCH_SMOKE") == "1"
"""``python -m bench --smoke``: every run cut to seconds (it checks the bench runs; its
figures mean nothing)."""
CYCLES = int(os.environ.get("VASIM_BENCH_MRCP_N", "3" if SMOKE else "150"))
WARMUP = 2 if SMOKE else 20
SPEEDUP_CYCLES = 3 if SMOKE else 60  # per run, 2 alternating runs per variant
SCENARIO_S = 0.2 if SMOKE else 3.0  # simulated seconds of the eight_robots scenario per variant
BROWSER_S = 1.0 if SMOKE else 8.0   # wall seconds of the served scenario
ROBOT_COUNTS = (2,) if SMOKE else (2, 4, 8, 16)


@dataclass
class Station:
    """What the bench needs: arms, their world, the task and the operator's path."""

    arms: dict[str, ArmKinematics]
    world: ProximityWorld
    task_points: list[TaskPoint]
    start: np.ndarray
    path: Callable[[float], np.ndarray]
    cones: dict[str, ToolCone]
    ignore: tuple[str, ...] = ()


def _hexagon(radius: float) -> list[TaskPoint]:
    """Six grasp points around the object, candidates waiting 4 cm further out."""
    out = []
    for k in range(6):
        a = k * np.pi / 3
        p = radius * np.array([np.cos(a), np.sin(a), 0.0])
        out.append(TaskPoint(p, approach=0.04 * p / radius))
    return out


def planar_station(n: int) -> Station:
    """``n`` planar arms on a circle around the task (reach 0.55 m, circle radius 0.5 m)."""
    root = Path(__file__).resolve().parents[1]
    if str(root) not in sys.path:
        sys.path.insert(0, str(root))
    from tests.mrcp.planar import PlanarArm, PlanarWorld, Sphere

    centre = np.array([0.0, 0.0, 0.0])
    tps = _hexagon(0.05)
    arms: dict[str, ArmKinematics] = {}
    configs = {}
    cones = {}
    for i in range(n):
        a = 2 * np.pi * i / n
        base = centre + 0.5 * np.array([np.cos(a), np.sin(a), 0.0])
        arm = PlanarArm(f"r{i}", base=base, yaw=a + np.pi, radius=0.012,
                        lower=np.array([-2.8, -2.8, -0.2]), upper=np.array([2.8, 2.8, 0.2]))
        goal = tps[i % 6].position if i == 0 else centre + 0.15 * (base - centre)
        q = arm.ik(goal, None, np.array([0.3, 1.2, 0.0]))
        if q is None:
            raise RuntimeError(f"planar station: robot {i} cannot reach its start")
        arms[arm.name], configs[arm.name] = arm, q
        cones[arm.name] = ToolCone(base + np.array([0.0, 0.0, 0.3]), np.array([0.0, 0.0, -1.0]),
                                   np.array([1.0, 0.0, 0.0]))
    obstacles = {"view_cone": Sphere(np.array([0.0, 0.0, 0.35]), 0.05, solid=False)}
    world = PlanarWorld(arms, configs, obstacles)  # type: ignore[arg-type]

    def path(t: float) -> np.ndarray:
        return centre + np.array([0.05 * np.sin(0.8 * t), 0.04 * np.sin(1.3 * t), 0.0])

    return Station(arms, world, tps, centre.copy(), path, cones)


def _ring(i: int, n: int) -> tuple[float, float]:
    """(angle [rad], radius [m]) of robot ``i`` of ``n``: a 0.5 m circle up to 8 robots,
    wider beyond so the bases stay as far apart (16 bases on the 0.5 m circle would be
    0.2 m apart: the RX60B bases touch and RSel's first move is a collision)."""
    return 2 * np.pi * i / n, 0.5 if n <= 8 else 0.62


def rx60b_station(n: int) -> Station:
    """``n`` RX60B arms of the pybullet backend on a circle (0.5 m) facing the task
    (a second ring beyond 8, see :func:`_ring`)."""
    from vasim.mrcp.backend import PybulletArm, PybulletWorld, pose_matrix
    from vasim.mrcp.dh import load_robot

    model = load_robot("rx60b")
    world = PybulletWorld()
    centre = np.array([0.0, 0.0, 0.2])
    tps = _hexagon(0.04)
    arms: dict[str, ArmKinematics] = {}
    cones = {}
    for i in range(n):
        a, radius = _ring(i, n)
        pos = radius * np.array([np.cos(a), np.sin(a), 0.0])
        c, s = np.cos(a + np.pi), np.sin(a + np.pi)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        base = pose_matrix(pos, rot)
        arm = PybulletArm(model, base, name=f"r{i}")
        # the candidates wait with their TCPs on a circle about the task, wider for more
        # than 8 robots (16 arms on the 8-robot circle would touch)
        goal = ((centre + tps[0].position) if i == 0
                else centre + 0.35 * (pos - centre) if n <= 8
                else centre + 0.6 * (pos - centre) + np.array([0.0, 0.0, 0.25]))
        q = arm.ik(goal, None, arm.home)
        if q is None:
            raise RuntimeError(f"rx60b station: robot {i} cannot reach its start")
        world.add_robot(arm.name, model, base, q)
        arms[arm.name] = arm
        cones[arm.name] = ToolCone(pos + np.array([0.0, 0.0, 0.6]), np.array([0.0, 0.0, -1.0]),
                                   np.array([1.0, 0.0, 0.0]))
    world.add_sphere("view_cone", 0.05, centre + np.array([0.0, 0.0, 0.45]))

    def path(t: float) -> np.ndarray:
        return centre + np.array([0.04 * np.sin(0.8 * t), 0.03 * np.sin(1.3 * t),
                                  0.02 * np.sin(0.5 * t)])

    return Station(arms, world, tps, centre.copy(), path, cones, ("view_cone",))


STATIONS: dict[str, Callable[[int], Station]] = {"planar": planar_station}
try:  # the RX60B world exists once vasim.mrcp.backend (helper M1) is present
    import vasim.mrcp.backend  # noqa: F401

    STATIONS["rx60b"] = rx60b_station
except ImportError:  # pragma: no cover - depends on the checkout
    pass


def six_indices(st: Station) -> tuple[IndexSpec, ...]:
    return (IndexSpec("rj"), IndexSpec("theta"), IndexSpec("cr", {"ignore": st.ignore}),
            IndexSpec("cone", {"cones": st.cones}), IndexSpec("visibility"),
            IndexSpec("force_torque"))


def time_cycles(st: Station, cycles: int = CYCLES, trajectory_ik: str = "exact",
                distance_points: str = "all", batch_ik: bool = True,
                batch_distances: bool = True, batch_indices: bool = True
                ) -> tuple[list[float], list[float], int]:
    """Per-cycle wall and thread-CPU times [ms] of ``cycles`` full TOp cycles, and the
    (robot, point) evaluations per cycle.

    Raises:
        RuntimeError: if a timed cycle is not a full evaluation cycle (a fault).
    """
    cfg = KernelConfig(indices=six_indices(st), ntt_threshold=1e9, trajectory_ik=trajectory_ik,
                       distance_points=distance_points, batch_ik=batch_ik,
                       batch_distances=batch_distances, batch_indices=batch_indices)
    rsel = next(iter(st.arms))
    k = MRCPKernel(st.arms, st.world, st.task_points, rsel, 0, st.start, config=cfg)
    wall, cpu = [], []
    pairs = 0
    for i in range(WARMUP + cycles):
        t = (i + 1) * cfg.dt
        c0, t0 = time.thread_time(), time.perf_counter()
        rec = k.step(t, st.path(t))
        dt, dc = (time.perf_counter() - t0) * 1e3, (time.thread_time() - c0) * 1e3
        if not rec.evaluations:
            raise RuntimeError(f"cycle {i} did not evaluate (state {rec.state.value}, "
                               f"events {rec.events})")
        if i >= WARMUP:
            wall.append(dt)
            cpu.append(dc)
            pairs = len(rec.evaluations)
    return wall, cpu, pairs


def _pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q))


def batch_speedup(n: int = 2 if SMOKE else 8,
                  cycles: int = SPEEDUP_CYCLES) -> tuple[float, float, float]:
    """CPU p50 [ms] of the ``n``-robot default cycle with the trajectory IK batched across
    robots and with one ``arm.ik`` call per point, alternating runs (the same cycles: the
    batch changes no configuration), and their ratio."""
    on: list[float] = []
    off: list[float] = []
    for _ in range(2):
        for batched, out in ((False, off), (True, on)):
            out.extend(time_cycles(rx60b_station(n), cycles, batch_ik=batched)[1])
    c_on, c_off = statistics.median(on), statistics.median(off)
    return c_on, c_off, c_off / c_on


@dataclass
class Comparison:
    """CPU and wall p50 / p99 [ms] of the same cycles with the evaluation's distances and
    Θ batched across robots and one call per robot (per (robot, point) for Θ)."""

    robots: int
    batched_cpu: list[float]
    batched_wall: list[float]
    per_robot_cpu: list[float]
    per_robot_wall: list[float]

    def row(self) -> str:
        b50, b99 = statistics.median(self.batched_cpu), _pct(self.batched_cpu, 99)
        o50, o99 = statistics.median(self.per_robot_cpu), _pct(self.per_robot_cpu, 99)
        bw50, bw99 = statistics.median(self.batched_wall), _pct(self.batched_wall, 99)
        ow50, ow99 = statistics.median(self.per_robot_wall), _pct(self.per_robot_wall, 99)
        return (f"{self.robots:6d} {b50:8.2f} {b99:8.2f} {bw50:8.2f} {bw99:8.2f} "
                f"{o50:8.2f} {o99:8.2f} {ow50:8.2f} {ow99:8.2f} {o50 / b50:7.2f}x "
                f"{o99 / b99:7.2f}x")


def batch_distances_comparison(n: int, cycles: int = SPEEDUP_CYCLES) -> Comparison:
    """The ``n``-RX60B default cycle with the evaluation's distances (and Θ) of all robots
    in one compiled call a cycle (``KernelConfig`` defaults) and with one distance call
    per robot and one Θ call per (robot, point) (``batch_distances=False,
    batch_indices=False``: the cycle before), alternating runs (the same cycles: the
    batch changes no value)."""
    out = Comparison(n, [], [], [], [])
    for _ in range(2):
        for batched in (False, True):
            wall, cpu, _ = time_cycles(rx60b_station(n), cycles, batch_distances=batched,
                                       batch_indices=batched)
            (out.batched_cpu if batched else out.per_robot_cpu).extend(cpu)
            (out.batched_wall if batched else out.per_robot_wall).extend(wall)
    return out


@contextmanager
def _before_issue_17_5() -> Iterator[None]:
    """The pose IK as it was before issue #17 §5: the Python refinement loop (every step by
    ``PybulletArm._python_step``, the arithmetic the compiled loop repeats bit for bit) and
    the numeric search also where the wrist centre is out of reach (the wrist-centre test
    answers "inside"); with ``batch_ik=False`` (see :func:`scenario_cycles`) the same
    configurations as now at the cost of then."""
    from vasim.mrcp import _ik_kernels, closed_form_ik
    from vasim.mrcp.arm import PybulletArm

    compiled = PybulletArm._refine
    outside = closed_form_ik.wrist_centre_outside

    def python(self: Any, q0: Any, target: Any, rot: Any, tol_p: float, tol_r: float,
               iterations: int = 60) -> Any:
        if rot is None:
            return compiled(self, q0, target, rot, tol_p, tol_r, iterations)
        history = np.empty(iterations)
        q = np.clip(np.asarray(q0, dtype=float), self.robot.lower, self.robot.upper)
        for it in range(iterations):
            q, status = self._python_step(q, target, rot, tol_p, tol_r, it, history)
            if status != _ik_kernels.NEEDS_PYTHON:
                return q if status == _ik_kernels.REACHED else None
        return None

    PybulletArm._refine = python  # type: ignore[method-assign]
    closed_form_ik.wrist_centre_outside = lambda *args, **kwargs: -math.inf
    try:
        yield
    finally:
        PybulletArm._refine = compiled  # type: ignore[method-assign]
        closed_form_ik.wrist_centre_outside = outside


def scenario_cycles(name: str = "eight_robots", duration: float = SCENARIO_S,
                    before: bool = False) -> tuple[list[float], list[float], float]:
    """Per-cycle wall and thread-CPU times [ms] of a scenario as ``vasim mrcp run`` (and the
    browser's panel) runs it — kernel, operator, invariant checks — and its period [s];
    ``before``: with the pose IK of before issue #17 §5 (:func:`_before_issue_17_5`, IK not
    batched)."""
    from vasim.mrcp.scenarios import SCENARIOS, ScenarioOptions
    from vasim.mrcp.scenarios.runner import run_setup

    setup = SCENARIOS[name].build(ScenarioOptions(seed=0, duration=duration))
    if before:
        setup.config = replace(setup.config, batch_ik=False)
    wall: list[float] = []
    cpu: list[float] = []
    last = [time.perf_counter(), time.thread_time()]

    def tick(_sample: Any) -> None:
        w, c = time.perf_counter(), time.thread_time()
        wall.append((w - last[0]) * 1e3)
        cpu.append((c - last[1]) * 1e3)
        last[0], last[1] = w, c

    with _before_issue_17_5() if before else nullcontext():
        last[0], last[1] = time.perf_counter(), time.thread_time()
        run_setup(name, setup, duration, tick)
    return wall[WARMUP:], cpu[WARMUP:], float(setup.config.dt)


def browser_realtime(name: str = "eight_robots", seconds: float = BROWSER_S) -> float:
    """Real-time factor (simulated s per wall s) of ``vasim serve --scene mrcp:<name>``'s
    scenario thread over ``seconds`` after its first cycles (the server runs, the view
    thread poses the station at 30 Hz; no browser attached)."""
    from vasim.viewer.mrcp_panel import MrcpViewerApp

    app = MrcpViewerApp(port=0, scenario=name).start()
    try:
        t_end = time.perf_counter() + 60.0
        while app.live.cycles < WARMUP and time.perf_counter() < t_end:
            time.sleep(0.05)
        c0, w0 = app.live.cycles, time.perf_counter()
        time.sleep(seconds)
        c1, w1 = app.live.cycles, time.perf_counter()
        return (c1 - c0) * app.live.dt / (w1 - w0)
    finally:
        app.stop()


def main() -> None:
    print(f"one MRCP cycle (6 indices x 6 task points, default sampling), {CYCLES} cycles; "
          f"budget {BUDGET_MS:.0f} ms; load average {os.getloadavg()[0]:.1f} on "
          f"{os.cpu_count()} cores (wall time includes waiting for a core, the cycle thread's "
          f"CPU time not)")
    print("variants: default = IK at every predicted point, distances at every point; "
          "fast = first-order steps along the prediction, distances at its two ends")
    print(f"{'station':8s} {'variant':7s} {'robots':>6s} {'pairs':>5s} {'wall p50':>9s} "
          f"{'wall p99':>9s} {'cpu p50':>8s} {'cpu p99':>8s} {'wall/cpu':>8s} "
          f"{'cpu99/18':>8s} {'wall99/18':>9s}")
    variants = [("planar", "default"), ("planar", "fast"), ("rx60b", "default"),
                ("rx60b", "fast")]
    for name, variant in variants:
        traj, dist = ("linear", "ends") if variant == "fast" else ("exact", "all")
        factory = STATIONS.get(name)
        if factory is None:
            print(f"{name:8s} not available")
            continue
        for n in ROBOT_COUNTS:
            try:
                st = factory(n)
                wall, cpu, pairs = time_cycles(st, CYCLES, traj, dist)
            except RuntimeError as exc:
                print(f"{name:8s} {variant:7s} {n:6d}  skipped: {exc}")
                continue
            w50, w99 = statistics.median(wall), float(np.percentile(wall, 99))
            c50, c99 = statistics.median(cpu), float(np.percentile(cpu, 99))
            print(f"{name:8s} {variant:7s} {n:6d} {pairs:5d} {w50:9.2f} {w99:9.2f} {c50:8.2f} "
                  f"{c99:8.2f} {w50 / c50:8.2f} {c99 / BUDGET_MS:8.2f} {w99 / BUDGET_MS:9.2f}",
                  flush=True)
    print(f"RX60B default: the evaluation's distances and Θ of all robots in one compiled "
          f"call a cycle (batched) vs one distance call per robot and one Θ call per "
          f"(robot, point) (per robot), alternating runs of {SPEEDUP_CYCLES} cycles, load "
          f"average {os.getloadavg()[0]:.1f}; ms:")
    print(f"{'robots':>6s} {'cpu p50':>8s} {'cpu p99':>8s} {'wall p50':>8s} {'wall p99':>8s} "
          f"{'cpu p50':>8s} {'cpu p99':>8s} {'wall p50':>8s} {'wall p99':>8s} "
          f"{'p50 gain':>8s} {'p99 gain':>8s}")
    print(f"{'':6s} {'batched':>35s} {'per robot':>35s}")
    for n in ROBOT_COUNTS:
        print(batch_distances_comparison(n).row(), flush=True)
    c_on, c_off, ratio = batch_speedup()
    print(f"8 RX60B default, trajectory IK batched across robots (one compiled call a cycle) "
          f"vs one arm.ik call per point: cpu p50 {c_on:.2f} vs {c_off:.2f} ms = {ratio:.2f}x "
          f"(the same cycles)", flush=True)
    print(f"scenario eight_robots (full-pose grasps, 3 indices; the runner's whole cycle), "
          f"{SCENARIO_S:g} s simulated, period 18 ms:")
    cpu50 = {}
    for label, before in (("now", False), ("before #17 §5", True)):
        wall, cpu, dt = scenario_cycles(before=before)
        cpu50[before] = statistics.median(cpu)
        print(f"  {label:13s} wall p50/p99 {statistics.median(wall):6.2f} / {_pct(wall, 99):6.2f}"
              f" ms, cpu p50/p99 {statistics.median(cpu):6.2f} / {_pct(cpu, 99):6.2f} ms; "
              f"real-time factor {dt * 1e3 * len(wall) / sum(wall):.2f} (wall), "
              f"{dt * 1e3 * len(cpu) / sum(cpu):.2f} (cpu)", flush=True)
    print(f"  speed-up of the cycle (cpu p50): {cpu50[True] / cpu50[False]:.2f}x "
          f"(compiled pose IK, no search out of reach, IK batched; the same run)", flush=True)
    print(f"browser panel (vasim serve --scene mrcp:eight_robots, no page attached), "
          f"{BROWSER_S:g} s: real-time factor {browser_realtime():.2f}; load average "
          f"{os.getloadavg()[0]:.1f}", flush=True)


if __name__ == "__main__":
    main()
