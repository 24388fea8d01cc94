"""The study station: analytic tool holder, instrument capsules, cones, needle geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.abdomen.anatomy import default_anatomy
from vasim.core.errors import ConfigError
from vasim.mrcp.fulcrum import fulcrum_offset
from vasim.mrcp.interfaces import ArmKinematics, ProximityWorld
from vasim.mrcp.toolstation import (
    CONE_HALF_ANGLE,
    ToolPositioner,
    build_station,
    segment_closest_points,
)
from vasim.operator.needle import (
    NEEDLE_HALF,
    RING_CLEARANCE,
    classify_grasp,
    grasp_offset,
    grasp_sigma,
    handover_point,
    needle_task,
    pregrasp_offset,
)
from vasim.operator.scripted import OperatorProfile

POS = ToolPositioner("p", np.array([0.1, -0.2, 0.3]))
joints = st.tuples(*[st.floats(-0.25, 0.25)] * 3, st.floats(-1.2, 1.2), st.floats(-1.2, 1.2),
                   st.floats(-3.0, 3.0))


@settings(max_examples=80, deadline=None)
@given(joints)
def test_positioner_ik_inverts_fk(q: tuple) -> None:
    q = np.array(q)
    pos, rot = POS.tcp_pose(q)
    np.testing.assert_allclose(rot.T @ rot, np.eye(3), atol=1e-12)
    sol = POS.ik(pos, rot, q + 0.1)
    assert sol is not None
    np.testing.assert_allclose(sol, q, atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(joints)
def test_positioner_jacobian_matches_finite_differences(q: tuple) -> None:
    q = np.array(q)
    jac = POS.jacobian(q)
    h = 1e-6
    p0, r0 = POS.tcp_pose(q)
    for j in range(6):
        dq = np.zeros(6)
        dq[j] = h
        p1, r1 = POS.tcp_pose(q + dq)
        np.testing.assert_allclose((p1 - p0) / h, jac[:3, j], atol=1e-6)
        w = (r1 @ r0.T - np.eye(3)) / h          # skew(omega) to first order
        np.testing.assert_allclose([w[2, 1], w[0, 2], w[1, 0]], jac[3:, j], atol=1e-5)


def test_positioner_refuses_poses_outside_its_limits() -> None:
    assert POS.ik(POS.origin + np.array([0.5, 0.0, 0.0])) is None
    tilted = POS.rotation(np.array([0, 0, 0, 0, 1.45, 0]))   # |v| > 1.3
    assert POS.ik(POS.origin, tilted) is None


@settings(max_examples=150, deadline=None)
@given(st.lists(st.floats(-1, 1), min_size=12, max_size=12))
def test_segment_distance_is_the_minimum_over_the_segments(c: list) -> None:
    p1, q1, p2, q2 = (np.array(c[i:i + 3]) for i in range(0, 12, 3))
    a, b = segment_closest_points(p1, q1, p2, q2)
    s = np.linspace(0.0, 1.0, 201)
    pa = p1 + s[:, None] * (q1 - p1)
    pb = p2 + s[:, None] * (q2 - p2)
    brute = np.min(np.linalg.norm(pa[:, None, :] - pb[None, :, :], axis=2))
    d = float(np.linalg.norm(a - b))
    assert d <= brute + 1e-9           # no sampled pair is closer than the answer
    assert d >= brute - 0.02 * (np.linalg.norm(q1 - p1) + np.linalg.norm(q2 - p2)) - 1e-9


@pytest.fixture(scope="module")
def station():
    return build_station()


def test_station_arms_keep_their_fulcrum_and_world_reports_capsules(station) -> None:
    world = station.world
    assert isinstance(world, ProximityWorld)
    for name, arm in station.arms.items():
        assert isinstance(arm, ArmKinematics)
        target = arm.fulcrum.point + np.array([0.01, 0.02, -0.08])
        q = arm.ik(target, None, world.configuration(name))
        assert q is not None
        np.testing.assert_allclose(arm.tcp_pose(q)[0], target, atol=1e-9)
        mount, rot = arm.arm.tcp_pose(q)
        assert fulcrum_offset(mount, rot, arm.fulcrum.point) < 1e-9
    mr, tr = world.segment("right")
    ml, tl = world.segment("left")
    a, b = segment_closest_points(mr, tr, ml, tl)
    prox = world.min_distance("right", "left")
    assert prox.distance == pytest.approx(float(np.linalg.norm(a - b)) - 0.005, abs=1e-12)
    assert not world.in_collision("right")
    world.add_sphere("probe", tr, 0.001)                # a sphere at the right tool's tip
    assert world.in_collision("right") and not world.in_collision("left")


def test_cones_force_a_change_of_hands(station) -> None:
    task = needle_task()
    assert task.sides == ("right", "left") * 3 and task.n_transfers == 5
    for ring, side in zip(task.rings, task.sides, strict=True):
        far = "left" if side == "right" else "right"
        own = station.cones[side].polar_azimuth(ring + grasp_offset(side))[0]
        away = station.cones[far].polar_azimuth(ring + grasp_offset(far))[0]
        assert own < CONE_HALF_ANGLE < away      # only the ring's own side can work there
    for a, b in zip(task.rings, task.rings[1:], strict=False):
        h = handover_point(a, b)
        for side in ("right", "left"):            # both instruments reach the hand-over
            assert station.cones[side].polar_azimuth(h + grasp_offset(side))[0] \
                < CONE_HALF_ANGLE


def test_rings_float_above_their_organ() -> None:
    task = needle_task()
    meshes = {o.name: o.mesh for o in default_anatomy()}
    for ring, organ in zip(task.rings, task.organs, strict=True):
        closest, dist, _ = meshes[organ].nearest.on_surface(ring[None, :])
        assert 0.5 * RING_CLEARANCE < dist[0] <= RING_CLEARANCE + 1e-9
        assert closest[0][2] < ring[2]
    assert float(np.linalg.norm(task.start - task.rings[0])) == pytest.approx(
        math.hypot(0.02, 0.02))


def test_grasp_geometry_and_skill_model() -> None:
    np.testing.assert_allclose(grasp_offset("right"), [-NEEDLE_HALF, 0, 0])
    np.testing.assert_allclose(grasp_offset("left"), [NEEDLE_HALF, 0, 0])
    assert pregrasp_offset("left")[0] > NEEDLE_HALF and pregrasp_offset("left")[2] > 0
    # sigma = perception_noise * (1 + (1 - s)) * (1 + P) ** -alpha (scripted operator §1)
    p = OperatorProfile.intermediate()
    assert grasp_sigma(p, 0) == pytest.approx(p.perception_noise * (2.0 - p.skill))
    assert grasp_sigma(p, 8) == pytest.approx(grasp_sigma(p, 0) * 9.0 ** -p.learning_rate)
    assert grasp_sigma(OperatorProfile.expert(), 0) < grasp_sigma(OperatorProfile.novice(), 0)
    assert [classify_grasp(e) for e in (0.0, 0.0015, 0.0016, 0.004, 0.0041)] == [
        "clean", "clean", "misaligned", "misaligned", "missed"]


def test_bad_input_is_named() -> None:
    with pytest.raises(ConfigError, match="n_rings"):
        needle_task(0)
    with pytest.raises(ConfigError, match="holder"):
        build_station(holder="puma")
