"""The pybullet backend: the same kinematics as the DH tables, IK that returns None when it
must, and distances that agree with an independent computation on the trimesh hulls."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pybullet as pb
import pytest
import trimesh
from scipy.optimize import minimize_scalar

from vasim.mrcp import closed_form_ik, dh
from vasim.mrcp.backend import (
    HULL_MARGIN,
    PybulletArm,
    PybulletWorld,
    pose_matrix,
    rotation_error,
)
from vasim.mrcp.interfaces import ArmKinematics, ProximityWorld
from vasim.mrcp.urdf import link_hulls, write_urdf

RX = dh.load_robot("rx60b")
BASE = pose_matrix([0.3, -0.2, 0.5], dh.rot_z(1.0) @ dh.rot_x(0.3))


@pytest.fixture(scope="module")
def arm() -> PybulletArm:
    return PybulletArm(RX, BASE, kinematics="pybullet")


def _samples(n: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(RX.lower, RX.upper, size=(n, 6))


def test_arm_and_world_implement_the_seams(arm: PybulletArm) -> None:
    assert isinstance(arm, ArmKinematics)
    assert isinstance(PybulletWorld(), ProximityWorld)


def test_pybullet_jacobian_equals_the_dh_jacobian(arm: PybulletArm) -> None:
    # calculateJacobian works in double precision: the two agree to round-off
    for q in _samples(40):
        np.testing.assert_allclose(arm.pybullet_jacobian(q), dh.jacobian(RX, q, BASE),
                                   atol=1e-9, rtol=0)


def test_pybullet_link_frames_equal_the_batched_dh_frames(arm: PybulletArm) -> None:
    # getLinkState reports single-precision floats: positions within a few float32 ulps
    # (|x| < 2 m -> ulp 1.2e-7), rotations within 1e-6
    qs = _samples(40, seed=1)
    frames = dh.link_frames(RX, qs, BASE)
    for i, q in enumerate(qs):
        arm._set(q)
        for k in range(RX.n_joints + 1):      # joint frames 1..n and the TCP
            st = pb.getLinkState(arm._body, k, computeForwardKinematics=1,
                                 physicsClientId=arm._cid)
            np.testing.assert_allclose(st[4], frames[i, k + 1, :3, 3], atol=2e-7, rtol=0)
        _, rot = arm.pybullet_tcp_pose(q)
        np.testing.assert_allclose(rot, frames[i, -1, :3, :3], atol=1e-6, rtol=0)


def test_default_arm_answers_from_the_dh_chain() -> None:
    fast = PybulletArm(RX, BASE)
    q = _samples(1, seed=2)[0]
    pos, _ = fast.tcp_pose(q)
    np.testing.assert_array_equal(pos, dh.fk(RX, q, BASE)[0])
    np.testing.assert_array_equal(fast.jacobian(q), dh.jacobian(RX, q, BASE))
    p_b, _ = fast.tcp_pose_batch(q[None])
    np.testing.assert_allclose(p_b[0], pos, atol=1e-14)


def test_ik_round_trip_lands_on_the_pose_within_limits(arm: PybulletArm) -> None:
    rng = np.random.default_rng(4)
    solved = 0
    for q in _samples(30, seed=5):
        pos, rot = dh.fk(RX, q, BASE)
        seed = np.clip(q + rng.normal(0.0, 0.3, 6), RX.lower, RX.upper)
        sol = arm.ik(pos, rot, q_seed=seed)
        assert sol is not None
        solved += 1
        assert RX.within_limits(sol)
        p2, r2 = dh.fk(RX, sol, BASE)
        assert np.linalg.norm(p2 - pos) < 1e-6
        assert np.linalg.norm(rotation_error(r2, rot)) < 1e-6
    assert solved == 30


def test_ik_from_home_finds_arbitrary_reachable_poses(arm: PybulletArm) -> None:
    # poses of random in-limit configurations: reachable by construction, far from home
    for q in _samples(40, seed=9):
        pos, rot = dh.fk(RX, q, BASE)
        sol = arm.ik(pos, rot)
        assert sol is not None
        assert RX.within_limits(sol)
        assert np.linalg.norm(dh.fk(RX, sol, BASE)[0] - pos) < 1e-6


def test_ik_from_a_nearby_seed_returns_the_nearby_branch(arm: PybulletArm) -> None:
    q = RX.home + np.array([0.2, 0.1, -0.2, 0.3, -0.2, 0.1])
    pos, rot = dh.fk(RX, q, BASE)
    sol = arm.ik(pos, rot, q_seed=q + 0.01)
    assert sol is not None
    np.testing.assert_allclose(sol, q, atol=1e-6)


def test_position_only_ik(arm: PybulletArm) -> None:
    pos, _ = dh.fk(RX, RX.home, BASE)
    target = pos + np.array([0.03, -0.02, 0.05])
    sol = arm.ik(target, q_seed=RX.home)
    assert sol is not None
    np.testing.assert_allclose(dh.fk(RX, sol, BASE)[0], target, atol=1e-6)


def test_ik_of_an_unreachable_pose_is_none(arm: PybulletArm) -> None:
    # the reach is sqrt((a2 + d4)^2 + d3^2) + tcp = 0.667 m from the shoulder
    far = BASE[:3, 3] + np.array([0.0, 0.0, 0.70])
    assert arm.ik(far) is None
    assert arm.ik(far, np.eye(3)) is None


def test_rotation_error_is_the_axis_angle_between_rotations() -> None:
    for angle in (1e-9, 0.3, 2.0, 3.1):
        axis = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
        r0 = dh.rot_x(0.4) @ dh.rot_z(-1.1)
        k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        rot = np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k
        np.testing.assert_allclose(rotation_error(r0, rot @ r0), angle * axis, atol=1e-9)


def test_hulls_contain_every_swept_sphere() -> None:
    for k, hull in enumerate(link_hulls(RX)):
        assert hull.is_convex
        radius = RX.links[k].radius
        offsets = hull.face_normals @ hull.vertices[hull.faces[:, 0]].T   # plane offsets
        plane_d = np.diag(offsets)
        for c in RX.link_key_points(k):
            assert np.all(hull.face_normals @ c + radius <= plane_d + 1e-12)


def test_urdf_is_written_once_per_content(tmp_path) -> None:
    p1 = write_urdf(RX)
    assert write_urdf(RX) == p1
    changed = dh.RobotModel(RX.name, RX.joints, tcp=np.array([0.0, 0.0, 0.1]), home=RX.home,
                            links=RX.links)
    assert write_urdf(changed) != p1


def _world_hull_distance(world: PybulletWorld, robot: str, point: np.ndarray) -> float:
    """Independent: distance from a point to the robot's hulls, posed by the DH frames."""
    model = world.robot_model(robot)
    frames = dh.link_frames(model, world.configuration(robot), world.robot_base(robot))
    best = math.inf
    for k, hull in enumerate(link_hulls(model)):
        posed = hull.copy()
        posed.apply_transform(frames[k])
        _, dist, _ = trimesh.proximity.closest_point(posed, point[None])
        inside = posed.contains(point[None])[0]
        best = min(best, -dist[0] if inside else dist[0])
    return best


