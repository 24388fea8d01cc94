"""numba kernels of the mass-spring integrator (private; the API is ``vasim.abdomen.integrate``).

Every kernel is ``@njit(cache=True, nogil=True, fastmath=False)``: compiled once and cached
on disk (``__pycache__``), run without the interpreter lock (two organs can step on two cores
while the haptic loop keeps running), and with strict IEEE arithmetic (NaN detection relies
on it). Arrays are C-contiguous float64 ``(n, 3)`` positions [m] in the world frame, int64
index arrays. The step kernel allocates nothing: its scratch arrays belong to the caller
(``OrganSolver``). The geometry kernels at the end (inward ray casting for the interior nodes,
the self-intersection test of user meshes) run once, when a model is built or a mesh loaded.

Spring model (for one spring s between nodes i and j, stiffness k [N/m], rest length r [m]):
``d = x_i - x_j``, ``l = |d|``, ``n = d / l``; energy ``E = k (l - r)^2 / 2``; force on i
``-k (l - r) n`` (and the opposite on j); Hessian block (on the i-i entry, ``-H`` on i-j)
``H = k [a I + (1 - a) n n^T]`` with ``a = 1 - r / l``. A compressed spring has ``a < 0``
(an indefinite Hessian: buckling); the kernels clamp ``a`` to 0 there, the standard
positive semi-definite projection, so that every Newton system is SPD.
"""

from __future__ import annotations

import numpy as np
from numba import njit

_EPS_LENGTH = 1e-12
"""Springs shorter than this [m] exert no force and have no direction (coincident nodes)."""

# Status codes returned by :func:`implicit_step`.
STATUS_OK = 0
STATUS_NONFINITE = 1
STATUS_BAD_INPUT = 2
STATUS_BAD_TARGETS = 3


@njit(cache=True, nogil=True, fastmath=False)
def spring_forces(x, si, sj, k, r, out):
    """Adds the spring forces at ``x`` into ``out`` (n, 3) [N]; returns the spring energy [J]."""
    e = 0.0
    for s in range(si.shape[0]):
        i = si[s]
        j = sj[s]
        d0 = x[i, 0] - x[j, 0]
        d1 = x[i, 1] - x[j, 1]
        d2 = x[i, 2] - x[j, 2]
        ln = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        dl = ln - r[s]
        e += 0.5 * k[s] * dl * dl
        if ln > _EPS_LENGTH:
            f = -k[s] * dl / ln
            out[i, 0] += f * d0
            out[i, 1] += f * d1
            out[i, 2] += f * d2
            out[j, 0] -= f * d0
            out[j, 1] -= f * d1
            out[j, 2] -= f * d2
    return e


@njit(cache=True, nogil=True, fastmath=False)
def spring_energy(x, si, sj, k, r):
    """Spring potential energy at ``x`` [J]."""
    e = 0.0
    for s in range(si.shape[0]):
        i = si[s]
        j = sj[s]
        d0 = x[i, 0] - x[j, 0]
        d1 = x[i, 1] - x[j, 1]
        d2 = x[i, 2] - x[j, 2]
        dl = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2) - r[s]
        e += 0.5 * k[s] * dl * dl
    return e


