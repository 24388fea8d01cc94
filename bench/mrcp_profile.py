"""Where the 8-robot MRCP cycle's CPU time goes, by part (issue #17 §4: "profile first").

``python -m bench mrcp_profile`` runs the cycle ``bench/mrcp.py`` times (``n`` RX60B x 6
indices x 6 task points, default variant) with the kernel's and the world's entry points
wrapped by timers, and prints each part's *exclusive* CPU time per cycle (the cycle
thread's ``time.thread_time``; time inside a nested part is that part's, not its caller's),
the calls per cycle, and the share of the cycle; what no part claims is the kernel's own
Python (prediction bookkeeping, contexts, texec series, selection): "glue".

Parts (what is wrapped):

* IK: the batched first attempts (``solve_first_attempts``, one compiled call a cycle) and
  every ``arm.ik`` call (trajectory points the batch missed, the transfer paths of ttransf*,
  RSel's follow step, the planner's steps);
* FK: ``arm.tcp_pose`` and the world's link frames (``dh.frames_many`` / ``frames_one``);
* Jacobians: ``arm.jacobian`` / ``jacobian_batch`` (first-order steps; Θ's Jacobians are
  inside its own compiled call and count as Θ);
* indices, each: its ``evaluate`` / ``evaluate_many`` (Θ: its compiled call, FK and
  Jacobians of its samples included);
* distances: the evaluation's batched queries (``prefetch_distances``), the compiled model
  (``swept_distances``, ``swept_pair_bounds``), pybullet's ``getClosestPoints``, the
  world's ``min_distance`` / ``min_distances`` / ``in_collision`` wrappers;
* planner: ``move_candidate`` (the candidates' guided moves) apart from what it calls;
* texec / ttransf*: ``MRCPKernel._to_time`` apart from the IK and FK it calls;
* pybullet poses: ``PybulletWorld.set_configuration``.

The wrappers cost about 1 µs a call (two ``thread_time`` reads); the header prints the
cycle's CPU time with and without them (the same cycles: the run is deterministic).
``VASIM_BENCH_MRCP_N`` sets the profiled cycles (default 150), ``VASIM_BENCH_MRCP_ROBOTS``
the robot count (default 8).
"""

from __future__ import annotations

import os
import statistics
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from bench.mrcp import CYCLES, WARMUP, rx60b_station, six_indices, time_cycles
from vasim.mrcp.kernel import KernelConfig, MRCPKernel

ROBOTS = int(os.environ.get("VASIM_BENCH_MRCP_ROBOTS",
                            "2" if os.environ.get("VASIM_BENCH_SMOKE") == "1" else "8"))


@dataclass
class PartClock:
    """Exclusive CPU time per part: a stack of the parts entered; the time since the last
    mark is charged to the part on top ("glue" when none)."""

    clock: Callable[[], float] = time.thread_time
    seconds: dict[str, float] = field(default_factory=dict)
    calls: dict[str, int] = field(default_factory=dict)
    stack: list[str] = field(default_factory=list)
    mark: float = 0.0

    def _charge(self) -> None:
        now = self.clock()
        top = self.stack[-1] if self.stack else "glue"
        self.seconds[top] = self.seconds.get(top, 0.0) + (now - self.mark)
        self.mark = now

    def enter(self, part: str) -> None:
        self._charge()
        self.stack.append(part)
        self.calls[part] = self.calls.get(part, 0) + 1

    def leave(self) -> None:
        self._charge()
        self.stack.pop()

    def start(self) -> None:
        self.mark = self.clock()

    def stop(self) -> None:
        self._charge()

    def reset(self) -> None:
        self.seconds.clear()
        self.calls.clear()
        self.mark = self.clock()


def _wrap(clock: PartClock, part: str, fn: Callable[..., Any]) -> Callable[..., Any]:
    def timed(*args: Any, **kwargs: Any) -> Any:
        clock.enter(part)
        try:
            return fn(*args, **kwargs)
        finally:
            clock.leave()

    return timed