def test_min_distance_to_a_sphere_matches_the_hull_geometry() -> None:
    world = PybulletWorld()
    world.add_robot("r1", RX)
    q = RX.home + np.array([0.4, -0.3, 0.2, 0.5, -0.4, 0.3])
    world.set_configuration("r1", q)
    for centre in ([0.5, 0.3, 0.2], [0.2, -0.3, 0.6], [-0.3, 0.1, 0.1]):
        c = np.array(centre)
        world.add_sphere(f"s{centre}", 0.05, c)
        prox = world.min_distance("r1", f"s{centre}", max_distance=2.0)
        expect = _world_hull_distance(world, "r1", c) - 0.05
        # pybullet pads every convex hull with its collision margin (the hull grown by a
        # 1 mm ball): the distance is the bare hull's minus the margin, to GJK's accuracy
        assert prox.distance == pytest.approx(expect - HULL_MARGIN, abs=5e-5)
        assert np.linalg.norm(prox.point_a - prox.point_b) == pytest.approx(
            abs(prox.distance), abs=1e-6)


def test_far_bodies_report_max_distance_and_nan_witnesses() -> None:
    world = PybulletWorld()
    world.add_robot("r1", RX)
    world.add_box("box", [0.1, 0.1, 0.1], [3.0, 0.0, 0.0])
    prox = world.min_distance("r1", "box", max_distance=0.5)
    assert prox.distance == 0.5
    assert np.all(np.isnan(prox.point_a))


