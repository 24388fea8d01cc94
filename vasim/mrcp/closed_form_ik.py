"""Closed-form inverse kinematics of PUMA-like 6R arms (the RX60B's structure, Craig's
*Introduction to Robotics* §4.7): all eight solutions of a pose, and their wrapping into the
joint limits. Numeric IK and the DH chain are :mod:`vasim.mrcp.dh`; :class:`vasim.mrcp.arm.
PybulletArm` tries these solutions first.

Angles in [rad], positions in [m], poses in the world frame of the robot's ``base``.
"""

from __future__ import annotations

import math

import numpy as np

from vasim.mrcp.dh import FloatArray, RobotModel, frames_one, rot_x


def is_puma_like(robot: RobotModel) -> bool:
    """True for Craig's PUMA 560 structure (the RX60B's): six joints, the first two axes
    intersecting at the shoulder, a spherical wrist (joint frames 4-6 share their origin)."""
    if robot.n_joints != 6:
        return False
    al, a, d, _ = robot.table
    h = math.pi / 2
    checks = [(al[0], 0.0), (a[0], 0.0), (al[1], -h), (a[1], 0.0), (d[1], 0.0), (al[2], 0.0),
              (al[3], -h), (al[4], h), (a[4], 0.0), (d[4], 0.0), (al[5], -h), (a[5], 0.0),
              (d[5], 0.0)]
    return all(abs(v - ref) < 1e-12 for v, ref in checks) and abs(a[2]) > 1e-9


def _zyz(m: FloatArray) -> list[tuple[float, float, float]]:
    """Both ``(a, b, c)`` with ``m = Rz(a) Ry(b) Rz(c)`` (one at ``b = 0``: singular)."""
    sb = math.hypot(m[0, 2], m[1, 2])
    cb = m[2, 2]
    if sb < 1e-12:                     # wrist singular: only a + c (or a - c) is defined
        c = math.atan2(m[1, 0], m[0, 0]) if cb > 0 else math.atan2(m[1, 0], -m[0, 0])
        return [(0.0, 0.0 if cb > 0 else math.pi, c)]
    out = []
    for s in (sb, -sb):
        out.append((math.atan2(m[1, 2] / s, m[0, 2] / s), math.atan2(s, cb),
                    math.atan2(m[2, 1] / s, -m[2, 0] / s)))
    return out


#: [m^2] negative squared lengths of :func:`puma_ik` above ``-_ROUND_OFF`` are round-off.
_ROUND_OFF = 1e-12


def puma_ik(robot: RobotModel, position: FloatArray, rotation: FloatArray,
            base: FloatArray | None = None) -> list[FloatArray]:
    """Closed-form inverse kinematics of a PUMA-like arm (Craig, *Introduction to Robotics*,
    §4.7): up to 8 joint vectors ``q`` (the DH offsets removed, not yet wrapped or checked
    against the limits) whose TCP reaches the pose; empty when out of reach or when the
    robot does not have that structure.

    Position: the wrist centre ``w = p - R tcp`` (base frame, shoulder height removed) gives
    ``theta1 = atan2(wy, wx) - atan2(d3, ±sqrt(wx^2 + wy^2 - d3^2))``,
    ``a3 cos(theta3) - d4 sin(theta3) = K`` with
    ``K = (|w|^2 - a2^2 - a3^2 - d3^2 - d4^2) / (2 a2)``, and ``theta2`` from the planar
    2x2 system of the arm's plane. Orientation: ``Rx(alpha3)^T R_36`` is the ZYZ product
    ``Rz(theta4) Ry(-theta5) Rz(theta6)`` (both wrist branches).
    """
    if not is_puma_like(robot):
        return []
    _, a, d, off = robot.table
    t = np.eye(4) if base is None else np.asarray(base, dtype=float)
    rb = t[:3, :3]
    p = rb.T @ (np.asarray(position, dtype=float) - t[:3, 3])
    rot = rb.T @ np.asarray(rotation, dtype=float)
    w = p - rot @ robot.tcp
    w[2] -= d[0]
    a2, a3, d3, d4 = a[2], a[3], d[2], d[3]
    # at the shoulder / elbow-straight boundaries rho2 / disc are 0 up to round-off (seen:
    # -1e-18): clamped, else a reachable pose there had no candidate
    rho2 = w[0] ** 2 + w[1] ** 2 - d3 ** 2
    if rho2 < 0:
        if rho2 < -_ROUND_OFF:
            return []
        rho2 = 0.0
    k = (w @ w - a2 ** 2 - a3 ** 2 - d3 ** 2 - d4 ** 2) / (2 * a2)
    disc = a3 ** 2 + d4 ** 2 - k ** 2
    if disc < 0:
        if disc < -_ROUND_OFF:
            return []
        disc = 0.0
    out: list[FloatArray] = []
    for arm_sign in (1.0, -1.0):
        x = arm_sign * math.sqrt(rho2)
        th1 = math.atan2(w[1], w[0]) - math.atan2(d3, x)
        c1, s1 = math.cos(th1), math.sin(th1)
        xx = c1 * w[0] + s1 * w[1]
        for elbow in (1.0, -1.0):
            th3 = math.atan2(a3, d4) - math.atan2(k, elbow * math.sqrt(disc))
            c3, s3 = math.cos(th3), math.sin(th3)
            big_a = a2 + a3 * c3 - d4 * s3
            big_b = a3 * s3 + d4 * c3
            th2 = math.atan2(-(big_b * xx + big_a * w[2]), big_a * xx - big_b * w[2])
            theta = np.array([th1, th2, th3, 0.0, 0.0, 0.0])
            r03 = frames_one(robot, theta - off)[3, :3, :3]
            m = rot_x(robot.joints[3].alpha).T @ (r03.T @ rot)
            for th4, b, th6 in _zyz(m):
                theta[3:] = (th4, -b, th6)
                out.append(theta - off)
    return out


