"""Compiled distances between sphere-swept link models (numba ``cache=True``).

A robot link of ``vasim.mrcp.urdf`` is the convex hull of an icosphere (circumscribed
about a sphere of radius ``r``) placed at each of the link's key points (at most three):
``hull = conv(P) ⊕ conv(S)`` with ``P`` the key points and ``S`` the scaled icosphere
vertices. A sphere obstacle is one point swept by a ball. For two such bodies ``A ⊕ S_a``
and ``B ⊕ S_b`` with closest points ``a*`` / ``b*`` of ``conv(A)`` / ``conv(B)`` at distance
``d`` and direction ``u = (b* - a*) / d``:

    ``d - h_Sa(u) - h_Sb(-u)  <=  dist(hull_a, hull_b)  <=  d - r_a - r_b``

(``h`` = support function; the left side is the separation along ``u``, a lower bound for
any direction, tight up to second order in the angle between ``u`` and the hulls' own
closest direction). :func:`swept_distance` returns the left side, which the world's tests
hold to pybullet's ``getClosestPoints`` within a stated tolerance.

The key-point hull distance ``d`` is exact for point sets of one to three points
(segment-segment and point-triangle closest points, segment-triangle crossings), Ericson,
*Real-Time Collision Detection* §5.1.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from vasim.mrcp.dh import _chain_kernel


@njit(cache=True, nogil=True)
def _clamp01(x: float) -> float:  # pragma: no cover - compiled
    return 0.0 if x < 0.0 else (1.0 if x > 1.0 else x)


@njit(cache=True, nogil=True, inline="always")
def _dot(ax: float, ay: float, az: float, bx: float, by: float, bz: float
         ) -> float:  # pragma: no cover - compiled
    return ax * bx + ay * by + az * bz


@njit(cache=True, nogil=True)
def _seg_seg(p1: np.ndarray, q1: np.ndarray, p2: np.ndarray, q2: np.ndarray,
             c1: np.ndarray, c2: np.ndarray) -> float:  # pragma: no cover - compiled
    """Squared distance between segments ``p1q1`` and ``p2q2``; closest points into c1, c2
    (scalar arithmetic: no temporaries)."""
    d1x, d1y, d1z = q1[0] - p1[0], q1[1] - p1[1], q1[2] - p1[2]
    d2x, d2y, d2z = q2[0] - p2[0], q2[1] - p2[1], q2[2] - p2[2]
    rx, ry, rz = p1[0] - p2[0], p1[1] - p2[1], p1[2] - p2[2]
    a = _dot(d1x, d1y, d1z, d1x, d1y, d1z)
    e = _dot(d2x, d2y, d2z, d2x, d2y, d2z)
    f = _dot(d2x, d2y, d2z, rx, ry, rz)
    eps = 1e-18
    if a <= eps and e <= eps:
        s = 0.0
        t = 0.0
    elif a <= eps:
        s = 0.0
        t = _clamp01(f / e)
    else:
        c = _dot(d1x, d1y, d1z, rx, ry, rz)
        if e <= eps:
            t = 0.0
            s = _clamp01(-c / a)
        else:
            b = _dot(d1x, d1y, d1z, d2x, d2y, d2z)
            den = a * e - b * b
            s = _clamp01((b * f - c * e) / den) if den > eps else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                t = 0.0
                s = _clamp01(-c / a)
            elif t > 1.0:
                t = 1.0
                s = _clamp01((b - c) / a)
    c1[0], c1[1], c1[2] = p1[0] + d1x * s, p1[1] + d1y * s, p1[2] + d1z * s
    c2[0], c2[1], c2[2] = p2[0] + d2x * t, p2[1] + d2y * t, p2[2] + d2z * t
    wx, wy, wz = c1[0] - c2[0], c1[1] - c2[1], c1[2] - c2[2]
    return _dot(wx, wy, wz, wx, wy, wz)


@njit(cache=True, nogil=True)
def _pt_tri(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray,
            out: np.ndarray) -> float:  # pragma: no cover - compiled
    """Squared distance from ``p`` to triangle ``abc`` (non-degenerate); closest point into
    ``out`` (Ericson §5.1.5, scalar arithmetic)."""
    abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    acx, acy, acz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    d1 = _dot(abx, aby, abz, p[0] - a[0], p[1] - a[1], p[2] - a[2])
    d2 = _dot(acx, acy, acz, p[0] - a[0], p[1] - a[1], p[2] - a[2])
    d3 = _dot(abx, aby, abz, p[0] - b[0], p[1] - b[1], p[2] - b[2])
    d4 = _dot(acx, acy, acz, p[0] - b[0], p[1] - b[1], p[2] - b[2])
    d5 = _dot(abx, aby, abz, p[0] - c[0], p[1] - c[1], p[2] - c[2])
    d6 = _dot(acx, acy, acz, p[0] - c[0], p[1] - c[1], p[2] - c[2])
    vc = d1 * d4 - d3 * d2
    vb = d5 * d2 - d1 * d6
    va = d3 * d6 - d5 * d4
    if d1 <= 0.0 and d2 <= 0.0:
        ox, oy, oz = a[0], a[1], a[2]
    elif d3 >= 0.0 and d4 <= d3:
        ox, oy, oz = b[0], b[1], b[2]
    elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        ox, oy, oz = a[0] + abx * v, a[1] + aby * v, a[2] + abz * v
    elif d6 >= 0.0 and d5 <= d6:
        ox, oy, oz = c[0], c[1], c[2]
    elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        ox, oy, oz = a[0] + acx * w, a[1] + acy * w, a[2] + acz * w
    elif va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        ox, oy, oz = b[0] + (c[0] - b[0]) * w, b[1] + (c[1] - b[1]) * w, b[2] + (c[2] - b[2]) * w
    else:
        den = 1.0 / (va + vb + vc)
        v = vb * den
        w = vc * den
        ox, oy, oz = a[0] + abx * v + acx * w, a[1] + aby * v + acy * w, a[2] + abz * v + acz * w
    out[0], out[1], out[2] = ox, oy, oz
    wx, wy, wz = p[0] - ox, p[1] - oy, p[2] - oz
    return _dot(wx, wy, wz, wx, wy, wz)


@njit(cache=True, nogil=True, inline="always")
def _cross_dot(nx: float, ny: float, nz: float, ux: float, uy: float, uz: float, vx: float,
               vy: float, vz: float) -> float:  # pragma: no cover - compiled
    """``n · (u x v)``."""
    return nx * (uy * vz - uz * vy) + ny * (uz * vx - ux * vz) + nz * (ux * vy - uy * vx)


@njit(cache=True, nogil=True)
def _seg_crosses_tri(p: np.ndarray, q: np.ndarray, a: np.ndarray, b: np.ndarray,
                     c: np.ndarray, out: np.ndarray) -> bool:  # pragma: no cover - compiled
    """True if segment ``pq`` crosses triangle ``abc`` (the crossing point into ``out``)."""
    abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    acx, acy, acz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    nx, ny, nz = aby * acz - abz * acy, abz * acx - abx * acz, abx * acy - aby * acx
    dp = _dot(nx, ny, nz, p[0] - a[0], p[1] - a[1], p[2] - a[2])
    dq = _dot(nx, ny, nz, q[0] - a[0], q[1] - a[1], q[2] - a[2])
    if dp * dq > 0.0 or dp == dq:
        return False
    t = dp / (dp - dq)
    x0, x1, x2 = p[0] + (q[0] - p[0]) * t, p[1] + (q[1] - p[1]) * t, p[2] + (q[2] - p[2]) * t
    if _cross_dot(nx, ny, nz, abx, aby, abz, x0 - a[0], x1 - a[1], x2 - a[2]) < 0.0:
        return False
    if _cross_dot(nx, ny, nz, c[0] - b[0], c[1] - b[1], c[2] - b[2], x0 - b[0], x1 - b[1],
                  x2 - b[2]) < 0.0:
        return False
    if _cross_dot(nx, ny, nz, a[0] - c[0], a[1] - c[1], a[2] - c[2], x0 - c[0], x1 - c[1],
                  x2 - c[2]) < 0.0:
        return False
    out[0], out[1], out[2] = x0, x1, x2
    return True


@njit(cache=True, nogil=True)
def hull_points_distance(pa: np.ndarray, na: int, pb: np.ndarray, nb: int,
                         ca: np.ndarray, cb: np.ndarray) -> float:  # pragma: no cover
    """Distance between the convex hulls of ``pa[:na]`` and ``pb[:nb]`` (1-3 points each;
    three points must not be collinear); closest points into ``ca``, ``cb``."""
    return _hull_distance(pa, na, pb, nb, ca, cb, np.empty(3), np.empty(3))


@njit(cache=True, nogil=True)
def _hull_distance(pa: np.ndarray, na: int, pb: np.ndarray, nb: int, ca: np.ndarray,
                   cb: np.ndarray, t1: np.ndarray, t2: np.ndarray
                   ) -> float:  # pragma: no cover - compiled
    best = np.inf
    ea = 1 if na == 1 else (1 if na == 2 else 3)
    eb = 1 if nb == 1 else (1 if nb == 2 else 3)
    for i in range(ea):
        p1 = pa[i]
        q1 = pa[(i + 1) % na] if na > 1 else pa[0]
        for j in range(eb):
            p2 = pb[j]
            q2 = pb[(j + 1) % nb] if nb > 1 else pb[0]
            d2 = _seg_seg(p1, q1, p2, q2, t1, t2)
            if d2 < best:
                best = d2
                ca[:] = t1
                cb[:] = t2
    if na == 3:
        for j in range(nb):
            d2 = _pt_tri(pb[j], pa[0], pa[1], pa[2], t1)
            if d2 < best:
                best = d2
                ca[:] = t1
                cb[:] = pb[j]
        for j in range(eb if nb > 1 else 0):
            if _seg_crosses_tri(pb[j], pb[(j + 1) % nb], pa[0], pa[1], pa[2], t1):
                ca[:] = t1
                cb[:] = t1
                return 0.0
    if nb == 3:
        for i in range(na):
            d2 = _pt_tri(pa[i], pb[0], pb[1], pb[2], t2)
            if d2 < best:
                best = d2
                ca[:] = pa[i]
                cb[:] = t2
        for i in range(ea if na > 1 else 0):
            if _seg_crosses_tri(pa[i], pa[(i + 1) % na], pb[0], pb[1], pb[2], t2):
                ca[:] = t2
                cb[:] = t2
                return 0.0
    return np.sqrt(best)


@njit(cache=True, nogil=True)
def _support(rot: np.ndarray, u: np.ndarray, verts: np.ndarray, nbrs: np.ndarray,
             scale: float, ball: float, point: np.ndarray) -> float:  # pragma: no cover
    """Support of the sweeping shape along world direction ``u``: a ball of radius ``ball``
    (when > 0) or the unit polytope ``verts`` (vertex neighbours ``nbrs``, -1 padded)
    scaled by ``scale`` in the frame ``rot``; the supporting point (world offset) into
    ``point``."""
    if ball > 0.0:
        for i in range(3):
            point[i] = u[i] * ball
        return ball
    ul0 = rot[0, 0] * u[0] + rot[1, 0] * u[1] + rot[2, 0] * u[2]
    ul1 = rot[0, 1] * u[0] + rot[1, 1] * u[1] + rot[2, 1] * u[2]
    ul2 = rot[0, 2] * u[0] + rot[1, 2] * u[1] + rot[2, 2] * u[2]
    best = -np.inf
    arg = 0
    # hill climbing over the vertex graph (exact on a convex polytope whose vertices all
    # lie on its hull), from the best of the first 12 vertices (an icosphere's icosahedron)
    for v in range(min(12, verts.shape[0])):
        s = verts[v, 0] * ul0 + verts[v, 1] * ul1 + verts[v, 2] * ul2
        if s > best:
            best = s
            arg = v
    moved = True
    while moved:
        moved = False
        for k in range(nbrs.shape[1]):
            v = nbrs[arg, k]
            if v < 0:
                continue
            s = verts[v, 0] * ul0 + verts[v, 1] * ul1 + verts[v, 2] * ul2
            if s > best:
                best = s
                arg = v
                moved = True
    for i in range(3):
        point[i] = scale * (rot[i, 0] * verts[arg, 0] + rot[i, 1] * verts[arg, 1]
                            + rot[i, 2] * verts[arg, 2])
    return best * scale


@njit(cache=True, nogil=True)
def _to_world(frames: np.ndarray, pts: np.ndarray, count: np.ndarray, centre: np.ndarray,
              world: np.ndarray, wcentre: np.ndarray) -> None:  # pragma: no cover
    for i in range(frames.shape[0]):
        for k in range(count[i]):
            for r in range(3):
                world[i, k, r] = (frames[i, r, 0] * pts[i, k, 0] + frames[i, r, 1] * pts[i, k, 1]
                                  + frames[i, r, 2] * pts[i, k, 2] + frames[i, r, 3])
        for r in range(3):
            wcentre[i, r] = (frames[i, r, 0] * centre[i, 0] + frames[i, r, 1] * centre[i, 1]
                             + frames[i, r, 2] * centre[i, 2] + frames[i, r, 3])


@njit(cache=True, nogil=True)
def _posed(frames: np.ndarray, pts: np.ndarray, count: np.ndarray, centre: np.ndarray,
           world: np.ndarray, wcentre: np.ndarray, rot: np.ndarray) -> None:  # pragma: no cover
    """:func:`_to_world` and each link's rotation ``rot`` ``(L, 3, 3)``."""
    _to_world(frames, pts, count, centre, world, wcentre)
    for i in range(frames.shape[0]):
        rot[i] = frames[i, :3, :3]


