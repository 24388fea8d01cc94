"""The control cycle on planar multi-robot scenarios: transfers happen for the right reason,
and the invariants hold every cycle — the task is never left ungrasped, RSel never collides,
no joint limit is exceeded."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from tests.mrcp.planar import PlanarArm, PlanarWorld, Sphere
from vasim.mrcp.indices import EvalContext
from vasim.mrcp.kernel import (
    CycleRecord,
    IndexSpec,
    KernelConfig,
    KernelParts,
    MRCPKernel,
    TaskPoint,
)
from vasim.mrcp.modes import KernelState

# A cross-shaped object with four grasp points; candidates wait 5 cm further out.
BAR = [TaskPoint(p, approach=p.copy()) for p in
       (np.array([-0.05, 0.0, 0.0]), np.array([0.05, 0.0, 0.0]),
        np.array([0.0, 0.05, 0.0]), np.array([0.0, -0.05, 0.0]))]


def two_robots(obstacles: dict[str, Sphere] | None = None
               ) -> tuple[dict[str, PlanarArm], PlanarWorld, np.ndarray]:
    a = PlanarArm("A", base=np.array([0.0, 0.0, 0.0]), radius=0.015)
    b = PlanarArm("B", base=np.array([0.8, 0.0, 0.0]), yaw=np.pi, radius=0.015)
    obj0 = np.array([0.3, 0.15, 0.0])
    qa = a.ik(obj0 + BAR[0].position, None, np.array([0.5, 1.0, 0.0]))
    qb = b.ik(np.array([0.6, -0.3, 0.0]), None, np.array([0.0, 1.0, 0.0]))
    return {"A": a, "B": b}, PlanarWorld({"A": a, "B": b}, {"A": qa, "B": qb}, obstacles), obj0


def run(kernel: MRCPKernel, world: PlanarWorld, arms: dict[str, PlanarArm],
        path: Callable[[float], np.ndarray], cycles: int) -> list[CycleRecord]:
    """Run the loop with an ideal controller, asserting the invariants every cycle."""
    out = []
    for i in range(cycles):
        t = (i + 1) * kernel.config.dt
        rec = kernel.step(t, path(t))
        out.append(rec)
        assert rec.holders, f"task ungrasped at t={t}"
        assert rec.rsel in rec.holders
        assert not world.in_collision(rec.rsel), f"RSel {rec.rsel} collides at t={t}"
        for name, arm in arms.items():
            q = world.configuration(name)
            assert np.all(q >= arm.joint_lower - 1e-12) and np.all(q <= arm.joint_upper + 1e-12)
            np.testing.assert_array_equal(rec.commands[name], q)
        # The holder really holds its point: its TCP is at the achieved task point.
        held, _ = kernel.point_pose(rec.cutp, rec.task_position, np.eye(3))
        tcp, _ = arms[rec.rsel].tcp_pose(world.configuration(rec.rsel))
        np.testing.assert_allclose(tcp, held, atol=1e-9)
    return out


def events(records: list[CycleRecord], prefix: str) -> list[tuple[float, str]]:
    return [(r.t, e) for r in records for e in r.events if e.startswith(prefix)]


def test_transfer_before_the_workspace_boundary() -> None:
    """A carries the bar away from its base toward B: the dexterity/joint indices fall as
    A's links align, and the task is handed to B before A would have to stop."""
    arms, world, obj0 = two_robots()
    cfg = KernelConfig(indices=(IndexSpec("rj"), IndexSpec("theta", {"rows": (0, 1, 2)})))
    k = MRCPKernel(arms, world, BAR, "A", 0, obj0, config=cfg)
    recs = run(k, world, arms, lambda t: obj0 + np.array([0.08 * t, 0.0, 0.0]), 330)
    starts = events(recs, "transfer_start")
    done = events(recs, "transfer_done")
    assert len(starts) >= 1 and done and done[0][1].startswith("transfer_done A -> B")
    assert "cause=theta" in starts[0][1] or "cause=rj" in starts[0][1]
    # A never had to refuse the operator (no hold before the hand-over).
    assert not [e for t, e in events(recs, "rsel_hold") if t < done[0][0]]
    # A's reach at the hand-over is still inside its workspace (l1 + l2 = 0.55 m).
    at_done = next(r for r in recs if r.t == done[0][0])
    a_point, _ = k.point_pose(0, at_done.task_position, np.eye(3))
    assert np.linalg.norm(a_point - arms["A"].base) < 0.55 - 0.005
    assert recs[-1].rsel == "B"
    # TT cycles hold the task still.
    tt = [r for r in recs if r.state.mode == "TT"]
    assert tt and all(np.allclose(r.task_position, tt[0].task_position) for r in tt)