@njit(cache=True, nogil=True, fastmath=False)
def _objective(x, y, z, free, mass_dt2, c_dt, si, sj, k, r, grad, coef):
    """Incremental potential g(x), its gradient and the per-spring Hessian data, in one pass.

    ``g(x) = sum_i m_i/(2 dt^2) |x_i - y_i|^2 + c/(2 dt) |x_i - z_i|^2 + E(x)`` over the free
    nodes (anchored nodes are fixed, their inertia terms are constants and left out).
    Writes ``grad`` (n, 3) (zero on anchored nodes) and ``coef`` (s, 4) = (n_x, n_y, n_z, a)
    per spring (``a`` clamped, see the module docstring). Returns g [J] (up to a constant).
    """
    n = x.shape[0]
    g = 0.0
    for i in range(n):
        if free[i]:
            a0 = x[i, 0] - y[i, 0]
            a1 = x[i, 1] - y[i, 1]
            a2 = x[i, 2] - y[i, 2]
            b0 = x[i, 0] - z[i, 0]
            b1 = x[i, 1] - z[i, 1]
            b2 = x[i, 2] - z[i, 2]
            md = mass_dt2[i]
            g += 0.5 * md * (a0 * a0 + a1 * a1 + a2 * a2)
            g += 0.5 * c_dt * (b0 * b0 + b1 * b1 + b2 * b2)
            grad[i, 0] = md * a0 + c_dt * b0
            grad[i, 1] = md * a1 + c_dt * b1
            grad[i, 2] = md * a2 + c_dt * b2
        else:
            grad[i, 0] = 0.0
            grad[i, 1] = 0.0
            grad[i, 2] = 0.0
    for s in range(si.shape[0]):
        i = si[s]
        j = sj[s]
        d0 = x[i, 0] - x[j, 0]
        d1 = x[i, 1] - x[j, 1]
        d2 = x[i, 2] - x[j, 2]
        ln = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        ks = k[s]
        dl = ln - r[s]
        g += 0.5 * ks * dl * dl
        if ln > _EPS_LENGTH:
            inv = 1.0 / ln
            n0 = d0 * inv
            n1 = d1 * inv
            n2 = d2 * inv
            a = 1.0 - r[s] * inv
            if a < 0.0:
                a = 0.0
        else:
            n0 = 0.0
            n1 = 0.0
            n2 = 0.0
            a = 0.0
        coef[s, 0] = n0
        coef[s, 1] = n1
        coef[s, 2] = n2
        coef[s, 3] = a
        f = ks * dl
        # accumulated on every row (no branch in the hot loop); the anchored rows are
        # zeroed below, the free rows get the same sums in the same order
        grad[i, 0] += f * n0
        grad[i, 1] += f * n1
        grad[i, 2] += f * n2
        grad[j, 0] -= f * n0
        grad[j, 1] -= f * n1
        grad[j, 2] -= f * n2
    for i in range(n):
        if not free[i]:
            grad[i, 0] = 0.0
            grad[i, 1] = 0.0
            grad[i, 2] = 0.0
    return g


@njit(cache=True, nogil=True, fastmath=False)
def _objective_value(x, y, z, free, mass_dt2, c_dt, si, sj, k, r):
    """g(x) only (the line search's trial evaluations), see :func:`_objective`."""
    g = 0.0
    for i in range(x.shape[0]):
        if free[i]:
            a0 = x[i, 0] - y[i, 0]
            a1 = x[i, 1] - y[i, 1]
            a2 = x[i, 2] - y[i, 2]
            b0 = x[i, 0] - z[i, 0]
            b1 = x[i, 1] - z[i, 1]
            b2 = x[i, 2] - z[i, 2]
            g += 0.5 * mass_dt2[i] * (a0 * a0 + a1 * a1 + a2 * a2)
            g += 0.5 * c_dt * (b0 * b0 + b1 * b1 + b2 * b2)
    return g + spring_energy(x, si, sj, k, r)


@njit(cache=True, nogil=True, fastmath=False)
def ldl_solve_inplace(lp, li, lx, up, ui, ux, dinv, b):
    """Solves ``L D L^T u = b`` in place; ``L`` unit lower triangular, diagonal not stored.

    Both substitutions gather (a dot product per row, no scattered stores): the forward one
    reads ``L`` by rows (CSR ``up, ui, ux``), the backward one reads ``L^T`` by rows, i.e.
    ``L`` by columns (CSC ``lp, li, lx``).

    Args:
        lp, li, lx: CSC column pointers (m+1,), row indices and values of the strict lower part.
        up, ui, ux: the same entries in CSR.
        dinv: (m,) inverse of D.
        b: (m, 3) right-hand sides (the three coordinates share the scalar matrix); overwritten.
    """
    m = b.shape[0]
    for j in range(m):
        s0 = b[j, 0]
        s1 = b[j, 1]
        s2 = b[j, 2]
        for p in range(up[j], up[j + 1]):
            i = ui[p]
            w = ux[p]
            s0 -= w * b[i, 0]
            s1 -= w * b[i, 1]
            s2 -= w * b[i, 2]
        b[j, 0] = s0
        b[j, 1] = s1
        b[j, 2] = s2
    # b holds L^-1 b; the diagonal scaling is folded into the backward pass
    for j in range(m - 1, -1, -1):
        d = dinv[j]
        s0 = b[j, 0] * d
        s1 = b[j, 1] * d
        s2 = b[j, 2] * d
        for p in range(lp[j], lp[j + 1]):
            i = li[p]
            w = lx[p]
            s0 -= w * b[i, 0]
            s1 -= w * b[i, 1]
            s2 -= w * b[i, 2]
        b[j, 0] = s0
        b[j, 1] = s1
        b[j, 2] = s2


