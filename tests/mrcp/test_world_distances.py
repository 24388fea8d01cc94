"""The compiled distance model of the pybullet world against pybullet itself, and its
key-point geometry against an independent convex minimisation (scipy)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize

from vasim.mrcp import dh
from vasim.mrcp._distance_kernels import hull_points_distance
from vasim.mrcp.backend import (
    COMPILED_TOLERANCE,
    PybulletArm,
    PybulletWorld,
    pose_matrix,
)

RX = dh.load_robot("rx60b")


@pytest.fixture(scope="module")
def world() -> PybulletWorld:
    w = PybulletWorld()
    w.add_robot("a", RX, pose_matrix([0.0, 0.0, 0.0]))
    w.add_robot("b", RX, pose_matrix([0.6, 0.1, 0.0], dh.rot_z(2.5)))
    w.add_sphere("ball", 0.05, np.array([0.3, 0.0, 0.4]))
    w.add_box("box", np.array([0.05, 0.1, 0.02]), np.array([0.3, -0.3, 0.3]))
    return w


def _pybullet(world: PybulletWorld, qs: np.ndarray, bodies: list[str],
              cap: float) -> np.ndarray:
    world.compiled_distances = False
    try:
        return world.min_distances("a", qs, bodies, cap)
    finally:
        world.compiled_distances = True


def test_compiled_distances_are_pybullets_within_the_stated_tolerance(
        world: PybulletWorld) -> None:
    rng = np.random.default_rng(3)
    bodies = ["b", "ball", "box"]
    diffs, near, penetrating = [], 0, 0
    for _ in range(120):
        world.set_configuration("b", rng.uniform(RX.lower, RX.upper))
        qs = rng.uniform(RX.lower, RX.upper, size=(3, 6))
        before = world.configuration("a")
        fast = world.min_distances("a", qs, bodies, 1.0)
        np.testing.assert_array_equal(world.configuration("a"), before)   # pose restored
        ref = _pybullet(world, qs, bodies, 1.0)
        diffs.append(fast - ref)
        near += int(np.sum((ref > 0) & (ref < 0.05)))
        penetrating += int(np.sum(ref < 0))
    d = np.array(diffs)
    assert near > 10 and penetrating > 10          # the sample covers contact cases
    assert d.min() >= -COMPILED_TOLERANCE           # a conservative lower bound ...
    assert d.max() <= 1e-5                          # ... never above pybullet's value
    np.testing.assert_array_equal(d[:, :, 2], 0.0)  # a box: pybullet itself


def test_compiled_distances_follow_a_moved_sphere(world: PybulletWorld) -> None:
    world.set_configuration("b", RX.home)
    q = RX.home[None, :]
    world.set_obstacle_pose("ball", np.array([0.2, 0.2, 0.5]))
    try:
        fast = world.min_distances("a", q, ["ball"], 2.0)
        ref = _pybullet(world, q, ["ball"], 2.0)
        assert ref[0, 0] < 1.0
        assert -COMPILED_TOLERANCE <= fast[0, 0] - ref[0, 0] <= 1e-5
    finally:
        world.set_obstacle_pose("ball", np.array([0.3, 0.0, 0.4]))


def test_far_bodies_are_capped(world: PybulletWorld) -> None:
    world.set_configuration("b", RX.home)
    out = world.min_distances("a", RX.home[None, :], ["b", "ball"], 0.01)
    ref = _pybullet(world, RX.home[None, :], ["b", "ball"], 0.01)
    np.testing.assert_array_equal(out <= 0.01, True)
    np.testing.assert_array_equal(out[ref >= 0.01], 0.01)


def test_a_finite_refine_threshold_sends_near_pairs_to_pybullet() -> None:
    w = PybulletWorld(refine_below=0.1)
    w.add_robot("a", RX)
    w.add_sphere("ball", 0.05, np.array([0.3, 0.0, 0.45]))
    q = RX.home[None, :]
    ref = _pybullet(w, q, ["ball"], 1.0)
    assert ref[0, 0] < 0.1
    np.testing.assert_array_equal(w.min_distances("a", q, ["ball"], 1.0), ref)


def test_min_distances_rejects_a_wrong_shape(world: PybulletWorld) -> None:
    with pytest.raises(ValueError, match="configs must have shape"):
        world.min_distances("a", np.zeros((2, 5)), ["b"])


def _convex_distance(pa: np.ndarray, pb: np.ndarray) -> float:
    """min |Σ λ_i a_i - Σ μ_j b_j| over the simplices (scipy SLSQP, an independent route)."""
    na, nb = len(pa), len(pb)

    def f(x: np.ndarray) -> float:
        w = x[:na] @ pa - x[na:] @ pb
        return float(w @ w)

    cons = [{"type": "eq", "fun": lambda x: np.sum(x[:na]) - 1.0},
            {"type": "eq", "fun": lambda x: np.sum(x[na:]) - 1.0}]
    best = np.inf
    for start in (np.r_[np.full(na, 1 / na), np.full(nb, 1 / nb)],
                  np.r_[np.eye(na)[0], np.eye(nb)[-1]]):
        res = minimize(f, start, method="SLSQP", bounds=[(0.0, 1.0)] * (na + nb),
                       constraints=cons, options={"ftol": 1e-14, "maxiter": 500})
        best = min(best, float(np.sqrt(max(res.fun, 0.0))))
    return best


coords = st.floats(-1.0, 1.0, allow_nan=False)
point = st.tuples(coords, coords, coords)


def _non_degenerate(pts: list[tuple[float, float, float]]) -> bool:
    p = np.array(pts)
    if len(p) == 2:
        return bool(np.linalg.norm(p[1] - p[0]) > 1e-3)
    if len(p) == 3:
        return bool(np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0])) > 1e-3)
    return True


@settings(max_examples=60, deadline=None)
@given(st.lists(point, min_size=1, max_size=3).filter(_non_degenerate),
       st.lists(point, min_size=1, max_size=3).filter(_non_degenerate))
def test_key_point_hull_distance_matches_a_convex_minimisation(a: list, b: list) -> None:
    pa, pb = np.zeros((3, 3)), np.zeros((3, 3))
    pa[:len(a)], pb[:len(b)] = a, b
    ca, cb = np.empty(3), np.empty(3)
    d = hull_points_distance(pa, len(a), pb, len(b), ca, cb)
    ref = _convex_distance(np.array(a), np.array(b))
    assert d <= ref + 1e-9                          # never worse than the optimiser ...
    assert d * d == pytest.approx(ref * ref, abs=1e-8)   # ... which converges in d²
    assert float(np.linalg.norm(cb - ca)) == pytest.approx(d, abs=1e-9)


def test_compiled_position_ik_reaches_or_refuses() -> None:
    arm = PybulletArm(RX)
    rng = np.random.default_rng(5)
    for q in rng.uniform(RX.lower, RX.upper, size=(30, 6)):
        target, _ = arm.tcp_pose(q)
        seed = np.clip(q + rng.normal(0.0, 0.05, 6), RX.lower, RX.upper)
        sol = dh.position_dls(RX, seed, target, arm.base)
        if sol is not None:    # may stagnate at a limit: then None, never a wrong answer
            assert np.linalg.norm(arm.tcp_pose(sol)[0] - target) <= 1e-6
            assert np.all(sol >= RX.lower) and np.all(sol <= RX.upper)
    far = arm.tcp_pose(RX.home)[0] + np.array([5.0, 0.0, 0.0])
    assert dh.position_dls(RX, RX.home, far, arm.base) is None


def test_compiled_batches_equal_the_single_configuration_chain() -> None:
    qs = np.random.default_rng(6).uniform(RX.lower, RX.upper, size=(7, 6))
    base = pose_matrix([0.1, 0.2, 0.3], dh.rot_z(0.4))
    frames = dh.frames_many(RX, qs, base)
    jac = dh.jacobian_batch(RX, qs, base)
    for k, q in enumerate(qs):
        np.testing.assert_allclose(frames[k], dh.frames_one(RX, q, base), atol=1e-12)
        np.testing.assert_allclose(jac[k], dh.jacobian(RX, q, base), atol=1e-12)


def test_min_distance_and_in_collision_are_pybullets_with_the_model_as_a_filter(
        world: PybulletWorld) -> None:
    # the model only chooses which link pairs pybullet is asked about: the same answers
    rng = np.random.default_rng(8)
    hits = 0
    for _ in range(80):
        world.set_configuration("a", rng.uniform(RX.lower, RX.upper))
        world.set_configuration("b", rng.uniform(RX.lower, RX.upper))
        fast = [world.min_distance("a", body, 0.5) for body in ("b", "ball")]
        coll = world.in_collision("a")
        world.compiled_distances = False
        try:
            ref = [world.min_distance("a", body, 0.5) for body in ("b", "ball")]
            assert world.in_collision("a") == coll
        finally:
            world.compiled_distances = True
        hits += int(coll)
        for f, r in zip(fast, ref, strict=True):
            assert f.distance == pytest.approx(r.distance, abs=1e-9)
            if r.distance < 0.5:
                assert (f.link_a, f.link_b) == (r.link_a, r.link_b)
                np.testing.assert_allclose(f.point_a, r.point_a, atol=1e-9)
    assert 5 < hits < 75        # both answers occur


# -- Pairs without a model estimate (-inf) are penetrations, refined in pybullet on request;
# deep penetrations stay lower bounds within the tolerance.
def test_pairs_without_a_model_estimate_are_a_penetration_or_refined_on_request() -> None:
    w = PybulletWorld()
    w.add_robot("a", RX)
    frames = dh.frames_one(RX, RX.home)
    pts = RX.link_key_points(2)                      # inside the upper arm's key-point hull
    centre = (frames[2] @ np.c_[pts, np.ones(len(pts))].T).T[:, :3].mean(axis=0)
    w.add_sphere("ball", 0.02, centre)
    q = RX.home[None, :]
    fast = w.min_distances("a", q, ["ball"], 1.0)
    ref = _pybullet(w, q, ["ball"], 1.0)
    assert ref[0, 0] < -0.05 and fast[0, 0] <= ref[0, 0]    # -inf: "in, no estimate"
    w.refine_below = 0.0                                      # every penetration exact
    np.testing.assert_array_equal(w.min_distances("a", q, ["ball"], 1.0), ref)


_LB_CASE = {   # the reviewer's case: model 1.087 mm below pybullet at 7 cm penetration
    "ba": [[0.6065586612966181, 0.6222882066102803, 0.4948171160336066, -0.003110412232102527],
           [-0.795038735160781, 0.47476215289796175, 0.37751067239170577,
            -0.07116146500204364],
           [0.0, -0.6223811421383633, 0.782714324584996, -0.06115749309388823],
           [0.0, 0.0, 0.0, 1.0]],
    "bb": [[-0.4637633934137484, 0.8859590932595957, 0.0, 0.6046569087288115],
           [-0.8859590932595957, -0.4637633934137484, 0.0, -0.21407365127791042],
           [0.0, 0.0, 1.0, 0.13603952372220537], [0.0, 0.0, 0.0, 1.0]],
    "qb": [0.9472087527795794, 0.045796167675844046, 2.63276413571293, 0.08369175160069808,
           1.731545909362709, 2.2359516790409195],
    "qa": [0.6222055973835809, -0.5786288879283412, 2.345150827846893, -0.12003676022323218,
           0.46676072661299306, -0.08693023199629568],
}


@pytest.mark.parametrize("case", ["reviewer", "same_base"])
def test_deep_penetrations_stay_within_the_tolerance(case: str) -> None:
    w = PybulletWorld()
    if case == "reviewer":
        w.add_robot("a", RX, np.array(_LB_CASE["ba"]))
        w.add_robot("b", RX, np.array(_LB_CASE["bb"]), np.array(_LB_CASE["qb"]))
        q = np.array(_LB_CASE["qa"])
    else:               # two arms 5 cm apart at home: model 2.6 mm below pybullet
        w.add_robot("a", RX)
        w.add_robot("b", RX, pose_matrix([0.05, 0.0, 0.0]))
        q = RX.home
    fast = w.min_distances("a", q[None], ["b"], 1.0)
    ref = _pybullet(w, q[None], ["b"], 1.0)
    assert ref[0, 0] < -0.05
    assert fast[0, 0] - ref[0, 0] <= 1e-5           # still a lower bound
    w.refine_below = 0.0
    assert w.min_distances("a", q[None], ["b"], 1.0)[0, 0] == ref[0, 0]
    w.refine_below = -math.inf
    w.set_configuration("a", q)
    exact = w.min_distance("a", "b").distance
    w.compiled_distances = False
    assert exact == pytest.approx(w.min_distance("a", "b").distance, abs=1e-12)


def test_random_penetrations_are_lower_bounds_and_exact_on_request() -> None:
    """The model is a lower bound everywhere, within the tolerance where pybullet finds no
    penetration, and any penetration keeps its sign; refine_below = 0 makes penetrations
    pybullet's values."""
    rng = np.random.default_rng(11)
    w = PybulletWorld()
    w.add_robot("a", RX)
    w.add_robot("b", RX, pose_matrix([0.45, 0.05, 0.0], dh.rot_z(2.8)))
    w.add_sphere("s", 0.06, np.array([0.25, 0.0, 0.3]))
    negative = 0
    for _ in range(40):
        w.set_configuration("b", rng.uniform(RX.lower, RX.upper))
        qs = rng.uniform(RX.lower, RX.upper, size=(4, 6))
        w.refine_below = -math.inf
        fast = w.min_distances("a", qs, ["b", "s"], 1.0)
        ref = _pybullet(w, qs, ["b", "s"], 1.0)
        d = fast - ref
        assert d.max() <= 1e-5
        assert d[ref > 0].min(initial=0.0) >= -COMPILED_TOLERANCE
        assert np.all(fast[ref < -1e-5] < 0)                   # a penetration stays one
        w.refine_below = 0.0
        exact = w.min_distances("a", qs, ["b", "s"], 1.0)
        np.testing.assert_allclose(exact[ref < -COMPILED_TOLERANCE],
                                   ref[ref < -COMPILED_TOLERANCE], atol=1e-12)
        negative += int(np.sum(ref < 0))
    assert negative > 5
