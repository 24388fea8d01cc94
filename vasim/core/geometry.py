"""Rotations from one source, in one quaternion order.

Every rotation vasim builds or converts goes through these functions, which wrap
``scipy.spatial.transform.Rotation`` (no hand-written quaternion algebra elsewhere).

**Decision** (the project's quaternion order is **wxyz**, scalar first: ``(w, x, y, z)``),
because that is what the device protocol and its recorded streams already store
(``vasim.haptics.device.DeviceSample.orientation``, the ``orientation`` column of a device
stream) and what viser, the viewer, takes (``handle.wxyz``). scipy (``as_quat()``) and
pybullet speak **xyzw** (scalar last): code converts at those edges only, with
:func:`to_xyzw` / :func:`from_xyzw` (the pybullet backend, the viewer's pybullet reads).

**Decision** (issue #29, one rotation source): the former direct sources call these
functions: the laparoscopic instrument's orientation (:func:`quat_from_frame_euler`, now
canonical like every quaternion here) and its shaft turn (:func:`rotate_by_rotvec`) in
``vasim.haptics.laparoscopic``; the bowel tilt of ``vasim.abdomen.anatomy`` (:func:`rot_x`,
bit-identical to trimesh's ``rotation_matrix`` about x there); the MRCP viewer's prop meshes
(:func:`homogeneous` of :func:`rot_y`/:func:`rot_z`); the IK's log map
(:func:`rotvec_between`, moved from ``vasim.mrcp.arm``); the vessel mesh of
``vasim.abdomen.anatomy`` (:func:`align_vectors`); the MRCP tool, gripper and tool-cone
frames (:func:`frame_z_x`, one Gram-Schmidt step, formerly three copies). Compiled kernels
(``*_kernels.py``) keep their inlined arithmetic.

**Decision** (:func:`align_vectors`, the one rotation built by a library other than scipy):
it wraps ``trimesh.geometry.align_vectors``, bit for bit. Turning one direction onto
another leaves the roll about the target free, and trimesh's choice differs from the
smallest rotation of :func:`matrix_z_to` (and from scipy's ``Rotation.align_vectors``);
the vessel's vertices were built with trimesh's, so only trimesh's keeps the stored trials
identical (issue #29). This is the one place vasim calls it.

Rotation matrices are ``(3, 3)`` (or ``(..., 3, 3)``) and act on column vectors:
``v_world = R @ v_local`` for a world-from-local ``R``. Quaternions returned here are unit
and canonical (**decision**: w >= 0, so a rotation has one quaternion and recorded files
compare bit for bit; for w = 0 scipy's canonical form picks the first non-zero
component positive).

Example:
    >>> import numpy as np
    >>> quat_from_matrix(np.eye(3)).tolist()
    [1.0, 0.0, 0.0, 0.0]
    >>> np.round(quat_from_matrix([[0, -1, 0], [1, 0, 0], [0, 0, 1]]), 6).tolist()  # 90 deg z
    [0.707107, 0.0, 0.0, 0.707107]
    >>> to_xyzw([1.0, 0.0, 0.0, 0.0]).tolist()
    [0.0, 0.0, 0.0, 1.0]
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation, Slerp

FloatArray = NDArray[np.float64]

QUAT_ORDER = "wxyz"
"""The project's quaternion order (module docstring): scalar first."""


def _quat(q: ArrayLike, name: str = "quaternion") -> FloatArray:
    a = np.asarray(q, dtype=np.float64)
    if a.shape[-1:] != (4,):
        raise ValueError(f"a {name} must have 4 components (last axis), got shape {a.shape}")
    return a


def to_xyzw(q_wxyz: ArrayLike) -> FloatArray:
    """``(..., 4)`` quaternion(s) wxyz -> xyzw (scipy, pybullet); no normalisation."""
    q = _quat(q_wxyz)
    return np.concatenate([q[..., 1:], q[..., :1]], axis=-1)


def from_xyzw(q_xyzw: ArrayLike) -> FloatArray:
    """``(..., 4)`` quaternion(s) xyzw (scipy, pybullet) -> wxyz; no normalisation."""
    q = _quat(q_xyzw)
    return np.concatenate([q[..., 3:], q[..., :3]], axis=-1)


def rotation(q_wxyz: ArrayLike) -> Rotation:
    """The scipy ``Rotation`` of ``(..., 4)`` quaternion(s) wxyz (normalised by scipy).

    Raises:
        ValueError: wrong shape, or a zero / non-finite quaternion.
    """
    q = _quat(q_wxyz)
    if not np.all(np.isfinite(q)) or np.any(np.linalg.norm(q, axis=-1) == 0.0):
        raise ValueError(f"a quaternion must be finite and non-zero, got {q.tolist()}")
    return Rotation.from_quat(q, scalar_first=True)


