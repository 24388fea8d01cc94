"""Tool–tissue contact against hand-computed penalty forces on a flat patch."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.abdomen.contact import (
    STABILITY_FRACTION,
    ContactPatch,
    ToolPose,
    ToolShape,
    detect_contacts,
    patch_force,
    sphere_offsets,
)
from vasim.core.errors import ConfigError


def flat_patch(n: int = 21, size: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """A square grid of n x n nodes in the z = 0 plane, triangles facing +z."""
    g = np.linspace(-size / 2, size / 2, n)
    xx, yy = np.meshgrid(g, g, indexing="ij")
    x = np.stack([xx.ravel(), yy.ravel(), np.zeros(n * n)], axis=1)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                            np.stack([a, c, d], -1).reshape(-1, 3)])
    return x, faces


X, FACES = flat_patch()
MASS = np.full(len(X), 0.05)  # heavy nodes: the stiffness bound does not bind at dt = 1 ms
SHAPE = ToolShape(radius=0.0025, contact_stiffness=400.0, spacing=0.0025)


def vertical_tool(depth: float, xy: tuple[float, float] = (0.003, 0.002)) -> ToolPose:
    return ToolPose(fulcrum=np.array([xy[0], xy[1], 0.12]), tip=np.array([xy[0], xy[1], -depth]))


def expected_vertical_force(depth: float, shape: ToolShape) -> float:
    """Σ k δ_j over the spheres on the axis: sphere j sits at z = -depth + ℓ_j."""
    ell = np.arange(200) * shape.spacing
    z = -depth + ell
    signed = z  # distance to the plane, negative below it
    delta = shape.radius - signed
    return float(shape.contact_stiffness * delta[delta > 0].sum())


def test_pressing_5mm_pushes_out_along_the_normal_with_the_penalty_magnitude():
    c = detect_contacts(X, FACES, MASS, vertical_tool(0.005), SHAPE, dt=1e-3)
    assert c.in_contact
    direction = c.force / np.linalg.norm(c.force)
    np.testing.assert_allclose(direction, [0, 0, 1], atol=1e-9)
    # spheres at z = -5, -2.5, 0, +2.5 mm → δ = 7.5, 5, 2.5, 0 mm: F = 400 * 0.015 = 6 N
    assert c.force[2] == pytest.approx(expected_vertical_force(0.005, SHAPE), rel=1e-9)
    assert c.force[2] == pytest.approx(6.0, rel=1e-9)
    assert c.max_penetration == pytest.approx(0.0075)


def test_reaction_on_the_tissue_balances_the_tool_force():
    c = detect_contacts(X, FACES, MASS, vertical_tool(0.004), SHAPE, dt=1e-3)
    np.testing.assert_allclose(c.node_force.sum(axis=0), -c.force, atol=1e-12)
    f = c.external_forces(len(X))
    np.testing.assert_allclose(f.sum(axis=0), -c.force, atol=1e-12)
    assert np.all(f[:, 2] <= 0)  # the tissue is pushed down, never pulled up


def test_no_contact_above_the_surface():
    c = detect_contacts(X, FACES, MASS, vertical_tool(-0.01), SHAPE, dt=1e-3)
    assert not c.in_contact
    assert np.all(c.force == 0) and c.patch.size == 0


def test_vertical_tool_has_no_torque_about_its_fulcrum():
    c = detect_contacts(X, FACES, MASS, vertical_tool(0.005), SHAPE, dt=1e-3)
    np.testing.assert_allclose(c.torque, 0.0, atol=1e-12)


def test_slanted_shaft_torque_is_arm_cross_force():
    fulcrum = np.array([-0.03, 0.0, 0.05])
    tip = np.array([0.02, 0.0, -0.001])
    c = detect_contacts(X, FACES, MASS, ToolPose(fulcrum, tip), SHAPE, dt=1e-3)
    assert c.in_contact
    # independent recomputation: each active sphere pushes up by k δ at its centre
    u = (tip - fulcrum) / np.linalg.norm(tip - fulcrum)
    torque = np.zeros(3)
    for ell in sphere_offsets(ToolPose(fulcrum, tip), SHAPE):
        centre = tip - ell * u
        delta = SHAPE.radius - centre[2]
        if delta > 0:
            torque += np.cross(centre - fulcrum, [0, 0, SHAPE.contact_stiffness * delta])
    np.testing.assert_allclose(c.torque, torque, rtol=1e-9, atol=1e-12)
    assert c.torque[1] < 0  # an upward push ahead of the fulcrum (+x) turns it about -y


def test_stiffness_is_bounded_by_the_explicit_stability_limit():
    light = np.full(len(X), 1e-3)
    dt = 4e-3
    c = detect_contacts(X, FACES, light, vertical_tool(0.002), SHAPE, dt=dt)
    bound = STABILITY_FRACTION * 1e-3 / dt**2
    assert bound < SHAPE.contact_stiffness
    np.testing.assert_allclose(c.patch.stiffness, bound)


def test_patch_force_reproduces_the_detection_and_its_derivative():
    pose = ToolPose(np.array([-0.02, 0.01, 0.1]), np.array([0.004, 0.003, -0.003]))
    c = detect_contacts(X, FACES, MASS, pose, SHAPE, dt=1e-3)
    f0, k0 = patch_force(c.patch, pose)
    np.testing.assert_allclose(f0, c.force_tip, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(k0, c.stiffness_tip, rtol=1e-9, atol=1e-9)
    # the derivative against central finite differences in every direction (pivoting and
    # sliding through the trocar alike)
    h = 1e-6
    for axis in range(3):
        dx = np.zeros(3)
        dx[axis] = h
        fp, _ = patch_force(c.patch, ToolPose(pose.fulcrum, pose.tip + dx))
        fm, _ = patch_force(c.patch, ToolPose(pose.fulcrum, pose.tip - dx))
        np.testing.assert_allclose((fp - fm) / (2 * h), k0[:, axis], rtol=1e-4, atol=1e-3)
    np.testing.assert_allclose(k0, k0.T, atol=1e-9)
    # the material term dominates: the springs push out (negative definite along n)
    assert np.linalg.eigvalsh(k0).min() < 0


def test_patch_force_is_unilateral():
    p = ContactPatch(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), np.array([300.0]),
                     np.zeros(1), 0.0025)
    away = ToolPose(np.array([0, 0, 0.1]), np.array([0, 0, 0.01]))
    f, k = patch_force(p, away)
    assert np.all(f == 0) and np.all(k == 0)


@settings(max_examples=40, deadline=None)
@given(x=st.floats(-0.03, 0.03), y=st.floats(-0.03, 0.03), depth=st.floats(-0.005, 0.01),
       lean=st.floats(-0.05, 0.05))
def test_force_never_pulls_the_tool_into_a_flat_patch(x, y, depth, lean):
    pose = ToolPose(np.array([x + lean, y, 0.1]), np.array([x, y, -depth]))
    c = detect_contacts(X, FACES, MASS, pose, SHAPE, dt=1e-3)
    assert c.force[2] >= 0.0
    assert np.all(np.isfinite(c.force)) and np.all(np.isfinite(c.torque))
    np.testing.assert_allclose(c.node_force.sum(axis=0) if c.in_contact else np.zeros(3),
                               -c.force, atol=1e-12)


@pytest.mark.parametrize("field,value", [("radius", 0.0), ("contact_stiffness", -1.0),
                                         ("spacing", 0.01), ("radius", float("nan"))])
def test_bad_tool_shape_is_refused_naming_the_field(field, value):
    with pytest.raises(ConfigError, match=f"tool.{field}"):
        ToolShape(**{field: value})