def test_two_rx60b_facing_collide_close_and_not_far() -> None:
    # at home each TCP reaches d4 = 0.31 m forward: at 0.5 m the forearms overlap,
    # at 1.5 m the closest points are the two TCPs/wrists, 1.5 - 2 * 0.31 - radii apart
    for distance, colliding in ((0.5, True), (1.5, False)):
        world = PybulletWorld()
        world.add_robot("a", RX, pose_matrix([-distance / 2, 0, 0]))
        world.add_robot("b", RX, pose_matrix([distance / 2, 0, 0], dh.rot_z(math.pi)))
        assert world.in_collision("a") is colliding
        assert world.in_collision("b") is colliding
        prox = world.min_distance("a", "b", max_distance=2.0)
        assert (prox.distance <= 0) is colliding


def test_self_collision_and_obstacles() -> None:
    world = PybulletWorld()
    world.add_robot("r1", RX)
    assert not world.in_collision("r1")
    pos, _ = dh.fk(RX, RX.home)
    world.add_sphere("ball", 0.02, pos)
    assert world.in_collision("r1")
    world.set_obstacle_pose("ball", pos + np.array([0.0, 0.0, -0.2]))
    assert not world.in_collision("r1")
    # adjacent links always touch and are never reported; the pairs checked are not adjacent
    assert all(b - a >= 2 for a, b in world.self_collision_pairs("r1"))


def test_configuration_round_trip_and_unknown_names() -> None:
    world = PybulletWorld()
    body = world.add_robot("r1", RX)
    for q in (RX.home, RX.home + 0.1):       # pybullet's joints follow, from the first pose
        if q is not RX.home:
            world.set_configuration("r1", q)
        np.testing.assert_array_equal(world.configuration("r1"), q)
        joints = [pb.getJointState(body, j, physicsClientId=world.client_id)[0]
                  for j in range(6)]
        np.testing.assert_array_equal(joints, q)
    assert world.robot_names() == ["r1"]
    with pytest.raises(KeyError, match="r1"):
        world.configuration("r2")
    with pytest.raises(ValueError, match="already exists"):
        world.add_sphere("r1", 0.1, [0, 0, 0])


def test_branch_and_bound_distance_equals_the_whole_body_query() -> None:
    world = PybulletWorld()
    world.add_robot("a", RX, pose_matrix([-0.3, 0, 0]))
    world.add_robot("b", RX, pose_matrix([0.3, 0, 0], dh.rot_z(math.pi)))
    ba, bb = world.body_id("a"), world.body_id("b")
    for qa, qb in zip(_samples(60, seed=12), _samples(60, seed=13), strict=True):
        world.set_configuration("a", qa)
        world.set_configuration("b", qb)
        prox = world.min_distance("a", "b", max_distance=1.0)
        pts = pb.getClosestPoints(ba, bb, 1.0, physicsClientId=world.client_id)
        expect = min((p[8] for p in pts), default=1.0)
        assert prox.distance == pytest.approx(expect, abs=1e-9)


def test_closed_form_and_numeric_ik_agree_on_what_is_reachable_within_limits() -> None:
    # poses of configurations partly outside the limits: reachable in space, but maybe
    # not within the limits; the closed form's None must match an exhaustive numeric search
    exact = PybulletArm(RX, BASE)
    numeric = PybulletArm(RX, BASE, closed_form=False)
    rng = np.random.default_rng(31)
    outcomes = set()
    for _ in range(25):
        q = rng.uniform(RX.lower - 1.0, RX.upper + 1.0)
        pos, rot = dh.fk(RX, q, BASE)
        a = exact.ik(pos, rot)
        b = numeric.ik(pos, rot, restarts=64)
        assert (a is None) == (b is None)
        outcomes.add(a is None)
        for sol in (a, b):
            if sol is not None:
                assert RX.within_limits(sol)
                assert np.linalg.norm(dh.fk(RX, sol, BASE)[0] - pos) < 1e-6
    assert outcomes == {True, False}