def quat_of(r: Rotation) -> FloatArray:
    """``(4,)`` / ``(n, 4)`` canonical unit quaternion(s) wxyz of a scipy ``Rotation``."""
    return np.asarray(r.as_quat(canonical=True, scalar_first=True), dtype=np.float64)


def quat_from_matrix(m: ArrayLike) -> FloatArray:
    """Canonical unit quaternion(s) wxyz (``(..., 4)``) of ``(..., 3, 3)`` rotation
    matrices (scipy projects a slightly non-orthogonal matrix onto the nearest rotation)."""
    a = np.asarray(m, dtype=np.float64)
    if a.shape[-2:] != (3, 3):
        raise ValueError(f"a rotation matrix must be 3 x 3, got shape {a.shape}")
    flat = a.reshape(-1, 3, 3)
    q = quat_of(Rotation.from_matrix(flat))
    return q.reshape(*a.shape[:-2], 4)


def matrix_from_quat(q_wxyz: ArrayLike) -> FloatArray:
    """``(..., 3, 3)`` rotation matrices of ``(..., 4)`` quaternion(s) wxyz."""
    q = _quat(q_wxyz)
    return np.asarray(rotation(q.reshape(-1, 4)).as_matrix()).reshape(*q.shape[:-1], 3, 3)


def rotvec_from_matrix(m: ArrayLike) -> FloatArray:
    """Rotation vector(s) (axis * angle [rad], ``(..., 3)``) of rotation matrices."""
    a = np.asarray(m, dtype=np.float64)
    return np.asarray(Rotation.from_matrix(a.reshape(-1, 3, 3)).as_rotvec()
                      ).reshape(*a.shape[:-2], 3)


def matrix_from_rotvec(v: ArrayLike) -> FloatArray:
    """Rotation matrices (``(..., 3, 3)``) of rotation vector(s) [rad]."""
    a = np.asarray(v, dtype=np.float64)
    return np.asarray(Rotation.from_rotvec(a.reshape(-1, 3)).as_matrix()
                      ).reshape(*a.shape[:-1], 3, 3)


def matrix_from_axis_angle(axis: ArrayLike, angle: float) -> FloatArray:
    """``(3, 3)`` rotation about ``axis`` (any length > 0, normalised here) by ``angle``
    [rad], right-handed."""
    a = np.asarray(axis, dtype=np.float64).reshape(3)
    n = float(np.linalg.norm(a))
    if not (math.isfinite(n) and n > 0.0):
        raise ValueError(f"a rotation axis must be finite and non-zero, got {a.tolist()}")
    return matrix_from_rotvec(a * (float(angle) / n))


def matrix_from_euler(seq: str, angles: ArrayLike) -> FloatArray:
    """``(3, 3)`` rotation of Euler ``angles`` [rad] in scipy's ``seq`` convention (upper
    case intrinsic, e.g. ``"YXZ"``; lower case extrinsic, e.g. ``"xyz"``, URDF's rpy)."""
    return np.asarray(Rotation.from_euler(seq, np.asarray(angles, dtype=np.float64)
                                          ).as_matrix())


def quat_from_frame_euler(frame: ArrayLike, seq: str, angles: ArrayLike) -> FloatArray:
    """``(4,)`` canonical wxyz of ``frame`` (a ``(3, 3)`` world-from-parent rotation) then
    the Euler rotation ``seq``/``angles`` [rad] in that frame: ``frame @ euler``, composed
    as quaternions (no matrix round trip)."""
    r = Rotation.from_matrix(np.asarray(frame, dtype=np.float64)) * Rotation.from_euler(
        seq, np.asarray(angles, dtype=np.float64))
    return quat_of(r)


def rotate_by_rotvec(rotvec: ArrayLike, v: ArrayLike) -> FloatArray:
    """``v`` (``(3,)`` or ``(n, 3)``) turned by the rotation vector ``rotvec`` (axis * angle
    [rad])."""
    return np.asarray(Rotation.from_rotvec(np.asarray(rotvec, dtype=np.float64)).apply(
        np.asarray(v, dtype=np.float64)))


def rotvec_between(current: ArrayLike, target: ArrayLike) -> FloatArray:
    """``(3,)`` rotation vector [rad] (world frame) turning matrix ``current`` into
    ``target``: the log map of ``target @ current.T``.

    **Decision** (moved here from ``vasim.mrcp.arm``, whose IK calls it per iteration): away
    from a half turn (cos angle > -0.99) it is the closed form from the skew part ``w``
    (``|w| = 2 sin angle``) and the trace (``2 cos angle + 1``), ``atan2`` for the angle,
    a few microseconds; near a half turn, where the skew part vanishes, it takes scipy's
    robust ``as_rotvec``. The tests check both routes against scipy.
    """
    r = np.asarray(target, dtype=np.float64) @ np.asarray(current, dtype=np.float64).T
    w = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    s = 0.5 * float(np.linalg.norm(w))
    c = 0.5 * (float(np.trace(r)) - 1.0)
    if c > -0.99:
        angle = math.atan2(s, c)
        return w * (0.5 if s < 1e-12 else angle / (2.0 * s))
    return rotvec_from_matrix(r)   # near pi: the robust (slower) route


