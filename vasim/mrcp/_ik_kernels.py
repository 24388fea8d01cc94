"""Compiled full-pose inverse kinematics on the DH chain (numba ``cache=True``).

:func:`pose_dls` is the damped-least-squares refinement of
:meth:`vasim.mrcp.arm.PybulletArm.ik` for a full pose (position and orientation), the same
iteration as the Python loop it replaces, bit for bit (issue #17 §5: that loop, run about
1,300 times a cycle, was 80 % of the 8-robot scenario's cycle):

* error ``e = [p* - p(q); ω(R(q) → R*)]`` (world frame, ``ω`` the axis-angle vector of
  :func:`vasim.mrcp.arm.rotation_error`; near π, where that takes scipy's route, the
  kernel hands that one step to Python and resumes after it);
* converged when ``|e_p| <= tol_p`` and ``|e_ω| <= tol_r`` (checked before every step);
* given up when, from step 8 on, ``|e|`` is above 0.7 x its value 5 steps earlier;
* step ``dq = Jᵀ (J Jᵀ + λ I)⁻¹ e`` (numpy's BLAS products and LAPACK solve: numba calls
  the same routines), scaled to at most 0.5 rad, joints wrapped by 2π into their limits
  then clamped (:func:`vasim.mrcp.dh.wrap_clip`).

**Decision** (bit-identical arithmetic, not just equal to round-off): the 8-robot scenario
turns on differences of 1e-16 rad (a Cholesky solve, equal to round-off, changed its
transfers), so every product here is the one the Python loop made: ``@`` on arrays (BLAS
``dgemm`` / ``dgemv`` as numpy), ``np.linalg.solve`` (LAPACK ``dgesv``), norms summed in
order; the tests compare the two bit for bit.

:func:`trajectory_ik` runs it (or the position-only iteration of
:func:`vasim.mrcp.dh.position_dls`) along the predicted points of many (robot, task point)
pairs in one call, each point seeded with the previous point's solution: the first attempt
of every IK the kernel makes in a cycle; the points where that attempt fails are left to
the arm's full search (closed form, restarts).

Units: metres, radians; poses in the world frame of the arm's ``base`` ``(4, 4)``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from vasim.mrcp.dh import _chain_kernel, _jacobian_kernel, _position_dls_kernel, _wrap_clip

#: :func:`pose_dls` status: reached the pose / gave up / stopped where the Python loop
#: must take over (a rotation error near π, whose route is scipy's).
REACHED, FAILED, NEEDS_PYTHON = 1, 0, -1


@njit(cache=True, nogil=True)
def _norm(x: np.ndarray) -> float:  # pragma: no cover - compiled
    """Euclidean norm, summed in order (``np.linalg.norm``'s result for short vectors)."""
    acc = 0.0
    for v in x:
        acc += v * v
    return np.sqrt(acc)


@njit(cache=True, nogil=True)
def rotation_error(cur: np.ndarray, rot: np.ndarray, out: np.ndarray
                   ) -> bool:  # pragma: no cover - compiled
    """Axis-angle vector [rad] (world frame) turning ``cur`` (C-contiguous ``(3, 3)``) into
    ``rot``, into ``out``: :func:`vasim.mrcp.arm.rotation_error`'s arithmetic (``atan2`` of
    the skew part's norm and the trace, the same BLAS product); False, ``out`` untouched,
    near π (``cos <= -0.99``), where that function takes scipy's route."""
    m = rot @ cur.T
    w = np.empty(3)
    w[0], w[1], w[2] = m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]
    s = 0.5 * _norm(w)
    c = 0.5 * (m[0, 0] + m[1, 1] + m[2, 2] - 1.0)
    if not c > -0.99:
        return False
    f = 0.5 if s < 1e-12 else np.arctan2(s, c) / (2.0 * s)
    out[0], out[1], out[2] = w[0] * f, w[1] * f, w[2] * f
    return True


