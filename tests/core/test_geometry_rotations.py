"""The rotation functions every former rotation source now calls (issue #29 item 6): axis-angle,
Euler, frame-then-Euler quaternions, rotating by a rotation vector, the log map between two
rotations, homogeneous transforms, against closed forms and scipy."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from vasim.core.geometry import (
    homogeneous,
    matrix_from_axis_angle,
    matrix_from_euler,
    matrix_from_rotvec,
    quat_from_frame_euler,
    rot_x,
    rot_y,
    rot_z,
    rotate_by_rotvec,
    rotvec_between,
)

finite = st.floats(min_value=-1.0, max_value=1.0, allow_nan=False)
axes = st.tuples(finite, finite, finite).map(np.array).filter(
    lambda a: np.linalg.norm(a) > 1e-3)
angles = st.floats(min_value=-2 * math.pi, max_value=2 * math.pi, allow_nan=False)
rotations = st.tuples(axes, angles).map(lambda p: matrix_from_axis_angle(*p))


def rodrigues(axis: np.ndarray, angle: float) -> np.ndarray:
    """R = I + sin(a) K + (1 - cos(a)) K^2 for the unit axis' cross-product matrix K."""
    x, y, z = axis / np.linalg.norm(axis)
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def quat_matrix(q: np.ndarray) -> np.ndarray:
    """The rotation matrix of a unit quaternion (w, x, y, z), written out."""
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


@settings(max_examples=100, deadline=None)
@given(axes, angles)
def test_axis_angle_is_rodrigues(axis: np.ndarray, angle: float) -> None:
    np.testing.assert_allclose(matrix_from_axis_angle(axis, angle), rodrigues(axis, angle),
                               atol=1e-12)


def test_axis_angle_refuses_a_zero_axis() -> None:
    with pytest.raises(ValueError, match="non-zero"):
        matrix_from_axis_angle([0.0, 0.0, 0.0], 1.0)
    with pytest.raises(ValueError, match="finite"):
        matrix_from_axis_angle([math.nan, 0.0, 1.0], 1.0)


@settings(max_examples=100, deadline=None)
@given(angles, angles, angles)
def test_euler_sequences_are_products_of_elementary_rotations(a: float, b: float,
                                                              c: float) -> None:
    # intrinsic Y-X'-Z'': R = Ry(a) Rx(b) Rz(c); extrinsic x-y-z: R = Rz(c) Ry(b) Rx(a)
    np.testing.assert_allclose(matrix_from_euler("YXZ", [a, b, c]),
                               rot_y(a) @ rot_x(b) @ rot_z(c), atol=1e-12)
    np.testing.assert_allclose(matrix_from_euler("xyz", [a, b, c]),
                               rot_z(c) @ rot_y(b) @ rot_x(a), atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(rotations, angles, angles, angles)
def test_frame_then_euler_quaternion_is_the_matrix_product(frame: np.ndarray, a: float,
                                                           b: float, c: float) -> None:
    q = quat_from_frame_euler(frame, "YXZ", [a, b, c])
    assert q[0] >= 0.0 and math.isclose(float(np.linalg.norm(q)), 1.0, rel_tol=1e-12)
    np.testing.assert_allclose(quat_matrix(q), frame @ rot_y(a) @ rot_x(b) @ rot_z(c),
                               atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(axes, angles, st.tuples(finite, finite, finite).map(np.array))
def test_rotate_by_rotvec_is_the_matrix_and_keeps_length(axis: np.ndarray, angle: float,
                                                         v: np.ndarray) -> None:
    rv = axis / np.linalg.norm(axis) * angle
    out = rotate_by_rotvec(rv, v)
    np.testing.assert_allclose(out, rodrigues(axis, angle) @ v, atol=1e-12)
    assert math.isclose(float(np.linalg.norm(out)), float(np.linalg.norm(v)), abs_tol=1e-12)


@settings(max_examples=200, deadline=None)
@given(rotations, axes, st.floats(min_value=0.0, max_value=math.pi, allow_nan=False))
def test_rotvec_between_is_the_log_map_on_both_routes(r0: np.ndarray, axis: np.ndarray,
                                                      angle: float) -> None:
    """``rotvec_between(r0, r1)`` turns r0 into r1: the closed form away from a half turn,
    scipy's route within it (cos angle <= -0.99, i.e. angle >= 3.0004 rad)."""
    r1 = rodrigues(axis, angle) @ r0
    rv = rotvec_between(r0, r1)
    np.testing.assert_allclose(matrix_from_rotvec(rv) @ r0, r1, atol=1e-9)
    assert math.isclose(float(np.linalg.norm(rv)), angle, abs_tol=1e-9)
    if angle < 3.0:  # unique there: exactly scipy's log map
        np.testing.assert_allclose(rv, Rotation.from_matrix(r1 @ r0.T).as_rotvec(),
                                   atol=1e-9)


def test_rotvec_between_identical_rotations_is_zero() -> None:
    r = rot_x(0.3) @ rot_z(1.1)
    np.testing.assert_allclose(rotvec_between(r, r), np.zeros(3), atol=1e-15)


def test_homogeneous_applies_the_rotation_then_the_translation() -> None:
    r, t, p = rot_z(0.7), np.array([0.1, -0.2, 0.3]), np.array([1.0, 2.0, 3.0])
    m = homogeneous(r, t)
    np.testing.assert_allclose((m @ [*p, 1.0])[:3], r @ p + t, atol=1e-15)
    np.testing.assert_array_equal(homogeneous(), np.eye(4))
    np.testing.assert_array_equal(homogeneous(translation=t)[:3, :3], np.eye(3))
