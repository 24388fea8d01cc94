"""The analytic test world itself (tests/mrcp/planar.py) against independent computations,
so the kernel tests stand on checked ground."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.mrcp.planar import (
    PlanarArm,
    PlanarWorld,
    Sphere,
    closest_segment_segment,
    segment_distances,
)
from vasim.mrcp.interfaces import ArmKinematics, ProximityWorld

coords = st.floats(-1.0, 1.0)


@settings(max_examples=60, deadline=None)
@given(st.lists(coords, min_size=12, max_size=12))
def test_segment_distance_against_dense_sampling(v: list[float]) -> None:
    p1, q1, p2, q2 = np.array(v).reshape(4, 3)
    ca, cb = closest_segment_segment(p1, q1, p2, q2)
    s = np.linspace(0.0, 1.0, 401)
    brute = np.linalg.norm((p1 + np.outer(s, q1 - p1))[:, None]
                           - (p2 + np.outer(s, q2 - p2))[None], axis=-1).min()
    # Sampling at 1/400 of each segment overestimates by at most that step (<= 0.0087 m).
    # segments shorter than sqrt(1e-15) m (~3e-8 m) are treated as points (planar.py)
    assert np.linalg.norm(ca - cb) <= brute + 1e-7
    assert np.linalg.norm(ca - cb) >= brute - 0.01
    assert float(segment_distances(p1, q1, p2, q2)) == pytest.approx(np.linalg.norm(ca - cb),
                                                                       abs=1e-12)
    assert float(segment_distances(p1, q1, p2, p2)) == pytest.approx(
        np.linalg.norm(closest_segment_segment(p1, q1, p2, p2)[0] - p2), abs=1e-12)


def test_batched_distances_equal_single_queries() -> None:
    a = PlanarArm("A")
    b = PlanarArm("B", base=np.array([0.5, 0.1, 0.02]), yaw=2.0)
    world = PlanarWorld({"A": a, "B": b}, {"A": np.zeros(3), "B": np.zeros(3)},
                        {"s": Sphere(np.array([0.2, 0.3, 0.0]), 0.05)})
    assert isinstance(world, ProximityWorld) and isinstance(a, ArmKinematics)
    qs = np.random.default_rng(0).uniform(a.lower, a.upper, (50, 3))
    batched = world.min_distances("A", qs, ["B", "s"], 5.0)
    single = []
    for q in qs:
        world.set_configuration("A", q)
        single.append([world.min_distance("A", "B", 5.0).distance,
                       world.min_distance("A", "s", 5.0).distance])
    np.testing.assert_allclose(batched, single, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(st.floats(-2.7, 2.7), st.floats(-2.7, 2.7), st.floats(-0.2, 0.2))
def test_ik_round_trip_and_jacobian(t1: float, t2: float, z: float) -> None:
    arm = PlanarArm("a", base=np.array([0.1, -0.2, 0.05]), yaw=0.7)
    q = np.array([t1, t2, z])
    p, rot = arm.tcp_pose(q)
    sol = arm.ik(p, None, q)
    assert sol is not None
    np.testing.assert_allclose(arm.tcp_pose(sol)[0], p, atol=1e-9)
    if abs(np.sin(t2)) > 1e-3:                       # the seed's own branch is the closest
        np.testing.assert_allclose(sol, q, atol=1e-6)
    # Jacobian against central differences of the TCP position.
    eps = 1e-6
    num = np.column_stack([(arm.tcp_pose(q + eps * e)[0] - arm.tcp_pose(q - eps * e)[0])
                           / (2 * eps) for e in np.eye(3)])
    np.testing.assert_allclose(arm.jacobian(q)[:3], num, atol=1e-7)
    assert arm.ik(arm.base + np.array([0.7, 0.0, 0.0]), None, q) is None   # beyond reach
    with_rot = arm.ik(p, rot, q)                     # the pose's own orientation: reachable
    assert with_rot is not None
    np.testing.assert_allclose(arm.tcp_pose(with_rot)[1], rot, atol=1e-6)   # acos near 1