def wrist_centre_outside(robot: RobotModel, position: FloatArray, rotation: FloatArray,
                         base: FloatArray | None = None) -> float:
    """A lower bound [m] of how far the wrist centre of a pose lies outside the set of wrist
    centres a PUMA-like arm reaches (joint limits ignored); <= 0 inside, ``-inf`` for an arm
    without that structure.

    The wrist centre ``w = p - R tcp`` (base frame, shoulder height removed) is reachable
    exactly when ``wx^2 + wy^2 >= d3^2`` (theta1 exists) and ``r_min <= |w| <= r_max`` with
    ``|w|^2 = a2^2 + a3^2 + d3^2 + d4^2 + 2 a2 K``, ``|K| <= sqrt(a3^2 + d4^2)`` (theta3
    exists; theta2 always does then): the conditions under which :func:`puma_ik` has
    solutions. The distance to an intersection is at least the distance to each set, so
    the larger of ``d3 - |w_xy|`` and the distance to the shell ``[r_min, r_max]`` is a
    lower bound. A configuration reaching the pose within ``tol_p`` [m] and ``tol_r``
    [rad] has its wrist centre within ``tol_p + |tcp| tol_r`` of the target's, so a bound
    above that proves no such configuration exists.
    """
    if not is_puma_like(robot):
        return -math.inf
    _, a, d, _ = robot.table
    t = np.eye(4) if base is None else np.asarray(base, dtype=float)
    rb = t[:3, :3]
    p = rb.T @ (np.asarray(position, dtype=float) - t[:3, 3])
    w = p - (rb.T @ np.asarray(rotation, dtype=float)) @ robot.tcp
    w[2] -= d[0]
    a2, a3, d3, d4 = float(a[2]), float(a[3]), float(d[2]), float(d[3])
    const = a2 ** 2 + a3 ** 2 + d3 ** 2 + d4 ** 2
    spread = 2.0 * abs(a2) * math.hypot(a3, d4)
    r_min = math.sqrt(max(const - spread, 0.0))
    r_max = math.sqrt(const + spread)
    norm = float(np.linalg.norm(w))
    return max(abs(d3) - math.hypot(float(w[0]), float(w[1])), r_min - norm, norm - r_max)


def wrap_into(q: FloatArray, lower: FloatArray, upper: FloatArray, near: FloatArray
              ) -> FloatArray | None:
    """``q`` ``(n,)`` with each joint shifted by a multiple of 2π into ``[lower, upper]``
    (the shift closest to ``near`` when several fit), or None if a joint fits no shift."""
    out = wrap_into_batch(np.asarray(q, dtype=float)[None], lower, upper, near)[0]
    return None if np.isnan(out[0]) else out


_SHIFTS = 2 * math.pi * np.arange(-2, 3)


def wrap_into_batch(q: FloatArray, lower: FloatArray, upper: FloatArray, near: FloatArray
                    ) -> FloatArray:
    """:func:`wrap_into` for ``(m, n)`` candidates at once; rows that fit no shift are NaN."""
    two_pi = 2 * math.pi
    base = q + two_pi * np.round((near - q) / two_pi)
    cand = base[..., None] + _SHIFTS                                  # (m, n, 5)
    ok = (cand >= (lower - 1e-12)[:, None]) & (cand <= (upper + 1e-12)[:, None])
    dist = np.where(ok, np.abs(cand - near[:, None]), np.inf)
    pick = np.argmin(dist, axis=-1)
    out = np.take_along_axis(cand, pick[..., None], axis=-1)[..., 0]
    out = np.clip(out, lower, upper)
    out[~np.all(np.isfinite(np.min(dist, axis=-1)), axis=-1)] = np.nan
    return out
