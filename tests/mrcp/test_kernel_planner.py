"""Action planner forces, the candidate hierarchy, and safe candidate motion."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.mrcp.planar import PlanarArm, PlanarWorld, Sphere
from vasim.mrcp.planner import (
    Mover,
    ObstacleMemory,
    PlannerParams,
    attraction,
    fallback_steps,
    guidance,
    move_candidate,
    repulsion,
    repulsion_magnitude,
)
from vasim.mrcp.select import candidate_hierarchy


def test_attraction_is_greedy_and_bounded() -> None:
    np.testing.assert_allclose(attraction(np.array([0.0, 0.3, 0.4]), 0.1), [0.0, 0.06, 0.08])
    np.testing.assert_allclose(attraction(np.array([0.01, 0.0, 0.0]), 0.1), [0.01, 0.0, 0.0])


def test_repulsion_magnitude_shape() -> None:
    # h = ΔR / (1 + |d + offset|^l) in d_scale units (seed eq. 4.11).
    assert repulsion_magnitude(0.0, 0.01, 2.0) == pytest.approx(0.01)
    assert repulsion_magnitude(1.0, 0.01, 2.0) == pytest.approx(0.005)
    assert repulsion_magnitude(2.0, 0.01, 1.0) == pytest.approx(0.01 / 3)
    assert repulsion_magnitude(2.0, 0.01, 4.0) == pytest.approx(0.01 / 17)
    assert repulsion_magnitude(1.0, 0.01, 2.0, d_offset=1.0) == pytest.approx(0.01 / 5)
    assert repulsion_magnitude(0.1, 0.01, 2.0, d_scale=0.1) == pytest.approx(0.005)


def test_repulsion_acts_only_while_approaching() -> None:
    p = PlannerParams(dr_max=0.01, d_scale=0.05)
    u0 = np.array([1.0, 0.0, 0.0])
    u1 = np.array([np.cos(0.1), np.sin(0.1), 0.0])
    assert np.all(repulsion(u1, u0, 0.05, 0.04, p) == 0.0)     # moving away
    f = repulsion(u1, u0, 0.05, 0.06, p)
    assert np.linalg.norm(f) == pytest.approx(0.01 / 2)        # h at d = d_scale
    du = (u1 - u0) / np.linalg.norm(u1 - u0)
    np.testing.assert_allclose(f / np.linalg.norm(f), -du)
    head_on = repulsion(u0, u0, 0.05, 0.06, p)                 # no Δû: straight away
    np.testing.assert_allclose(head_on / np.linalg.norm(head_on), -u0)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3),
       st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3))
def test_guidance_never_exceeds_dr_max(a: list[float], r: list[float]) -> None:
    p = PlannerParams(dr_max=0.01, w_rand=0.2)
    f = guidance(np.array(a), [np.array(r)], p, np.random.default_rng(0))
    assert np.linalg.norm(f) <= 0.01 + 1e-12


def test_random_force_breaks_a_deadlock() -> None:
    p = PlannerParams(dr_max=0.01, w_rand=0.1)
    f = guidance(np.array([0.01, 0, 0]), [np.array([-0.01, 0, 0])], p,
                 np.random.default_rng(1))
    assert np.linalg.norm(f) == pytest.approx(0.001)
    with pytest.raises(ValueError, match="w_rand"):
        PlannerParams(w_rand=0.5)
    with pytest.raises(ValueError, match="shape_l"):
        PlannerParams(shape_l=0.5)
    with pytest.raises(ValueError, match="stall_cycles"):
        PlannerParams(stall_cycles=0)


def test_hierarchy_by_tus_with_distinct_points() -> None:
    tus = {("a", 1): 2.0, ("a", 2): 1.0, ("b", 1): 3.0, ("b", 2): 0.5, ("c", 2): -1.0}
    order = candidate_hierarchy(tus, ["a", "b", "c"], reserved=[0])
    assert [(x.robot, x.point) for x in order] == [("b", 1), ("a", 2), ("c", None)]
    order = candidate_hierarchy(tus, ["a", "b"], reserved=[1])
    assert [(x.robot, x.point) for x in order] == [("a", 2), ("b", None)]


def test_candidate_reaches_its_goal_and_never_collides() -> None:
    a = PlanarArm("a", radius=0.02)
    world = PlanarWorld({"a": a}, {"a": np.array([0.0, 1.5, 0.0])},
                        {"ball": Sphere(np.array([0.2, 0.36, 0.0]), 0.03)})
    goal = np.array([0.1, 0.4, 0.0])
    p = PlannerParams(dr_max=0.01)
    mem = ObstacleMemory()
    rng = np.random.default_rng(0)
    q = world.configuration("a")
    for _ in range(300):
        q = move_candidate(Mover(world, a, "a"), q, goal, None, ["ball"], mem, p, 0.018, rng)
        assert not world.in_collision("a")
        assert np.all(q >= a.lower) and np.all(q <= a.upper)
    assert np.linalg.norm(a.tcp_pose(q)[0] - goal) < 1e-6


def _waiting_at_the_margin(goal_side: float) -> tuple[PlanarArm, PlanarWorld, np.ndarray,
                                                      np.ndarray, PlannerParams]:
    """An arm whose TCP end waits exactly ``safety_margin`` in front of a sphere (along its
    last link), and a goal ``goal_side`` beside the sphere's centre, 2 cm beyond it."""
    a = PlanarArm("a", radius=0.02)
    q0 = np.array([0.0, 1.5, 0.0])
    _, elbow, tcp = a.points(q0)
    ahead = (tcp - elbow) / np.linalg.norm(tcp - elbow)
    side = np.array([-ahead[1], ahead[0], 0.0])
    p = PlannerParams(dr_max=0.01)
    radius = 0.03
    centre = tcp + (a.radius + p.safety_margin + radius) * ahead
    world = PlanarWorld({"a": a}, {"a": q0}, {"ball": Sphere(centre, radius)})
    goal = centre + goal_side * side + 0.02 * ahead
    return a, world, q0, goal, p