@njit(cache=True, nogil=True)
def _pair(wa: np.ndarray, na: int, rot_a: np.ndarray, scale_a: float, ball_a: float,
          wb: np.ndarray, nb: int, rot_b: np.ndarray, scale_b: float, ball_b: float,
          verts: np.ndarray, nbrs: np.ndarray, iterations: int, skip_above: float,
          ws: np.ndarray, stop_above: float = np.inf) -> float:  # pragma: no cover
    """Lower bound of the distance between two swept links (see the module docstring),
    the direction improved ``iterations`` times: the key-point hulls shifted by the current
    supporting points give the next direction; ``inf`` when the links' capsule bound is
    already ``>= skip_above``. ``ws`` ``(16, 3)`` is scratch space; the witness points are
    left in its rows 14 (on a) and 15 (on b).

    ``stop_above``: once a separation reaches it, the improvements stop and that
    separation is returned. Every improvement only raises the value (the maximum over the
    directions is kept), so a caller that wants the pair only when it is below
    ``stop_above`` (a running minimum) gets the same minimum with less work; with the
    default ``inf`` the value is the full one."""
    ca, cb, sa, sb, u, nu = ws[0], ws[1], ws[2], ws[3], ws[4], ws[5]
    ta, tb = ws[6:9], ws[9:12]
    t1, t2 = ws[12], ws[13]
    d = _hull_distance(wa, na, wb, nb, ca, cb, t1, t2)
    # the capsule bound (the sweeping shapes inside their circumscribed balls) first
    if d - (scale_a if ball_a <= 0.0 else ball_a) - (scale_b if ball_b <= 0.0 else ball_b) \
            >= skip_above:
        return np.inf
    if d <= 1e-12:      # the key-point hulls touch: no direction, no estimate
        return -np.inf
    for r in range(3):
        u[r] = (cb[r] - ca[r]) / d
        nu[r] = -u[r]
    best = -np.inf
    for it in range(iterations + 1):
        ha = _support(rot_a, u, verts, nbrs, scale_a, ball_a, sa)
        hb = _support(rot_b, nu, verts, nbrs, scale_b, ball_b, sb)
        # separation along u: a lower bound for any direction
        lo = -np.inf
        for k in range(na):
            v = wa[k, 0] * u[0] + wa[k, 1] * u[1] + wa[k, 2] * u[2]
            if v > lo:
                lo = v
        hi = np.inf
        for k in range(nb):
            v = wb[k, 0] * u[0] + wb[k, 1] * u[1] + wb[k, 2] * u[2]
            if v < hi:
                hi = v
        sep = hi - lo - ha - hb
        if sep > best:
            best = sep
            for r in range(3):
                ws[14, r] = ca[r] + sa[r]
                ws[15, r] = cb[r] + sb[r]
        if it == iterations or (ball_a > 0.0 and ball_b > 0.0) or best >= stop_above:
            break
        for k in range(na):
            for r in range(3):
                ta[k, r] = wa[k, r] + sa[r]
        for k in range(nb):
            for r in range(3):
                tb[k, r] = wb[k, r] + sb[r]
        d2 = _hull_distance(ta, na, tb, nb, ca, cb, t1, t2)
        if d2 <= 1e-12:
            break
        for r in range(3):
            u[r] = (cb[r] - ca[r]) / d2
            nu[r] = -u[r]
            ca[r] -= sa[r]
            cb[r] -= sb[r]
    return best