@njit(cache=True, nogil=True, fastmath=False)
def _precondition(kind, r, out, free, pdiag, lp, li, lx, up, ui, ux, dinv, perm, buf):
    """out = P^-1 r; returns r . out over the free nodes.

    kind 0: ``pdiag`` (n,) is the inverse diagonal; kind 1: the prefactored matrix.
    """
    n = r.shape[0]
    rz = 0.0
    if kind == 0:
        for i in range(n):
            if free[i]:
                w = pdiag[i]
                r0 = r[i, 0]
                r1 = r[i, 1]
                r2 = r[i, 2]
                out[i, 0] = w * r0
                out[i, 1] = w * r1
                out[i, 2] = w * r2
                rz += w * (r0 * r0 + r1 * r1 + r2 * r2)
            else:
                out[i, 0] = 0.0
                out[i, 1] = 0.0
                out[i, 2] = 0.0
    else:
        m = perm.shape[0]
        for q in range(m):
            i = perm[q]
            buf[q, 0] = r[i, 0]
            buf[q, 1] = r[i, 1]
            buf[q, 2] = r[i, 2]
        ldl_solve_inplace(lp, li, lx, up, ui, ux, dinv, buf)
        for i in range(n):
            out[i, 0] = 0.0
            out[i, 1] = 0.0
            out[i, 2] = 0.0
        for q in range(m):
            i = perm[q]
            out[i, 0] = buf[q, 0]
            out[i, 1] = buf[q, 1]
            out[i, 2] = buf[q, 2]
            rz += r[i, 0] * buf[q, 0] + r[i, 1] * buf[q, 1] + r[i, 2] * buf[q, 2]
    return rz


@njit(cache=True, nogil=True, fastmath=False)
def _spring_hess_dot(p, free, si, sj, k, coef, out):
    """``out = H p`` and returns ``p . H p`` over the free nodes.

    ``H = diag(m/dt^2 + c/dt) + sum of clamped spring Hessians`` on the free rows (anchored
    rows zeroed). The caller has already written the diagonal term ``out = diag * p`` (fused
    with its direction update); the dot product is fused with the zeroing of the anchored
    rows (the sums of :func:`_dot`, in the same order).
    """
    for s in range(si.shape[0]):
        i = si[s]
        j = sj[s]
        q0 = p[i, 0] - p[j, 0]
        q1 = p[i, 1] - p[j, 1]
        q2 = p[i, 2] - p[j, 2]
        n0 = coef[s, 0]
        n1 = coef[s, 1]
        n2 = coef[s, 2]
        a = coef[s, 3]
        ks = k[s]
        nq = (1.0 - a) * (n0 * q0 + n1 * q1 + n2 * q2)
        h0 = ks * (a * q0 + nq * n0)
        h1 = ks * (a * q1 + nq * n1)
        h2 = ks * (a * q2 + nq * n2)
        out[i, 0] += h0
        out[i, 1] += h1
        out[i, 2] += h2
        out[j, 0] -= h0
        out[j, 1] -= h1
        out[j, 2] -= h2
    total = 0.0
    for i in range(p.shape[0]):
        if free[i]:
            total += p[i, 0] * out[i, 0] + p[i, 1] * out[i, 1] + p[i, 2] * out[i, 2]
        else:
            out[i, 0] = 0.0
            out[i, 1] = 0.0
            out[i, 2] = 0.0
    return total