def test_collision_risk_drives_a_transfer() -> None:
    arms, world, obj0 = two_robots()
    k = MRCPKernel(arms, world, BAR, "A", 0, obj0)              # rj, theta, cr
    recs = run(k, world, arms, lambda t: obj0 + np.array([0.1 * t, 0.0, 0.0]), 200)
    assert events(recs, "transfer_done A -> B")


def test_a_new_index_plugs_in_without_touching_the_kernel() -> None:
    class Forbidden:
        """A task-oriented index: robot A may not continue (value 0)."""

        name = "forbidden"

        def evaluate(self, ctx: EvalContext) -> float:
            return 0.0 if ctx.robot == "A" else 1.0

    arms, world, obj0 = two_robots()
    k = MRCPKernel(arms, world, BAR, "A", 0, obj0, parts=KernelParts(indices=[Forbidden()]))
    recs = run(k, world, arms, lambda t: obj0, 120)
    first = events(recs, "transfer_start")[0][1]
    assert "B@" in first and "cause=forbidden" in first
    assert recs[-1].rsel == "B"
    assert recs[0].evaluations[("A", 0)].texec_min == 0.0


def test_rsel_collision_is_a_safety_stop() -> None:
    """An obstacle on the task's path with no collision index: RSel is never commanded into
    it; the kernel stops in FAULT and moves nothing until reset."""
    ball = {"ball": Sphere(np.array([0.3, 0.3, 0.0]), 0.03)}
    arms, world, obj0 = two_robots(ball)
    cfg = KernelConfig(indices=(IndexSpec("rj"),))
    k = MRCPKernel(arms, world, BAR, "A", 0, obj0, config=cfg)
    recs = run(k, world, arms, lambda t: obj0 + np.array([0.0, 0.15 * t, 0.0]), 120)
    faults = events(recs, "rsel_collision")
    assert len(faults) == 1
    i = next(j for j, r in enumerate(recs) if r.state is KernelState.FAULT)
    frozen = recs[i].commands
    for r in recs[i:]:
        assert r.state is KernelState.FAULT
        for name in arms:
            np.testing.assert_array_equal(r.commands[name], frozen[name])
    k.reset_fault()
    assert k.state is KernelState.TOP


def test_three_robots_wandering_task_keeps_the_invariants() -> None:
    a = PlanarArm("A", base=np.array([0.0, 0.0, 0.0]), radius=0.015)
    b = PlanarArm("B", base=np.array([0.75, 0.0, 0.0]), yaw=np.pi, radius=0.015)
    c = PlanarArm("C", base=np.array([0.375, 0.6, 0.0]), yaw=-np.pi / 2, radius=0.015)
    arms = {"A": a, "B": b, "C": c}
    obj0 = np.array([0.3, 0.2, 0.0])
    configs = {"A": a.ik(obj0 + BAR[0].position, None, np.array([0.5, 1.0, 0.0])),
               "B": b.ik(np.array([0.55, -0.3, 0.0]), None, np.array([0.0, 1.0, 0.0])),
               "C": c.ik(np.array([0.2, 0.45, 0.0]), None, np.array([0.0, 1.0, 0.0]))}
    world = PlanarWorld(arms, configs, {"post": Sphere(np.array([0.37, -0.25, 0.0]), 0.04)})
    k = MRCPKernel(arms, world, BAR, "A", 0, obj0)

    def path(t: float) -> np.ndarray:
        return obj0 + np.array([0.15 * np.sin(0.6 * t), 0.08 * np.sin(1.1 * t), 0.0])

    recs = run(k, world, arms, path, 500)
    assert len({r.rsel for r in recs}) >= 2                      # the task changed hands