@njit(cache=True, nogil=True)
def _axis_bound(wa: np.ndarray, na: int, wb: np.ndarray, nb: int, ca: np.ndarray,
                cb: np.ndarray) -> float:  # pragma: no cover - compiled
    """Separation of the key points ``wa[:na]`` / ``wb[:nb]`` along the unit direction
    ``ca -> cb`` (a lower bound of their hulls' distance; ``-inf`` when ``ca == cb``)."""
    ux, uy, uz = cb[0] - ca[0], cb[1] - ca[1], cb[2] - ca[2]
    n = np.sqrt(ux * ux + uy * uy + uz * uz)
    if n <= 1e-12:
        return -np.inf
    lo = -np.inf
    for k in range(na):
        v = wa[k, 0] * ux + wa[k, 1] * uy + wa[k, 2] * uz
        if v > lo:
            lo = v
    hi = np.inf
    for k in range(nb):
        v = wb[k, 0] * ux + wb[k, 1] * uy + wb[k, 2] * uz
        if v < hi:
            hi = v
    return (hi - lo) / n


@njit(cache=True, nogil=True)
def swept_distances(frames_a: np.ndarray, pts_a: np.ndarray, n_a: np.ndarray,
                    scale_a: np.ndarray, ball_a: np.ndarray, bcen_a: np.ndarray,
                    brad_a: np.ndarray, frames_b: np.ndarray, pts_b: np.ndarray,
                    n_b: np.ndarray, scale_b: np.ndarray, ball_b: np.ndarray,
                    bcen_b: np.ndarray, brad_b: np.ndarray, starts: np.ndarray,
                    margins: np.ndarray, verts: np.ndarray, nbrs: np.ndarray,
                    cutoff: float, iterations: int, out: np.ndarray
                    ) -> None:  # pragma: no cover - compiled
    """Minimum over link pairs of the swept-model distance between body ``a`` posed at
    each of ``N`` configurations and each of ``B`` fixed bodies, into ``out`` ``(N, B)``.

    Args: world frames ``(N, La, 4, 4)`` of ``a``; the links of the ``B`` bodies stacked
    (``(Lb, 4, 4)`` world frames, body ``k`` = links ``starts[k]:starts[k + 1]``). Per link:
    key points ``(L, 3, 3)`` in the link frame with counts ``(L,)``; polytope scales
    ``(L,)``; ball radii ``(L,)`` (> 0: a ball instead of the polytope); bounding spheres
    (centres ``(L, 3)`` link frame, radii ``(L,)``) for the branch and bound. ``verts`` /
    ``nbrs``: the unit polytope and its vertex graph. ``margins[k]`` is subtracted from
    body ``k``'s distances; nothing nearer than ``cutoff`` -> ``cutoff``; ``-inf`` where
    the key-point hulls of two links meet (no estimate).
    """
    la = frames_a.shape[1]
    lb = frames_b.shape[0]
    wa = np.empty((la, 3, 3))
    wb = np.empty((lb, 3, 3))
    sa = np.empty((la, 3))
    sb = np.empty((lb, 3))
    rot_a = np.empty((la, 3, 3))
    rot_b = np.empty((lb, 3, 3))
    _posed(frames_b, pts_b, n_b, bcen_b, wb, sb, rot_b)
    bound = np.empty(la * lb)
    ws = np.empty((16, 3))
    for c in range(frames_a.shape[0]):
        fa = frames_a[c]
        _posed(fa, pts_a, n_a, bcen_a, wa, sa, rot_a)
        for body in range(starts.shape[0] - 1):
            out[c, body] = _min_to_body(wa, sa, rot_a, n_a, scale_a, ball_a, brad_a, wb, sb,
                                        rot_b, n_b, scale_b, ball_b, brad_b, starts[body],
                                        starts[body + 1], margins[body], verts, nbrs, cutoff,
                                        iterations, bound, ws)