@njit(cache=True, nogil=True, fastmath=False)
def _update_precondition(kind, alpha, pdir, hp, d, r, out, free, pdiag, lp, li, lx, up, ui,
                         ux, dinv, perm, buf):
    """``d += alpha pdir``, ``r -= alpha hp``, then ``out = P^-1 r``; returns ``r . out``
    over the free nodes: the CG update and :func:`_precondition` in one pass over the nodes
    (kind 0) or with the update fused into the factor's gather (kind 1; the anchored rows
    of ``d`` and ``r`` are left alone: ``pdir`` and ``hp`` are zero there)."""
    n = r.shape[0]
    rz = 0.0
    if kind == 0:
        for i in range(n):
            d0 = d[i, 0] + alpha * pdir[i, 0]
            d1 = d[i, 1] + alpha * pdir[i, 1]
            d2 = d[i, 2] + alpha * pdir[i, 2]
            r0 = r[i, 0] - alpha * hp[i, 0]
            r1 = r[i, 1] - alpha * hp[i, 1]
            r2 = r[i, 2] - alpha * hp[i, 2]
            d[i, 0] = d0
            d[i, 1] = d1
            d[i, 2] = d2
            r[i, 0] = r0
            r[i, 1] = r1
            r[i, 2] = r2
            if free[i]:
                w = pdiag[i]
                out[i, 0] = w * r0
                out[i, 1] = w * r1
                out[i, 2] = w * r2
                rz += w * (r0 * r0 + r1 * r1 + r2 * r2)
            else:
                out[i, 0] = 0.0
                out[i, 1] = 0.0
                out[i, 2] = 0.0
        return rz
    # Decision (issue #29 item 6): the permuted LDL solve and scatter are written out as in
    # _precondition (kind 1), fused here with the CG update of d and r (one pass over the
    # rows instead of an update pass and a _precondition call).
    m = perm.shape[0]
    for q in range(m):
        i = perm[q]
        for c in range(3):
            d[i, c] += alpha * pdir[i, c]
            v = r[i, c] - alpha * hp[i, c]
            r[i, c] = v
            buf[q, c] = v
    ldl_solve_inplace(lp, li, lx, up, ui, ux, dinv, buf)
    for i in range(n):
        out[i, 0] = 0.0
        out[i, 1] = 0.0
        out[i, 2] = 0.0
    for q in range(m):
        i = perm[q]
        out[i, 0] = buf[q, 0]
        out[i, 1] = buf[q, 1]
        out[i, 2] = buf[q, 2]
        rz += r[i, 0] * buf[q, 0] + r[i, 1] * buf[q, 1] + r[i, 2] * buf[q, 2]
    return rz


@njit(cache=True, nogil=True, fastmath=False)
def _dot(a, b, free):
    s = 0.0
    for i in range(a.shape[0]):
        if free[i]:
            s += a[i, 0] * b[i, 0] + a[i, 1] * b[i, 1] + a[i, 2] * b[i, 2]
    return s


@njit(cache=True, nogil=True, fastmath=False)
def _max_abs(a, free):
    s = 0.0
    for i in range(a.shape[0]):
        if free[i]:
            for c in range(3):
                v = abs(a[i, c])
                if v > s:
                    s = v
    return s


@njit(cache=True, nogil=True, fastmath=False)
def _all_finite(a):
    for i in range(a.shape[0]):
        for c in range(a.shape[1]):
            if not np.isfinite(a[i, c]):
                return False
    return True


