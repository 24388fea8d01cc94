"""Tool–tissue contact: the default abdomen with the tool pressing, the 1 kHz contact patch,
and pybullet's deformable world with a rigid probe pressing the same organ.

Prints, from one run. Every time is given twice: wall clock (``perf_counter``) and the CPU
time of the stepping thread (``thread_time``). On this 2-core host shared with other jobs the
wall clock also counts the time the thread waited for a core; the CPU time is the cost "on
one core" the goals are stated in. Medians unless said otherwise.

1. The default abdomen (``vasim.abdomen.world.Abdomen``) with every organ integrated
   (``always_awake``) and the tool pressing 5 mm into the liver: ms per physics step
   (contact detection + reaction forces + every organ's implicit step), against the issue's
   goal of <= 4 ms (>= 250 Hz) on one core; the same world with the tool withdrawn (every
   organ still integrated), so the cost of contact shows; and the world as a headless trial
   runs it (organs asleep until touched).
2. The contact pieces on their own: ``detect_contacts`` at the physics rate, and
   ``patch_force`` / ``patch_force_into`` -- the force and its derivative the 1 kHz loop
   evaluates between physics updates -- against the goal of <= 100 µs.
3. With contact, vasim vs pybullet on the guide's ellipsoids of 492 / 1,962 / 7,842 nodes
   (k = 100 N/m, bending 0.1 k, 1 kg, 5 anchors, gravity, dt = 1 ms): the same probe on
   both sides, a 2.5 mm sphere rising from 2 mm below the rest surface to 5 mm into it over
   the first half of the run, then held (pybullet: a kinematic rigid sphere in the
   deformable world with a 1 mm collision margin; vasim: a tool of one sphere,
   ``ToolShape(max_spheres=1)``). Per step, ms over the steps in contact (pybullet: contact
   points after the step; vasim: contacts found) and the ratio, goal >= 5x. Also vasim's
   step without the probe and its whole-shaft tool (43 spheres along 10 cm), and pybullet
   with its default collision margin at 1,962 nodes (which finds far more contacts).
"""

from __future__ import annotations

import math
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from bench.abdomen import ellipsoid, quiet_stdout, soft_body, top_anchors, vasim_model
from vasim.abdomen.contact import (
    ToolPose,
    ToolShape,
    detect_contacts,
    patch_force,
    patch_force_into,
)
from vasim.abdomen.integrate import OrganSolver
from vasim.abdomen.world import Abdomen

SMOKE = os.environ.get("VASIM_BENCH_SMOKE") == "1"
"""``python -m bench --smoke``: every run cut to seconds (it checks the bench runs; its
figures mean nothing)."""
SIZES = (7,) if SMOKE else (7, 14, 28)
WORLD_STEPS = 5 if SMOKE else 200
"""Geodesic frequencies of the guide's ellipsoids: 492, 1,962, 7,842 nodes."""
PROBE_R = 0.0025
APPROACH = 0.002
"""The probe starts this far below the rest surface [m] ..."""
DEPTH = 0.005
"""... and rises to this depth into it [m] over the first half of the run."""


def log(msg: str) -> None:
    print(f"[bench.contact] {msg}", file=sys.stderr, flush=True)


def _med(times: list[float]) -> float:
    return statistics.median(times) * 1e3 if times else math.nan


def _p95(times: list[float]) -> float:
    return float(np.percentile(times, 95)) * 1e3 if times else math.nan


def _timed(fn: Callable[[], object]) -> tuple[object, float, float]:
    """(result, wall s, thread CPU s) of one call."""
    c0 = time.thread_time()
    t0 = time.perf_counter()
    out = fn()
    t1 = time.perf_counter()
    c1 = time.thread_time()
    return out, t1 - t0, c1 - c0


def liver_press(world: Abdomen, depth: float = 0.005) -> ToolPose:
    liver = world.latest.organ("liver").surface
    top = liver[np.argmax(liver[:, 2])]
    return ToolPose(top + np.array([0.0, -0.04, 0.12]), top - np.array([0.0, 0.0, depth]))


# -- 1. the default abdomen ----------------------------------------------------------------