@njit(cache=True, nogil=True)
def _pruned_pair(wa: np.ndarray, sa: np.ndarray, rot_a: np.ndarray, n_a: np.ndarray,
                 scale_a: np.ndarray, ball_a: np.ndarray, wb: np.ndarray, sb: np.ndarray,
                 rot_b: np.ndarray, n_b: np.ndarray, scale_b: np.ndarray,
                 ball_b: np.ndarray, i: int, j: int, margin: float, best: float,
                 verts: np.ndarray, nbrs: np.ndarray, iterations: int,
                 ws: np.ndarray) -> float:  # pragma: no cover - compiled
    """The swept-model distance of link pair ``(i, j)`` less ``margin`` if it can be below
    ``best``, else a value ``>= best`` (the step of every branch and bound here).

    A cheaper lower bound first: the key points' separation along the line of the bounding
    centres, less both sweeping radii (the pair's value is at least its capsule bound,
    which is at least this; 1e-9 m of slack for round-off keeps the minimum exactly the one
    of the full values). Then :func:`_pair`, which skips the support search when the
    capsule bound is already ``>= best`` and stops refining once the pair is surely no
    nearer than ``best``: the minimum is the one of the full values, at about half the cost
    per pair."""
    if _axis_bound(wa[i], n_a[i], wb[j], n_b[j], sa[i], sb[j]) \
            - (scale_a[i] if ball_a[i] <= 0.0 else ball_a[i]) \
            - (scale_b[j] if ball_b[j] <= 0.0 else ball_b[j]) \
            - margin - 1e-9 >= best:
        return np.inf
    return _pair(wa[i], n_a[i], rot_a[i], scale_a[i], ball_a[i], wb[j], n_b[j],
                 rot_b[j], scale_b[j], ball_b[j], verts, nbrs, iterations,
                 best + margin, ws, best + margin) - margin


