"""The cycle's batched distance queries (issue #17 §4) give the values of the one-by-one
queries: the compiled branch and bound (with its cheap axis pre-test and early stop) is the
minimum over every link pair of the full pair values, and ``prefetch_distances`` stores in
each context what that context would have queried itself."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.mrcp import dh
from vasim.mrcp.backend import PybulletArm, PybulletWorld, pose_matrix
from vasim.mrcp.indices.base import EvalContext, prefetch_distances

RX = dh.load_robot("rx60b")


@pytest.fixture(scope="module")
def world() -> PybulletWorld:
    w = PybulletWorld()
    w.add_robot("a", RX, pose_matrix([0.0, 0.0, 0.0]))
    w.add_robot("b", RX, pose_matrix([0.55, 0.1, 0.0], dh.rot_z(2.5)))
    w.add_robot("c", RX, pose_matrix([0.1, 0.6, 0.0], dh.rot_z(-1.7)))
    w.add_sphere("ball", 0.05, np.array([0.3, 0.2, 0.4]))
    w.add_box("box", np.array([0.05, 0.1, 0.02]), np.array([0.3, -0.3, 0.3]))
    return w


def _brute(world: PybulletWorld, q: np.ndarray, body: str, cap: float) -> float:
    """min over all link pairs of the full pair values (no pruning), capped."""
    world.set_configuration("a", q)
    pairs = world._all_pairs("a", body)
    assert pairs is not None
    vals = world._pair_bounds("a", body, pairs, np.inf)
    assert vals is not None
    return float(min(cap, vals.min()))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), cap=st.sampled_from([0.05, 0.3, 1.0]))
def test_branch_and_bound_is_the_minimum_over_all_link_pairs(world: PybulletWorld, seed: int,
                                                              cap: float) -> None:
    rng = np.random.default_rng(seed)
    saved = world.configuration("a")
    for other in ("b", "c"):
        world.set_configuration(other, rng.uniform(RX.lower, RX.upper))
    qs = rng.uniform(RX.lower, RX.upper, size=(4, 6))
    bodies = ["b", "c", "ball"]
    fast = world.min_distances("a", qs, bodies, cap)
    try:
        ref = np.array([[_brute(world, q, b, cap) for b in bodies] for q in qs])
    finally:
        world.set_configuration("a", saved)
    finite = np.isfinite(ref)
    np.testing.assert_array_equal(np.isfinite(fast), finite)     # -inf (no estimate) alike
    np.testing.assert_allclose(fast[finite], ref[finite], rtol=0.0, atol=1e-12)


def _context(world: PybulletWorld, configs: np.ndarray, reach: np.ndarray, point: int,
             points: str) -> EvalContext:
    n = configs.shape[0]
    return EvalContext(robot="a", arm=PybulletArm(RX, name="a"), point=point, selected=False,
                       times=0.05 * np.arange(n), positions=np.zeros((n, 3)),
                       std=np.zeros((n, 3)), rotations=None,
                       configs=np.where(reach[:, None], configs, np.nan), reachable=reach,
                       joint_velocity=np.zeros_like(configs), past_configs=[], world=world,
                       distance_points=points)


@pytest.mark.parametrize("points", ["all", "ends"])
def test_prefetched_distances_are_each_contexts_own(world: PybulletWorld, points: str) -> None:
    rng = np.random.default_rng(11)
    reach = [np.array([True, True, False, True, True]), np.ones(5, dtype=bool),
             np.array([True, False, False, False, False])]
    configs = [rng.uniform(RX.lower, RX.upper, size=(5, 6)) for _ in reach]
    pairs = list(enumerate(zip(configs, reach, strict=True)))
    batched = [_context(world, c, r, k, points) for k, (c, r) in pairs]
    single = [_context(world, c, r, k, points) for k, (c, r) in pairs]
    queried = prefetch_distances(batched, 1.0)
    rows = sum(int(c.distance_rows().size) for c in single)
    assert queried == rows == (4 + 5 + 1 if points == "all" else 2 + 2 + 1)
    for b, s in zip(batched, single, strict=True):
        for cap in (1.0, 0.05):        # a smaller range reads the stored values, capped
            names_b, d_b = b.body_distances(cap)
            names_s, d_s = s.body_distances(cap)
            assert names_b == names_s == ["b", "c", "ball", "box"]
            np.testing.assert_array_equal(d_b, d_s)
        assert np.isnan(d_b[~b.reachable]).all()
    assert prefetch_distances(batched, 1.0) == 0      # already stored: nothing queried


def test_prefetch_refuses_contexts_of_several_robots(world: PybulletWorld) -> None:
    c = _context(world, np.zeros((2, 6)), np.ones(2, dtype=bool), 0, "all")
    with pytest.raises(ValueError, match="one robot and world"):
        prefetch_distances([c, replace(c, robot="b")], 1.0)