@njit(cache=True, nogil=True, fastmath=False)
def implicit_step(
    x, v, rest, anchors, anchor_targets, free, f_ext, v_frame, mass, damping, gravity, dt,
    si, sj, k, r, kind, pdiag, lp, li, lx, up, ui, ux, dinv, perm,
    tol, atol, cg_tol, max_newton, max_cg, work, scal, coef, buf, stats,
):  # fmt: skip
    """One backward-Euler step: ``x``, ``v`` (n, 3) are advanced by ``dt`` in place.

    Minimises the incremental potential g (see :func:`_objective`) from the inertial
    prediction with Newton's method. Each Newton system ``H d = -grad g`` is solved by a
    preconditioned conjugate gradient (CG) from ``d = 0``; a backtracking (Armijo) line search
    on g then accepts ``x + alpha d``. Since every accepted iterate lowers g, a truncated
    solve (an exhausted CG budget) still returns a state no worse than the prediction.

    Every criterion is *relative* to the step itself, so a truncated solve delays the
    approach to equilibrium but never leaves a permanent offset (an absolute threshold on the
    residual would: smooth modes such as a slow sag have a tiny residual per metre of error,
    and the body would creep under gravity). CG stops when its preconditioned residual has
    fallen by ``cg_tol``. The step has converged when

    * the accepted update is below ``tol`` times the step's displacement ``max|x - x_n|``
      (or below ``atol`` [m], a round-off floor), or
    * the full Newton step was accepted, its CG converged and the actual decrease of g
      matched the quadratic model's prediction within ``tol``: the model is exact to that
      accuracy, so another Newton iteration would change nothing that matters (this saves
      the second gradient evaluation at small ``dt``), or
    * the preconditioned gradient is below ``atol`` (at rest in equilibrium to round-off).

    Args:
        x, v: (n, 3) positions [m] and velocities [m/s]; overwritten with the new state.
        rest: (n, 3) rest positions [m] (for the displacement bound in ``stats[4]``).
        anchors: (a,) anchored node indices; anchor_targets: (a, 3) their positions at t + dt.
        free: (n,) uint8, 1 for simulated nodes, 0 for anchored ones.
        f_ext: (n, 3) external forces [N]; v_frame: (n, 3) velocity the damping pulls toward.
        mass: (n,) [kg]; damping: viscous coefficient per node [N s/m]; gravity: (3,) [m/s^2].
        dt: time step [s].
        si, sj, k, r: springs (s,) endpoints, stiffness [N/m], rest length [m].
        kind: preconditioner, 0 = diagonal: ``pdiag`` (n,) holds the inverse diagonal;
            1 = the prefactored matrix ``lp, li, lx, up, ui, ux, dinv, perm``
            (:func:`ldl_solve_inplace`; ``perm[q]`` is the node of factor row q).
        tol: relative tolerance; atol: absolute floor [m]; cg_tol: CG relative residual;
            max_newton: Newton iterations at most; max_cg: CG iterations (Hessian products)
            at most for the whole step.
        work: (10, n, 3) scratch; scal: (2, n) scratch; coef: (s, 4) scratch; buf: (m, 3)
            scratch for the factor solve (m = number of free nodes).
        stats: (7,) float64 output: Newton iterations, CG iterations, converged (0/1), the
            last accepted update max|alpha d| [m], max |x - rest| [m] and max |v| [m/s]
            (per coordinate) after the step, passes over the springs.

    Returns:
        STATUS_OK; STATUS_NONFINITE when the new state is not finite (the caller resets);
        STATUS_BAD_INPUT when ``x``, ``v``, ``f_ext`` or ``v_frame`` is not finite on entry,
        STATUS_BAD_TARGETS when ``anchor_targets`` is not (nothing is changed).
    """
    n = x.shape[0]
    stats[0] = 0.0
    stats[1] = 0.0
    stats[2] = 0.0
    stats[3] = 0.0
    stats[4] = 0.0
    stats[5] = 0.0
    stats[6] = 0.0
    if not _all_finite(anchor_targets):
        return STATUS_BAD_TARGETS
    if not (_all_finite(x) and _all_finite(v) and _all_finite(f_ext) and _all_finite(v_frame)):
        return STATUS_BAD_INPUT
    xn = work[0]
    y = work[1]
    z = work[2]
    grad = work[3]
    d = work[4]
    res = work[5]
    pz = work[6]
    hp = work[7]
    pdir = work[8]
    xt = work[9]
    mass_dt2 = scal[0]
    diag = scal[1]
    inv_dt = 1.0 / dt
    c_dt = damping * inv_dt
    for i in range(n):
        mass_dt2[i] = mass[i] * inv_dt * inv_dt
        diag[i] = mass_dt2[i] + c_dt
    for i in range(n):
        for c in range(3):
            xn[i, c] = x[i, c]
            y[i, c] = x[i, c] + dt * v[i, c] + dt * dt * (gravity[c] + f_ext[i, c] / mass[i])
            z[i, c] = x[i, c] + dt * v_frame[i, c]
            x[i, c] = y[i, c]  # warm start: the inertial prediction
    for a in range(anchors.shape[0]):
        i = anchors[a]
        for c in range(3):
            x[i, c] = anchor_targets[a, c]
    g = _objective(x, y, z, free, mass_dt2, c_dt, si, sj, k, r, grad, coef)
    passes = 1  # passes over the springs (objective, line-search trials, Hessian products)
    n_newton = 0
    n_cg = 0
    converged = 0
    last = 0.0
    for _newton in range(max_newton):
        for i in range(n):
            for c in range(3):
                d[i, c] = 0.0
                res[i, c] = -grad[i, c]
        rz = _precondition(kind, res, pz, free, pdiag, lp, li, lx, up, ui, ux, dinv,
                           perm, buf)
        if _max_abs(pz, free) <= atol:
            converged = 1
            break
        n_newton += 1
        rz0 = rz
        model = 0.0  # decrease of the quadratic model so far (sum of alpha_i r_i.z_i / 2)
        cg_done = False
        # The node-wise passes of each CG iteration are fused (same operations in the same
        # order as one pass each, so the same bits): the direction update with the diagonal
        # term of the next Hessian product, the zeroing of anchored rows with p.Hp, the
        # update of d and the residual with the preconditioner's first pass.
        for i in range(n):
            w = diag[i]
            for c in range(3):
                pv = pz[i, c]
                pdir[i, c] = pv
                hp[i, c] = w * pv
        while n_cg < max_cg:
            php = _spring_hess_dot(pdir, free, si, sj, k, coef, hp)
            n_cg += 1
            if not php > 0.0:
                cg_done = True  # round-off level: nothing left to solve
                break
            alpha = rz / php
            model += 0.5 * alpha * rz
            rz_new = _update_precondition(kind, alpha, pdir, hp, d, res, pz, free, pdiag, lp, li,
                                          lx, up, ui, ux, dinv, perm, buf)
            if rz_new <= cg_tol * cg_tol * rz0:
                cg_done = True
                break
            beta = rz_new / rz
            rz = rz_new
            for i in range(n):
                w = diag[i]
                for c in range(3):
                    pv = pz[i, c] + beta * pdir[i, c]
                    pdir[i, c] = pv
                    hp[i, c] = w * pv
        # Backtracking line search on g along d (Armijo), from alpha = 1.
        slope = _dot(grad, d, free)
        if not slope < 0.0:
            break  # no descent direction (round-off level): keep the current iterate
        step = 1.0
        accepted = False
        gt = g
        for _ls in range(40):
            for i in range(n):
                if free[i]:
                    for c in range(3):
                        xt[i, c] = x[i, c] + step * d[i, c]
                else:
                    for c in range(3):
                        xt[i, c] = x[i, c]
            gt = _objective_value(xt, y, z, free, mass_dt2, c_dt, si, sj, k, r)
            passes += 1
            if gt <= g + 1e-4 * step * slope:
                accepted = True
                break
            step *= 0.5
        if not accepted:
            break
        for i in range(n):
            for c in range(3):
                x[i, c] = xt[i, c]
        last = step * _max_abs(d, free)
        scale = 0.0
        for i in range(n):
            if free[i]:
                for c in range(3):
                    e = abs(x[i, c] - xn[i, c])
                    if e > scale:
                        scale = e
        if last <= max(tol * scale, atol):
            converged = 1
            break
        if step == 1.0 and cg_done and abs((g - gt) - model) <= tol * model:
            converged = 1
            break
        if _newton + 1 >= max_newton or n_cg >= max_cg:
            break  # budget spent: keep the (improved) iterate
        g = _objective(x, y, z, free, mass_dt2, c_dt, si, sj, k, r, grad, coef)
        passes += 1
    status = STATUS_OK
    disp = 0.0
    speed = 0.0
    for i in range(n):
        for c in range(3):
            vi = (x[i, c] - xn[i, c]) * inv_dt
            v[i, c] = vi
            if not (np.isfinite(vi) and np.isfinite(x[i, c])):
                status = STATUS_NONFINITE
            e = abs(x[i, c] - rest[i, c])
            if e > disp:
                disp = e
            if abs(vi) > speed:
                speed = abs(vi)
    stats[0] = n_newton
    stats[1] = n_cg
    stats[2] = converged
    stats[3] = last
    stats[4] = disp
    stats[5] = speed
    stats[6] = passes + n_cg
    return status