@njit(cache=True, nogil=True)
def _min_to_body(wa: np.ndarray, sa: np.ndarray, rot_a: np.ndarray, n_a: np.ndarray,
                 scale_a: np.ndarray, ball_a: np.ndarray, brad_a: np.ndarray, wb: np.ndarray,
                 sb: np.ndarray, rot_b: np.ndarray, n_b: np.ndarray, scale_b: np.ndarray,
                 ball_b: np.ndarray, brad_b: np.ndarray, j0: int, j1: int, margin: float,
                 verts: np.ndarray, nbrs: np.ndarray, cutoff: float, iterations: int,
                 bound: np.ndarray, ws: np.ndarray) -> float:  # pragma: no cover - compiled
    """Branch and bound over the link pairs of body ``a`` (world key points ``wa``,
    bounding centres ``sa``, rotations ``rot_a``) and the links ``j0:j1`` of the stacked
    bodies ``b``: the smallest swept-model distance less ``margin``, ``cutoff`` when none
    is nearer (``bound``, ``ws``: scratch space). The one per-(configuration, body) step of
    :func:`swept_distances` and :func:`swept_distances_many`."""
    la = wa.shape[0]
    nbl = j1 - j0
    for i in range(la):
        for jj in range(nbl):
            j = j0 + jj
            dx, dy, dz = sa[i, 0] - sb[j, 0], sa[i, 1] - sb[j, 1], sa[i, 2] - sb[j, 2]
            bound[i * nbl + jj] = (np.sqrt(dx * dx + dy * dy + dz * dz) - brad_a[i]
                                   - brad_b[j] - margin)
    order = np.argsort(bound[:la * nbl])
    best = cutoff
    for idx in order:
        if bound[idx] >= best:
            break
        i = idx // nbl
        j = j0 + idx % nbl
        dist = _pruned_pair(wa, sa, rot_a, n_a, scale_a, ball_a, wb, sb, rot_b, n_b, scale_b,
                            ball_b, i, j, margin, best, verts, nbrs, iterations, ws)
        if dist < best:
            best = dist
    return best


