"""The mass-spring abdomen physics vs pybullet's deformable world, and the default abdomen.

Printed in one run (same process, so the ratios compare like with like on this noisy host).
Times are CPU time of the stepping thread (``thread_time``): the cost on one core, which the
goals are stated in; on this 2-core host shared with other jobs the wall clock also counts
the waits for a core (section 1 prints it too; pybullet's DIRECT client steps in the calling
thread, so its CPU time is measured the same way):

1. Per-step time at dt = 1 ms, k = 100 N/m on the closed ellipsoids of the massspring guide
   (0.12 x 0.08 x 0.06 m, geodesic icosahedra of 492 / 1,962 / 7,842 nodes; edge springs k,
   bending springs across each edge 0.1 k, 1 kg, 5 anchored nodes at the top, gravity), for
   vasim's ``OrganSolver`` (library defaults) and pybullet's deformable world configured as the
   guide says (``RESET_USE_DEFORMABLE_WORLD``, ``useMassSpring=1``, ``useBendingSprings=1``,
   ``springElasticStiffness=k``, ``springBendingStiffness=0.1k``,
   ``springDampingStiffness=0.05``, ``createSoftBodyAnchor``, the mesh from an OBJ in a temp
   dir; Bullet spreads the mass evenly, so vasim uses ``mass_distribution="uniform"``). Goal:
   vasim >= 5x faster at each size.
2. Stability at k = 1,000 N/m, 1,962 nodes, dt = 4 ms: blow-up (non-finite, or a node 1 m
   from rest) in pybullet vs vasim's largest displacement.
3. The default abdomen (``protocols/scenes/default.toml``, its real-time solver budget) at
   250 Hz on one core: ms per step while breathing, and with a 1 N contact force on the
   liver (the lead's contact goes through the same ``forces`` hook); positions against a
   converged solve of the same scene. Goal: <= 4 ms per step on one core, judged on the
   CPU time of the stepping thread (``thread_time``; the wall clock of this shared 2-core
   host also counts the waits for a core). The tool's contact itself is in ``bench.contact``.
4. The 7,842-node ellipsoid as an organ (interior nodes and spokes: 8,298 nodes) at dt = 16 ms
   under a real-time budget (one Newton step of one CG iteration with the prefactored
   preconditioner that "auto" picks there: the quality of one Liu local/global iteration),
   k = 100 and 1,000 N/m; and the guide's membrane (diagonal, 12 CG iterations): stability,
   displacement and ms per step. Goal: <= 16 ms.
5. Springs processed per second (springs x CG iterations / CPU time) next to the guide's
   machine limits (~0.7 G springs/s from DRAM, ~2.4 G from L2).
6. The two preconditioners on the same problems (the measurement behind
   ``vasim.abdomen.integrate``'s choice).

pybullet is imported here only (never by ``vasim.abdomen``). Run: ``python -m bench abdomen``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from tqdm import tqdm

from vasim.abdomen.integrate import OrganSolver
from vasim.abdomen.model import AnchorRule, OrganModel, OrganParams, build_organ
from vasim.abdomen.scene import ScenePhysics, load_scene

SMOKE = os.environ.get("VASIM_BENCH_SMOKE") == "1"
"""``python -m bench --smoke``: every run cut to seconds (it checks the bench runs; its
figures mean nothing)."""
SIZES = (7, 14) if SMOKE else (7, 14, 28)
BIG = SIZES[-1]  # the "7,842-node" organ of stage 4 (1,962 nodes in the smoke run)

"""Geodesic frequencies: 10 f² + 2 nodes = 492, 1,962, 7,842 (the guide's S, M, L)."""
EXTENTS = (0.12, 0.08, 0.06)
DRAM_SPRINGS_PER_S = 0.7e9
L2_SPRINGS_PER_S = 2.4e9
BLOW_UP_M = 1.0


def log(msg: str) -> None:
    print(f"[bench.abdomen] {msg}", file=sys.stderr, flush=True)


@contextlib.contextmanager
def quiet_stdout() -> Iterator[None]:
    """Silences C-level writes to stdout (pybullet prints its build time and loader notes)."""
    sys.stdout.flush()
    saved = os.dup(1)
    with open(os.devnull, "w") as null:
        os.dup2(null.fileno(), 1)
        try:
            yield
        finally:
            sys.stdout.flush()
            os.dup2(saved, 1)
            os.close(saved)


def ellipsoid(freq: int) -> trimesh.Trimesh:
    """Closed geodesic ellipsoid: icosahedron faces split into freq² triangles, on the sphere,
    scaled to :data:`EXTENTS` (10 freq² + 2 vertices)."""
    ico = trimesh.creation.icosahedron()
    index: dict[tuple[float, ...], int] = {}
    verts: list[np.ndarray] = []
    faces = []

    def vid(p: np.ndarray) -> int:
        q = p / np.linalg.norm(p)
        key = tuple(np.round(q, 9))
        if key not in index:
            index[key] = len(verts)
            verts.append(q)
        return index[key]

    for a, b, c in ico.faces:
        pa, pb, pc = ico.vertices[a], ico.vertices[b], ico.vertices[c]
        grid = {(i, j): vid(pa + (pb - pa) * i / freq + (pc - pa) * j / freq)
                for i in range(freq + 1) for j in range(freq + 1 - i)}
        for i in range(freq):
            for j in range(freq - i):
                faces.append((grid[i, j], grid[i + 1, j], grid[i, j + 1]))
                if i + j < freq - 1:
                    faces.append((grid[i + 1, j], grid[i + 1, j + 1], grid[i, j + 1]))
    v = np.array(verts)
    v = v / np.ptp(v, axis=0) * np.asarray(EXTENTS)
    mesh = trimesh.Trimesh(v, np.array(faces), process=False)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def top_anchors(mesh: trimesh.Trimesh, count: int = 5) -> np.ndarray:
    return np.sort(np.argsort(mesh.vertices[:, 2])[-count:])


def vasim_model(mesh: trimesh.Trimesh, k: float, *, volume: bool = False) -> OrganModel:
    """The guide's spring model of ``mesh``, anchored at the same 5 nodes as pybullet; with
    ``volume``, an organ: interior nodes and spokes of stiffness k / 2 as well."""
    n = len(mesh.vertices)
    # 0.5 m above the origin (the top of the scene bounds, far above the 6 cm ellipsoid):
    # its nearest nodes are the top ones; replaced below by exactly the 5 pybullet anchors
    rule = AnchorRule(to="point", point=(0.0, 0.0, 0.5), fraction=5 / n)
    params = OrganParams(stiffness=k, bending_stiffness=0.1 * k, mass=1.0, damping=0.0,
                         volume=volume, volume_stiffness=0.5 * k,
                         mass_distribution="uniform", anchors=(rule,))
    model = build_organ(mesh, params, name=f"ellipsoid_{n}")
    return dataclasses.replace(model, anchors=top_anchors(mesh))


def median_ms(times: list[float]) -> float:
    return statistics.median(times) * 1e3


# -- vasim -------------------------------------------------------------------------------


def run_vasim(model: OrganModel, dt: float, steps: int, **options: object) -> dict:
    """Steps from rest under gravity; per-step times, iterations and the largest excursion."""
    solver = OrganSolver(model, dt, **options)
    state = solver.initial_state()
    target = model.rest[model.anchors]
    solver.step(solver.initial_state(), target)  # compile / warm up
    times, cpu, iters, resets, worst, passes = [], [], [], 0, 0.0, 0
    for _ in range(steps):
        c0 = time.thread_time()
        t0 = time.perf_counter()
        report = solver.step(state, target)
        times.append(time.perf_counter() - t0)
        cpu.append(time.thread_time() - c0)
        iters.append(report.iterations)
        passes += solver.last_spring_passes
        resets += report.reset
        worst = max(worst, float(np.abs(state.x - model.rest).max()))
    return {"ms": median_ms(cpu), "wall": median_ms(times), "iters": float(np.mean(iters)),
            "resets": resets, "max_disp": worst, "finite": bool(np.all(np.isfinite(state.x))),
            "springs": len(model.springs), "total_s": sum(cpu), "cg": int(np.sum(iters)),
            "passes": passes, "preconditioner": solver.preconditioner, "nodes": model.n_nodes}


# -- pybullet ------------------------------------------------------------------------------


def soft_body(p: Any, cid: int, path: Path, k: float, dt: float, *,
              face_contact: bool = False, **extra: Any) -> int:
    """A deformable world with gravity and ``dt``, and the mesh at ``path`` as a mass-spring
    soft body: the guide's configuration (bending 0.1 k, spring damping 0.05, 1 kg)."""
    p.resetSimulation(p.RESET_USE_DEFORMABLE_WORLD, physicsClientId=cid)
    p.setGravity(0.0, 0.0, -9.81, physicsClientId=cid)
    p.setTimeStep(dt, physicsClientId=cid)
    return p.loadSoftBody(
        str(path), basePosition=[0, 0, 0], mass=1.0, useMassSpring=1,
        useBendingSprings=1, springElasticStiffness=k,
        springBendingStiffness=0.1 * k, springDampingStiffness=0.05,
        useSelfCollision=0, useFaceContact=int(face_contact), physicsClientId=cid, **extra)


def run_pybullet(mesh: trimesh.Trimesh, k: float, dt: float, steps: int) -> dict:
    """pybullet's deformable world mass-spring, configured as in the massspring guide."""
    with quiet_stdout():
        import pybullet as p

        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "ellipsoid.obj"
            mesh.export(path)
            cid = p.connect(p.DIRECT)
            try:
                body = soft_body(p, cid, path, k, dt)
                n, verts = p.getMeshData(body, -1, flags=p.MESH_DATA_SIMULATION_MESH,
                                         physicsClientId=cid)
                x0 = np.asarray(verts)
                if n != len(mesh.vertices) or np.abs(x0 - mesh.vertices).max() > 1e-5:
                    raise RuntimeError("pybullet reordered the mesh nodes")
                for i in top_anchors(mesh):
                    p.createSoftBodyAnchor(body, int(i), -1, -1, physicsClientId=cid)
                times, cpu, blew_up, worst = [], [], None, 0.0
                for s in range(steps):
                    c0 = time.thread_time()
                    t0 = time.perf_counter()
                    p.stepSimulation(physicsClientId=cid)
                    times.append(time.perf_counter() - t0)
                    cpu.append(time.thread_time() - c0)
                    if s % 10 == 9 or s == steps - 1:
                        _, verts = p.getMeshData(body, -1, flags=p.MESH_DATA_SIMULATION_MESH,
                                                 physicsClientId=cid)
                        x = np.asarray(verts)
                        disp = float(np.abs(x - x0).max()) if np.all(np.isfinite(x)) else math.inf
                        worst = max(worst, disp)
                        if disp > BLOW_UP_M:
                            blew_up = s + 1
                            break
            finally:
                p.disconnect(cid)
    return {"ms": median_ms(cpu), "wall": median_ms(times), "blew_up": blew_up,
            "max_disp": worst, "steps": len(times)}


# -- the default abdomen ---------------------------------------------------------------------


def run_abdomen(steps: int = 400, ref_steps: int = 250) -> dict:
    scene = load_scene("default")
    models = scene.build()
    nodes = sum(m.n_nodes for m in models if m.kind != "wall")
    springs = sum(len(m.springs) for m in models)

    free_c: list[float] = []
    push_c: list[float] = []

    def simulate(n: int, **options: object) -> tuple[list[float], list[float], dict, int]:
        physics = ScenePhysics(scene, models, **options)
        liver = physics.models["liver"]
        top = np.argsort(liver.rest[: liver.n_surface, 2])[-20:]
        push = np.zeros((liver.n_nodes, 3))
        push[top, 2] = -1.0 / len(top)  # 1 N on the liver's top, like a tool pressing
        physics.step()  # warm up
        free_t, push_t, cg, passes = [], [], 0, 0
        for i in range(n):
            pushing = i >= n // 2
            c0 = time.thread_time()
            t0 = time.perf_counter()
            reports = physics.step({"liver": push} if pushing else None)
            t1 = time.perf_counter()
            (push_t if pushing else free_t).append(t1 - t0)
            (push_c if pushing else free_c).append(time.thread_time() - c0)
            cg += sum(r.iterations * len(physics.models[k].springs) for k, r in reports.items())
            passes += sum(s.last_spring_passes * len(physics.models[k].springs)
                          for k, s in physics.solvers.items() if reports[k].iterations)
        return free_t, push_t, physics.snapshot(), (cg, passes)

    log(f"default abdomen: {nodes} nodes, {springs} springs, {steps} steps")
    free_t, push_t, _, (spring_cg, spring_passes) = simulate(steps)
    free_cpu, push_cpu = list(free_c), list(push_c)
    log(f"default abdomen: converged reference, {ref_steps} steps")
    _, _, ref_fast, _ = simulate(ref_steps)
    _, _, ref, _ = simulate(ref_steps, tol=1e-4, cg_tol=1e-4, max_newton=10,
                            max_iterations=1000)
    dev = max(float(np.abs(ref_fast[n] - ref[n]).max()) for n in ref)
    return {"nodes": nodes, "springs": springs, "free_ms": median_ms(free_t),
            "free_p95": float(np.percentile(free_t, 95)) * 1e3, "push_ms": median_ms(push_t),
            "push_p95": float(np.percentile(push_t, 95)) * 1e3, "dev_mm": dev * 1e3,
            "free_cpu": median_ms(free_cpu), "push_cpu": median_ms(push_cpu),
            "cg_per_step": spring_cg / steps, "total_s": sum(free_cpu) + sum(push_cpu),
            "spring_cg": spring_cg, "spring_passes": spring_passes, "scene": scene}


# -- report ----------------------------------------------------------------------------------


def main() -> None:
    stages: list[tuple[str, Callable[[], object]]] = []
    meshes = {f: ellipsoid(f) for f in SIZES}
    results: dict[str, object] = {}
    vasim_steps = {7: 3, 14: 2} if SMOKE else {7: 400, 14: 200, 28: 50}
    bullet_steps = {7: 3, 14: 2} if SMOKE else {7: 300, 14: 100, 28: 25}
    stab_steps, big_steps, pre_steps = (3, 2, 2) if SMOKE else (250, 60, 100)  # stages 2, 4, 6
    for f in SIZES:
        n = len(meshes[f].vertices)
        stages.append((f"vasim {n} nodes, k=100, dt=1 ms", lambda f=f: results.__setitem__(
            f"v{f}", run_vasim(vasim_model(meshes[f], 100.0), 1e-3, vasim_steps[f]))))
        stages.append((f"pybullet {n} nodes, k=100, dt=1 ms", lambda f=f: results.__setitem__(
            f"b{f}", run_pybullet(meshes[f], 100.0, 1e-3, bullet_steps[f]))))
    stages.append(("stability: vasim 1962 nodes, k=1000, dt=4 ms", lambda: results.__setitem__(
        "vstab", run_vasim(vasim_model(meshes[14], 1000.0), 4e-3, stab_steps))))
    stages.append(("stability: pybullet 1962 nodes, k=1000, dt=4 ms",
                   lambda: results.__setitem__("bstab", run_pybullet(meshes[14], 1000.0, 4e-3,
                                                                     stab_steps))))
    stages.append(("default abdomen", lambda: results.__setitem__(
        "abd", run_abdomen(5, 5) if SMOKE else run_abdomen())))
    budget = {"max_newton": 1, "max_iterations": 1, "cg_tol": 0.1}
    stages.append(("7842-node organ at dt=16 ms", lambda: results.__setitem__(
        "big", run_vasim(vasim_model(meshes[BIG], 100.0, volume=True), 16e-3, big_steps,
                         **budget))))
    stages.append(("7842-node organ at dt=16 ms, k=1000", lambda: results.__setitem__(
        "big1000", run_vasim(vasim_model(meshes[BIG], 1000.0, volume=True), 16e-3, big_steps,
                             **budget))))
    stages.append(("7842-node membrane at dt=16 ms", lambda: results.__setitem__(
        "bigm", run_vasim(vasim_model(meshes[BIG], 100.0), 16e-3, big_steps,
                          **{**budget, "max_iterations": 12, "cg_tol": 0.05}))))
    for pre in ("diagonal", "factor"):
        stages.append((f"preconditioner {pre}: 1962 nodes k=100 1 ms", lambda pre=pre:
                       results.__setitem__(f"p{pre}1", run_vasim(
                           vasim_model(meshes[14], 100.0), 1e-3, pre_steps, preconditioner=pre))))
        stages.append((f"preconditioner {pre}: 1962 nodes k=1000 4 ms", lambda pre=pre:
                       results.__setitem__(f"p{pre}4", run_vasim(
                           vasim_model(meshes[14], 1000.0), 4e-3, pre_steps, preconditioner=pre))))
    t_start = time.perf_counter()
    bar = tqdm(stages, desc="bench.abdomen", file=sys.stderr, disable=not sys.stderr.isatty())
    for label, run in bar:
        log(label)
        run()
    log(f"done in {time.perf_counter() - t_start:.0f} s")
    report(results, meshes)


def report(r: dict, meshes: dict) -> None:
    print("(every ms below is the median CPU time of the stepping thread per step; the wall "
          "clock of this shared host also counts the waits for a core)")
    print("1. per step at dt = 1 ms, k = 100 N/m (median; vasim library defaults)")
    print(f"   {'nodes':>6} {'springs':>8} {'vasim ms':>9} {'CG it':>6} {'precond':>9} "
          f"{'pybullet ms':>12} {'speed-up':>9}  goal >= 5x   wall ms: vasim, pybullet")
    for f in SIZES:
        v, b = r[f"v{f}"], r[f"b{f}"]
        ratio = b["ms"] / v["ms"]
        print(f"   {len(meshes[f].vertices):>6} {v['springs']:>8} {v['ms']:>9.3f} "
              f"{v['iters']:>6.1f} {v['preconditioner']:>9} {b['ms']:>12.3f} {ratio:>8.1f}x  "
              f"{'ok' if ratio >= 5 else 'MISSED':<6}       {v['wall']:.3f}, {b['wall']:.3f}")
    vs, bs = r["vstab"], r["bstab"]
    print("2. stability, 1962 nodes, k = 1000 N/m, dt = 4 ms, 250 steps (1 s)")
    bl = (f"blew up at step {bs['blew_up']} (a node > {BLOW_UP_M:g} m from rest)"
          if bs["blew_up"] else f"bounded, max displacement {bs['max_disp'] * 1e3:.1f} mm")
    print(f"   pybullet: {bl}; {bs['ms']:.2f} ms/step")
    print(f"   vasim:    {'finite' if vs['finite'] else 'NON-FINITE'}, {vs['resets']} resets, "
          f"max displacement {vs['max_disp'] * 1e3:.1f} mm; {vs['ms']:.2f} ms/step, "
          f"{vs['iters']:.1f} CG it/step ({vs['preconditioner']})")
    a = r["abd"]
    phys = a["scene"].physics
    print(f"3. default abdomen: {a['nodes']} nodes (+ kinematic wall), {a['springs']} springs, "
          f"dt = {phys.dt * 1e3:g} ms; budget: {phys.max_newton} Newton step, <= "
          f"{phys.max_iterations} CG it per organ, cg_tol {phys.cg_tol:g}")
    for label, med, p95, cpu in (
            ("breathing", a["free_ms"], a["free_p95"], a["free_cpu"]),
            ("breathing + 1 N on the liver", a["push_ms"], a["push_p95"], a["push_cpu"])):
        print(f"   {label:<30} {med:6.2f} ms/step (p95 {p95:5.2f}), CPU {cpu:5.2f} ms = "
              f"{1e3 / cpu:5.0f} Hz  goal <= 4 ms on one core: "
              f"{'ok' if cpu <= 4.0 else 'MISSED'}")
    print(f"   {a['cg_per_step'] / a['springs']:.1f} CG it/step (spring-weighted organ mean); "
          f"after 250 steps the positions are within {a['dev_mm']:.2f} mm of a converged solve")
    print("4. dt = 16 ms, real-time budget (1 Newton step, 1 CG it), 60 steps (0.96 s) "
          "from rest under gravity")
    for key, label in (("big", "organ, k = 100 N/m"), ("big1000", "organ, k = 1000 N/m"),
                       ("bigm", "membrane, k = 100 N/m")):
        b = r[key]
        print(f"   {b['nodes']} nodes, {label:<20} {b['preconditioner']:>8} {b['ms']:6.2f} ms/step "
              f"({b['iters']:4.1f} CG it), {'finite' if b['finite'] else 'NON-FINITE'}, "
              f"{b['resets']} resets, max displacement {b['max_disp'] * 1e3:5.1f} mm  "
              f"goal <= 16 ms: {'ok' if b['ms'] <= 16.0 else 'MISSED'}")
    print("   (the membrane has no volume term: it collapses under gravity, as the guide notes; "
          "its budget is 12 CG it)")
    print("5. springs processed per second vs the guide's limits (~0.7 G/s DRAM, ~2.4 G/s L2)")
    print(f"   {'':<24} {'springs x CG it / s':>20} {'all spring passes / s':>22}")
    rows = [(f"{len(meshes[f].vertices)} nodes, 1 ms", r[f"v{f}"]) for f in SIZES]
    rows.append(("7842-node organ, 16 ms", r["big"]))
    for label, x in rows:
        cg = x["springs"] * x["cg"] / x["total_s"]
        allp = x["springs"] * x["passes"] / x["total_s"]
        print(f"   {label:<24} {cg / 1e9:14.3f} G/s {allp / 1e9:16.3f} G/s "
              f"({allp / DRAM_SPRINGS_PER_S:4.2f} x DRAM, {allp / L2_SPRINGS_PER_S:4.2f} x L2)")
    cg = a["spring_cg"] / a["total_s"]
    allp = a["spring_passes"] / a["total_s"]
    print(f"   {'default abdomen':<24} {cg / 1e9:14.3f} G/s {allp / 1e9:16.3f} G/s "
          f"({allp / DRAM_SPRINGS_PER_S:4.2f} x DRAM, {allp / L2_SPRINGS_PER_S:4.2f} x L2)")
    print("6. preconditioners, 1962 nodes (ms/step, CG it/step)")
    for key, label in (("1", "k = 100, dt = 1 ms"), ("4", "k = 1000, dt = 4 ms")):
        d, f = r[f"pdiagonal{key}"], r[f"pfactor{key}"]
        print(f"   {label:<20} diagonal {d['ms']:7.2f} ms ({d['iters']:5.1f} it)   factor "
              f"{f['ms']:7.2f} ms ({f['iters']:5.1f} it)   factor/diagonal "
              f"{f['ms'] / d['ms']:4.1f}x")


if __name__ == "__main__":
    main()
