"""Compiled inner loops of Θ (:mod:`vasim.mrcp.indices.dexterity`), numba ``cache=True``.

Pure functions of arrays: the arm's Jacobians are computed outside (the arm is Python). The
maths is the module docstring of ``dexterity``; the tests hold the compiled path to the
analytic values and to an independent numpy implementation.
"""

from __future__ import annotations

import numpy as np
from numba import njit

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
    for k in range(kk):
        if not (reach[k] and reach[k + 1]):
            continue
        if k == 0:
            if ok0:
                left, sig = _svd_padded(jac_pts[0])
                seg[0] = _phi(pos[0], left, sig, samp[0], dens, ok[0])
            continue
        acc = 0.0
        for a in range(s_count):
            if not ok[k - 1, a]:
                continue
            left, sig = _svd_padded(jac_s[k - 1, a])
            acc += dens[a] * _phi(samp[k - 1, a], left, sig, samp[k], dens, ok[k])
        seg[k] = acc / total
    return seg