@njit(cache=True, nogil=True)
def swept_distances_many(table: np.ndarray, tcp: np.ndarray, bases: np.ndarray,
                         qs: np.ndarray, row_query: np.ndarray, wanted: np.ndarray,
                         pts_a: np.ndarray, n_a: np.ndarray, scale_a: np.ndarray,
                         ball_a: np.ndarray, bcen_a: np.ndarray, brad_a: np.ndarray,
                         frames_b: np.ndarray, pts_b: np.ndarray, n_b: np.ndarray,
                         scale_b: np.ndarray, ball_b: np.ndarray, bcen_b: np.ndarray,
                         brad_b: np.ndarray, starts: np.ndarray, margins: np.ndarray,
                         verts: np.ndarray, nbrs: np.ndarray, cutoff: float,
                         iterations: int, out: np.ndarray) -> None:  # pragma: no cover
    """:func:`swept_distances` for the configurations of several robots of one model at
    once, their link frames included (issue #17 §4: one compiled call per cycle for the
    distances and the forward kinematics of every robot).

    Args: the model's DH ``table`` ``(4, n)`` and ``tcp`` ``(3,)``; per query robot its base
    ``bases[r]`` ``(4, 4)``; configurations ``qs`` ``(N, n)``, row ``c`` of query robot
    ``row_query[c]``; ``wanted`` ``(R, B)``: the bodies each query robot is measured
    against (False for itself). The ``B`` bodies are stacked once for all query robots
    (their world key points computed once: shared by every query); the other arguments
    as in :func:`swept_distances`. ``out[c, k]`` ``(N, B)`` is written where
    ``wanted[row_query[c], k]``: the value :func:`swept_distances` gives the robot at
    ``qs[c]`` (frames of :func:`vasim.mrcp.dh.frames_many`) against body ``k``, bit for bit
    (the same compiled steps in the same order).
    """
    la = pts_a.shape[0]
    lb = frames_b.shape[0]
    n = qs.shape[1]
    frames = np.empty((n + 2, 4, 4))
    wa = np.empty((la, 3, 3))
    wb = np.empty((lb, 3, 3))
    sa = np.empty((la, 3))
    sb = np.empty((lb, 3))
    rot_a = np.empty((la, 3, 3))
    rot_b = np.empty((lb, 3, 3))
    _posed(frames_b, pts_b, n_b, bcen_b, wb, sb, rot_b)
    bound = np.empty(la * lb)
    ws = np.empty((16, 3))
    for c in range(qs.shape[0]):
        r = row_query[c]
        _chain_kernel(table, tcp, bases[r], qs[c], frames)
        fa = frames[:la]
        _posed(fa, pts_a, n_a, bcen_a, wa, sa, rot_a)
        for body in range(starts.shape[0] - 1):
            if not wanted[r, body]:
                continue
            out[c, body] = _min_to_body(wa, sa, rot_a, n_a, scale_a, ball_a, brad_a, wb, sb,
                                        rot_b, n_b, scale_b, ball_b, brad_b, starts[body],
                                        starts[body + 1], margins[body], verts, nbrs, cutoff,
                                        iterations, bound, ws)


