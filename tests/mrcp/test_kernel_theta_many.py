"""Θ of every (robot, point) context of a cycle in one compiled call (issue #17 §4,
``evaluate_many``) gives each context's ``evaluate`` value bit for bit, whatever the mix of
arms, horizons, unreachable points and arms without a DH chain."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vasim.mrcp import dh
from vasim.mrcp.backend import PybulletArm, PybulletWorld, pose_matrix
from vasim.mrcp.indices.base import EvalContext
from vasim.mrcp.indices.dexterity import AnisotropicDexterityIndex
from vasim.mrcp.kernel import KernelConfig, MRCPKernel

RX = dh.load_robot("rx60b")


@pytest.fixture(scope="module")
def station() -> Iterator[tuple[list[PybulletArm], PybulletWorld]]:
    arms = [PybulletArm(RX, pose_matrix([0.5 * i, -0.2, 0.05], dh.rot_z(0.7 * i)),
                        name=f"a{i}") for i in range(3)]
    world = PybulletWorld()
    for a in arms:
        world.add_robot(a.name, RX, a.base)
    yield arms, world
    for a in arms:
        a.close()
    world.close()


class _NoChain:
    """An arm without ``dh_chain``: Θ takes its general path (outside the batch)."""

    def __init__(self, arm: PybulletArm) -> None:
        self._arm = arm

    def __getattr__(self, name: str) -> object:
        if name == "dh_chain":
            raise AttributeError(name)
        return getattr(self._arm, name)


def _context(arm: object, world: PybulletWorld, rng: np.random.Generator,
             points: int) -> EvalContext:
    q0 = rng.uniform(RX.lower, RX.upper)
    configs = q0 + np.cumsum(rng.normal(0.0, 0.05, size=(points, 6)), axis=0)
    configs[0] = q0
    reach = rng.uniform(size=points) > 0.25
    reach[0] = rng.uniform() > 0.15            # sometimes the point itself is unreachable
    pos = np.array([arm.tcp_pose(q)[0] for q in configs])  # type: ignore[attr-defined]
    std = np.abs(rng.normal(0.0, 0.01, size=(points, 3))) * (np.arange(points) > 0)[:, None]
    return EvalContext(robot=arm.name, arm=arm, point=0, selected=False,  # type: ignore[arg-type, attr-defined]
                       times=0.05 * np.arange(points), positions=pos, std=std, rotations=None,
                       configs=np.where(reach[:, None], configs, np.nan), reachable=reach,
                       joint_velocity=np.zeros_like(configs), past_configs=[], world=world)


@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**31 - 1), count=st.integers(1, 14),
       threshold_rows=st.sampled_from([(0, 1, 2, 3, 4, 5), (0, 1, 2), (3, 4, 5)]),
       threshold=st.sampled_from([0.01, 0.1]))
def test_theta_of_many_contexts_in_one_call_equals_each_evaluate(
        station: tuple[list[PybulletArm], PybulletWorld], seed: int, count: int,
        threshold_rows: tuple, threshold: float) -> None:
    arms, world = station
    rng = np.random.default_rng(seed)
    contexts = []
    for i in range(count):
        arm: object = arms[i % 3] if i % 5 != 4 else _NoChain(arms[i % 3])
        contexts.append(_context(arm, world, rng, int(rng.choice([1, 3, 4]))))
    ix = AnisotropicDexterityIndex(threshold_rows=threshold_rows, sigma_min_threshold=threshold,
                                   seed=seed % 89)
    one = [ix.evaluate(c) for c in contexts]
    many = ix.evaluate_many(contexts)
    assert many == one                          # bit for bit, in the contexts' order
    assert all(isinstance(v, float) for v in many)


def test_kernel_cycles_are_the_same_with_batched_or_per_context_indices() -> None:
    """A kernel with Θ in one call a cycle makes exactly the cycles of one calling
    ``evaluate`` per (robot, point) (3 RX60B, 4 task points, RJ + Θ)."""
    from vasim.mrcp.kernel import TaskPoint

    records = []
    for batched in (True, False):
        arms = {f"r{i}": PybulletArm(RX, pose_matrix([0.5 * np.cos(2.1 * i),
                                                      0.5 * np.sin(2.1 * i), 0.0],
                                                     dh.rot_z(2.1 * i + np.pi)), name=f"r{i}")
                for i in range(3)}
        world = PybulletWorld()
        centre = np.array([0.0, 0.0, 0.25])
        for name, arm in arms.items():
            q = arm.ik(centre + 0.3 * (arm.base[:3, 3] - centre) * (name != "r0"), None,
                       arm.home)
            assert q is not None
            world.add_robot(name, RX, arm.base, q)
        points = [TaskPoint(0.03 * np.array([np.cos(a), np.sin(a), 0.0]))
                  for a in np.linspace(0.0, 2 * np.pi, 4, endpoint=False)]
        cfg = KernelConfig(indices=KernelConfig().indices[:2], ntt_threshold=1e9,
                           batch_indices=batched)
        k = MRCPKernel(arms, world, points, "r0", 0, centre, config=cfg)
        path = [centre + 0.02 * np.array([np.sin(0.9 * t), np.sin(1.4 * t), 0.0])
                for t in 0.018 * np.arange(1, 16)]
        records.append([k.step(0.018 * (i + 1), p) for i, p in enumerate(path)])
    theta = set()
    for a, b in zip(*records, strict=True):
        assert all(np.array_equal(a.commands[r], b.commands[r]) for r in a.commands)
        for key, ev in a.evaluations.items():
            assert ev.values == b.evaluations[key].values
            theta.add(ev.values["theta"])
    assert len(theta) > 10          # Θ varies: the comparison is not of constants
