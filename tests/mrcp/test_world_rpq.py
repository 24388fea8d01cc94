"""RPQ (seed appendix A): the optimised robot-pair query answers exactly what brute force does,
its box test agrees with an independent engine, and its matrices behave as the seed says."""

from __future__ import annotations

import math

import numpy as np
import pybullet as pb
import pytest
from scipy.spatial.transform import Rotation

from vasim.mrcp import dh
from vasim.mrcp.backend import PybulletWorld, pose_matrix
from vasim.mrcp.rpq import RPQ, _obb_overlap

RX = dh.load_robot("rx60b")


def facing(distance: float) -> PybulletWorld:
    world = PybulletWorld()
    world.add_robot("a", RX, pose_matrix([-distance / 2, 0, 0]))
    world.add_robot("b", RX, pose_matrix([distance / 2, 0, 0], dh.rot_z(math.pi)))
    return world


def _configs(n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(np.tile(RX.lower, 2), np.tile(RX.upper, 2),
                                               size=(n, 12)).reshape(n, 2, 6)


@pytest.mark.parametrize("distance", [0.4, 0.6, 0.8])
def test_rpq_answers_exactly_what_brute_force_answers(distance: float) -> None:
    world = facing(distance)
    variants = [RPQ(world), RPQ(world, use_box=False), RPQ(world, use_obb=False),
                RPQ(world, use_weights=False, use_matrix=False)]
    hits = 0
    for qa, qb in _configs(150, seed=int(distance * 10)):
        world.set_configuration("a", qa)
        world.set_configuration("b", qb)
        truth = variants[0].brute_force("a", "b")
        hits += truth
        assert [v.collide("a", "b") for v in variants] == [truth] * len(variants)
    if distance == 0.4:
        assert hits > 0          # the comparison covered colliding configurations too
    # the culling levels leave a small fraction of brute force's 49 hull queries per pair
    assert variants[0].stats.hull_tests < 0.1 * 49 * 150


def test_rpq_against_an_obstacle_matches_brute_force() -> None:
    world = PybulletWorld()
    world.add_robot("r", RX)
    world.add_box("table", [0.2, 0.3, 0.02], [0.45, 0.0, 0.0])
    rpq = RPQ(world)
    seen = set()
    for q in np.random.default_rng(7).uniform(RX.lower, RX.upper, size=(120, 6)):
        world.set_configuration("r", q)
        truth = rpq.brute_force("r", "table")
        seen.add(truth)
        assert rpq.collide("r", "table") is truth
    assert seen == {True, False}


def test_obb_overlap_agrees_with_pybullet_boxes() -> None:
    # independent engine: pybullet's box-box distance on the same random boxes
    cid = pb.connect(pb.DIRECT)
    try:
        rng = np.random.default_rng(11)
        agree = 0
        for _ in range(300):
            half = rng.uniform(0.02, 0.2, size=(2, 3))
            poses = []
            for _ in range(2):
                rot = dh.rot_z(rng.uniform(-3, 3)) @ dh.rot_x(rng.uniform(-3, 3)) @ \
                    dh.rot_z(rng.uniform(-3, 3))
                poses.append(pose_matrix(rng.uniform(-0.25, 0.25, 3), rot))
            bodies = []
            for k in range(2):
                shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half[k].tolist(),
                                                physicsClientId=cid)
                bodies.append(pb.createMultiBody(
                    0.0, shape, basePosition=poses[k][:3, 3].tolist(),
                    baseOrientation=Rotation.from_matrix(poses[k][:3, :3]).as_quat().tolist(),
                    physicsClientId=cid))
            pts = pb.getClosestPoints(bodies[0], bodies[1], 1.0, physicsClientId=cid)
            d = min(p[8] for p in pts)
            if abs(d) < 1e-3:          # grazing contact: either answer is within tolerance
                continue
            assert _obb_overlap(poses[0], half[0], poses[1], half[1]) == (d < 0)
            agree += 1
            for b in bodies:
                pb.removeBody(b, physicsClientId=cid)
        assert agree > 250
    finally:
        pb.disconnect(cid)