def run_world(always_awake: bool, steps: int, *, withdrawn: bool = False) -> dict:
    world = Abdomen("default", always_awake=always_awake)
    pose = liver_press(world)
    for _ in range(5):
        world.step(pose)  # warm up (numba, first contact)
    tool = None if withdrawn else pose
    wall, cpu, in_contact = [], [], 0
    snap = world.latest
    for _ in range(steps):
        snap, w, c = _timed(lambda: world.step(tool))
        wall.append(w)
        cpu.append(c)
        in_contact += snap.in_contact
    return {"ms": _med(wall), "p95": _p95(wall), "cpu": _med(cpu), "cpu_p95": _p95(cpu),
            "contact_steps": in_contact, "steps": steps,
            "force": float(np.linalg.norm(snap.force)), "awake": sum(world.awake().values()),
            "nodes": world.n_nodes}


# -- 2. the contact pieces -----------------------------------------------------------------


def run_patch(n: int = 4000) -> dict:
    world = Abdomen("default", always_awake=True)
    pose = liver_press(world)
    snap = world.latest
    for _ in range(50):
        snap = world.step(pose)
    body = next(b for b in world._bodies if b.model.name == "liver")
    m = body.model
    det, det_cpu = [], []
    for _ in range(300):
        _, w, c = _timed(lambda: detect_contacts(body.state.x, m.faces, m.mass, pose,
                                                 world.tool, dt=world.dt,
                                                 max_edge=body.max_edge))
        det.append(w)
        det_cpu.append(c)
    patch = snap.patch
    rng = np.random.default_rng(0)
    tips = [pose.tip + d for d in rng.normal(0.0, 2e-4, (n, 3))]
    poses = [ToolPose(pose.fulcrum, t) for t in tips]
    for p in poses[:10]:
        patch_force(patch, p)  # warm up
    pt, pt_cpu = [], []
    for p in poses:
        _, w, c = _timed(lambda p=p: patch_force(patch, p))
        pt.append(w)
        pt_cpu.append(c)
    f, k = np.empty(3), np.empty((3, 3))
    ful = np.asarray(pose.fulcrum, dtype=np.float64)
    pi, pi_cpu = [], []
    for t in tips:
        _, w, c = _timed(lambda t=t: patch_force_into(patch, ful, t, f, k))
        pi.append(w)
        pi_cpu.append(c)
    us = 1e3
    return {"detect_us": _med(det) * us, "detect_cpu_us": _med(det_cpu) * us,
            "patch_us": _med(pt) * us, "patch_p99_us": float(np.percentile(pt, 99)) * 1e6,
            "patch_cpu_us": _med(pt_cpu) * us, "into_us": _med(pi) * us,
            "into_p99_us": float(np.percentile(pi, 99)) * 1e6, "into_cpu_us": _med(pi_cpu) * us,
            "planes": patch.size}


# -- 3. vasim vs pybullet with contact -----------------------------------------------------


def probe_height(s: int, steps: int) -> float:
    """Height of the probe's centre above its start [m] at step ``s``."""
    return min(1.0, s / (0.5 * steps)) * (APPROACH + DEPTH)


def run_vasim_probe(freq: int, steps: int, *, shaft: bool = False, probe: bool = True) -> dict:
    """The ellipsoid stepped with the probe (or without: ``probe=False``); per-step times
    (detection + reaction forces + implicit step), split into the steps in contact."""
    model = vasim_model(ellipsoid(freq), 100.0)
    solver = OrganSolver(model, 1e-3)
    state = solver.initial_state()
    targets = model.rest[model.anchors]
    bottom = model.rest[np.argmin(model.rest[:, 2])]
    start = bottom - np.array([0.0, 0.0, PROBE_R + APPROACH])
    shape = ToolShape(radius=PROBE_R) if shaft else ToolShape(radius=PROBE_R, max_spheres=1)
    solver.step(solver.initial_state(), targets)  # warm up (numba)
    detect_contacts(model.rest, model.faces, model.mass,
                    ToolPose(start - [0, 0, 0.1], start), shape, dt=solver.dt)
    wall: list[float] = []
    cpu: list[float] = []
    touch: list[bool] = []
    cg_contact, cg_free, det, force, worst = [], [], [], 0.0, 0
    for s in range(steps):
        tip = start + np.array([0.0, 0.0, probe_height(s, steps)])
        pose = ToolPose(tip - np.array([0.0, 0.0, 0.1]), tip)

        def one(pose: ToolPose = pose) -> tuple[int, int, float, float]:
            d0 = time.thread_time()
            c = (detect_contacts(state.x, model.faces, model.mass, pose, shape, dt=solver.dt)
                 if probe else None)
            d1 = time.thread_time()
            f = c.external_forces(model.n_nodes) if c is not None and c.in_contact else None
            report = solver.step(state, targets, f)
            return (c.n_contacts if c is not None else 0, report.iterations,
                    float(np.linalg.norm(c.force)) if c is not None else 0.0, d1 - d0)

        (n_c, iters, f_norm, d_cpu), w, c = _timed(one)
        wall.append(w)
        cpu.append(c)
        touch.append(n_c > 0)
        det.append(d_cpu)
        (cg_contact if n_c else cg_free).append(iters)
        force = f_norm if n_c else force
        worst = max(worst, n_c)
    on = [i for i, t in enumerate(touch) if t]
    return {"ms": _med([wall[i] for i in on]), "cpu": _med([cpu[i] for i in on]),
            "all_ms": _med(wall), "all_cpu": _med(cpu), "contact_steps": len(on),
            "steps": steps, "detect_us": _med(det) * 1e3, "force": force,
            "cg_contact": float(np.mean(cg_contact)) if cg_contact else math.nan,
            "cg_free": float(np.mean(cg_free)) if cg_free else math.nan,
            "max_contacts": worst, "finite": bool(np.all(np.isfinite(state.x))),
            "nodes": model.n_nodes}