# -- Non-finite joints and IK inputs are refused (a NaN seed hung pybullet's IK); the closed-
# form IK at the shoulder singularity falls back to the numeric search.
def test_non_finite_joints_are_rejected_by_the_world() -> None:
    w = PybulletWorld()
    w.add_robot("a", RX)
    w.add_robot("b", RX, pose_matrix([0.5, 0.0, 0.0], dh.rot_z(math.pi)))
    q = RX.home.copy()
    q[0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        w.set_configuration("a", q)
    np.testing.assert_array_equal(w.configuration("a"), RX.home)   # unchanged
    q[0] = np.inf
    with pytest.raises(ValueError, match="finite"):
        w.min_distances("a", np.stack([RX.home, q]), ["b"], 1.0)
    w.compiled_distances = False
    with pytest.raises(ValueError, match="finite"):
        w.min_distances("a", q[None], ["b"], 1.0)


@pytest.fixture(scope="module")
def closed_form_arm() -> PybulletArm:
    return PybulletArm(RX)


def test_ik_rejects_non_finite_rotation_and_seed(closed_form_arm: PybulletArm) -> None:
    p, r = closed_form_arm.tcp_pose(RX.home)
    bad_r = r.copy()
    bad_r[0, 0] = np.nan
    with pytest.raises(ValueError, match="rotation"):
        closed_form_arm.ik(p, bad_r, RX.home)
    with pytest.raises(ValueError, match="rotation"):
        closed_form_arm.ik(p, bad_r)
    with pytest.raises(ValueError, match="rotation"):
        closed_form_arm.ik(p, np.eye(4))
    with pytest.raises(ValueError, match="q_seed"):
        closed_form_arm.ik(p, r, np.full(6, np.nan))
    with pytest.raises(ValueError, match="position"):
        closed_form_arm.ik(np.array([np.nan, 0.0, 0.3]), r)


def test_ik_position_only_with_a_nan_seed_raises_instead_of_hanging() -> None:
    # in a subprocess: the old code looped forever inside pybullet
    code = ("import numpy as np\n"
            "from vasim.mrcp import dh\n"
            "from vasim.mrcp.backend import PybulletArm\n"
            "arm = PybulletArm(dh.load_robot('rx60b'))\n"
            "p, _ = arm.tcp_pose(arm.home)\n"
            "try:\n"
            "    arm.ik(p, None, np.full(6, np.nan))\n"
            "except ValueError as e:\n"
            "    print('ValueError', e)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, check=False)
    assert "ValueError" in out.stdout and "q_seed" in out.stdout, out.stderr[-2000:]


def _shoulder_singular(q: np.ndarray) -> np.ndarray:
    """``q`` with joint 2 moved so that the wrist centre lies on the d3 circle about the
    first axis (rho2 = 0: the shoulder singularity)."""
    d3 = RX.joints[2].d

    def rho2(q2: float) -> float:
        qq = q.copy()
        qq[1] = q2
        w = dh.frames_one(RX, qq)[4][:3, 3]
        return float(w[0] ** 2 + w[1] ** 2 - d3 ** 2)

    res = minimize_scalar(rho2, bounds=(q[1] - 1e-3, q[1] + 1e-3), method="bounded",
                          options={"xatol": 1e-12})
    out = q.copy()
    out[1] = res.x
    assert abs(rho2(res.x)) < 1e-12
    return out


@pytest.mark.parametrize("q", [[-1.7107, -1.7253, 1.8697, 2.6558, 0.7911, -1.9774],
                               [-0.6936, -2.0168, 2.4321, 1.9764, 0.5328, 2.2632]])
def test_closed_form_ik_at_the_shoulder_singularity(closed_form_arm: PybulletArm, q: list[float]
                                                    ) -> None:
    qs = _shoulder_singular(np.array(q))
    p, r = closed_form_arm.tcp_pose(qs)
    assert len(closed_form_ik.puma_ik(RX, p, r)) == 8            # was 0 (round-off)
    sol = closed_form_arm.ik(p, r)
    assert sol is not None and RX.within_limits(sol)
    p2, r2 = closed_form_arm.tcp_pose(sol)
    assert np.linalg.norm(p2 - p) <= 1e-6
    assert np.linalg.norm(rotation_error(r2, r)) <= 1e-6


def test_an_empty_closed_form_within_reach_falls_back_to_the_numeric_search(
        closed_form_arm: PybulletArm, monkeypatch: pytest.MonkeyPatch) -> None:
    q = np.array([0.3, -1.2, 2.6, 0.4, 1.0, -0.5])
    p, r = closed_form_arm.tcp_pose(q)
    monkeypatch.setattr(closed_form_ik, "puma_ik", lambda *args, **kwargs: [])
    assert closed_form_arm._closed_form_ik(p, r, RX.home, 1e-6, 1e-6) == (None, False)
    sol = closed_form_arm.ik(p, r)
    assert sol is not None
    assert np.linalg.norm(closed_form_arm.tcp_pose(sol)[0] - p) <= 1e-6
