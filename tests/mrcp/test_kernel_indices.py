"""Suitability indices: RJ (Fig. 3.3), measures, ψ/Θ on the analytic planar arm, CR, cone,
visibility, force-torque, and the registry."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.mrcp.planar import PlanarArm, PlanarWorld, Sphere, make_context
from vasim.mrcp.indices import INDICES, IndexRegistry, Wrench
from vasim.mrcp.indices.collision import CollisionRiskIndex, impact_time
from vasim.mrcp.indices.cone import ConeSector, ToolCone, ToolConeIndex
from vasim.mrcp.indices.dexterity import AnisotropicDexterityIndex
from vasim.mrcp.indices.force_torque import ForceTorqueIndex, ft_eval
from vasim.mrcp.indices.joint_limits import (
    JointLimitIndex,
    jeval,
    joint_distance,
    modulation_b,
    rj_trajectory,
)
from vasim.mrcp.indices.measures import (
    condition_number,
    directional_manipulability,
    isotropy,
    manipulability,
    mean_trace,
    order_independent_manipulability,
    reciprocal_condition_number,
    sigma_min,
)
from vasim.mrcp.indices.visibility import VisibilityIndex

LO, HI = -2.79, 2.79   # RX60B joint 1 (Table 3.1)


# ---------------------------------------------------------------- RJ, Fig. 3.3
@pytest.mark.parametrize("b", [1, 2, 3, 4, 5, 6])
def test_fig_3_3_curves(b: int) -> None:
    theta = np.linspace(LO, HI, 2001)
    j = jeval(joint_distance(theta, LO, HI), b)
    assert j[0] == pytest.approx(0.0) and j[-1] == pytest.approx(0.0)
    assert j[1000] == pytest.approx(1.0)                       # mid-range
    np.testing.assert_allclose(j, j[::-1], atol=1e-12)       # symmetric about the centre
    assert np.all(np.diff(j[:1001]) >= -1e-15)               # rises toward the centre
    # Jeval = 1/2 exactly where dist = 0.5^b (analytic: (1 - cos(π/2))/2).
    half = LO + (0.5 ** b) * (HI - LO) / 2
    assert float(jeval(joint_distance(half, LO, HI), b)) == pytest.approx(0.5, abs=1e-12)


def test_larger_b_alarms_later() -> None:
    theta = np.linspace(LO + 0.05, -0.05, 50)      # strictly inside, off-centre
    curves = np.array([jeval(joint_distance(theta, LO, HI), b) for b in range(1, 7)])
    assert np.all(np.diff(curves, axis=0) > 0.0)


def test_b_modulated_by_approach_speed() -> None:
    lo, hi, vmax = np.array([-1.0]), np.array([1.0]), np.array([2.0])
    th = np.array([0.5])                                          # nearer the upper limit
    assert modulation_b(th, np.array([0.0]), lo, hi, vmax)[0] == 6.0
    assert modulation_b(th, np.array([2.0]), lo, hi, vmax)[0] == 1.0
    assert modulation_b(th, np.array([1.0]), lo, hi, vmax)[0] == pytest.approx(3.5)
    assert modulation_b(th, np.array([-2.0]), lo, hi, vmax)[0] == 6.0   # moving away
    with pytest.raises(ValueError, match="b must be >= 1"):
        jeval(0.5, 0.5)


def test_prediction_error_shrinks_the_range() -> None:
    configs = np.array([[0.0], [0.5], [0.9]])
    reach = np.ones(3, dtype=bool)
    b = np.ones((3, 1))
    none = rj_trajectory(configs, reach, np.array([-1.0]), np.array([1.0]), b, np.zeros((3, 1)))
    errs = np.array([[0.0], [0.2], [-0.2]])                  # either sign shrinks both sides
    shrunk = rj_trajectory(configs, reach, np.array([-1.0]), np.array([1.0]), b, errs)
    # Analytic: w = (1, 1/2, 1/3); Jeval(d) = (1 - cos(π d))/2 with d = 1, 0.5, 0.1 (none)
    # and d = 1, 0.3/0.8, 0 (ranges [-0.8, 0.8]: 0.9 is now beyond the limit).
    w = np.array([1.0, 0.5, 1 / 3])
    exp_none = (w @ ((1 - np.cos(np.pi * np.array([1.0, 0.5, 0.1]))) / 2)) / w.sum()
    exp_shr = (w @ ((1 - np.cos(np.pi * np.array([1.0, 0.375, 0.0]))) / 2)) / w.sum()
    assert none == pytest.approx(exp_none)
    assert shrunk == pytest.approx(exp_shr)
    unreachable = rj_trajectory(configs, np.array([True, True, False]), np.array([-1.0]),
                                np.array([1.0]), b, np.zeros((3, 1)))
    assert unreachable < none


def test_rj_index_falls_toward_a_joint_limit() -> None:
    arm = PlanarArm("a", lower=np.array([-2.8, 0.2, -0.2]), upper=np.array([2.8, 2.8, 0.2]))
    world = PlanarWorld({"a": arm}, {"a": np.array([0.0, 1.5, 0.0])})
    ix = JointLimitIndex()
    values = []
    for reach in (0.3, 0.4, 0.5):                            # stretching: θ2 -> its 0.2 limit
        pos = np.array([[reach + 0.02 * k, 0.0, 0.0] for k in range(4)])
        values.append(ix.evaluate(make_context(arm, world, pos)))
    assert values[0] > values[1] > values[2] > 0.0


# ---------------------------------------------------------------- measures
def _jxy(arm: PlanarArm, q: np.ndarray) -> np.ndarray:
    return arm.jacobian(q)[:2, :2]


@settings(max_examples=40, deadline=None)
@given(st.floats(-3.0, 3.0), st.floats(-3.0, 3.0))
def test_measures_on_the_two_link_arm(t1: float, t2: float) -> None:
    arm = PlanarArm("a")
    j = _jxy(arm, np.array([t1, t2, 0.0]))
    # Analytic: det J_xy = l1 l2 sin θ2.
    # (sqrt of a rounded determinant: ~1e-9 absolute at the singularity)
    assert float(manipulability(j)) == pytest.approx(arm.l1 * arm.l2 * abs(np.sin(t2)),
                                                     abs=1e-8)
    assert float(order_independent_manipulability(j)) == pytest.approx(
        float(manipulability(j)) ** 0.5, abs=1e-7)
    assert 0.0 <= float(isotropy(j)) <= 1.0 + 1e-12
    assert 0.0 <= float(reciprocal_condition_number(j)) <= 1.0 + 1e-12
    s = np.linalg.svd(j, compute_uv=False)
    assert float(sigma_min(j)) == pytest.approx(s[-1], abs=1e-12)
    assert float(mean_trace(j)) == pytest.approx(np.mean(s ** 2))
    if s[-1] > 1e-9:
        assert float(condition_number(j)) == pytest.approx(s[0] / s[-1])


@settings(max_examples=40, deadline=None)
@given(st.floats(-3.0, 3.0), st.floats(0.1, 3.0), st.floats(0.0, 2 * np.pi))
def test_psi_is_the_reciprocal_minimum_norm_joint_speed(t1: float, t2: float, a: float) -> None:
    j = _jxy(PlanarArm("a"), np.array([t1, t2, 0.0]))
    u = np.array([np.cos(a), np.sin(a)])
    # Independent: the least-norm joint velocity producing unit TCP speed along u is J⁺u.
    expected = 1.0 / np.linalg.norm(np.linalg.pinv(j) @ u)
    assert float(directional_manipulability(j, u[None, :])[0]) == pytest.approx(expected)


def test_psi_is_zero_along_a_lost_direction() -> None:
    arm = PlanarArm("a")
    j = _jxy(arm, np.array([0.3, 0.0, 0.0]))                   # links aligned
    radial = np.array([[np.cos(0.3), np.sin(0.3)]])
    tangential = np.array([[-np.sin(0.3), np.cos(0.3)]])
    assert directional_manipulability(j, radial)[0] == 0.0
    # Both columns are tangential, (l1 + l2) t and l2 t: the one singular value is their norm.
    assert directional_manipulability(j, tangential)[0] == pytest.approx(
        np.hypot(arm.l1 + arm.l2, arm.l2))


# ---------------------------------------------------------------- Θ on the planar arm
def _theta_along(direction: np.ndarray, t2: float, std: float = 0.002) -> float:
    arm = PlanarArm("a")
    q = np.array([0.0, t2, 0.0])
    world = PlanarWorld({"a": arm}, {"a": q})
    p0, _ = arm.tcp_pose(q)
    pos = p0[None, :] + 0.01 * np.arange(4)[:, None] * direction[None, :]
    stds = np.full((4, 3), std)
    stds[0] = 0.0
    ctx = make_context(arm, world, pos, std=stds, seed=q)
    return AnisotropicDexterityIndex(rows=(0, 1)).evaluate(ctx)


def test_theta_drops_near_link_alignment_in_the_lost_direction() -> None:
    """Fig. 3.11 analogue: Θ along the radial direction collapses as the links align
    (workspace-boundary singularity, det J = l1 l2 sin θ2 -> 0); tangentially it does not."""
    radial = np.array([1.0, 0.0, 0.0])     # θ1 = 0: the arm points along x
    tangential = np.array([0.0, 1.0, 0.0])
    far = _theta_along(radial, 1.5)
    near = _theta_along(-radial, 0.25)       # retracting would re-open: move inward is safe
    at_edge = _theta_along(radial, 0.25)
    assert at_edge < 0.5 * far
    assert _theta_along(tangential, 0.25) > 0.8 * _theta_along(tangential, 1.5)
    assert near > 0.0


def test_theta_threshold_zeroes_near_singular_samples() -> None:
    arm = PlanarArm("a")
    q = np.array([0.0, 0.4, 0.0])
    world = PlanarWorld({"a": arm}, {"a": q})
    p0, _ = arm.tcp_pose(q)
    pos = p0[None, :] + 0.005 * np.arange(4)[:, None] * np.array([0.0, 1.0, 0.0])[None, :]
    ctx = make_context(arm, world, pos, seed=q)
    assert AnisotropicDexterityIndex(rows=(0, 1), threshold_rows=(0, 1)).evaluate(ctx) > 0.0
    # σ_min of J_xy here is below l1 l2 sin(0.4) / σ_max < 0.1: a 0.2 threshold kills it.
    assert AnisotropicDexterityIndex(rows=(0, 1), threshold_rows=(0, 1),
                                     sigma_min_threshold=0.2).evaluate(ctx) == 0.0


def test_theta_is_psi_for_a_certain_straight_trajectory() -> None:
    """With zero uncertainty Θ is the w_k-weighted ψ along the segments (analytic check)."""
    arm = PlanarArm("a")
    q = np.array([0.2, 1.2, 0.0])
    world = PlanarWorld({"a": arm}, {"a": q})
    p0, _ = arm.tcp_pose(q)
    d = np.array([0.6, 0.8, 0.0])
    pos = p0[None, :] + 0.004 * np.arange(4)[:, None] * d[None, :]
    ctx = make_context(arm, world, pos, seed=q)
    psi = [float(directional_manipulability(_jxy(arm, ctx.configs[k]), d[None, :2])[0])
           for k in range(3)]
    w = np.array([1.0, 0.5, 1 / 3])
    expected = float(w @ psi / w.sum())
    assert AnisotropicDexterityIndex(rows=(0, 1)).evaluate(ctx) == pytest.approx(expected,
                                                                                 rel=1e-9)


# ---------------------------------------------------------------- CR
def test_impact_time_analytic() -> None:
    t = np.array([0.0, 0.1, 0.2])
    assert impact_time(t, np.array([0.3, 0.2, 0.1]), 5.0) == pytest.approx(0.3)
    assert impact_time(t, np.array([0.3, 0.3, 0.4]), 5.0) == 5.0        # not closing
    # The second segment closes 0.26 m in 0.1 s: contact 0.25/2.6 s after t = 0.1.
    assert impact_time(t, np.array([0.3, 0.25, -0.01]), 5.0) == pytest.approx(0.1 + 0.25 / 2.6)
    assert impact_time(t, np.array([-0.01, 0.2, 0.3]), 5.0) == 0.0


def test_cr_on_a_robot_moving_toward_a_sphere() -> None:
    arm = PlanarArm("a", radius=0.01)
    world = PlanarWorld({"a": arm}, {"a": np.array([0.0, 1.2, 0.0])},
                        {"ball": Sphere(np.array([0.0, 0.0, 0.3]), 0.05)})
    pos = np.array([[0.3, 0.2, 0.0 + 0.01 * k] for k in range(4)])  # lift rises 0.2 m/s
    ctx = make_context(arm, world, pos, dt=0.05)
    ix = CollisionRiskIndex(t_max=10.0)
    # The shoulder segment sits on the lift axis under the ball: gap = 0.3 - z - 0.06.
    assert ix.evaluate(ctx) == pytest.approx((0.3 - 0.06) / 0.2, rel=1e-6)
    assert world.configuration("a")[1] == 1.2                    # the pose was restored
    combined = ix.combine({("a", 0): 1.0, ("b", 0): 2.0})
    assert combined == {("a", 0): 0.5, ("b", 0): 1.0}


# ---------------------------------------------------------------- cone, visibility, FT
def test_cone_margin_and_sectors() -> None:
    cone = ToolCone(np.zeros(3), np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0]),
                    (ConeSector(0.0, np.pi, 0.8, 1.0), ConeSector(np.pi, 2 * np.pi, 0.6, 1.0)))
    assert cone.margin(np.array([0.0, 0.0, -0.1])) == pytest.approx(1.0)
    half = np.arctan(0.8) / 2                                     # azimuth 0: r = a = 0.8
    tip = 0.1 * np.array([np.sin(half), 0.0, -np.cos(half)])
    assert cone.margin(tip) == pytest.approx(0.5)
    # Azimuth π lies in the a = 0.6 sector of the base (measured from x, about the normal).
    _, theta = cone.polar_azimuth(np.array([-np.sin(half), 0.0, -np.cos(half)]))
    assert theta == pytest.approx(np.pi)
    assert cone.max_polar(np.pi) == pytest.approx(np.arctan(0.6))
    assert cone.margin(np.array([-1.0, 0.0, -0.1])) == 0.0      # outside
    arm = PlanarArm("a")
    world = PlanarWorld({"a": arm}, {"a": np.array([0.0, 1.0, 0.0])})
    ctx = make_context(arm, world, np.array([[0.3, 0.2, 0.0]] * 3))
    assert ToolConeIndex().evaluate(ctx) == 1.0                 # no fulcrum for this robot


def test_visibility_index() -> None:
    arm = PlanarArm("a", radius=0.01)
    q = np.array([0.0, 1.0, 0.0])
    cone = Sphere(np.array([0.0, 0.0, 0.2]), 0.05, solid=False)
    world = PlanarWorld({"a": arm}, {"a": q}, {"view_cone": cone})
    p0, _ = arm.tcp_pose(q)
    ctx = make_context(arm, world, np.array([p0, p0]))
    # Gap from the shoulder (on the lift axis, z = 0) to the cone stand-in: 0.2 - 0.06.
    assert VisibilityIndex(d_ref=0.28).evaluate(ctx) == pytest.approx(0.5)
    assert VisibilityIndex(d_ref=0.1).evaluate(ctx) == 1.0
    assert not world.in_collision("a")
    cone.center = np.array([0.0, 0.0, 0.03])          # a new cycle: a new context
    assert VisibilityIndex().evaluate(make_context(arm, world, np.array([p0, p0]))) == 0.0


def test_force_torque_and_moved_wrench() -> None:
    assert ft_eval(np.zeros(3), np.zeros(3), 10.0, 1.0) == 1.0
    assert ft_eval(np.array([0.0, 0.0, 20.0]), np.zeros(3), 10.0, 1.0) == 0.0
    w = Wrench(np.array([0.0, 0.0, -10.0]), np.zeros(3), np.zeros(3))
    moved = w.moved_to(np.array([0.1, 0.0, 0.0]))
    # τ' = (p - p') x F = (-0.1, 0, 0) x (0, 0, -10) = (0, -1, 0)
    np.testing.assert_allclose(moved.torque, [0.0, -1.0, 0.0])
    arm = PlanarArm("a")
    world = PlanarWorld({"a": arm}, {"a": np.array([0.0, 1.0, 0.0])})
    ctx = make_context(arm, world, np.array([[0.3, 0.2, 0.0]] * 2))
    assert ForceTorqueIndex().evaluate(ctx) == 1.0
    from dataclasses import replace
    loaded = replace(ctx, wrench=Wrench(np.array([0, 0, -10.0]), np.zeros(3),
                                        np.array([0.2, 0.2, 0.0])))
    # At the point, τ = 1 N m about y: min((50-10)/50, (4-1)/4) = 0.75.
    assert ForceTorqueIndex(f_max=50.0, tau_max=4.0).evaluate(loaded) == pytest.approx(0.75)


# ---------------------------------------------------------------- registry
def test_registry() -> None:
    for name in ("rj", "theta", "psi", "cr", "cone", "visibility", "force_torque",
                 "manipulability", "isotropy"):
        assert name in INDICES
        assert INDICES.create(name).name == name
    reg = IndexRegistry()
    reg.add("x")(JointLimitIndex)
    with pytest.raises(ValueError, match="already registered"):
        reg.add("x")(JointLimitIndex)
    with pytest.raises(ValueError, match="unknown index 'nope'"):
        INDICES.create("nope")
    with pytest.raises(ValueError, match="b_min"):
        INDICES.create("rj", b_min=0.5)


def test_cone_azimuth_just_below_zero_is_covered_by_two_sectors() -> None:
    """``np.mod(-1e-17, 2π)`` rounds to exactly 2π; a cone split into half-open sectors
    ending at 2π must still cover that azimuth (it is the azimuth 0)."""
    cone = ToolCone(fulcrum=np.zeros(3), normal=np.array([0.0, 0.0, 1.0]),
                    x_axis=np.array([1.0, 0.0, 0.0]),
                    sectors=(ConeSector(0.0, np.pi, 0.8, 1.0),
                             ConeSector(np.pi, 2 * np.pi, 0.6, 1.0)))
    assert float(np.mod(-1e-17, 2 * np.pi)) == 2 * np.pi  # the round-off this guards
    tip = np.array([0.5, -1e-17, np.sqrt(3) / 2])  # azimuth -1e-17 rad, 30 deg off the normal
    assert cone.max_polar(-1e-17) == cone.max_polar(0.0)
    single = cone.margin(tip)
    assert single == pytest.approx(1.0 - (np.pi / 6) / np.arctan(0.8))  # φ(0) = atan(a)
    assert cone.margins(tip[None, :])[0] == pytest.approx(single)


def test_minus_infinity_is_an_impact_and_nan_is_still_skipped() -> None:
    t = np.array([0.0, 0.1, 0.2])
    assert impact_time(t, np.array([0.3, -np.inf, 0.1]), 5.0) == pytest.approx(0.1)
    assert impact_time(t, np.array([-np.inf, 0.2, 0.1]), 5.0) == 0.0
    assert impact_time(t, np.array([0.3, np.nan, 0.1]), 5.0) == pytest.approx(0.3)
    assert impact_time(t, np.array([0.3, np.nan, np.nan]), 5.0) == 5.0
