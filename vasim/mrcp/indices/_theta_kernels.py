"""Compiled inner loops of Θ (:mod:`vasim.mrcp.indices.dexterity`), numba ``cache=True``.

Pure functions of arrays: the arm's Jacobians are computed outside (the arm is Python). The
maths is the module docstring of ``dexterity``; the tests hold the compiled path to the
analytic values and to an independent numpy implementation.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from vasim.mrcp.dh import _many_kernel  # the compiled DH chain (frames and Jacobians)

_EPS = 1e-12


@njit(cache=True, nogil=True)
def sample_configs(std: np.ndarray, z: np.ndarray, configs: np.ndarray,
                   jac: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """First-order configurations of the samples of points 1..K: ``q_k + J_k⁺ (σ_k ∘ z_s)``.

    Args:
        std: ``(K+1, m)`` standard deviations; z: ``(S, m)`` standard-normal draws;
        configs: ``(K+1, n)``; jac: ``(K+1, m, n)`` task Jacobians.

    Returns:
        ``(K, S, n)``.
    """
    kk = configs.shape[0] - 1
    s_count = z.shape[0]
    m = jac.shape[1]
    n = configs.shape[1]
    out = np.empty((kk, s_count, n))
    for k in range(1, kk + 1):
        pinv = np.linalg.pinv(jac[k])                      # (n, m)
        for s in range(s_count):
            for i in range(n):
                acc = configs[k, i]
                for j in range(m):
                    acc += pinv[i, j] * std[k, j] * z[s, j]
                out[k - 1, s, i] = acc
    return out


@njit(cache=True, nogil=True)
def sigma_min_many(jac: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """Smallest singular value of each ``(N, r, n)`` matrix (0 for rank-deficient shapes)."""
    out = np.empty(jac.shape[0])
    r, n = jac.shape[1], jac.shape[2]
    for i in range(jac.shape[0]):
        a = np.ascontiguousarray(jac[i])
        g = a @ a.T if r <= n else a.T @ a
        lam = np.linalg.eigvalsh(g)[0]
        out[i] = np.sqrt(lam) if lam > 0.0 else 0.0
    return out


@njit(cache=True, nogil=True)
def sigma_min_at_least(jac: np.ndarray, threshold: float
                       ) -> np.ndarray:  # pragma: no cover - compiled
    """``σ_min(J_i) >= threshold`` for each ``(N, r, n)`` matrix, ``r <= n``, without an
    eigen-decomposition: ``J Jᵀ - threshold² I`` is positive definite (a Cholesky
    factorisation succeeds). **Decision**: the same test as ``sigma_min_many(jac) >=
    threshold`` except exactly at equality (and within round-off of it)."""
    count, r, n = jac.shape
    out = np.empty(count, dtype=np.bool_)
    g = np.empty((r, r))
    low = np.zeros((r, r))
    t2 = threshold * threshold
    for k in range(count):
        for i in range(r):
            for j in range(i + 1):
                acc = 0.0
                for c in range(n):
                    acc += jac[k, i, c] * jac[k, j, c]
                g[i, j] = acc
        for i in range(r):
            g[i, i] -= t2
        ok = True
        for j in range(r):
            d = g[j, j]
            for c in range(j):
                d -= low[j, c] * low[j, c]
            if not d > 0.0:
                ok = False
                break
            low[j, j] = np.sqrt(d)
            for i in range(j + 1, r):
                acc = g[i, j]
                for c in range(j):
                    acc -= low[i, c] * low[j, c]
                low[i, j] = acc / low[j, j]
        out[k] = ok or (threshold <= 0.0)
    return out


@njit(cache=True, nogil=True)
def _psi(left: np.ndarray, sig: np.ndarray, u: np.ndarray) -> float:  # pragma: no cover
    """ψ along unit ``u`` from the SVD (``left`` m x m, ``sig`` padded to m)."""
    m = left.shape[0]
    smax = sig[0] if sig[0] > _EPS else _EPS
    quad = 0.0
    for j in range(m):
        c = 0.0
        for i in range(m):
            c += u[i] * left[i, j]
        if sig[j] < 1e-9 * smax:
            if c * c > 1e-12:
                return 0.0                                     # a lost direction
        else:
            quad += c * c / (sig[j] * sig[j])
    if quad <= 0.0:
        return 0.0
    return 1.0 / np.sqrt(quad)


@njit(cache=True, nogil=True)
def _svd_padded(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover
    u, s, _ = np.linalg.svd(np.ascontiguousarray(a))
    m = a.shape[0]
    sig = np.zeros(m)
    for i in range(s.shape[0]):
        sig[i] = s[i]
    return u, sig


@njit(cache=True, nogil=True)
def _phi(origin: np.ndarray, left: np.ndarray, sig: np.ndarray, dest: np.ndarray,
         dens: np.ndarray, ok: np.ndarray) -> float:  # pragma: no cover - compiled
    m = origin.shape[0]
    total = 0.0
    acc = 0.0
    u = np.empty(m)
    still = 1.0
    for j in range(m):
        still *= sig[j]
    still = still ** (1.0 / m) if still > 0.0 else 0.0
    for b in range(dest.shape[0]):
        total += dens[b]
        if not ok[b]:
            continue
        norm = 0.0
        for j in range(m):
            u[j] = dest[b, j] - origin[j]
            norm += u[j] * u[j]
        norm = np.sqrt(norm)
        if norm > 1e-9:
            for j in range(m):
                u[j] /= norm
            acc += dens[b] * _psi(left, sig, u)
        else:
            acc += dens[b] * still
    return acc / total


@njit(cache=True, nogil=True)
def _gram_inverse(a: np.ndarray, ginv: np.ndarray) -> float:  # pragma: no cover - compiled
    """``(A Aᵀ)⁻¹`` of a wide ``(m, n)`` matrix into ``ginv`` by Cholesky, and
    ``det(A Aᵀ)``; returns -1 when ``det < 1e-12 trace^m`` (then ``λ_min / λ_max`` may be
    below 1e-12 and the caller takes the SVD route, which tells lost directions apart)."""
    m, n = a.shape
    g = np.empty((m, m))
    trace = 0.0
    for i in range(m):
        for j in range(i + 1):
            acc = 0.0
            for c in range(n):
                acc += a[i, c] * a[j, c]
            g[i, j] = acc
            g[j, i] = acc
        trace += g[i, i]
    low = np.zeros((m, m))
    det = 1.0
    for j in range(m):
        d = g[j, j]
        for c in range(j):
            d -= low[j, c] * low[j, c]
        if d <= 0.0:
            return -1.0
        low[j, j] = np.sqrt(d)
        det *= d
        for i in range(j + 1, m):
            acc = g[i, j]
            for c in range(j):
                acc -= low[i, c] * low[j, c]
            low[i, j] = acc / low[j, j]
    if det < 1e-12 * trace ** m:
        return -1.0
    # inverse of L, then (L Lᵀ)⁻¹ = L⁻ᵀ L⁻¹
    linv = np.zeros((m, m))
    for i in range(m):
        linv[i, i] = 1.0 / low[i, i]
        for j in range(i):
            acc = 0.0
            for c in range(j, i):
                acc -= low[i, c] * linv[c, j]
            linv[i, j] = acc / low[i, i]
    for i in range(m):
        for j in range(m):
            acc = 0.0
            for c in range(max(i, j), m):
                acc += linv[c, i] * linv[c, j]
            ginv[i, j] = acc
    return det


@njit(cache=True, nogil=True)
def _phi_gram(origin: np.ndarray, ginv: np.ndarray, det: float, dest: np.ndarray,
              dens: np.ndarray, ok: np.ndarray) -> float:  # pragma: no cover - compiled
    """:func:`_phi` for a well-conditioned Jacobian from its Gram inverse:
    ``ψ_u = (uᵀ (J Jᵀ)⁻¹ u)^(-1/2)`` (= the SVD form ``(Σ_j (u·U_j)² / σ_j²)^(-1/2)``) and
    the geometric mean of the singular values ``det(J Jᵀ)^(1/2m)``."""
    m = origin.shape[0]
    total = 0.0
    acc = 0.0
    u = np.empty(m)
    still = det ** (1.0 / (2.0 * m))
    for b in range(dest.shape[0]):
        total += dens[b]
        if not ok[b]:
            continue
        norm = 0.0
        for j in range(m):
            u[j] = dest[b, j] - origin[j]
            norm += u[j] * u[j]
        norm = np.sqrt(norm)
        if norm > 1e-9:
            quad = 0.0
            for i in range(m):
                row = 0.0
                for j in range(m):
                    row += ginv[i, j] * u[j]
                quad += u[i] * row
            quad /= norm * norm
            acc += dens[b] * (1.0 / np.sqrt(quad) if quad > 0.0 else 0.0)
        else:
            acc += dens[b] * still
    return acc / total


@njit(cache=True, nogil=True)
def _phi_of(origin: np.ndarray, jac: np.ndarray, dest: np.ndarray, dens: np.ndarray,
            ok: np.ndarray, ginv: np.ndarray) -> float:  # pragma: no cover - compiled
    """Φ from ``origin`` with the task Jacobian ``jac``: the Gram route when it is well
    conditioned (**decision**: the same value in exact arithmetic, no SVD), else the SVD."""
    det = _gram_inverse(jac, ginv)
    if det > 0.0:
        return _phi_gram(origin, ginv, det, dest, dens, ok)
    left, sig = _svd_padded(jac)
    return _phi(origin, left, sig, dest, dens, ok)


@njit(cache=True, nogil=True)
def theta_segments(pos: np.ndarray, std: np.ndarray, z: np.ndarray, dens: np.ndarray,
                   reach: np.ndarray, jac_pts: np.ndarray, jac_s: np.ndarray,
                   ok0: bool, ok: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """Φ of every predicted segment.

    Args:
        pos, std: ``(K+1, m)`` predicted points and their deviations.
        z, dens: ``(S, m)`` draws and ``(S,)`` their densities.
        reach: ``(K+1,)`` reachability.
        jac_pts: ``(K+1, m, n)`` task Jacobians at the points (only [0] used: the origin).
        jac_s: ``(K, S, m, n)`` task Jacobians at the samples of points 1..K.
        ok0: the observed origin passes the σ_min threshold.
        ok: ``(K, S)`` the samples pass it (and their point is reachable).

    Returns:
        ``(K,)`` segment values (0 where an end is unreachable).
    """
    kk = pos.shape[0] - 1
    s_count = z.shape[0]
    m = pos.shape[1]
    seg = np.zeros(kk)
    samp = np.empty((kk, s_count, m))
    for k in range(kk):
        for s in range(s_count):
            for j in range(m):
                samp[k, s, j] = pos[k + 1, j] + std[k + 1, j] * z[s, j]
    total = 0.0
    for s in range(s_count):
        total += dens[s]
    ginv = np.empty((m, m))
    for k in range(kk):
        if not (reach[k] and reach[k + 1]):
            continue
        if k == 0:
            if ok0:
                seg[0] = _phi_of(pos[0], jac_pts[0], samp[0], dens, ok[0], ginv)
            continue
        acc = 0.0
        for a in range(s_count):
            if not ok[k - 1, a]:
                continue
            acc += dens[a] * _phi_of(samp[k - 1, a], jac_s[k - 1, a], samp[k], dens, ok[k],
                                     ginv)
        seg[k] = acc / total
    return seg


@njit(cache=True, nogil=True)
def theta_dh_segments(table: np.ndarray, tcp: np.ndarray, base: np.ndarray,
                      configs: np.ndarray, pos: np.ndarray, std: np.ndarray, z: np.ndarray,
                      dens: np.ndarray, reach: np.ndarray, rows: np.ndarray, tr: np.ndarray,
                      threshold: float, at_least: bool) -> np.ndarray:  # pragma: no cover
    """Θ's segment values for an arm given by its compiled DH chain, in one call: the same
    steps and arithmetic as ``AnisotropicDexterityIndex.evaluate``'s general path
    (Jacobians at the points, first-order samples, their Jacobians, the σ_min test on the
    ``tr`` rows, :func:`theta_segments`), without the Python between them.

    Args:
        table, tcp, base: the chain (``RobotModel.table``, ``.tcp``, ``(4, 4)`` base).
        configs: ``(K+1, n)``; pos, std: ``(K+1, m)`` (the ``rows`` columns).
        rows: ``(m,)`` task rows of ψ; tr: rows held against ``threshold``;
        at_least: ``len(tr) <= n`` (:func:`sigma_min_at_least`, else :func:`sigma_min_many`).

    Returns:
        ``(K,)`` segment values.
    """
    kk = configs.shape[0] - 1
    n = configs.shape[1]
    m = rows.shape[0]
    s_count = z.shape[0]
    t = tr.shape[0]
    full = np.empty((kk + 1, 6, n))
    _many_kernel(table, tcp, base, configs, np.empty((kk + 1, n + 2, 4, 4)), full, True)
    jac = np.empty((kk + 1, m, n))
    for k in range(kk + 1):
        for a in range(m):
            for i in range(n):
                jac[k, a, i] = full[k, rows[a], i]
    q_samp = sample_configs(std, z, configs, jac).reshape(kk * s_count, n)
    full_s = np.empty((kk * s_count, 6, n))
    _many_kernel(table, tcp, base, q_samp, np.empty((kk * s_count, n + 2, 4, 4)), full_s,
                 True)
    stack = np.empty((1 + kk * s_count, t, n))
    for a in range(t):
        for i in range(n):
            stack[0, a, i] = full[0, tr[a], i]
    for p in range(kk * s_count):
        for a in range(t):
            for i in range(n):
                stack[1 + p, a, i] = full_s[p, tr[a], i]
    if at_least:
        passes = sigma_min_at_least(stack, threshold)
    else:
        passes = sigma_min_many(stack) >= threshold
    ok = np.empty((kk, s_count), dtype=np.bool_)
    jac_s = np.empty((kk, s_count, m, n))
    for k in range(kk):
        for s in range(s_count):
            ok[k, s] = passes[1 + k * s_count + s] and reach[k + 1]
            for a in range(m):
                for i in range(n):
                    jac_s[k, s, a, i] = full_s[k * s_count + s, rows[a], i]
    return theta_segments(pos, std, z, dens, reach, jac, jac_s, bool(passes[0]), ok)


@njit(cache=True, nogil=True)
def theta_dh_many(tables: np.ndarray, tcps: np.ndarray, bases: np.ndarray, arm: np.ndarray,
                  configs: np.ndarray, pos: np.ndarray, std: np.ndarray, z: np.ndarray,
                  dens: np.ndarray, reach: np.ndarray, rows: np.ndarray, tr: np.ndarray,
                  threshold: float, at_least: bool, out: np.ndarray
                  ) -> None:  # pragma: no cover - compiled
    """:func:`theta_dh_segments` for many (robot, point) contexts in one call (issue #17
    §4: the cycle's Jacobians and Θ of every robot at once): context ``c`` uses the chain
    ``arm[c]`` of ``tables`` ``(A, 4, n)`` / ``tcps`` ``(A, 3)`` / ``bases`` ``(A, 4, 4)``
    and ``configs[c]`` ``(K+1, n)``, ``pos[c]`` / ``std[c]`` ``(K+1, m)``, ``reach[c]``;
    its ``(K,)`` segment values go to ``out[c]`` (the same compiled steps, bit for bit)."""
    for c in range(configs.shape[0]):
        a = arm[c]
        out[c] = theta_dh_segments(tables[a], tcps[a], bases[a], configs[c], pos[c], std[c],
                                   z, dens, reach[c], rows, tr, threshold, at_least)