@njit(cache=True, nogil=True)
def _nearest_of_bodies(wa: np.ndarray, sa: np.ndarray, rot_a: np.ndarray, n_a: np.ndarray,
                       scale_a: np.ndarray, ball_a: np.ndarray, brad_a: np.ndarray,
                       wb: np.ndarray, sb: np.ndarray, rot_b: np.ndarray, n_b: np.ndarray,
                       scale_b: np.ndarray, ball_b: np.ndarray, brad_b: np.ndarray,
                       starts: np.ndarray, margins: np.ndarray, member: np.ndarray,
                       verts: np.ndarray, nbrs: np.ndarray, cutoff: float, iterations: int,
                       bound: np.ndarray, link_i: np.ndarray, link_j: np.ndarray,
                       link_m: np.ndarray, ws: np.ndarray) -> float:  # pragma: no cover
    """:func:`_min_to_body` over the link pairs of every body ``k`` with ``member[k]`` at
    once: one branch and bound whose best value so far prunes the pairs of all of them
    (each body's pairs less that body's margin). The result is the minimum over those
    bodies of :func:`_min_to_body`'s values, bit for bit: both are the minimum of the same
    full pair values (a pair is pruned or stopped early only when its value cannot be
    below the best so far), the pair that attains it computed in full either way.
    ``bound``, ``link_*``: scratch space (at least ``La x Lb``)."""
    la = wa.shape[0]
    count = 0
    for body in range(starts.shape[0] - 1):
        if not member[body]:
            continue
        margin = margins[body]
        for i in range(la):
            for j in range(starts[body], starts[body + 1]):
                dx, dy, dz = sa[i, 0] - sb[j, 0], sa[i, 1] - sb[j, 1], sa[i, 2] - sb[j, 2]
                bound[count] = (np.sqrt(dx * dx + dy * dy + dz * dz) - brad_a[i] - brad_b[j]
                                - margin)
                link_i[count] = i
                link_j[count] = j
                link_m[count] = margin
                count += 1
    # Decision (issue #29 item 6): the best-first pruned search below is written out as
    # in _min_to_body, not shared: there a bound's index maps to the link pair arithmetically
    # (j0 + idx % nbl, one margin); here through link_i/link_j/link_m over several bodies,
    # and a shared compiled helper would take both mappings' arrays.
    order = np.argsort(bound[:count])
    best = cutoff
    for idx in order:
        if bound[idx] >= best:
            break
        i = link_i[idx]
        j = link_j[idx]
        margin = link_m[idx]
        dist = _pruned_pair(wa, sa, rot_a, n_a, scale_a, ball_a, wb, sb, rot_b, n_b, scale_b,
                            ball_b, i, j, margin, best, verts, nbrs, iterations, ws)
        if dist < best:
            best = dist
    return best


@njit(cache=True, nogil=True)
def swept_nearest_many(table: np.ndarray, tcp: np.ndarray, bases: np.ndarray,
                       qs: np.ndarray, row_query: np.ndarray, groups: np.ndarray,
                       cutoffs: np.ndarray, pts_a: np.ndarray, n_a: np.ndarray,
                       scale_a: np.ndarray, ball_a: np.ndarray, bcen_a: np.ndarray,
                       brad_a: np.ndarray, frames_b: np.ndarray, pts_b: np.ndarray,
                       n_b: np.ndarray, scale_b: np.ndarray, ball_b: np.ndarray,
                       bcen_b: np.ndarray, brad_b: np.ndarray, starts: np.ndarray,
                       margins: np.ndarray, verts: np.ndarray, nbrs: np.ndarray,
                       iterations: int, out: np.ndarray) -> None:  # pragma: no cover
    """The nearest body of each group, for the configurations of several robots of one
    model (issue #17 §4: the distances an index reads are often only the nearest of a set
    of bodies — CR's — so one branch and bound serves the whole set).

    Args as in :func:`swept_distances_many`, with ``groups`` ``(R, G, B)``: the bodies of
    group ``g`` for query robot ``r``, and ``cutoffs`` ``(G,)``. ``out[c, g]`` ``(N, G)``:
    the minimum over the group's bodies of what :func:`swept_distances_many` gives with
    cutoff ``cutoffs[g]`` (bit for bit, :func:`_nearest_of_bodies`); ``cutoffs[g]`` for
    an empty group.
    """
    la = pts_a.shape[0]
    lb = frames_b.shape[0]
    n = qs.shape[1]
    frames = np.empty((n + 2, 4, 4))
    wa = np.empty((la, 3, 3))
    wb = np.empty((lb, 3, 3))
    sa = np.empty((la, 3))
    sb = np.empty((lb, 3))
    rot_a = np.empty((la, 3, 3))
    rot_b = np.empty((lb, 3, 3))
    _posed(frames_b, pts_b, n_b, bcen_b, wb, sb, rot_b)
    bound = np.empty(la * lb)
    link_i = np.empty(la * lb, dtype=np.int64)
    link_j = np.empty(la * lb, dtype=np.int64)
    link_m = np.empty(la * lb)
    ws = np.empty((16, 3))
    for c in range(qs.shape[0]):
        r = row_query[c]
        _chain_kernel(table, tcp, bases[r], qs[c], frames)
        fa = frames[:la]
        _posed(fa, pts_a, n_a, bcen_a, wa, sa, rot_a)
        for g in range(groups.shape[1]):
            out[c, g] = _nearest_of_bodies(wa, sa, rot_a, n_a, scale_a, ball_a, brad_a, wb,
                                           sb, rot_b, n_b, scale_b, ball_b, brad_b, starts,
                                           margins, groups[r, g], verts, nbrs, cutoffs[g],
                                           iterations, bound, link_i, link_j, link_m, ws)