def test_bad_configuration_is_named() -> None:
    arms, world, obj0 = two_robots()
    with pytest.raises(ValueError, match=r"KernelConfig\.dt"):
        KernelConfig(dt=0.0)
    with pytest.raises(ValueError, match="unknown index 'nope'"):
        KernelConfig(indices=(IndexSpec("nope"),))
    with pytest.raises(ValueError, match="rsel 'Z'"):
        MRCPKernel(arms, world, BAR, "Z", 0, obj0)
    with pytest.raises(ValueError, match="cutp 9"):
        MRCPKernel(arms, world, BAR, "A", 9, obj0)


def test_an_aborted_transfer_cools_down() -> None:
    """RCnt too slow to arrive: the transfer is aborted at the timeout, RSel keeps the task,
    and the same (robot, point) is not chosen again before the cooldown."""

    class Forbidden:
        name = "forbidden"

        def evaluate(self, ctx: EvalContext) -> float:
            return 0.0 if ctx.robot == "A" else 1.0

    arms, world, obj0 = two_robots()
    arms["B"].vmax = np.full(3, 1e-3)                      # B can hardly move
    cfg = KernelConfig(tt_timeout=0.3, abort_cooldown=1.0)
    k = MRCPKernel(arms, world, BAR, "A", 0, obj0, config=cfg,
                   parts=KernelParts(indices=[Forbidden()]))
    recs = run(k, world, arms, lambda t: obj0, 150)
    aborts = events(recs, "transfer_abort")
    assert aborts and all(r.rsel == "A" for r in recs)
    t_abort, text = aborts[0]
    target = text.split()[1]                              # e.g. "B@3"
    again = [t for t, e in events(recs, "transfer_start") if f" {target} " in f" {e} "
             and t > t_abort]
    assert not again or again[0] >= t_abort + 1.0 - 1e-9
    assert len(events(recs, "transfer_start")) >= 2       # other points were tried meanwhile


class _Blind:
    """An index that sees nothing coming (1 for everyone): only the hold can hand over."""

    name = "blind"

    def evaluate(self, ctx: EvalContext) -> float:
        return 1.0


@pytest.mark.parametrize("hold_s", [0.2, float("inf")])
def test_a_held_rsel_hands_the_task_over(hold_s: float) -> None:
    """Issue #26 §4: A carries the bar to the edge of its reach (0.55 m) while no index
    warns; the task is held (``rsel_hold``: the joint speed at the stretched elbow). After
    ``hold_transfer_s`` of holding, A has no time left and B takes the task over (cause
    ``hold``); with the rule off A holds it to the end."""
    arms, world, obj0 = two_robots()
    cfg = KernelConfig(hold_transfer_s=hold_s)
    k = MRCPKernel(arms, world, BAR, "A", 0, obj0, config=cfg,
                   parts=KernelParts(indices=[_Blind()]))
    recs = run(k, world, arms, lambda t: obj0 + np.array([0.1 * t, 0.0, 0.0]), 300)
    holds = events(recs, "rsel_hold A")
    assert holds
    starts = events(recs, "transfer_start")
    if math.isinf(hold_s):
        assert not starts and recs[-1].rsel == "A"
        return
    assert starts and "cause=hold" in starts[0][1]
    assert holds[0][0] + hold_s - 1e-9 <= starts[0][0] <= holds[0][0] + hold_s + 0.05
    done = events(recs, "transfer_done A -> B")
    assert done and recs[-1].rsel == "B"
    # A is not handed the pose it could not follow straight back (abort_cooldown).
    assert not [e for t, e in events(recs, "transfer_start A@0")
                if t < done[0][0] + cfg.abort_cooldown]


def test_hold_transfer_s_is_validated() -> None:
    with pytest.raises(ValueError, match="hold_transfer_s"):
        KernelConfig(hold_transfer_s=-1.0)