@pytest.mark.parametrize("goal_side", [0.08, -0.08])
def test_candidate_at_the_margin_slides_around_the_obstacle(goal_side: float) -> None:
    a, world, q0, goal, p = _waiting_at_the_margin(goal_side)
    d0 = world.min_distance("a", "ball").distance
    assert d0 == pytest.approx(p.safety_margin, abs=1e-12)
    assert a.ik(goal) is not None
    # The plain guidance step (attraction only: no approach history yet) would cross the
    # margin, so the old rule rejected it and the candidate stalled at q0 for ever.
    tcp = a.tcp_pose(q0)[0]
    plain = a.ik(tcp + attraction(goal - tcp, p.dr_max), None, q0)
    assert plain is not None
    assert world.min_distances("a", plain[None, :], ["ball"])[0, 0] < p.safety_margin
    mem = ObstacleMemory()
    rng = np.random.default_rng(0)
    q = q0
    for _ in range(p.stall_cycles - 1):     # a rejection may be transient: it waits first
        q = move_candidate(Mover(world, a, "a"), q, goal, None, ["ball"], mem, p, 0.018, rng)
        np.testing.assert_array_equal(q, q0)
    q = move_candidate(Mover(world, a, "a"), q, goal, None, ["ball"], mem, p, 0.018, rng)
    assert np.linalg.norm(a.tcp_pose(q)[0] - tcp) > 0.5 * p.dr_max     # then it slid
    # ... and keeps going around the sphere without ever crossing the margin (100 cycles of
    # at most 1 cm for a ~11 cm detour).
    for _ in range(100):
        assert world.min_distance("a", "ball").distance >= min(d0, p.safety_margin) - 1e-12
        if np.linalg.norm(a.tcp_pose(q)[0] - goal) < 1e-9:
            break
        q = move_candidate(Mover(world, a, "a"), q, goal, None, ["ball"], mem, p, 0.018, rng)
    assert np.linalg.norm(a.tcp_pose(q)[0] - goal) < 1e-9


def test_candidate_at_the_margin_retreats_from_a_goal_straight_behind() -> None:
    a, world, q0, _, p = _waiting_at_the_margin(0.0)
    tcp = a.tcp_pose(q0)[0]
    prox = world.min_distance("a", "ball")
    normal = (prox.point_b - prox.point_a) / np.linalg.norm(prox.point_b - prox.point_a)
    goal = tcp + 0.2 * normal                   # straight through the sphere: nothing to slide
    assert fallback_steps(attraction(goal - tcp, p.dr_max), normal)[0] == pytest.approx(
        -p.dr_max * normal)
    mem = ObstacleMemory()
    rng = np.random.default_rng(0)
    q = q0
    for _ in range(p.stall_cycles):
        q = move_candidate(Mover(world, a, "a"), q, goal, None, ["ball"], mem, p, 0.018, rng)
    assert world.min_distance("a", "ball").distance > prox.distance + 0.5 * p.dr_max
    for _ in range(60):
        q = move_candidate(Mover(world, a, "a"), q, goal, None, ["ball"], mem, p, 0.018, rng)
        assert world.min_distance("a", "ball").distance >= p.safety_margin - 1e-12
        assert not world.in_collision("a")


def test_fallback_steps_slide_then_retreat() -> None:
    n = np.array([0.0, 1.0, 0.0])
    slide, retreat = fallback_steps(np.array([0.006, 0.008, 0.0]), n)
    np.testing.assert_allclose(slide, [0.006, 0.0, 0.0])              # tangent plane of n
    np.testing.assert_allclose(retreat, [0.0, -0.01, 0.0])            # |F| away from the body
    away = fallback_steps(np.array([0.006, -0.008, 0.0]), n)[0]        # not approaching: kept
    np.testing.assert_allclose(away, [0.006, -0.008, 0.0])
    assert len(fallback_steps(np.array([0.0, 0.01, 0.0]), n)) == 1     # head-on: retreat only