def run_pybullet_probe(freq: int, steps: int, margin: float | None = None) -> dict:
    mesh = ellipsoid(freq)
    with quiet_stdout():
        import pybullet as p

        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "ellipsoid.obj"
            mesh.export(path)
            cid = p.connect(p.DIRECT)
            try:
                extra = {} if margin is None else {"collisionMargin": margin}
                body = soft_body(p, cid, path, 100.0, 1e-3, face_contact=True, **extra)
                for i in top_anchors(mesh):
                    p.createSoftBodyAnchor(body, int(i), -1, -1, physicsClientId=cid)
                bottom = mesh.vertices[np.argmin(mesh.vertices[:, 2])]
                sphere = p.createCollisionShape(p.GEOM_SPHERE, radius=PROBE_R,
                                                physicsClientId=cid)
                start = bottom - np.array([0.0, 0.0, PROBE_R + APPROACH])
                probe = p.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=sphere,
                                          basePosition=start.tolist(), physicsClientId=cid)
                x0 = np.asarray(p.getMeshData(body, -1, flags=p.MESH_DATA_SIMULATION_MESH,
                                              physicsClientId=cid)[1])
                wall, cpu, touch, blew_up, most = [], [], [], None, 0
                for s in range(steps):
                    at = (start + np.array([0.0, 0.0, probe_height(s, steps)])).tolist()
                    p.resetBasePositionAndOrientation(probe, at, [0, 0, 0, 1],
                                                      physicsClientId=cid)
                    _, w, c = _timed(lambda: p.stepSimulation(physicsClientId=cid))
                    wall.append(w)
                    cpu.append(c)
                    n_c = len(p.getContactPoints(bodyA=probe, physicsClientId=cid))
                    touch.append(n_c > 0)
                    most = max(most, n_c)
                    if s % 10 == 9:
                        x = np.asarray(p.getMeshData(body, -1,
                                                     flags=p.MESH_DATA_SIMULATION_MESH,
                                                     physicsClientId=cid)[1])
                        if not np.all(np.isfinite(x)) or np.abs(x - x0).max() > 0.5:
                            blew_up = s + 1
                            break
            finally:
                p.disconnect(cid)
    on = [i for i, t in enumerate(touch) if t]
    return {"ms": _med([wall[i] for i in on]), "cpu": _med([cpu[i] for i in on]),
            "all_ms": _med(wall), "all_cpu": _med(cpu), "contact_steps": len(on),
            "steps": len(wall), "blew_up": blew_up, "max_contacts": most}


# -- report --------------------------------------------------------------------------------


