"""The seed's RPQ test bed (appendix A, Table A.1): two RX60B facing each other at 400-800 mm,
9,216 joint configurations per distance, collision or not.

Prints per distance: the collision share beside the seed's Table A.1, and the time per robot
pair query of (a) :class:`vasim.mrcp.rpq.RPQ` (box -> OBB -> hull, weight matrix, collision
matrix), (b) brute force (every link pair queried in pybullet, the seed's baseline) and
(c) pybullet's own whole-body query (one ``getClosestPoints`` call, its internal broad
phase), with the speed-ups. Every configuration's answer is checked identical across the
three (the run stops if not).

The 9,216 configurations are :func:`vasim.mrcp.rpq.seed_test_bed_pairs`: 96 per robot (a
4 x 4 x 6 grid over θ1, θ2, θ3, the wrist at home), every pair of them (the decision is
written there).

Then why the shares still differ from the seed's: the share at each distance for two
samplings (the grid; a scrambled Halton sample over both robots' twelve joints, the
previous test bed) and three link bulks (the shipped hulls, and every link's radius grown
by 30 and 60 mm: the seed's test bed used 23,012-triangle CAD models of the real housings,
this model approximates them by hulls of spheres).

First, the per-call costs of the robot world the kernel leans on (FK, Jacobian, IK tracking,
distance and collision queries), median over random in-limit configurations.

Usage: ``python -m bench.mrcp_rpq [--quick]`` (``--quick``: every 16th configuration, 576
per distance).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np
import pybullet as pb
from scipy.stats import qmc

from vasim.mrcp.dh import RobotModel, load_robot
from vasim.mrcp.rpq import (
    RPQ,
    SEED_TABLE_A1,
    collision_share,
    facing_pair,
    inflated,
    seed_test_bed_pairs,
)

N_CONFIGURATIONS = 9216
SMOKE = os.environ.get("VASIM_BENCH_SMOKE") == "1"
"""``python -m bench --smoke``: every run cut to seconds (it checks the bench runs; its
figures mean nothing)."""


def log(msg: str) -> None:
    print(f"[bench.mrcp_rpq] {msg}", file=sys.stderr, flush=True)


def halton_pairs(robot: RobotModel, n: int = N_CONFIGURATIONS) -> np.ndarray:
    """``(n, 2, joints)``: the previous test bed, a scrambled Halton sample (seed 0) over
    both robots' joints within their imposed limits."""
    k = robot.n_joints
    u = qmc.Halton(d=2 * k, scramble=True, seed=0).random(n)
    lo, up = np.tile(robot.lower, 2), np.tile(robot.upper, 2)
    return (lo + u * (up - lo)).reshape(n, 2, k)


def why_shares_differ(robot: RobotModel, step: int) -> None:
    """Prints the collision shares per distance for two samplings x three link bulks."""
    print("why the shares differ from the seed's (collision %, 400/500/600/700/800 mm):")
    print(f"  {'seed Table A.1':<44} " + " ".join(f"{v:6.2f}" for v in SEED_TABLE_A1.values()))
    for label, pairs in (("96 x 96 grid (the test bed)", seed_test_bed_pairs(robot)),
                         ("Halton over 12 joints", halton_pairs(robot))):
        for extra in (0.0, 0.03, 0.06):
            model = inflated(robot, extra)
            shares = [collision_share(model, mm / 1000.0, pairs[::step])
                      for mm in SEED_TABLE_A1]
            name = f"{label}, links +{extra * 1000:.0f} mm"
            print(f"  {name:<44} " + " ".join(f"{v:6.2f}" for v in shares), flush=True)


def run_distance(robot: RobotModel, distance: float, pairs: np.ndarray) -> dict:
    world = facing_pair(robot, distance)
    rpq = RPQ(world)                     # boxes and reaches prepared here, outside the timing
    ba, bb, cid = world.body_id("a"), world.body_id("b"), world.client_id
    t_rpq = t_bf = t_pb = 0.0
    hits = 0
    for qa, qb in pairs:
        world.set_configuration("a", qa)
        world.set_configuration("b", qb)
        t0 = time.perf_counter()
        r = rpq.collide("a", "b")
        t1 = time.perf_counter()
        bf = rpq.brute_force("a", "b")
        t2 = time.perf_counter()
        whole = any(p[8] <= 0.0 for p in pb.getClosestPoints(ba, bb, 0.0, physicsClientId=cid))
        t3 = time.perf_counter()
        if not r == bf == whole:
            raise SystemExit(f"RPQ {r}, brute force {bf}, pybullet {whole} differ at "
                             f"{distance} m, qa={qa.tolist()}, qb={qb.tolist()}")
        hits += int(r)
        t_rpq += t1 - t0
        t_bf += t2 - t1
        t_pb += t3 - t2
    n = len(pairs)
    st = rpq.stats
    world.close()
    return {"n": n, "hits": hits, "rpq_us": t_rpq / n * 1e6, "bf_us": t_bf / n * 1e6,
            "pb_us": t_pb / n * 1e6, "by_box": st.by_box / n,
            "skipped": st.pairs_skipped / max(1, st.pairs_skipped + st.pairs_in_matrix),
            "hull_per_query": st.hull_tests / n}