@njit(cache=True, nogil=True)
def swept_pair_bounds(frames_a: np.ndarray, pts_a: np.ndarray, n_a: np.ndarray,
                      scale_a: np.ndarray, ball_a: np.ndarray, bcen_a: np.ndarray,
                      brad_a: np.ndarray, frames_b: np.ndarray, pts_b: np.ndarray,
                      n_b: np.ndarray, scale_b: np.ndarray, ball_b: np.ndarray,
                      bcen_b: np.ndarray, brad_b: np.ndarray, verts: np.ndarray,
                      nbrs: np.ndarray, margin: float, cutoff: float, window: float,
                      iterations: int, ia: np.ndarray, ib: np.ndarray, out: np.ndarray
                      ) -> None:  # pragma: no cover - compiled
    """The swept-model distance of each listed link pair ``(ia[p], ib[p])`` into ``out``
    ``(P,)`` (frames ``(L, 4, 4)`` of one configuration per body; other arguments as in
    :func:`swept_distances`): ``-inf`` where the key-point hulls meet (no estimate), ``inf``
    where the pair is surely ``>= cutoff`` or (bounding spheres apart) more than ``window``
    above the smallest value (pairs are visited in increasing bounding-sphere order)."""
    la = frames_a.shape[0]
    lb = frames_b.shape[0]
    wa = np.empty((la, 3, 3))
    wb = np.empty((lb, 3, 3))
    sa = np.empty((la, 3))
    sb = np.empty((lb, 3))
    rot_a = np.empty((la, 3, 3))
    rot_b = np.empty((lb, 3, 3))
    _posed(frames_a, pts_a, n_a, bcen_a, wa, sa, rot_a)
    _posed(frames_b, pts_b, n_b, bcen_b, wb, sb, rot_b)
    count = ia.shape[0]
    bound = np.empty(count)
    for p in range(count):
        i = ia[p]
        j = ib[p]
        dx, dy, dz = sa[i, 0] - sb[j, 0], sa[i, 1] - sb[j, 1], sa[i, 2] - sb[j, 2]
        bound[p] = np.sqrt(dx * dx + dy * dy + dz * dz) - brad_a[i] - brad_b[j] - margin
    ws = np.empty((16, 3))
    best = np.inf
    for p in np.argsort(bound):
        # the window never skips a pair whose spheres overlap (so that every pair
        # without an estimate, -inf, is reported)
        limit = min(cutoff, best + window) if bound[p] >= 0.0 else cutoff
        if bound[p] >= limit:
            out[p] = np.inf
            continue
        i = ia[p]
        j = ib[p]
        out[p] = _pair(wa[i], n_a[i], rot_a[i], scale_a[i], ball_a[i], wb[j], n_b[j],
                       rot_b[j], scale_b[j], ball_b[j], verts, nbrs, iterations,
                       limit + margin, ws) - margin
        if out[p] < best:
            best = out[p]


@njit(cache=True, nogil=True)
def swept_pair_bounds_bodies(frames_a: np.ndarray, pts_a: np.ndarray, n_a: np.ndarray,
                             scale_a: np.ndarray, ball_a: np.ndarray, bcen_a: np.ndarray,
                             brad_a: np.ndarray, frames_b: np.ndarray, pts_b: np.ndarray,
                             n_b: np.ndarray, scale_b: np.ndarray, ball_b: np.ndarray,
                             bcen_b: np.ndarray, brad_b: np.ndarray, starts: np.ndarray,
                             margins: np.ndarray, verts: np.ndarray, nbrs: np.ndarray,
                             cutoff: float, window: float, iterations: int, out: np.ndarray
                             ) -> None:  # pragma: no cover - compiled
    """:func:`swept_pair_bounds` of every link pair of body ``a`` with each of several
    bodies (stacked as in :func:`swept_distances`: body ``k`` = links
    ``starts[k]:starts[k + 1]``, ``margins[k]``), in one call: body ``k``'s ``La x Lk``
    values, pairs in row-major order (``a``'s link first), go to ``out`` from
    ``La x starts[k]`` on — the values of one :func:`swept_pair_bounds` call per body, bit
    for bit (the same call per body)."""
    la = frames_a.shape[0]
    for body in range(starts.shape[0] - 1):
        j0 = starts[body]
        j1 = starts[body + 1]
        lk = j1 - j0
        ia = np.empty(la * lk, dtype=np.int64)
        ib = np.empty(la * lk, dtype=np.int64)
        for i in range(la):
            for j in range(lk):
                ia[i * lk + j] = i
                ib[i * lk + j] = j
        swept_pair_bounds(frames_a, pts_a, n_a, scale_a, ball_a, bcen_a, brad_a,
                          frames_b[j0:j1], pts_b[j0:j1], n_b[j0:j1], scale_b[j0:j1],
                          ball_b[j0:j1], bcen_b[j0:j1], brad_b[j0:j1], verts, nbrs,
                          margins[body], cutoff, window, iterations, ia, ib,
                          out[la * j0:la * j1])