# ---------------------------------------------------------------------------------------
# Geometry (model building and mesh validation; run once, not per step)


@njit(cache=True, nogil=True, fastmath=False)
def _ray_triangle(o0, o1, o2, d0, d1, d2, a, b, c):
    """Distance t >= 0 along the ray o + t d to triangle (a, b, c), or -1 (Möller–Trumbore)."""
    e10 = b[0] - a[0]
    e11 = b[1] - a[1]
    e12 = b[2] - a[2]
    e20 = c[0] - a[0]
    e21 = c[1] - a[1]
    e22 = c[2] - a[2]
    p0 = d1 * e22 - d2 * e21
    p1 = d2 * e20 - d0 * e22
    p2 = d0 * e21 - d1 * e20
    det = e10 * p0 + e11 * p1 + e12 * p2
    scale = (e10 * e10 + e11 * e11 + e12 * e12) * (e20 * e20 + e21 * e21 + e22 * e22)
    if det * det <= 1e-24 * scale:
        return -1.0  # ray parallel to the triangle's plane (or a degenerate triangle)
    inv = 1.0 / det
    s0 = o0 - a[0]
    s1 = o1 - a[1]
    s2 = o2 - a[2]
    u = (s0 * p0 + s1 * p1 + s2 * p2) * inv
    if u < 0.0 or u > 1.0:
        return -1.0
    q0 = s1 * e12 - s2 * e11
    q1 = s2 * e10 - s0 * e12
    q2 = s0 * e11 - s1 * e10
    w = (d0 * q0 + d1 * q1 + d2 * q2) * inv
    if w < 0.0 or u + w > 1.0:
        return -1.0
    return (e20 * q0 + e21 * q1 + e22 * q2) * inv


