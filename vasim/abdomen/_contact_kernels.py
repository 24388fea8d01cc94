"""numba kernels of tool–tissue contact (private; the API is ``vasim.abdomen.contact``).

Two entry points, both compiled once and cached on disk, run without the interpreter lock,
strict IEEE arithmetic (``fastmath=False``), and scalar code throughout: no array is
allocated inside a loop (3-vectors live in registers as floats), only the results.

* :func:`tool_contacts` (physics rate): the whole of ``detect_contacts`` in one pass -- the
  sampling spheres along the shaft, the broad phase, the narrow phase (per sphere the
  nearest triangle: Ericson, *Real-Time Collision Detection*, 2005, §5.1.5, region tests;
  the first one on ties, in face order), the penalty forces, their spread onto the nodes,
  the force and torque on the tool, and the force at the tip with its derivative.
* :func:`patch_tip_force` (1 kHz): the force at the tip and its derivative against frozen
  contact planes, written into caller-owned arrays (no allocation at all).

The previous version (numba with 3-vector arrays in the narrow phase, which allocated a
dozen small arrays per sphere–triangle pair, then numpy for the forces) spent 0.22 ms per
call on the liver and 0.8 / 0.9 / 3.3 ms on the guide's ellipsoids of 492 / 1,962 / 7,842
nodes with a 10 cm shaft; this one 16 µs and 55 / 95 / 230 µs (same host, quiet). The
equations are unchanged: ``tests/abdomen/test_contact_kernels.py`` compares the kernels with
the numpy/trimesh implementation they replace.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_NO_DELTA = np.zeros(0)
"""Empty penetrations: :func:`_tip_force` computes them from the planes (a global constant,
frozen into the compiled code)."""


@njit(cache=True, nogil=True, fastmath=False)
def _closest(p0, p1, p2, a0, a1, a2, b0, b1, b2, c0, c1, c2):  # pragma: no cover - compiled
    """Closest point of triangle abc to p and its barycentric weights (Ericson §5.1.5).

    Decision (issue #29 item 6): the vertex and edge region tests are alike in shape, as in
    Ericson's algorithm; they are written out (scalars, no arrays) for the compiled kernel.

    Returns:
        (q0, q1, q2, u, v, w): the point and its weights on a, b, c.
    """
    ab0 = b0 - a0
    ab1 = b1 - a1
    ab2 = b2 - a2
    ac0 = c0 - a0
    ac1 = c1 - a1
    ac2 = c2 - a2
    ap0 = p0 - a0
    ap1 = p1 - a1
    ap2 = p2 - a2
    d1 = ab0 * ap0 + ab1 * ap1 + ab2 * ap2
    d2 = ac0 * ap0 + ac1 * ap1 + ac2 * ap2
    if d1 <= 0.0 and d2 <= 0.0:
        return a0, a1, a2, 1.0, 0.0, 0.0
    bp0 = p0 - b0
    bp1 = p1 - b1
    bp2 = p2 - b2
    d3 = ab0 * bp0 + ab1 * bp1 + ab2 * bp2
    d4 = ac0 * bp0 + ac1 * bp1 + ac2 * bp2
    if d3 >= 0.0 and d4 <= d3:
        return b0, b1, b2, 0.0, 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    # Degenerate (zero-area) triangles make these denominators 0: numba raises
    # ZeroDivisionError on a float division by zero (it would kill the physics thread), so
    # each is guarded and falls back to a vertex.
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        if not d1 - d3 > 0.0:
            return a0, a1, a2, 1.0, 0.0, 0.0
        v = d1 / (d1 - d3)
        return a0 + v * ab0, a1 + v * ab1, a2 + v * ab2, 1.0 - v, v, 0.0
    cp0 = p0 - c0
    cp1 = p1 - c1
    cp2 = p2 - c2
    d5 = ab0 * cp0 + ab1 * cp1 + ab2 * cp2
    d6 = ac0 * cp0 + ac1 * cp1 + ac2 * cp2
    if d6 >= 0.0 and d5 <= d6:
        return c0, c1, c2, 0.0, 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        if not d2 - d6 > 0.0:
            return a0, a1, a2, 1.0, 0.0, 0.0
        w = d2 / (d2 - d6)
        return a0 + w * ac0, a1 + w * ac1, a2 + w * ac2, 1.0 - w, 0.0, w
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        if not (d4 - d3) + (d5 - d6) > 0.0:
            return b0, b1, b2, 0.0, 1.0, 0.0
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return (b0 + w * (c0 - b0), b1 + w * (c1 - b1), b2 + w * (c2 - b2), 0.0, 1.0 - w, w)
    if va + vb + vc == 0.0:
        return a0, a1, a2, 1.0, 0.0, 0.0
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return (a0 + ab0 * v + ac0 * w, a1 + ab1 * v + ac1 * w, a2 + ab2 * v + ac2 * w,
            1.0 - v - w, v, w)


@njit(cache=True, nogil=True, fastmath=False)
def _tip_force(offsets, u0, u1, u2, length, normals, stiffness, delta, points, radius, tip,
               count, force, stiff):  # pragma: no cover - compiled
    """Force at the tip and its derivative from contact planes (``vasim.abdomen.contact``).

    ``F = Σ k_j δ_j g_j`` with ``g_j = (1 - a_j) n_j + a_j (u·n_j) u``, ``a_j = clip(ℓ_j/L)``;
    ``dF/dx = -Σ k_j g_j g_jᵀ + t_w uᵀ + u t_wᵀ + (Σ_j w_j u·n_j) (I - u uᵀ)`` with
    ``w_j = k_j δ_j a_j / L``, ``t_w = Σ w_j (n_j - (u·n_j) u)`` (the geometric term only when
    some ``a_j > 0``).

    Args:
        offsets: (m,) ℓ_j [m]. u0, u1, u2: shaft direction. length: L [m].
        normals: (m, 3). stiffness: (m,) [N/m].
        delta: (m,) penetrations δ_j [m] of active planes; or empty: then
            ``δ_j = radius - (tip - ℓ_j u - q_j)·n_j`` from ``points`` (m, 3) and ``tip`` (3,),
            and a plane counts only when it is positive (unilateral).
        count: planes to read (the first ``count`` rows).
        force: (3,) output [N]. stiff: (3, 3) output [N/m].

    Returns:
        The number of planes that count.
    """
    f0 = 0.0
    f1 = 0.0
    f2 = 0.0
    k00 = 0.0
    k01 = 0.0
    k02 = 0.0
    k11 = 0.0
    k12 = 0.0
    k22 = 0.0
    t0 = 0.0
    t1 = 0.0
    t2 = 0.0
    wun = 0.0
    geometric = False
    given = delta.shape[0] > 0
    on = 0
    for j in range(count):
        ell = offsets[j]
        a = 0.0
        if length > 0.0:
            a = ell / length
            a = 0.0 if a < 0.0 else (1.0 if a > 1.0 else a)
            if a > 0.0:
                geometric = True
        n0 = normals[j, 0]
        n1 = normals[j, 1]
        n2 = normals[j, 2]
        if given:
            dj = delta[j]
        else:
            dj = radius - ((tip[0] - ell * u0 - points[j, 0]) * n0
                           + (tip[1] - ell * u1 - points[j, 1]) * n1
                           + (tip[2] - ell * u2 - points[j, 2]) * n2)
            if not dj > 0.0:
                continue
        on += 1
        un = n0 * u0 + n1 * u1 + n2 * u2
        b = 1.0 - a
        au = a * un
        g0 = b * n0 + au * u0
        g1 = b * n1 + au * u1
        g2 = b * n2 + au * u2
        ks = stiffness[j]
        kd = ks * dj
        f0 += kd * g0
        f1 += kd * g1
        f2 += kd * g2
        k00 -= ks * g0 * g0
        k01 -= ks * g0 * g1
        k02 -= ks * g0 * g2
        k11 -= ks * g1 * g1
        k12 -= ks * g1 * g2
        k22 -= ks * g2 * g2
        if length > 0.0:
            w = kd * a / length
            t0 += w * (n0 - un * u0)
            t1 += w * (n1 - un * u1)
            t2 += w * (n2 - un * u2)
            wun += w * un
    force[0] = f0
    force[1] = f1
    force[2] = f2
    if length > 0.0 and geometric:
        k00 += t0 * u0 + u0 * t0 + wun * (1.0 - u0 * u0)
        k01 += t0 * u1 + u0 * t1 + wun * (0.0 - u0 * u1)
        k02 += t0 * u2 + u0 * t2 + wun * (0.0 - u0 * u2)
        k11 += t1 * u1 + u1 * t1 + wun * (1.0 - u1 * u1)
        k12 += t1 * u2 + u1 * t2 + wun * (0.0 - u1 * u2)
        k22 += t2 * u2 + u2 * t2 + wun * (1.0 - u2 * u2)
    stiff[0, 0] = k00
    stiff[0, 1] = k01
    stiff[0, 2] = k02
    stiff[1, 0] = k01
    stiff[1, 1] = k11
    stiff[1, 2] = k12
    stiff[2, 0] = k02
    stiff[2, 1] = k12
    stiff[2, 2] = k22
    return on


@njit(cache=True, nogil=True, fastmath=False)
def _axis(tip, fulcrum):  # pragma: no cover - compiled
    """(u0, u1, u2, L): shaft direction fulcrum → tip (-z when degenerate) and length [m]."""
    d0 = tip[0] - fulcrum[0]
    d1 = tip[1] - fulcrum[1]
    d2 = tip[2] - fulcrum[2]
    length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if length > 1e-12:
        return d0 / length, d1 / length, d2 / length, length
    return 0.0, 0.0, -1.0, length


@njit(cache=True, nogil=True, fastmath=False)
def patch_tip_force(points, normals, stiffness, offsets, radius, tip, fulcrum, force,
                    stiff):  # pragma: no cover - compiled
    """``patch_force`` of ``vasim.abdomen.contact``: writes F_tip (3,) and dF/dx (3, 3).

    Sphere j sits at ``c_j = tip - ℓ_j u``; its plane pushes when ``δ_j = r - (c_j - q_j)·n_j``
    is positive (unilateral). Allocates nothing.

    Args:
        points, normals: (m, 3) plane points q_j and unit normals n_j. stiffness, offsets:
        (m,) k_j [N/m] and ℓ_j [m]. radius: r [m]. tip, fulcrum: (3,) [m].
        force: (3,) output [N]. stiff: (3, 3) output [N/m].

    Returns:
        The number of pushing planes.
    """
    u0, u1, u2, length = _axis(tip, fulcrum)
    return _tip_force(offsets, u0, u1, u2, length, normals, stiffness, _NO_DELTA, points,
                      radius, tip, points.shape[0], force, stiff)


@njit(cache=True, nogil=True, fastmath=False)
def tool_contacts(x, faces, mass, tip, fulcrum, radius, spacing, max_spheres,
                  contact_stiffness, beta, dt, max_edge):  # pragma: no cover - compiled
    """The tool's contacts with one organ surface (``detect_contacts``), in one pass.

    Spheres: ``c_j = tip - ℓ_j u``, ``ℓ_j = j · spacing``, ``j < min(⌊L/spacing⌋ + 1,
    max_spheres)``. Broad phase: the spheres inside the organ's bounding box grown by
    ``margin = radius + max_edge``, the nodes within ``margin`` of the axis segment those
    spheres span, the faces with such a node. Narrow phase: per sphere, among the faces with
    a near node within ``margin`` of its centre, the nearest one (the first on ties). A
    sphere touches when ``δ = r - s > 0`` (``s`` the distance, negative behind the face).
    Contact law, normals, stiffness bound, lever and torque: ``vasim.abdomen.contact``.

    Args:
        x: (n, 3) node positions [m]. faces: (f, 3) int64. mass: (n,) [kg].
        tip, fulcrum: (3,) [m]. radius, spacing [m]; max_spheres: int.
        contact_stiffness: k_c [N/m]; beta: the stability fraction; dt: solver step [s].
        max_edge: longest surface edge [m]; negative: computed here.

    Returns:
        (count (-1: the pose is not finite, -2: a face index is out of range),
        max_penetration, force (3,), force_tip (3,),
        torque (3,), stiffness_tip (3, 3), node_index (3 count,), node_force (3 count, 3),
        points (count, 3), normals (count, 3), stiffness (count,), offsets (count,)).
    """
    n = x.shape[0]
    nf = faces.shape[0]
    u0, u1, u2, length = _axis(tip, fulcrum)
    force = np.zeros(3)
    force_tip = np.zeros(3)
    torque = np.zeros(3)
    stiff = np.zeros((3, 3))
    bad = 0
    if not (math.isfinite(length) and math.isfinite(tip[0] + tip[1] + tip[2])):
        bad = -1
    for f in range(nf):  # every index in range (the loops below do not check)
        for j in range(3):
            if faces[f, j] < 0 or faces[f, j] >= n:
                bad = -2
    if bad < 0:
        e = np.empty(0)
        return (bad, 0.0, force, force_tip, torque, stiff, np.empty(0, dtype=np.int64),
                np.empty((0, 3)), np.empty((0, 3)), np.empty((0, 3)), e, e)
    ms = math.floor(length / spacing) + 1
    if ms > max_spheres:
        ms = max_spheres
    if max_edge < 0.0:
        e2 = 0.0
        for f in range(nf):
            for j in range(3):
                a = faces[f, j]
                b = faces[f, (j + 1) % 3]
                d0 = x[b, 0] - x[a, 0]
                d1 = x[b, 1] - x[a, 1]
                d2 = x[b, 2] - x[a, 2]
                s = d0 * d0 + d1 * d1 + d2 * d2
                if s > e2:
                    e2 = s
        max_edge = math.sqrt(e2)
    margin = radius + max_edge
    m2 = margin * margin
    # per sphere: nearest face, closest point, weights, face normal, distance, side
    face = np.full(ms, -1, dtype=np.int64)
    best = np.full(ms, np.inf)
    qs = np.zeros((ms, 3))
    bary = np.zeros((ms, 3))
    nfs = np.zeros((ms, 3))
    front = np.zeros(ms, dtype=np.bool_)
    first = -1
    last = -1
    if n > 0 and ms > 0:
        lo0 = hi0 = x[0, 0]
        lo1 = hi1 = x[0, 1]
        lo2 = hi2 = x[0, 2]
        for i in range(1, n):
            v = x[i, 0]
            lo0 = v if v < lo0 else lo0
            hi0 = v if v > hi0 else hi0
            v = x[i, 1]
            lo1 = v if v < lo1 else lo1
            hi1 = v if v > hi1 else hi1
            v = x[i, 2]
            lo2 = v if v < lo2 else lo2
            hi2 = v if v > hi2 else hi2
        lo0 -= margin
        lo1 -= margin
        lo2 -= margin
        hi0 += margin
        hi1 += margin
        hi2 += margin
        for s in range(ms):
            ell = s * spacing
            c0 = tip[0] - ell * u0
            c1 = tip[1] - ell * u1
            c2 = tip[2] - ell * u2
            if lo0 <= c0 <= hi0 and lo1 <= c1 <= hi1 and lo2 <= c2 <= hi2:
                if first < 0:
                    first = s
                last = s
    if first >= 0:
        # the axis segment the in-box spheres span: from sphere `last` to sphere `first`
        la = last * spacing
        fa = first * spacing
        a0 = tip[0] - la * u0
        a1 = tip[1] - la * u1
        a2 = tip[2] - la * u2
        ab0 = (tip[0] - fa * u0) - a0
        ab1 = (tip[1] - fa * u1) - a1
        ab2 = (tip[2] - fa * u2) - a2
        denom = ab0 * ab0 + ab1 * ab1 + ab2 * ab2
        near = np.zeros(n, dtype=np.bool_)
        n_near = 0
        for i in range(n):
            p0 = x[i, 0] - a0
            p1 = x[i, 1] - a1
            p2 = x[i, 2] - a2
            t = (p0 * ab0 + p1 * ab1 + p2 * ab2) / denom if denom > 0.0 else 0.0
            t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
            e0 = p0 - t * ab0
            e1 = p1 - t * ab1
            e2_ = p2 - t * ab2
            if e0 * e0 + e1 * e1 + e2_ * e2_ <= m2:
                near[i] = True
                n_near += 1
        nc = 0
        cand = np.empty(nf if n_near > 0 else 0, dtype=np.int64)
        if n_near > 0:
            for f in range(nf):
                if near[faces[f, 0]] or near[faces[f, 1]] or near[faces[f, 2]]:
                    cand[nc] = f
                    nc += 1
        for s in range(first, last + 1):
            ell = s * spacing
            p0 = tip[0] - ell * u0
            p1 = tip[1] - ell * u1
            p2 = tip[2] - ell * u2
            bs = np.inf
            for kk in range(nc):
                f = cand[kk]
                ia = faces[f, 0]
                ib = faces[f, 1]
                ic = faces[f, 2]
                reach = False
                for v in (ia, ib, ic):
                    if near[v]:
                        d0 = x[v, 0] - p0
                        d1 = x[v, 1] - p1
                        d2 = x[v, 2] - p2
                        if d0 * d0 + d1 * d1 + d2 * d2 <= m2:
                            reach = True
                            break
                if not reach:
                    continue
                xa0 = x[ia, 0]
                xa1 = x[ia, 1]
                xa2 = x[ia, 2]
                xb0 = x[ib, 0]
                xb1 = x[ib, 1]
                xb2 = x[ib, 2]
                xc0 = x[ic, 0]
                xc1 = x[ic, 1]
                xc2 = x[ic, 2]
                q0, q1, q2, wa, wb, wc = _closest(p0, p1, p2, xa0, xa1, xa2, xb0, xb1, xb2,
                                                  xc0, xc1, xc2)
                d0 = p0 - q0
                d1 = p1 - q1
                d2 = p2 - q2
                dd = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                if dd < bs:
                    e10 = xb0 - xa0
                    e11 = xb1 - xa1
                    e12 = xb2 - xa2
                    e20 = xc0 - xa0
                    e21 = xc1 - xa1
                    e22 = xc2 - xa2
                    r0 = e11 * e22 - e12 * e21
                    r1 = e12 * e20 - e10 * e22
                    r2 = e10 * e21 - e11 * e20
                    rn = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
                    if rn > 0.0:
                        r0 = r0 / rn
                        r1 = r1 / rn
                        r2 = r2 / rn
                    bs = dd
                    face[s] = f
                    qs[s, 0] = q0
                    qs[s, 1] = q1
                    qs[s, 2] = q2
                    bary[s, 0] = wa
                    bary[s, 1] = wb
                    bary[s, 2] = wc
                    nfs[s, 0] = r0
                    nfs[s, 1] = r1
                    nfs[s, 2] = r2
                    front[s] = (d0 * r0 + d1 * r1 + d2 * r2) >= 0.0
            best[s] = bs
    # the touching spheres, tip first
    count = 0
    for s in range(ms):
        if face[s] >= 0:
            signed = best[s] if front[s] else -best[s]
            if radius - signed > 0.0:
                count += 1
    points = np.empty((count, 3))
    normals = np.empty((count, 3))
    kout = np.empty(count)
    ells = np.empty(count)
    deltas = np.empty(count)
    node_index = np.empty(3 * count, dtype=np.int64)
    node_force = np.empty((3 * count, 3))
    max_pen = 0.0
    j = 0
    dt2 = dt * dt
    tq0 = 0.0
    tq1 = 0.0
    tq2 = 0.0
    fs0 = 0.0
    fs1 = 0.0
    fs2 = 0.0
    for s in range(ms):
        if face[s] < 0:
            continue
        dist = best[s]
        signed = dist if front[s] else -dist
        dl = radius - signed
        if not dl > 0.0:
            continue
        ell = s * spacing
        c0 = tip[0] - ell * u0
        c1 = tip[1] - ell * u1
        c2 = tip[2] - ell * u2
        if front[s] and dist > 1e-9:
            den = dist if dist > 1e-300 else 1e-300
            n0 = (c0 - qs[s, 0]) / den
            n1 = (c1 - qs[s, 1]) / den
            n2 = (c2 - qs[s, 2]) / den
        else:
            n0 = nfs[s, 0]
            n1 = nfs[s, 1]
            n2 = nfs[s, 2]
        w0 = min(max(bary[s, 0], 0.0), 1.0)
        w1 = min(max(bary[s, 1], 0.0), 1.0)
        w2 = min(max(bary[s, 2], 0.0), 1.0)
        ws = w0 + w1 + w2
        if not ws > 0.0:  # guarded: a float division by zero raises in numba
            w0 = 1.0
            ws = 1.0
        w0 /= ws
        w1 /= ws
        w2 /= ws
        f = face[s]
        ia = faces[f, 0]
        ib = faces[f, 1]
        ic = faces[f, 2]
        m_eff = w0 * mass[ia] + w1 * mass[ib] + w2 * mass[ic]
        kj = beta * m_eff / dt2
        if contact_stiffness < kj:
            kj = contact_stiffness
        kd = kj * dl
        fj0 = kd * n0
        fj1 = kd * n1
        fj2 = kd * n2
        fs0 += fj0
        fs1 += fj1
        fs2 += fj2
        r0 = c0 - fulcrum[0]
        r1 = c1 - fulcrum[1]
        r2 = c2 - fulcrum[2]
        tq0 += r1 * fj2 - r2 * fj1
        tq1 += r2 * fj0 - r0 * fj2
        tq2 += r0 * fj1 - r1 * fj0
        node_index[3 * j] = ia
        node_index[3 * j + 1] = ib
        node_index[3 * j + 2] = ic
        node_force[3 * j, 0] = -(w0 * fj0)
        node_force[3 * j, 1] = -(w0 * fj1)
        node_force[3 * j, 2] = -(w0 * fj2)
        node_force[3 * j + 1, 0] = -(w1 * fj0)
        node_force[3 * j + 1, 1] = -(w1 * fj1)
        node_force[3 * j + 1, 2] = -(w1 * fj2)
        node_force[3 * j + 2, 0] = -(w2 * fj0)
        node_force[3 * j + 2, 1] = -(w2 * fj1)
        node_force[3 * j + 2, 2] = -(w2 * fj2)
        points[j, 0] = qs[s, 0]
        points[j, 1] = qs[s, 1]
        points[j, 2] = qs[s, 2]
        normals[j, 0] = n0
        normals[j, 1] = n1
        normals[j, 2] = n2
        kout[j] = kj
        ells[j] = ell
        deltas[j] = dl
        if dl > max_pen:
            max_pen = dl
        j += 1
    force[0] = fs0
    force[1] = fs1
    force[2] = fs2
    torque[0] = tq0
    torque[1] = tq1
    torque[2] = tq2
    if count > 0:
        _tip_force(ells, u0, u1, u2, length, normals, kout, deltas, points, radius, tip,
                   count, force_tip, stiff)
    return (count, max_pen, force, force_tip, torque, stiff, node_index, node_force, points,
            normals, kout, ells)


@njit(cache=True, nogil=True, fastmath=False)
def box_apart(x, lo, hi, margin):  # pragma: no cover - compiled
    """True when the bounding box of the nodes ``x`` (n, 3), grown by ``margin`` [m], and the
    box ``lo``–``hi`` (3,) are disjoint on some axis (one pass, no temporaries)."""
    n = x.shape[0]
    if n == 0:
        return True
    for a in range(3):
        mn = x[0, a]
        mx = mn
        for i in range(1, n):
            v = x[i, a]
            if v < mn:
                mn = v
            elif v > mx:
                mx = v
        if mn - margin > hi[a] or mx + margin < lo[a]:
            return True
    return False


@njit(cache=True, nogil=True, fastmath=False)
def cells_near(centres, r2, body, n_bodies, fulcrum, tip):  # pragma: no cover - compiled
    """The world's broad phase: which organs have a cell sphere the tool axis passes through.

    Args:
        centres: (c, 3) cell centres [m]. r2: (c,) squared reach of each cell (its radius
            plus the tool's) [m²]. body: (c,) organ index of each cell. n_bodies: organs.
        fulcrum, tip: (3,) the tool axis [m].

    Returns:
        (near (n_bodies,) bool, gap [m]): ``gap`` is, when no cell is hit, the smallest
        distance from the axis to a cell sphere's surface (0 without cells; not computed, 0,
        when some cell is hit).
    """
    near = np.zeros(n_bodies, dtype=np.bool_)
    d0 = tip[0] - fulcrum[0]
    d1 = tip[1] - fulcrum[1]
    d2 = tip[2] - fulcrum[2]
    dd = d0 * d0 + d1 * d1 + d2 * d2
    hit = False
    gap = np.inf
    for c in range(centres.shape[0]):
        p0 = centres[c, 0] - fulcrum[0]
        p1 = centres[c, 1] - fulcrum[1]
        p2 = centres[c, 2] - fulcrum[2]
        u = 0.0
        if dd > 0.0:
            u = (p0 * d0 + p1 * d1 + p2 * d2) / dd
            u = 0.0 if u < 0.0 else (1.0 if u > 1.0 else u)
        e0 = p0 - u * d0
        e1 = p1 - u * d1
        e2 = p2 - u * d2
        dist2 = e0 * e0 + e1 * e1 + e2 * e2
        if dist2 <= r2[c]:
            near[body[c]] = True
            hit = True
        elif not hit:
            g = math.sqrt(dist2) - math.sqrt(r2[c])
            if g < gap:
                gap = g
    if hit or centres.shape[0] == 0:
        gap = 0.0
    return near, gap


@njit(cache=True, nogil=True, fastmath=False)
def scatter_forces(out, index, force):  # pragma: no cover - compiled
    """``out[:] = 0; out[index[p]] += force[p]`` in ``p`` order (``np.add.at``'s sums)."""
    for i in range(out.shape[0]):
        out[i, 0] = 0.0
        out[i, 1] = 0.0
        out[i, 2] = 0.0
    for p in range(index.shape[0]):
        i = index[p]
        out[i, 0] += force[p, 0]
        out[i, 1] += force[p, 1]
        out[i, 2] += force[p, 2]