def homogeneous(rotation: ArrayLike | None = None,
                translation: ArrayLike | None = None) -> FloatArray:
    """``(4, 4)`` transform of a ``(3, 3)`` rotation and a ``(3,)`` translation (identity
    for the one not given)."""
    t = np.eye(4)
    if rotation is not None:
        t[:3, :3] = np.asarray(rotation, dtype=np.float64)
    if translation is not None:
        t[:3, 3] = np.asarray(translation, dtype=np.float64)
    return t


def rot_x(angle: float) -> FloatArray:
    """``(3, 3)`` right-handed rotation about x by ``angle`` [rad].

    **Decision**: the elementary rotations are the closed form (cos/sin), not
    ``Rotation.from_euler``, because the DH kinematics and the tool station's Jacobian
    build several per control cycle and a scipy object costs tens of microseconds each;
    the tests check them against scipy.
    """
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle: float) -> FloatArray:
    """``(3, 3)`` right-handed rotation about y by ``angle`` [rad] (:func:`rot_x`)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle: float) -> FloatArray:
    """``(3, 3)`` right-handed rotation about z by ``angle`` [rad] (:func:`rot_x`)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation_angle(r0: ArrayLike, r1: ArrayLike) -> float:
    """The angle [rad, in [0, pi]] of the rotation taking matrix ``r0`` to ``r1``."""
    return float(Rotation.from_matrix(np.asarray(r0, dtype=np.float64).T
                                      @ np.asarray(r1, dtype=np.float64)).magnitude())


def slerp_matrix(r0: ArrayLike, r1: ArrayLike, fraction: float) -> FloatArray:
    """``(3, 3)``: the rotation a ``fraction`` of the way from ``r0`` to ``r1`` along the
    shortest arc (spherical linear interpolation; 0 -> ``r0``, 1 -> ``r1``)."""
    ends = Rotation.from_matrix(np.stack([np.asarray(r0, dtype=np.float64),
                                          np.asarray(r1, dtype=np.float64)]))
    return np.asarray(Slerp([0.0, 1.0], ends)([float(fraction)]).as_matrix()[0])


def euler_xyz_from_matrix(m: ArrayLike) -> FloatArray:
    """Extrinsic x-y-z Euler angles (roll, pitch, yaw [rad]; URDF's ``rpy``) of a matrix."""
    return np.asarray(Rotation.from_matrix(np.asarray(m, dtype=np.float64)).as_euler("xyz"))


def quat_z_to(direction: ArrayLike) -> FloatArray:
    """``(4,)`` wxyz: the smallest rotation taking +z onto ``direction`` (any length > 0).

    A zero direction gives the identity; exactly the opposite of +z gives the half turn
    about x (**decision**: any axis normal to z would do; x is the one the viewer always
    used). Otherwise the axis is z x d and the angle atan2(|z x d|, z . d), accurate up to
    the antiparallel limit.
    """
    d = np.asarray(direction, dtype=np.float64).reshape(3)
    n = float(np.linalg.norm(d))
    if n < 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0])
    d = d / n
    # |z x d| by hypot, not by squaring: for a direction within ~1e-154 of the z axis the
    # squares underflow to subnormals and the norm lost its precision (hypothesis found
    # d = (0, 1.1e-162, -0.5) turned onto (0, 0.0092, -0.99996)).
    s = math.hypot(float(d[0]), float(d[1]))
    if s == 0.0:
        return np.array([1.0, 0.0, 0.0, 0.0]) if d[2] > 0 else np.array([0.0, 1.0, 0.0, 0.0])
    axis = np.array([-d[1] / s, d[0] / s, 0.0])  # z x d, unit
    return quat_of(Rotation.from_rotvec(axis * math.atan2(s, float(d[2]))))


def matrix_z_to(direction: ArrayLike) -> FloatArray:
    """``(3, 3)`` rotation taking +z onto ``direction`` (:func:`quat_z_to`)."""
    return matrix_from_quat(quat_z_to(direction))