@njit(cache=True, nogil=True)
def pose_dls(table: np.ndarray, tcp: np.ndarray, base: np.ndarray, q0: np.ndarray,
             target: np.ndarray, rot: np.ndarray, lower: np.ndarray, upper: np.ndarray,
             tol_p: float, tol_r: float, iterations: int, damping: float, start: int = 0,
             history: np.ndarray | None = None
             ) -> tuple[np.ndarray, int, int]:  # pragma: no cover - compiled
    """Full-pose damped least squares from ``q0`` (see the module docstring): the final
    configuration, :data:`REACHED` (within ``tol_p`` [m] of ``target`` ``(3,)`` and
    ``tol_r`` [rad] of ``rot`` ``(3, 3)``), :data:`FAILED` or :data:`NEEDS_PYTHON` (a
    rotation error near π at that step), and the step it stopped at.

    ``start`` / ``history`` resume a run at step ``start`` with the error norms of the
    earlier steps (``(iterations,)``, filled in place): after :data:`NEEDS_PYTHON` the
    caller makes that one step in Python and resumes here at the next.

    Bit for bit the Python loop's arithmetic (the same BLAS / LAPACK products and solve,
    norms summed in order: the tests compare them exactly), so every scenario's outcome
    is the one the Python loop gave; the 8-robot scenario's turns on differences of 1e-16.
    """
    n = q0.shape[0]
    q = np.minimum(np.maximum(q0, lower), upper)
    frames = np.empty((n + 2, 4, 4))
    jac = np.empty((6, n))
    hist = np.empty(iterations) if history is None else history
    err = np.empty(6)
    er = np.empty(3)
    for it in range(start, iterations):
        _chain_kernel(table, tcp, base, q, frames)
        _jacobian_kernel(frames, jac)
        for r in range(3):
            err[r] = target[r] - frames[n + 1, r, 3]
        if not rotation_error(np.ascontiguousarray(frames[n + 1, :3, :3]), rot, er):
            return q, NEEDS_PYTHON, it
        err[3], err[4], err[5] = er[0], er[1], er[2]
        if _norm(err[:3]) <= tol_p and _norm(er) <= tol_r:
            return q, REACHED, it
        norm = _norm(err)
        hist[it] = norm
        if it >= 8 and norm > 0.7 * hist[it - 5]:     # stagnating: give this start up
            return q, FAILED, it
        jj = jac @ jac.T
        for a in range(6):
            jj[a, a] += damping
        dq = jac.T @ np.linalg.solve(jj, err)
        step = np.max(np.abs(dq))
        if step > 0.5:
            dq *= 0.5 / step
        q = _wrap_clip(q + dq, lower, upper)
    return q, FAILED, iterations


@njit(cache=True, nogil=True)
def trajectory_ik(tables: np.ndarray, tcps: np.ndarray, bases: np.ndarray,
                  lowers: np.ndarray, uppers: np.ndarray, arm: np.ndarray,
                  seeds: np.ndarray, first: np.ndarray, positions: np.ndarray,
                  rotations: np.ndarray, full_pose: np.ndarray, tol_p: float, tol_r: float,
                  pose_iterations: int, position_iterations: int, configs: np.ndarray,
                  solved: np.ndarray) -> None:  # pragma: no cover - compiled
    """The first IK attempt along the predicted points of ``P`` (robot, point) pairs.

    Pair ``p`` uses arm ``arm[p]`` (its DH ``tables[a]`` ``(4, n)``, ``tcps[a]``, world
    ``bases[a]`` ``(4, 4)``, limits ``lowers[a]`` / ``uppers[a]``), starts from ``seeds[p]``
    ``(n,)`` and visits the ``K + 1`` targets ``positions[p]`` ``(K+1, 3)`` (and
    ``rotations[p]`` ``(K+1, 3, 3)`` when ``full_pose[p]``) in order; point 0 is given
    (``configs[p, 0]`` already filled) when ``first[p]``. Each point starts from the last
    solved point's configuration (or the seed): :func:`pose_dls` with
    ``pose_iterations`` for a full pose, the position-only iteration with
    ``position_iterations`` otherwise. ``solved[p, k]`` says whether that attempt reached
    the target (``configs[p, k]`` its solution); a point it did not reach is left to the
    caller, and so is every point after it (their seeds depend on the caller's answer).
    """
    npairs = seeds.shape[0]
    npts = positions.shape[1]
    for p in range(npairs):
        a = arm[p]
        s = seeds[p].copy()
        for k in range(npts):
            solved[p, k] = False
        for k in range(npts):
            if k == 0 and first[p]:
                solved[p, 0] = True
                s = configs[p, 0].copy()
                continue
            if full_pose[p]:
                q, status, _ = pose_dls(tables[a], tcps[a], bases[a], s, positions[p, k],
                                        rotations[p, k], lowers[a], uppers[a], tol_p, tol_r,
                                        pose_iterations, 1e-6)
                ok = status == REACHED
            else:
                q, ok = _position_dls_kernel(tables[a], tcps[a], bases[a], s, positions[p, k],
                                             lowers[a], uppers[a], tol_p,
                                             position_iterations, 1e-6)
            if not ok:
                break
            configs[p, k] = q
            solved[p, k] = True
            s = q