@njit(cache=True, nogil=True, fastmath=False)
def inward_depth(vertices, normals, faces, eps):
    """Distance [m] from each vertex, inward along its normal, to the opposite surface.

    Args:
        vertices: (n, 3) [m]; normals: (n, 3) outward unit vertex normals; faces: (f, 3).
        eps: hits closer than this [m] are ignored (the vertex's own faces).

    Returns:
        (n,) depth [m]; -1 where the inward ray leaves without a hit (an open mesh).
    """
    n = vertices.shape[0]
    out = np.full(n, -1.0)
    for i in range(n):
        o0 = vertices[i, 0]
        o1 = vertices[i, 1]
        o2 = vertices[i, 2]
        d0 = -normals[i, 0]
        d1 = -normals[i, 1]
        d2 = -normals[i, 2]
        best = np.inf
        for f in range(faces.shape[0]):
            fa = faces[f, 0]
            fb = faces[f, 1]
            fc = faces[f, 2]
            if fa == i or fb == i or fc == i:
                continue
            t = _ray_triangle(o0, o1, o2, d0, d1, d2, vertices[fa], vertices[fb], vertices[fc])
            if eps < t < best:
                best = t
        if best < np.inf:
            out[i] = best
    return out


@njit(cache=True, nogil=True, fastmath=False)
def _segment_hits_triangle(p, q, a, b, c):
    """True if the open segment p-q crosses the interior of triangle (a, b, c)."""
    d0 = q[0] - p[0]
    d1 = q[1] - p[1]
    d2 = q[2] - p[2]
    t = _ray_triangle(p[0], p[1], p[2], d0, d1, d2, a, b, c)
    return 1e-9 < t < 1.0 - 1e-9