def frame_z_x(z: ArrayLike, x_hint: ArrayLike, *, any_x: bool = False,
              what: str = "x_hint") -> FloatArray:
    """``(3, 3)`` rotation whose columns are ``x``, ``z × x`` and ``z``: ``z`` the given unit
    axis, ``x`` the part of ``x_hint`` orthogonal to it, normalised (one Gram-Schmidt step;
    the MRCP tool and gripper frames and the tool cone's frame).

    Args:
        z: ``(3,)`` unit axis (not normalised here).
        x_hint: ``(3,)`` preferred x direction.
        any_x: when ``x_hint`` is parallel to ``z`` (its orthogonal part under 1e-9), use
            the world axis least aligned with ``z`` instead of raising.
        what: names ``x_hint`` in the error.

    Raises:
        ValueError: ``x_hint`` parallel to ``z`` (unless ``any_x``).

    Example:
        >>> frame_z_x([0.0, 0.0, 1.0], [1.0, 1.0, 5.0]).round(6).tolist()[0]
        [0.707107, -0.707107, 0.0]
    """
    zz = np.asarray(z, dtype=np.float64)
    hint = np.asarray(x_hint, dtype=np.float64)
    x = hint - zz * float(hint @ zz)
    n = vector_norm(x)
    if n < 1e-9:
        if not any_x:
            raise ValueError(f"{what} {x_hint!r} is parallel to {zz.tolist()!r}")
        x = np.eye(3)[int(np.argmin(np.abs(zz)))]
        x = x - zz * float(x @ zz)
        n = vector_norm(x)
    elif n < 1e-4 * vector_norm(hint):
        # A hint within 1e-4 rad of z: the subtraction cancels and x keeps a part along z of
        # order eps/n (2.6e-9 for a hint 2.6e-9 rad off z, a hypothesis example); a second
        # Gram-Schmidt step removes it ("twice is enough"). Above that angle one step is kept:
        # every frame the callers build stays bit for bit what it was.
        x = x - zz * float(x @ zz)
        n = vector_norm(x)
    if x.shape != (3,) or zz.shape != (3,) or n == 0.0:   # (n == 0: numpy's inf/nan)
        x = x / n
        return np.column_stack([x, np.cross(zz, x), zz])
    # Speed (the MRCP IK builds a frame per call): np.cross and np.column_stack cost tens of
    # microseconds of dispatch on 3-vectors; the explicit x / n and cross product below are
    # numpy's float operations (a1 b2 - a2 b1, ...), so the frame is bit for bit the same.
    x0, x1, x2 = x.tolist()
    x0, x1, x2 = x0 / n, x1 / n, x2 / n
    z0, z1, z2 = zz.tolist()
    return np.array([[x0, z1 * x2 - z2 * x1, z0],
                     [x1, z2 * x0 - z0 * x2, z1],
                     [x2, z0 * x1 - z1 * x0, z2]])


def vector_norm(x: FloatArray) -> float:
    """``float(np.linalg.norm(x))`` of a float64 array, bit for bit.

    **Decision** (speed of the MRCP control cycle): numpy's 2-norm of a float array is
    ``sqrt(y.dot(y))`` with ``y = x.ravel(order="K")`` (numpy 2.x ``linalg.norm``, ord and
    axis None); doing exactly that skips microseconds of argument handling per call. Any
    other input goes to ``np.linalg.norm`` itself. Not ``math.hypot``: it rounds differently.
    """
    if not isinstance(x, np.ndarray) or x.dtype != np.float64:
        return float(np.linalg.norm(x))
    y = x.ravel(order="K")
    return math.sqrt(float(y.dot(y)))


def align_vectors(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """``(3, 3)`` rotation taking direction ``a`` onto direction ``b`` (any lengths > 0),
    with trimesh's roll about ``b``: ``trimesh.geometry.align_vectors``' rotation block, bit
    for bit (module docstring: why trimesh's and not :func:`matrix_z_to` or scipy's).

    Example:
        >>> import numpy as np
        >>> r = align_vectors([0.0, 0.0, 1.0], [0.0, 1.0, 0.0])
        >>> np.round(r @ [0.0, 0.0, 1.0], 12).tolist()
        [0.0, 1.0, 0.0]
    """
    import trimesh  # here: its only user, and core.geometry stays quick to import

    t = trimesh.geometry.align_vectors(np.asarray(a, dtype=np.float64),
                                       np.asarray(b, dtype=np.float64))
    return np.asarray(t, dtype=np.float64)[:3, :3]   # a view, as the vessel always used


__all__ = [
    "QUAT_ORDER",
    "align_vectors",
    "euler_xyz_from_matrix",
    "frame_z_x",
    "from_xyzw",
    "homogeneous",
    "matrix_from_axis_angle",
    "matrix_from_euler",
    "matrix_from_quat",
    "matrix_from_rotvec",
    "matrix_z_to",
    "quat_from_frame_euler",
    "quat_from_matrix",
    "quat_of",
    "quat_z_to",
    "rot_x",
    "rot_y",
    "rot_z",
    "rotate_by_rotvec",
    "rotation",
    "rotation_angle",
    "rotvec_between",
    "rotvec_from_matrix",
    "slerp_matrix",
    "to_xyzw",
    "vector_norm",
]
