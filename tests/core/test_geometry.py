"""Rotations from one source (``vasim.core.geometry``): the project's wxyz order against
independent closed forms (the quaternion's matrix and the Hamilton product written out)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from vasim.core.geometry import (
    QUAT_ORDER,
    align_vectors,
    euler_xyz_from_matrix,
    frame_z_x,
    from_xyzw,
    homogeneous,
    matrix_from_axis_angle,
    matrix_from_euler,
    matrix_from_quat,
    matrix_from_rotvec,
    matrix_z_to,
    quat_from_frame_euler,
    quat_from_matrix,
    quat_z_to,
    rot_x,
    rot_y,
    rot_z,
    rotate_by_rotvec,
    rotation,
    rotation_angle,
    rotvec_between,
    rotvec_from_matrix,
    slerp_matrix,
    to_xyzw,
    vector_norm,
)

finite = st.floats(min_value=-1.0, max_value=1.0, allow_nan=False)
quats = st.tuples(finite, finite, finite, finite).map(np.array).filter(
    lambda q: np.linalg.norm(q) > 1e-3).map(lambda q: q / np.linalg.norm(q))
vectors = st.tuples(finite, finite, finite).map(np.array)


def closed_form_matrix(q: np.ndarray) -> np.ndarray:
    """The rotation matrix of a unit quaternion (w, x, y, z), written out."""
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def hamilton(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The Hamilton product p q of quaternions (w, x, y, z), written out."""
    a1, b1, c1, d1 = p
    a2, b2, c2, d2 = q
    return np.array([a1 * a2 - b1 * b2 - c1 * c2 - d1 * d2,
                     a1 * b2 + b1 * a2 + c1 * d2 - d1 * c2,
                     a1 * c2 - b1 * d2 + c1 * a2 + d1 * b2,
                     a1 * d2 + b1 * c2 - c1 * b2 + d1 * a2])


def same_rotation(p: np.ndarray, q: np.ndarray) -> bool:
    return bool(np.allclose(p, q, atol=1e-9) or np.allclose(p, -q, atol=1e-9))


