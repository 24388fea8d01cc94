"""The cycle's trajectory IK batched across robots (issue #17 §4): the compiled first
attempts give exactly the configurations ``arm.ik`` gives, point by point and seed by seed,
and a kernel with the batch makes exactly the cycles of one without it."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vasim.mrcp import dh
from vasim.mrcp.backend import PybulletArm, pose_matrix
from vasim.mrcp.batch_ik import TrajectoryRequest, solve_first_attempts
from vasim.mrcp.kernel import KernelConfig, MRCPKernel

RX = dh.load_robot("rx60b")


def _arms() -> list[PybulletArm]:
    return [PybulletArm(RX, pose_matrix([0.4 * i, 0.0, 0.0], dh.rot_z(0.7 * i)), name=f"a{i}")
            for i in range(3)]


def _sequential(arm: PybulletArm, req: TrajectoryRequest) -> np.ndarray:
    """What the kernel did before the batch: ``arm.ik`` at each point, seeded along."""
    out = np.full((req.positions.shape[0], 6), np.nan)
    s = req.seed
    for k in range(req.positions.shape[0]):
        sol = req.first if (k == 0 and req.first is not None) else \
            arm.ik(req.positions[k], req.rotations[k], s)
        if sol is None:
            if k == 0:
                break
            continue
        out[k], s = sol, sol
    return out


@pytest.mark.parametrize("full_pose", [True, False])
def test_batched_first_attempts_equal_arm_ik_bit_for_bit(full_pose: bool) -> None:
    arms = _arms()
    rng = np.random.default_rng(3)
    reqs, hard = [], 0
    for i in range(30):
        arm = arms[i % 3]
        q = rng.uniform(RX.lower, RX.upper)
        p0, r0 = arm.tcp_pose(q)
        # small steps (tracking) and, every third pair, jumps the first attempt misses
        step = 0.3 if i % 3 == 0 else 0.01
        pos = p0 + step * np.cumsum(rng.normal(size=(4, 3)), axis=0) * [[0], [1], [1], [1]]
        rots = [Rotation.from_rotvec(rng.normal(size=3) * step).as_matrix() @ r0
                for _ in range(4)] if full_pose else [None] * 4
        first = q if i % 5 == 0 else None
        reqs.append(TrajectoryRequest(arm, q + rng.normal(0, 0.02, 6), first, pos, rots))
    results = solve_first_attempts(reqs)
    for req, res in zip(reqs, results, strict=True):
        assert res is not None
        configs, solved = res
        seq = _sequential(req.arm, req)          # type: ignore[arg-type]  # PybulletArm
        prefix = int(np.argmin(solved)) if not solved.all() else len(solved)
        assert solved[:prefix].all() and not solved[prefix:].any()     # a prefix is solved
        assert np.array_equal(configs[:prefix], seq[:prefix])          # bit for bit
        hard += prefix < len(solved)
    assert hard > 0          # some attempts failed and were left to arm.ik


def test_kernel_cycles_are_the_same_with_and_without_the_batch() -> None:
    root = Path(__file__).resolve().parents[2]
    if str(root) not in sys.path:
        sys.path.insert(0, str(root))
    from bench.mrcp import rx60b_station, six_indices

    records = []
    for batched in (True, False):
        st = rx60b_station(4)
        cfg = KernelConfig(indices=six_indices(st), ntt_threshold=1e9, batch_ik=batched)
        k = MRCPKernel(st.arms, st.world, st.task_points, next(iter(st.arms)), 0, st.start,
                       config=cfg)
        recs = [k.step((i + 1) * cfg.dt, st.path((i + 1) * cfg.dt)) for i in range(12)]
        records.append(recs)
    evaluated = 0
    for a, b in zip(*records, strict=True):
        assert a.events == b.events
        assert all(np.array_equal(a.commands[r], b.commands[r]) for r in a.commands)
        assert a.evaluations.keys() == b.evaluations.keys()
        for key, ev in a.evaluations.items():
            assert ev.values == b.evaluations[key].values
            assert ev.tus == b.evaluations[key].tus or (np.isnan(ev.tus)
                                                        and np.isnan(b.evaluations[key].tus))
            evaluated += 1
    assert evaluated == 12 * 16


def test_an_arm_that_overrides_ik_is_not_batched() -> None:
    class Shifted(PybulletArm):          # a different ik: its first attempt is not known
        def ik(self, position, rotation=None, q_seed=None, **kw):  # type: ignore[no-untyped-def, override]
            return None

    arm = Shifted(RX)
    p, r = arm.tcp_pose(RX.home)
    assert arm.first_attempt() is None and PybulletArm(RX).first_attempt() is not None
    req = TrajectoryRequest(arm, RX.home, None, np.array([p]), [r])
    assert solve_first_attempts([req]) == [None]