def _targets() -> list[tuple[str, Any, str]]:
    """(part, owner, attribute) of every wrapped entry point."""
    import pybullet

    from vasim.mrcp import dh, kernel, planner, world
    from vasim.mrcp.arm import PybulletArm
    from vasim.mrcp.indices import INDICES

    out: list[tuple[str, Any, str]] = [
        ("IK: batched first attempts", kernel, "solve_first_attempts"),
        ("IK: arm.ik", PybulletArm, "ik"),
        ("FK", PybulletArm, "tcp_pose"),
        ("FK", dh, "frames_many"),
        ("FK", dh, "frames_one"),
        ("Jacobians", PybulletArm, "jacobian"),
        ("Jacobians", PybulletArm, "jacobian_batch"),
        ("distances: evaluation prefetch (Python)", kernel, "prefetch_distances"),
        ("distances: min_distances (Python)", world.PybulletWorld, "min_distances"),
        ("distances: min_distance (Python)", world.PybulletWorld, "min_distance"),
        ("distances: collision checks (Python)", world.PybulletWorld, "in_collision"),
        ("distances: compiled, per robot", world, "swept_distances"),
        ("distances: compiled, link-pair bounds", world, "swept_pair_bounds"),
        ("distances: pybullet getClosestPoints", pybullet, "getClosestPoints"),
        ("planner (Python)", kernel, "move_candidate"),
        ("texec / ttransf* (Python)", kernel.MRCPKernel, "_to_time"),
        ("pybullet poses", world.PybulletWorld, "set_configuration"),
    ]
    for name in ("rj", "theta", "cr", "cone", "visibility", "force_torque"):
        cls = type(INDICES.create(name))
        out.append((f"index {name}", cls, "evaluate"))
        if "evaluate_many" in cls.__dict__:
            out.append((f"index {name}", cls, "evaluate_many"))
    if hasattr(kernel, "prefetch_distances_all"):
        out.append(("distances: evaluation prefetch (Python)", kernel,
                    "prefetch_distances_all"))
        out.append(("distances: min_distances_many (Python)", world.PybulletWorld,
                    "min_distances_many"))
    if hasattr(world, "swept_distances_many"):
        out.append(("distances: compiled, all robots", world, "swept_distances_many"))
    if hasattr(world, "swept_pair_bounds_bodies"):
        out.append(("distances: compiled, link-pair bounds", world,
                    "swept_pair_bounds_bodies"))
    if hasattr(world, "swept_nearest_many"):
        out.append(("distances: compiled, all robots", world, "swept_nearest_many"))
        out.append(("distances: nearest_distances_many (Python)", world.PybulletWorld,
                    "nearest_distances_many"))
    del planner
    return out


@contextmanager
def instrumented(clock: PartClock) -> Iterator[None]:
    """Every entry point of :func:`_targets` wrapped by ``clock`` (restored on exit)."""
    saved = []
    for part, owner, attr in _targets():
        fn = owner.__dict__[attr] if isinstance(owner, type) else getattr(owner, attr)
        saved.append((owner, attr, fn))
        setattr(owner, attr, _wrap(clock, part, fn))
    try:
        yield
    finally:
        for owner, attr, fn in reversed(saved):
            setattr(owner, attr, fn)


def profile_cycles(n: int = ROBOTS, cycles: int = CYCLES, **config: Any
                   ) -> tuple[dict[str, float], dict[str, float], float]:
    """Exclusive CPU ms per cycle and calls per cycle of each part over ``cycles`` cycles
    of the ``n``-robot default cycle, and the instrumented cycle's CPU p50 [ms]."""
    st = rx60b_station(n)
    cfg = KernelConfig(indices=six_indices(st), ntt_threshold=1e9, **config)
    k = MRCPKernel(st.arms, st.world, st.task_points, next(iter(st.arms)), 0, st.start,
                   config=cfg)
    clock = PartClock()
    per_cycle: list[float] = []
    with instrumented(clock):
        for i in range(WARMUP + cycles):
            if i == WARMUP:
                clock.reset()
            t = (i + 1) * cfg.dt
            c0 = time.thread_time()
            clock.start()
            k.step(t, st.path(t))
            clock.stop()
            if i >= WARMUP:
                per_cycle.append((time.thread_time() - c0) * 1e3)
    ms = {p: s * 1e3 / cycles for p, s in clock.seconds.items()}
    calls = {p: c / cycles for p, c in clock.calls.items()}
    return ms, calls, statistics.median(per_cycle)


def print_profile(ms: dict[str, float], calls: dict[str, float], label: str) -> None:
    total = sum(ms.values())
    print(f"{label}: {total:.2f} ms CPU a cycle (mean, exclusive parts)")
    print(f"  {'part':42s} {'ms/cycle':>8s} {'share':>6s} {'calls/cycle':>11s}")
    for part, v in sorted(ms.items(), key=lambda kv: -kv[1]):
        print(f"  {part:42s} {v:8.2f} {100 * v / total:5.1f}% {calls.get(part, 0.0):11.1f}")


def main() -> None:
    print(f"the {ROBOTS}-RX60B cycle by part (default variant, 6 indices x 6 task points), "
          f"{CYCLES} cycles; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    plain = statistics.median(time_cycles(rx60b_station(ROBOTS), CYCLES)[1])
    ms, calls, wrapped = profile_cycles()
    print(f"cycle CPU p50 {plain:.2f} ms unwrapped, {wrapped:.2f} ms wrapped (the wrappers' "
          f"cost: {wrapped - plain:+.2f} ms)")
    print_profile(ms, calls, "batched (KernelConfig defaults)")
    ms0, calls0, _ = profile_cycles(batch_distances=False, batch_indices=False)
    print_profile(ms0, calls0, "per robot (batch_distances=False, batch_indices=False)")


if __name__ == "__main__":
    main()