def _median_us(fn, n: int) -> float:
    fn(0)
    times = []
    for i in range(n):
        t0 = time.perf_counter()
        fn(i)
        times.append(time.perf_counter() - t0)
    return float(np.median(times)) * 1e6


def world_costs(robot: RobotModel, n: int) -> None:
    """Prints the median cost of each world query the kernel uses [µs per call]."""
    from vasim.mrcp.backend import PybulletArm
    from vasim.mrcp.dh import fk

    arm = PybulletArm(robot)
    qs = np.random.default_rng(0).uniform(robot.lower, robot.upper, size=(n + 1, 6))
    step = np.clip(qs + 0.005, robot.lower, robot.upper)       # a small task increment
    poses = [fk(robot, q) for q in step]
    world = facing_pair(robot, 0.6)
    world.add_sphere("ball", 0.05, [0.0, 0.3, 0.2])

    def pose_both(i: int) -> None:
        world.set_configuration("a", qs[i])
        world.set_configuration("b", qs[-1 - i])

    rows = [
        ("tcp_pose (compiled DH)", lambda i: arm.tcp_pose(qs[i])),
        ("jacobian (compiled DH)", lambda i: arm.jacobian(qs[i])),
        ("tcp_pose_batch, per sample (1000)", None),
        ("ik, tracking a 5 mrad step", lambda i: arm.ik(*poses[i], q_seed=qs[i])),
        ("set_configuration x2 + min_distance", lambda i: (pose_both(i),
                                                           world.min_distance("a", "b"))),
        ("set_configuration x2 + in_collision", lambda i: (pose_both(i),
                                                           world.in_collision("a"))),
    ]
    print("robot world, median cost per call:")
    for name, fn in rows:
        if fn is None:
            big = np.random.default_rng(1).uniform(robot.lower, robot.upper, (1000, 6))
            us = _median_us(lambda _i, b=big: arm.tcp_pose_batch(b), 5) / 1000
        else:
            us = _median_us(fn, n)
        print(f"  {name:<40} {us:8.1f} us")
    world.close()
    arm.close()


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m bench.mrcp_rpq", description=__doc__)
    parser.add_argument("--quick", action="store_true", help="every 16th pair only")
    args = parser.parse_args([] if argv is None else argv)
    robot = load_robot("rx60b")
    pairs = seed_test_bed_pairs(robot)
    if args.quick:
        pairs = pairs[::16]
    if SMOKE:
        pairs = pairs[::1024]
    warm = facing_pair(robot, 0.6)      # compile / load the kernels outside the timing
    RPQ(warm).collide("a", "b")
    warm.close()
    world_costs(robot, 5 if SMOKE else 50 if args.quick else 200)
    log(f"{len(pairs)} configurations per distance")
    quick = ", every 16th (--quick)" if args.quick else ""
    print(f"two RX60B facing each other, {len(pairs)} joint configurations per distance "
          f"(96 per robot: a 4 x 4 x 6 grid over θ1-θ3, every pair{quick})")
    print(f"{'distance':>8} {'collisions':>10} {'%':>7} {'seed %':>7} | {'RPQ us':>7} "
          f"{'brute us':>8} {'x brute':>7} | {'pybullet us':>11} {'x pybullet':>10} | "
          f"{'L4 %':>5} {'matrix skip %':>13} {'hulls/query':>11}")
    tot = {"rpq": 0.0, "bf": 0.0, "pb": 0.0}
    for mm in SEED_TABLE_A1:
        r = run_distance(robot, mm / 1000.0, pairs)
        tot["rpq"] += r["rpq_us"]
        tot["bf"] += r["bf_us"]
        tot["pb"] += r["pb_us"]
        print(f"{mm:>6}mm {r['hits']:>10} {100 * r['hits'] / r['n']:>7.2f} "
              f"{SEED_TABLE_A1[mm]:>7.2f} | {r['rpq_us']:>7.1f} {r['bf_us']:>8.1f} "
              f"{r['bf_us'] / r['rpq_us']:>7.1f} | {r['pb_us']:>11.1f} "
              f"{r['pb_us'] / r['rpq_us']:>10.2f} | {100 * r['by_box']:>5.1f} "
              f"{100 * r['skipped']:>13.1f} {r['hull_per_query']:>11.2f}", flush=True)
    print(f"answers identical (RPQ = brute force = pybullet whole-body) on every "
          f"configuration; overall speed-up over brute force x{tot['bf'] / tot['rpq']:.1f}, "
          f"over pybullet's whole-body query x{tot['pb'] / tot['rpq']:.2f}")
    why_shares_differ(robot, 1024 if SMOKE else 16 if args.quick else 1)


if __name__ == "__main__":
    main(sys.argv[1:])