def test_the_order_is_scalar_first_and_identity_is_one() -> None:
    assert QUAT_ORDER == "wxyz"
    assert quat_from_matrix(np.eye(3)).tolist() == [1.0, 0.0, 0.0, 0.0]
    np.testing.assert_array_equal(matrix_from_quat([1.0, 0.0, 0.0, 0.0]), np.eye(3))
    np.testing.assert_array_equal(rotvec_from_matrix(np.eye(3)), np.zeros(3))
    np.testing.assert_array_equal(matrix_from_rotvec(np.zeros(3)), np.eye(3))
    # 90 deg about z: w = cos 45 deg, z = sin 45 deg; the x axis goes to y
    q = quat_from_matrix([[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    np.testing.assert_allclose(q, [math.sqrt(0.5), 0, 0, math.sqrt(0.5)], atol=1e-15)
    np.testing.assert_allclose(matrix_from_quat(q) @ [1, 0, 0], [0, 1, 0], atol=1e-15)


@settings(max_examples=200, deadline=None)
@given(quats)
def test_matrix_of_a_quaternion_is_the_closed_form(q: np.ndarray) -> None:
    np.testing.assert_allclose(matrix_from_quat(q), closed_form_matrix(q), atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(quats)
def test_round_trips_between_orders_and_matrices(q: np.ndarray) -> None:
    np.testing.assert_array_equal(from_xyzw(to_xyzw(q)), q)
    np.testing.assert_array_equal(to_xyzw(q), [q[1], q[2], q[3], q[0]])
    back = quat_from_matrix(closed_form_matrix(q))
    assert same_rotation(back, q)
    assert back[0] >= 0.0                                    # canonical: w >= 0
    np.testing.assert_allclose(np.linalg.norm(back), 1.0, atol=1e-12)
    r = closed_form_matrix(q)
    np.testing.assert_allclose(matrix_from_rotvec(rotvec_from_matrix(r)), r, atol=1e-9)
    # the same rotation read the pybullet / scipy way (xyzw) gives the same matrix
    np.testing.assert_allclose(matrix_from_quat(from_xyzw(to_xyzw(q))), r, atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(quats, quats)
def test_composition_matches_matrices(p: np.ndarray, q: np.ndarray) -> None:
    """R(p q) = R(p) R(q), the product computed independently (Hamilton)."""
    np.testing.assert_allclose(matrix_from_quat(hamilton(p, q)),
                               closed_form_matrix(p) @ closed_form_matrix(q), atol=1e-12)
    assert same_rotation(quat_from_matrix(closed_form_matrix(p) @ closed_form_matrix(q)),
                         hamilton(p, q))


@settings(max_examples=100, deadline=None)
@given(quats, quats, st.floats(min_value=0.0, max_value=1.0))
def test_slerp_and_angle_follow_the_shortest_arc(p: np.ndarray, q: np.ndarray,
                                                  s: float) -> None:
    r0, r1 = closed_form_matrix(p), closed_form_matrix(q)
    rel = hamilton(np.array([p[0], -p[1], -p[2], -p[3]]), q)   # p^-1 q
    angle = 2.0 * math.atan2(np.linalg.norm(rel[1:]), abs(rel[0]))
    assert rotation_angle(r0, r1) == pytest.approx(angle, abs=1e-9)
    mid = slerp_matrix(r0, r1, s)
    assert rotation_angle(r0, mid) == pytest.approx(s * angle, abs=1e-7)
    assert rotation_angle(mid, r1) == pytest.approx((1.0 - s) * angle, abs=1e-7)


@settings(max_examples=200, deadline=None)
@given(vectors.filter(lambda d: np.linalg.norm(d) > 1e-6))
@example(np.array([0.0, 1.1081229462067945e-162, -0.5]))  # |z x d|^2 underflowed (CI 12-02)
def test_z_to_a_direction_is_the_smallest_rotation(d: np.ndarray) -> None:
    u = d / np.linalg.norm(d)
    m = matrix_z_to(d)
    np.testing.assert_allclose(m @ [0, 0, 1], u, atol=1e-9)
    np.testing.assert_allclose(m.T @ m, np.eye(3), atol=1e-12)
    # smallest rotation: its angle is the angle between z and d
    angle = math.acos(max(-1.0, min(1.0, u[2])))
    q = quat_z_to(d)
    assert 2.0 * math.acos(min(1.0, q[0])) == pytest.approx(angle, abs=1e-6)


def test_z_to_degenerate_directions() -> None:
    assert quat_z_to([0, 0, 0]).tolist() == [1.0, 0.0, 0.0, 0.0]
    assert quat_z_to([0, 0, -2]).tolist() == [0.0, 1.0, 0.0, 0.0]   # half turn about x
    np.testing.assert_allclose(matrix_z_to([0, 0, -1]) @ [0, 0, 1], [0, 0, -1], atol=1e-15)


def test_euler_is_urdf_rpy() -> None:
    """rpy = (roll, pitch, yaw): R = Rz(yaw) Ry(pitch) Rx(roll)."""
    roll, pitch, yaw = 0.1, -0.4, 1.2
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch),
                              math.sin(pitch), math.cos(yaw), math.sin(yaw))
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    np.testing.assert_allclose(euler_xyz_from_matrix(rz @ ry @ rx), [roll, pitch, yaw],
                               atol=1e-12)


def test_bad_quaternions_are_refused() -> None:
    with pytest.raises(ValueError, match="4 components"):
        to_xyzw([1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="non-zero"):
        rotation([0.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="finite"):
        matrix_from_quat([math.nan, 0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="3 x 3"):
        quat_from_matrix(np.eye(4))


@settings(max_examples=100, deadline=None)
@given(st.floats(min_value=-10.0, max_value=10.0, allow_nan=False))
def test_elementary_rotations_are_scipys(a: float) -> None:
    for axis, fn in (("x", rot_x), ("y", rot_y), ("z", rot_z)):
        np.testing.assert_allclose(fn(a), Rotation.from_euler(axis, a).as_matrix(),
                                   atol=1e-12)
    # a quarter turn about z takes x to y, about x takes y to z, about y takes z to x
    np.testing.assert_allclose(rot_z(math.pi / 2) @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(rot_x(math.pi / 2) @ [0, 1, 0], [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(rot_y(math.pi / 2) @ [0, 0, 1], [1, 0, 0], atol=1e-15)


# -- the functions the former rotation sources now call (issue #29 item 6): axis-angle,
# Euler, frame-then-Euler quaternions, rotating by a rotation vector, the log map between two
# rotations, homogeneous transforms

axes = st.tuples(finite, finite, finite).map(np.array).filter(
    lambda a: np.linalg.norm(a) > 1e-3)
angles = st.floats(min_value=-2 * math.pi, max_value=2 * math.pi, allow_nan=False)
rotations = st.tuples(axes, angles).map(lambda p: matrix_from_axis_angle(*p))


def rodrigues(axis: np.ndarray, angle: float) -> np.ndarray:
    """R = I + sin(a) K + (1 - cos(a)) K^2 for the unit axis' cross-product matrix K."""
    x, y, z = axis / np.linalg.norm(axis)
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


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
    np.testing.assert_allclose(closed_form_matrix(q), frame @ rot_y(a) @ rot_x(b) @ rot_z(c),
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


@settings(max_examples=200, deadline=None)
@given(vectors.filter(lambda d: np.linalg.norm(d) > 1e-3),
       vectors.filter(lambda d: np.linalg.norm(d) > 1e-3))
def test_align_vectors_turns_a_onto_b_with_trimesh_s_roll(a: np.ndarray, b: np.ndarray) -> None:
    import trimesh

    r = align_vectors(a, b)
    # a rotation (orthonormal, det 1) taking the direction of a onto that of b
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-9)
    assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_allclose(r @ (a / np.linalg.norm(a)), b / np.linalg.norm(b), atol=1e-7)
    # trimesh's own, bit for bit (its roll: the stored vessel meshes depend on it)
    np.testing.assert_array_equal(r, trimesh.geometry.align_vectors(a, b)[:3, :3])


def test_align_vectors_roll_is_not_the_smallest_rotation_s() -> None:
    # why the wrapper exists (vasim.core.geometry, decision): for +z onto a tilted
    # direction trimesh picks another roll than matrix_z_to; both take z onto d
    d = np.array([0.3, -0.5, 0.8])
    r, smallest = align_vectors([0.0, 0.0, 1.0], d), matrix_z_to(d)
    np.testing.assert_allclose(r[:, 2], d / np.linalg.norm(d), atol=1e-12)
    np.testing.assert_allclose(smallest[:, 2], d / np.linalg.norm(d), atol=1e-12)
    assert not np.allclose(r, smallest, atol=1e-6)


@settings(max_examples=200, deadline=None)
@given(vectors.filter(lambda d: np.linalg.norm(d) > 1e-3), vectors)
@example(np.array([0.0, 2.5647018427852933e-09, 1.0]), np.array([0.0, 0.0, 1.0]))  # make test
def test_frame_z_x_is_a_rotation_with_z_and_x_in_the_hint_s_plane(d: np.ndarray,
                                                                  hint: np.ndarray) -> None:
    z = d / np.linalg.norm(d)
    perp = hint - z * float(hint @ z)
    if np.linalg.norm(perp) < 1e-6:      # (nearly) parallel: raised, or any x with any_x
        if np.linalg.norm(perp) < 1e-9:
            with pytest.raises(ValueError, match="parallel"):
                frame_z_x(z, hint)
        r = frame_z_x(z, hint, any_x=True)
    else:
        r = frame_z_x(z, hint)
        # x is the hint's part orthogonal to z, normalised (Gram-Schmidt)
        np.testing.assert_allclose(r[:, 0], perp / np.linalg.norm(perp), atol=1e-9)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-9)
    assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_array_equal(r[:, 2], z)


wide = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_subnormal=True)


@settings(max_examples=300, deadline=None)
@given(st.lists(wide, min_size=0, max_size=9).map(lambda v: np.array(v, dtype=np.float64)))
@example(np.array([1e-200, 1e-200, 0.0]))          # squares underflow: both give 0.0
@example(np.array([3.0, 4.0]))
def test_vector_norm_is_numpys_norm_bit_for_bit(x: np.ndarray) -> None:
    """The MRCP cycle's fast norm is np.linalg.norm's value, bit for bit (the simulated
    trials, stored and replayed, stay what they were): for 1-D arrays, a strided view and a
    (3, 3) matrix's Frobenius norm."""
    assert vector_norm(x) == float(np.linalg.norm(x))
    assert vector_norm(x[::2]) == float(np.linalg.norm(x[::2]))
    m = np.resize(x, (3, 3)) if x.size else np.zeros((3, 3))
    assert vector_norm(m.T) == float(np.linalg.norm(m.T))
    assert vector_norm([3.0, 4.0]) == 5.0           # a list: numpy's own norm


@settings(max_examples=300, deadline=None)
@given(vectors.filter(lambda d: np.linalg.norm(d) > 1e-3), vectors)
def test_frame_z_x_is_numpys_cross_and_column_stack_bit_for_bit(d: np.ndarray,
                                                                hint: np.ndarray) -> None:
    """frame_z_x's written-out cross product gives the frame np.cross and np.column_stack
    gave (the same float operations), bit for bit."""
    z = d / np.linalg.norm(d)
    r = frame_z_x(z, hint, any_x=True)
    x = r[:, 0]
    np.testing.assert_array_equal(r, np.column_stack([x, np.cross(z, x), z]))
    n = float(np.linalg.norm(hint - z * float(hint @ z)))
    if n >= max(1e-9, 1e-4 * float(np.linalg.norm(hint))):   # one Gram-Schmidt step
        np.testing.assert_array_equal(x, (hint - z * float(hint @ z)) / n)