@njit(cache=True, nogil=True, fastmath=False)
def self_intersections(vertices, faces, limit):
    """Pairs of non-adjacent triangles that intersect (broad phase: sweep and prune on x).

    Two triangles that share a vertex are adjacent and not tested. A pair intersects when an
    edge of one crosses the other (Möller–Trumbore per edge, both ways); coplanar overlaps
    are not detected (a measure-zero case for a triangulated organ surface).

    Args:
        vertices: (n, 3); faces: (f, 3) int64.
        limit: stop after this many pairs.

    Returns:
        (m, 2) int64 face index pairs, m <= limit.
    """
    nf = faces.shape[0]
    lo = np.empty((nf, 3))
    hi = np.empty((nf, 3))
    for f in range(nf):
        for c in range(3):
            a = vertices[faces[f, 0], c]
            b = vertices[faces[f, 1], c]
            e = vertices[faces[f, 2], c]
            lo[f, c] = min(a, min(b, e))
            hi[f, c] = max(a, max(b, e))
    order = np.argsort(lo[:, 0])
    out = np.empty((limit, 2), dtype=np.int64)
    m = 0
    for ii in range(nf):
        f = order[ii]
        for jj in range(ii + 1, nf):
            g = order[jj]
            if lo[g, 0] > hi[f, 0]:
                break
            if lo[g, 1] > hi[f, 1] or hi[g, 1] < lo[f, 1]:
                continue
            if lo[g, 2] > hi[f, 2] or hi[g, 2] < lo[f, 2]:
                continue
            shared = False
            for u in range(3):
                for w in range(3):
                    if faces[f, u] == faces[g, w]:
                        shared = True
            if shared:
                continue
            va = vertices[faces[f, 0]]
            vb = vertices[faces[f, 1]]
            vc = vertices[faces[f, 2]]
            wa = vertices[faces[g, 0]]
            wb = vertices[faces[g, 1]]
            wc = vertices[faces[g, 2]]
            hit = (
                _segment_hits_triangle(va, vb, wa, wb, wc)
                or _segment_hits_triangle(vb, vc, wa, wb, wc)
                or _segment_hits_triangle(vc, va, wa, wb, wc)
                or _segment_hits_triangle(wa, wb, va, vb, vc)
                or _segment_hits_triangle(wb, wc, va, vb, vc)
                or _segment_hits_triangle(wc, wa, va, vb, vc)
            )
            if hit:
                out[m, 0] = f
                out[m, 1] = g
                m += 1
                if m >= limit:
                    return out[:m]
    return out[:m]


# ---------------------------------------------------------------------------------------
# The moving frame (per step, per organ)


@njit(cache=True, nogil=True, fastmath=False)
def frame_velocity(cb, amp_b, ch, w_h, heart, out):  # pragma: no cover - compiled
    """``out = cb A_b (+ ch W_h)``: the frame velocity of every node into ``out`` (n, 3).

    The same products and sum as ``vasim.abdomen.motion.PointMotion.velocities`` (so the
    same bits), without its two temporaries. ``cb``, ``ch``: the breathing and heartbeat
    rate factors ``ω cos(ω t + φ)``; amp_b: (3,) [m]; w_h: (n, 3) heartbeat weight times
    amplitude [m]; heart: add the heartbeat term.
    """
    for i in range(out.shape[0]):
        for c in range(3):
            v = cb * amp_b[c]
            if heart:
                v += ch * w_h[i, c]
            out[i, c] = v