def test_collision_matrix_discards_pairs_out_of_reach() -> None:
    near, far = RPQ(facing(0.4)), RPQ(facing(1.2))
    m_near, m_far = near.collision_matrix("a", "b"), far.collision_matrix("a", "b")
    assert m_near.shape == (7, 7)
    # the bases (0.1 m column) cannot meet at 1.2 m; every far pair allowed is allowed near
    assert not m_far[0, 0]
    assert np.all(m_near >= m_far)
    assert m_far.sum() < m_near.sum()
    # the distal links sweep the largest balls: flange vs flange possible at 1.2 m
    # (reach 0.667 m each)
    assert m_far[6, 6]


def test_weight_matrix_starts_distal_first_and_learns() -> None:
    world = facing(0.4)
    rpq = RPQ(world)
    w0 = rpq.weight_matrix("a", "b")
    assert w0[6, 6] == w0.max() and w0[0, 0] == w0.min()
    # elbows pointing at each other: a collision found raises the colliding links' weights
    q = RX.home.copy()
    world.set_configuration("a", q)
    world.set_configuration("b", q)
    assert rpq.collide("a", "b")
    w1 = rpq.weight_matrix("a", "b")
    assert np.any(w1 > w0)
    assert rpq.stats.collisions == 1


def test_seed_test_bed_is_96_by_96_pairs_spanning_the_arm_joints() -> None:
    from vasim.mrcp.rpq import seed_test_bed_configurations, seed_test_bed_pairs

    one = seed_test_bed_configurations(RX)
    pairs = seed_test_bed_pairs(RX)
    assert one.shape == (96, 6) and pairs.shape == (9216, 2, 6)      # Table A.1's count
    assert len({(tuple(a), tuple(b)) for a, b in pairs}) == 9216       # all distinct
    for j, k in enumerate((4, 4, 6)):       # the grid reaches both ends of each range
        vals = np.unique(one[:, j])
        assert len(vals) == k and vals[0] == RX.lower[j] and vals[-1] == RX.upper[j]
    np.testing.assert_array_equal(one[:, 3:], np.tile(RX.home[3:], (96, 1)))
    # a's configuration is the slow index, b's the fast one: every b with every a
    np.testing.assert_array_equal(pairs[:96, 1], one)
    np.testing.assert_array_equal(pairs[::96, 0], one)


def test_test_bed_shares_fall_with_distance_and_grow_with_link_bulk() -> None:
    """The measured reasons behind bench/mrcp_rpq's table: fewer collisions the farther
    apart the robots, more the bulkier the links (every 8th pair: 1,152)."""
    from vasim.mrcp.rpq import collision_share, inflated, seed_test_bed_pairs

    pairs = seed_test_bed_pairs(RX)[::8]
    thin = [collision_share(RX, d, pairs) for d in (0.4, 0.6, 0.8)]
    bulky = [collision_share(inflated(RX, 0.06), d, pairs) for d in (0.4, 0.6, 0.8)]
    assert thin[0] > thin[1] > thin[2] and bulky[0] > bulky[1] > bulky[2]
    assert all(b > t for b, t in zip(bulky, thin, strict=True))
    # the shipped hulls stay well under the seed's 52.78 % at 400 mm; +60 mm links reach it
    assert thin[0] < 35.0 < bulky[0]


def test_rpq_matches_brute_force_on_the_seed_test_bed() -> None:
    from vasim.mrcp.rpq import seed_test_bed_pairs

    world = facing(0.4)
    rpq = RPQ(world)
    hits = 0
    for qa, qb in seed_test_bed_pairs(RX)[::37]:
        world.set_configuration("a", qa)
        world.set_configuration("b", qb)
        truth = rpq.brute_force("a", "b")
        hits += truth
        assert rpq.collide("a", "b") is truth
    assert 0 < hits < 250
