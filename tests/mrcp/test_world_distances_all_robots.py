"""The evaluation's distances of all robots in one compiled call (issue #17 §4): the
batched world queries give the per-robot queries' values bit for bit — per body
(``min_distances_many``) and nearest of a set of bodies (``nearest_distances_many``, one
branch and bound over the whole set) — the contexts store what they would have computed
themselves, and a kernel with the batch makes exactly the cycles of one without it."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.mrcp import dh
from vasim.mrcp import world as world_module
from vasim.mrcp.backend import PybulletArm, PybulletWorld, pose_matrix
from vasim.mrcp.indices.base import EvalContext, NearestQuery, prefetch_distances_all
from vasim.mrcp.kernel import KernelConfig, MRCPKernel

RX = dh.load_robot("rx60b")
ROBOTS = ("a", "b", "c")


def _station(**kwargs: float | bool) -> PybulletWorld:
    w = PybulletWorld(**kwargs)  # type: ignore[arg-type]
    w.add_robot("a", RX, pose_matrix([0.0, 0.0, 0.0]))
    w.add_robot("b", RX, pose_matrix([0.55, 0.1, 0.0], dh.rot_z(2.5)))
    w.add_robot("c", RX, pose_matrix([0.1, 0.6, 0.0], dh.rot_z(-1.7)))
    w.add_sphere("ball", 0.05, np.array([0.3, 0.2, 0.4]))
    w.add_box("box", np.array([0.05, 0.1, 0.02]), np.array([0.3, -0.3, 0.3]))  # pybullet
    return w


@pytest.fixture(scope="module")
def world() -> PybulletWorld:
    return _station()


def _pose_randomly(w: PybulletWorld, rng: np.random.Generator) -> None:
    """Robots near each other (home +- 1 rad: many pairs within centimetres, some
    penetrating, so every branch of the bounds is taken)."""
    for r in ROBOTS:
        w.set_configuration(r, np.clip(RX.home + rng.uniform(-1.0, 1.0, 6), RX.lower,
                                       RX.upper))


def _others(robot: str) -> list[str]:
    return [b for b in (*ROBOTS, "ball", "box") if b != robot]


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), cap=st.sampled_from([0.05, 0.3, 1.0]))
def test_all_robots_in_one_call_equal_each_robots_call_bit_for_bit(
        world: PybulletWorld, seed: int, cap: float) -> None:
    rng = np.random.default_rng(seed)
    _pose_randomly(world, rng)
    queries = [(r, np.clip(RX.home + rng.uniform(-1.0, 1.0, (int(rng.integers(1, 6)), 6)),
                           RX.lower, RX.upper), _others(r)) for r in ROBOTS]
    queries.append(("b", queries[0][1][:0], _others("b")))        # no rows
    queries.append(("c", queries[2][1], ["ball", "a"]))            # a subset, another order
    many = world.min_distances_many(queries, cap)
    for (robot, qs, bodies), got in zip(queries, many, strict=True):
        one = world.min_distances(robot, qs, bodies, cap)
        assert got.shape == one.shape == (qs.shape[0], len(bodies))
        assert np.array_equal(got, one)          # bit for bit (inf and -inf alike)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_nearest_of_a_set_is_the_row_minimum_of_the_per_body_values(
        world: PybulletWorld, seed: int) -> None:
    rng = np.random.default_rng(seed)
    _pose_randomly(world, rng)
    caps = [1.0, 0.05, 0.3, 0.2]
    queries = []
    for r in ROBOTS:
        qs = np.clip(RX.home + rng.uniform(-1.0, 1.0, (4, 6)), RX.lower, RX.upper)
        robots = [b for b in ROBOTS if b != r]
        groups = [_others(r), ["ball"], [*robots, "box"], []]      # all, one, mixed, none
        queries.append((r, qs, groups))
    got = world.nearest_distances_many(queries, caps)
    below = 0
    for (robot, qs, groups), values in zip(queries, got, strict=True):
        assert values.shape == (4, len(caps))
        for g, (bodies, cap) in enumerate(zip(groups, caps, strict=True)):
            ref = (world.min_distances(robot, qs, bodies, cap).min(axis=1) if bodies
                   else np.full(4, cap))
            assert np.array_equal(values[:, g], ref)
            below += int(np.sum(ref < cap))
    assert below > 0            # not only the caps: some bodies were within range


def test_the_exact_fallbacks_give_the_same_values() -> None:
    """Worlds that refine penetrations in pybullet (``refine_below``) or ask pybullet
    everything answer the batched calls as their own ``min_distances`` does."""
    rng = np.random.default_rng(5)
    for kwargs in ({"refine_below": 0.0}, {"compiled_distances": False}):
        w = _station(**kwargs)
        _pose_randomly(w, rng)
        qs = np.clip(RX.home + rng.uniform(-1.0, 1.0, (2, 6)), RX.lower, RX.upper)
        (got,) = w.min_distances_many([("a", qs, _others("a"))], 0.3)
        assert np.array_equal(got, w.min_distances("a", qs, _others("a"), 0.3))
        (near,) = w.nearest_distances_many([("a", qs, [_others("a")])], [0.3])
        assert np.array_equal(near[:, 0], w.min_distances("a", qs, _others("a"), 0.3)
                              .min(axis=1))
        w.close()


def test_bad_queries_name_the_problem(world: PybulletWorld) -> None:
    q = RX.home[None, :]
    with pytest.raises(KeyError, match="nobody"):
        world.min_distances_many([("a", q, ["b", "nobody"])], 1.0)
    with pytest.raises(KeyError, match="nobody"):
        world.nearest_distances_many([("a", q, [["nobody"]])], [1.0])
    with pytest.raises(ValueError, match=r"a: configs must have shape \(N, 6\)"):
        world.min_distances_many([("a", np.zeros((2, 5)), ["b"])], 1.0)
    with pytest.raises(ValueError, match="row 1"):
        world.nearest_distances_many([("a", np.array([RX.home, RX.home * np.nan]),
                                       [["b"]])], [1.0])
    with pytest.raises(ValueError, match="2 groups for 1 max_distances"):
        world.nearest_distances_many([("a", q, [["b"], ["c"]])], [1.0])


def _context(w: PybulletWorld, robot: str, configs: np.ndarray, reach: np.ndarray,
             point: int, points: str) -> EvalContext:
    n = configs.shape[0]
    return EvalContext(robot=robot, arm=PybulletArm(RX, name=robot), point=point,
                       selected=False, times=0.05 * np.arange(n), positions=np.zeros((n, 3)),
                       std=np.zeros((n, 3)), rotations=None,
                       configs=np.where(reach[:, None], configs, np.nan), reachable=reach,
                       joint_velocity=np.zeros_like(configs), past_configs=[], world=w,
                       distance_points=points)


@pytest.mark.parametrize("points", ["all", "ends"])
def test_prefetch_for_all_robots_stores_each_contexts_own_values(world: PybulletWorld,
                                                                 points: str) -> None:
    rng = np.random.default_rng(17)
    _pose_randomly(world, rng)
    reach = [np.array([True, True, False, True, True]), np.ones(5, dtype=bool),
             np.array([True, False, False, False, False]), np.zeros(5, dtype=bool)]
    specs = [(r, k, np.clip(RX.home + rng.uniform(-1.0, 1.0, (5, 6)), RX.lower, RX.upper),
              reach[(i + k) % 4]) for i, r in enumerate(ROBOTS) for k in range(3)]
    batched = [_context(world, r, c, m, k, points) for r, k, c, m in specs]
    single = [_context(world, r, c, m, k, points) for r, k, c, m in specs]
    nearest = [NearestQuery(1.0, exclude=frozenset({"ball"})),
               NearestQuery(0.05, only=frozenset({"ball"}))]
    queried = prefetch_distances_all(batched, 1.0, nearest)
    assert queried == 2 * sum(int(c.distance_rows().size) for c in single)  # per body, nearest
    for b, s in zip(batched, single, strict=True):
        for cap in (1.0, 0.05):
            names_b, d_b = b.body_distances(cap)
            names_s, d_s = s.body_distances(cap)
            assert names_b == names_s == _others(b.robot)
            assert np.array_equal(d_b, d_s, equal_nan=True)
        for q in nearest:           # stored by the batch vs computed from body_distances
            assert ("nearest", q) in b._memo and ("nearest", q) not in s._memo
            assert np.array_equal(b.nearest_distances(q), s.nearest_distances(q),
                                  equal_nan=True)
    assert prefetch_distances_all(batched, 1.0, nearest) == 0     # all stored already


def test_prefetch_refuses_contexts_of_several_worlds(world: PybulletWorld) -> None:
    other = _station()
    c = [_context(w, "a", np.tile(RX.home, (2, 1)), np.ones(2, dtype=bool), 0, "all")
         for w in (world, other)]
    with pytest.raises(ValueError, match="one world"):
        prefetch_distances_all(c, 1.0)
    other.close()


def _bench() -> tuple[object, object]:
    root = Path(__file__).resolve().parents[2]
    if str(root) not in sys.path:
        sys.path.insert(0, str(root))
    from bench.mrcp import rx60b_station, six_indices

    return rx60b_station, six_indices


def test_kernel_cycles_are_the_same_with_one_call_or_one_per_robot(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """8 RX60B x 6 indices (CR and visibility read the nearest bodies, the view cone is a
    sphere) x 6 task points: every command, event and index value bit for bit, and the
    batched evaluation makes one compiled distance call per cycle."""
    rx60b_station, six_indices = _bench()
    calls: list[int] = []
    compiled = world_module.swept_nearest_many

    def counted(*args: object) -> None:
        compiled(*args)
        out, cutoffs = np.asarray(args[-1]), np.asarray(args[6])
        calls.append(int(np.sum(out < cutoffs[None, :])))     # values within range

    monkeypatch.setattr(world_module, "swept_nearest_many", counted)
    cycles = 8
    records = []
    for batched in (True, False):
        st_ = rx60b_station(8)  # type: ignore[operator]
        cfg = KernelConfig(indices=six_indices(st_), ntt_threshold=1e9,  # type: ignore[operator]
                           batch_distances=batched)
        k = MRCPKernel(st_.arms, st_.world, st_.task_points, next(iter(st_.arms)), 0,
                       st_.start, config=cfg)
        records.append([k.step((i + 1) * cfg.dt, st_.path((i + 1) * cfg.dt))
                        for i in range(cycles)])
        if batched:
            assert len(calls) == cycles          # one compiled call a cycle, all robots
    assert len(calls) == cycles                  # none without the batch
    compared = 0
    for a, b in zip(*records, strict=True):
        assert a.events == b.events
        assert all(np.array_equal(a.commands[r], b.commands[r]) for r in a.commands)
        assert a.evaluations.keys() == b.evaluations.keys()
        for key, ev in a.evaluations.items():
            assert ev.values == b.evaluations[key].values
            assert ev.texec == b.evaluations[key].texec
            compared += 1
    assert compared == cycles * (1 + 7 * 5)
    assert min(calls) > 0          # every cycle has bodies within range, not only caps


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), cutoff=st.sampled_from([2e-5, 0.05, 0.3, np.inf]),
       window=st.sampled_from([1e-3, 0.02, np.inf]))
def test_pair_bounds_of_all_bodies_in_one_call_equal_one_call_per_body(
        world: PybulletWorld, seed: int, cutoff: float, window: float) -> None:
    rng = np.random.default_rng(seed)
    _pose_randomly(world, rng)
    for a in ROBOTS:
        many = world._pair_bounds_each(a, _others(a), cutoff, window)
        assert sorted(many) == sorted(b for b in _others(a) if b != "box")   # box: no model
        for b, got in many.items():
            pairs = world._all_pairs(a, b)
            assert pairs is not None
            one = world._pair_bounds(a, b, pairs, cutoff, window)
            assert one is not None and np.array_equal(got, one)


def test_collision_checks_agree_with_pybullets_whole_body_query() -> None:
    """``in_collision`` (the model's bounds of all bodies in one call choosing which bodies
    pybullet is asked about) against pybullet's own answer for every body, over random
    poses of which some collide."""
    import pybullet as pb

    w = _station()
    rng = np.random.default_rng(23)
    hits = 0
    for _ in range(40):
        _pose_randomly(w, rng)
        for a in ROBOTS:
            body = w.body_id(a)
            touching = any(p[8] <= 0.0 for other in _others(a)
                           for p in pb.getClosestPoints(body, w.body_id(other), 0.0,
                                                        physicsClientId=w.client_id))
            if touching:
                assert w.in_collision(a)
                hits += 1
            elif not w.in_collision(a):
                continue
            else:       # no other body touches: the robot touches itself
                pairs = w.self_collision_pairs(a)
                assert any(w.links_in_collision(body, i, body, j) for i, j in pairs)
    assert hits > 0
    w.close()
