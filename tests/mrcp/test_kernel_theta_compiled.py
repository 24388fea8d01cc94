"""Θ's one-call compiled path for arms with a DH chain (issue #17 §4) gives exactly the
value of the general path (Jacobians through the arm, compiled steps called from Python)."""

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

RX = dh.load_robot("rx60b")


@pytest.fixture(scope="module")
def station() -> Iterator[tuple[PybulletArm, PybulletWorld]]:
    arm = PybulletArm(RX, pose_matrix([0.1, -0.2, 0.05], dh.rot_z(0.7)), name="a")
    world = PybulletWorld()
    world.add_robot("a", RX, arm.base)
    yield arm, world
    arm.close()
    world.close()


class _NoChain:
    """The same arm without ``dh_chain``: Θ takes its general path."""

    def __init__(self, arm: PybulletArm) -> None:
        self._arm = arm

    def __getattr__(self, name: str) -> object:
        if name == "dh_chain":
            raise AttributeError(name)
        return getattr(self._arm, name)


@settings(max_examples=30, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**31 - 1), points=st.integers(2, 6),
       rows=st.sampled_from([(0, 1, 2), (0, 2)]),
       threshold_rows=st.sampled_from([(0, 1, 2, 3, 4, 5), (0, 1, 2), (3, 4, 5)]))
def test_compiled_theta_equals_the_general_path(
        station: tuple[PybulletArm, PybulletWorld], seed: int, points: int, rows: tuple,
        threshold_rows: tuple) -> None:
    arm_, world = station
    rng = np.random.default_rng(seed)
    q0 = rng.uniform(RX.lower, RX.upper)
    configs = q0 + np.cumsum(rng.normal(0.0, 0.05, size=(points, 6)), axis=0)
    configs[0] = q0
    reach = rng.uniform(size=points) > 0.2
    reach[0] = True
    pos = np.array([arm_.tcp_pose(q)[0] for q in configs])
    std = np.abs(rng.normal(0.0, 0.01, size=(points, 3))) * (np.arange(points) > 0)[:, None]
    ix = AnisotropicDexterityIndex(rows=rows, threshold_rows=threshold_rows, seed=seed % 97)

    def ctx(arm: object) -> EvalContext:
        return EvalContext(robot="a", arm=arm, point=0, selected=True,  # type: ignore[arg-type]
                           times=0.05 * np.arange(points), positions=pos, std=std,
                           rotations=None, configs=np.where(reach[:, None], configs, np.nan),
                           reachable=reach, joint_velocity=np.zeros_like(configs),
                           past_configs=[], world=world)

    fast = ix.evaluate(ctx(arm_))
    general = ix.evaluate(ctx(_NoChain(arm_)))
    assert fast == general