def main() -> None:
    t0 = time.perf_counter()
    log("default abdomen, every organ integrated, tool pressing the liver")
    full = run_world(True, WORLD_STEPS)
    log("default abdomen, every organ integrated, tool withdrawn")
    free = run_world(True, WORLD_STEPS, withdrawn=True)
    log("default abdomen as a headless trial runs it (organs asleep until touched)")
    sleepy = run_world(False, WORLD_STEPS)
    log("contact detection and the 1 kHz patch force")
    patch = run_patch(200) if SMOKE else run_patch()
    probes: dict[int, tuple[dict, dict, dict, dict]] = {}
    steps = {7: 20} if SMOKE else {7: 200, 14: 160, 28: 60}
    for f in SIZES:
        log(f"ellipsoid {10 * f * f + 2} nodes: vasim (sphere probe, shaft, no probe)")
        vs = run_vasim_probe(f, steps[f])
        vshaft = run_vasim_probe(f, steps[f], shaft=True)
        vfree = run_vasim_probe(f, steps[f], probe=False)
        log(f"ellipsoid {10 * f * f + 2} nodes: pybullet, 1 mm collision margin")
        bm = run_pybullet_probe(f, steps[f], margin=0.001)
        probes[f] = (vs, vshaft, vfree, bm)
    log("1962-node ellipsoid: pybullet, default collision margin")
    mid = SIZES[-1] if SMOKE else 14  # the 1,962-node ellipsoid (492 in the smoke run)
    bdef = run_pybullet_probe(mid, 20 if SMOKE else 120)
    log(f"done in {time.perf_counter() - t0:.0f} s")

    print(f"1. default abdomen ({full['nodes']} nodes incl. the kinematic wall), dt = 4 ms; "
          "ms/step wall (p95) | CPU of the stepping thread (p95)")
    rows = (("every organ integrated, tool 5 mm into the liver", full),
            ("every organ integrated, tool withdrawn", free),
            ("sleeping until touched, tool in the liver", sleepy))
    for label, r in rows:
        print(f"   {label:<50} {r['ms']:5.2f} ({r['p95']:5.2f}) | {r['cpu']:5.2f} "
              f"({r['cpu_p95']:5.2f})")
    print(f"   goal <= 4 ms on one core with contact: CPU {full['cpu']:.2f} ms = "
          f"{1e3 / full['cpu']:.0f} Hz -> {'ok' if full['cpu'] <= 4.0 else 'MISSED'} "
          f"(wall {'ok' if full['ms'] <= 4.0 else 'MISSED'}); contact costs "
          f"{full['cpu'] / free['cpu']:.2f}x the withdrawn step; contact force "
          f"{full['force']:.2f} N, {full['contact_steps']}/{full['steps']} steps in contact; "
          f"asleep: {sleepy['awake']} organ(s) awake")
    print("2. contact pieces (µs/call, wall | CPU)")
    print(f"   detect_contacts (liver, physics rate)        {patch['detect_us']:7.1f} | "
          f"{patch['detect_cpu_us']:6.1f}")
    print(f"   patch_force ({patch['planes']} planes, 1 kHz)                 "
          f"{patch['patch_us']:7.1f} | {patch['patch_cpu_us']:6.1f}   "
          f"(p99 {patch['patch_p99_us']:.1f}; goal <= 100 µs)")
    print(f"   patch_force_into (no allocation)             {patch['into_us']:7.1f} | "
          f"{patch['into_cpu_us']:6.1f}   (p99 {patch['into_p99_us']:.1f})")
    print("3. with contact: ellipsoid, k = 100 N/m, dt = 1 ms, 2.5 mm sphere probe 5 mm in; "
          "ms/step over the steps in contact, wall | CPU")
    print(f"   {'nodes':>6} {'vasim':>15} {'pybullet 1 mm':>15} {'speed-up':>8}  goal >= 5x"
          f"   | vasim: no probe, shaft tool, detect µs, CG it/step free -> contact")
    for f in SIZES:
        vs, vshaft, vfree, bm = probes[f]
        ratio = bm["cpu"] / vs["cpu"]
        print(f"   {vs['nodes']:>6} {vs['ms']:6.2f} | {vs['cpu']:6.2f} {bm['ms']:6.2f} | "
              f"{bm['cpu']:6.2f} {ratio:7.1f}x  {'ok' if ratio >= 5 else 'MISSED':<6}"
              f"   | {vfree['all_cpu']:6.2f} {vshaft['cpu']:6.2f} {vs['detect_us']:6.1f}  "
              f"{vfree['cg_free']:4.1f} -> {vs['cg_contact']:4.1f}")
        print(f"   {'':>6} steps in contact: vasim {vs['contact_steps']}/{vs['steps']} "
              f"(force {vs['force']:.2f} N), pybullet {bm['contact_steps']}/{bm['steps']} "
              f"(up to {bm['max_contacts']} points"
              f"{', blew up at ' + str(bm['blew_up']) if bm['blew_up'] else ''}); "
              f"shaft: {vshaft['contact_steps']} steps, up to {vshaft['max_contacts']} spheres")
    print(f"   1962 nodes, pybullet default margin: {bdef['ms']:.2f} | {bdef['cpu']:.2f} "
          f"ms/step in contact ({bdef['contact_steps']}/{bdef['steps']} steps, up to "
          f"{bdef['max_contacts']} points): vasim "
          f"{bdef['cpu'] / probes[mid][0]['cpu']:.0f}x faster")


if __name__ == "__main__":
    main()
