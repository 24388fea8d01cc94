"""Compiled evaluations of RJ and the tool cone along a trajectory (numba ``cache=True``).

Same maths as the numpy pure functions of ``joint_limits`` and ``cone`` (which stay the
reference: the tests hold these kernels to them); one call per (robot, point) instead of a
dozen small numpy operations.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _jeval(dist: float, b: float) -> float:  # pragma: no cover - compiled
    d = min(1.0, max(0.0, dist))
    return (1.0 - np.cos(np.pi * d ** (1.0 / b))) / 2.0


@njit(cache=True, nogil=True)
def rj_along(configs: np.ndarray, reach: np.ndarray, vel: np.ndarray, lower: np.ndarray,
             upper: np.ndarray, vmax: np.ndarray, b_min: float, b_max: float,
             errors: np.ndarray) -> float:  # pragma: no cover - compiled
    """RJ along a trajectory: ``min_i Σ_k w_k Jeval_{k,i} / Σ_k w_k`` with velocity-modulated
    ``b`` and ranges shrunk by ``|e_k|`` (see ``joint_limits``)."""
    n_pts, n = configs.shape
    wsum = 0.0
    for k in range(n_pts):
        wsum += 1.0 / (k + 1.0)
    best = np.inf
    for i in range(n):
        acc = 0.0
        for k in range(n_pts):
            if not reach[k]:
                continue
            th = configs[k, i]
            toward_upper = abs(th - upper[i]) <= abs(th - lower[i])
            v = vel[k, i] if toward_upper else -vel[k, i]
            ratio = min(1.0, max(0.0, v) / vmax[i])
            b = b_max - (b_max - b_min) * ratio
            e = abs(errors[k, i])
            lo = lower[i] + e
            hi = upper[i] - e
            half = (hi - lo) / 2.0
            if half <= 0.0 or th <= lo or th >= hi:
                continue
            acc += _jeval(min(abs(th - hi), abs(th - lo)) / half, b) / (k + 1.0)
        best = min(best, acc / wsum)
    return best


@njit(cache=True, nogil=True)
def cone_along(tips: np.ndarray, reach: np.ndarray, fulcrum: np.ndarray, x: np.ndarray,
               y: np.ndarray, z: np.ndarray, sectors: np.ndarray,
               b: float) -> float:  # pragma: no cover - compiled
    """Weighted mean of the modulated cone margin ``Jeval(1 - α/φ(θ), b)`` over the tips;
    ``sectors`` rows are ``(start, end, a, b)``; -1 when an azimuth is not covered."""
    wsum = 0.0
    acc = 0.0
    for k in range(tips.shape[0]):
        w = 1.0 / (k + 1.0)
        wsum += w
        if not reach[k]:
            continue
        d0 = tips[k, 0] - fulcrum[0]
        d1 = tips[k, 1] - fulcrum[1]
        d2 = tips[k, 2] - fulcrum[2]
        nrm = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if nrm <= 1e-12:
            alpha, theta = 0.0, 0.0
        else:
            dz = (d0 * z[0] + d1 * z[1] + d2 * z[2]) / nrm
            dx = (d0 * x[0] + d1 * x[1] + d2 * x[2]) / nrm
            dy = (d0 * y[0] + d1 * y[1] + d2 * y[2]) / nrm
            alpha = np.arccos(min(1.0, max(-1.0, dz)))
            theta = np.arctan2(dy, dx) % (2.0 * np.pi)
            if theta >= 2.0 * np.pi:  # -1e-17 % 2π rounds to 2π (cone._wrap)
                theta = 0.0
        phi = -1.0
        for s in range(sectors.shape[0]):
            if sectors[s, 0] <= theta < sectors[s, 1]:
                sa, sb = sectors[s, 2], sectors[s, 3]
                r = sa * sb / np.hypot(sb * np.cos(theta), sa * np.sin(theta))
                phi = np.arctan(r)
                break
        if phi < 0.0:
            return -1.0
        acc += w * _jeval(1.0 - alpha / phi, b)
    return acc / wsum
