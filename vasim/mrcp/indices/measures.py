"""Classic dexterity measures of a Jacobian (spec/mrcp.md §4, seed chapter 2).

Pure functions of a translational (or any ``m x n``) Jacobian ``J``; every function accepts a
stack ``(..., m, n)`` and returns ``(...)``. With ``A = J J'`` (``m x m``):

* manipulability ``w = sqrt(det A)`` (Yoshikawa);
* order-independent manipulability ``M = det(A)^(1/(2m))`` (the m-th root of ``w``);
* ``σ_min`` (smallest singular value of ``J``), condition number ``σ_max/σ_min`` and its
  reciprocal (``0`` at a singularity, ``1`` when isotropic);
* ``trace(A)/m`` and isotropy ``Δ = det(A)^(1/m) / (trace(A)/m)`` in ``[0, 1]``;
* directional manipulability ``ψ_u = 1 / sqrt(u' A⁺ u)`` (seed eq. 2.9-2.10, 3.21): the
  distance from the centre of the velocity ellipsoid to its surface along the unit
  direction ``u``. A pseudo-inverse makes a singular ``J`` give ``ψ = 0`` along the lost
  direction instead of an exception.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

_EPS = 1e-12


def _det(a: FloatArray) -> FloatArray:
    with np.errstate(divide="ignore", invalid="ignore"):   # LU of an exactly singular A
        return np.clip(np.nan_to_num(np.linalg.det(a)), 0.0, None)


def _gram(jac: FloatArray) -> FloatArray:
    j = np.asarray(jac, dtype=np.float64)
    return j @ np.swapaxes(j, -1, -2)


def singular_values(jac: FloatArray) -> FloatArray:
    """``(..., min(m, n))`` singular values of ``J``, descending."""
    return np.linalg.svd(np.asarray(jac, dtype=np.float64), compute_uv=False)


def manipulability(jac: FloatArray) -> FloatArray:
    """Yoshikawa's ``w = sqrt(det(J J'))`` (0 at a singularity).

    Example:
        >>> import numpy as np
        >>> float(manipulability(np.diag([2.0, 3.0])))
        6.0
    """
    return np.sqrt(_det(_gram(jac)))


def order_independent_manipulability(jac: FloatArray) -> FloatArray:
    """``M = det(J J')^(1/(2m))``: the geometric mean of the singular values."""
    m = np.asarray(jac).shape[-2]
    return _det(_gram(jac)) ** (1.0 / (2 * m))


def sigma_min(jac: FloatArray) -> FloatArray:
    """Smallest singular value of ``J`` (0 at a singularity)."""
    return singular_values(jac)[..., -1]


def condition_number(jac: FloatArray) -> FloatArray:
    """``σ_max / σ_min`` (``inf`` at a singularity)."""
    s = singular_values(jac)
    with np.errstate(divide="ignore"):
        return np.where(s[..., -1] > _EPS, s[..., 0] / np.maximum(s[..., -1], _EPS), np.inf)


def reciprocal_condition_number(jac: FloatArray) -> FloatArray:
    """``σ_min / σ_max`` in ``[0, 1]`` (0 at a singularity, 1 isotropic)."""
    s = singular_values(jac)
    return np.where(s[..., 0] > _EPS, s[..., -1] / np.maximum(s[..., 0], _EPS), 0.0)


def mean_trace(jac: FloatArray) -> FloatArray:
    """``trace(J J') / m``: the mean squared singular value."""
    g = _gram(jac)
    return np.trace(g, axis1=-2, axis2=-1) / g.shape[-1]


def isotropy(jac: FloatArray) -> FloatArray:
    """``Δ = det(J J')^(1/m) / (trace(J J')/m)`` in ``[0, 1]`` (AM-GM of σ²)."""
    g = _gram(jac)
    m = g.shape[-1]
    det = _det(g)
    tr = np.trace(g, axis1=-2, axis2=-1) / m
    return np.where(tr > _EPS, det ** (1.0 / m) / np.maximum(tr, _EPS), 0.0)


def directional_manipulability(jac: FloatArray, u: FloatArray) -> FloatArray:
    """``ψ_u = 1 / sqrt(u' (J J')⁺ u)`` for unit directions ``u``.

    Args:
        jac: ``(..., m, n)`` Jacobian(s).
        u: ``(..., k, m)`` unit directions; broadcast against the Jacobian stack, giving
            ``(..., k)`` values (``k`` directions per Jacobian).

    Returns:
        ``(..., k)`` ψ values [same unit as ``J``'s rows per joint unit]; 0 along a direction
        the Jacobian cannot produce.

    Example:
        >>> import numpy as np
        >>> j = np.diag([2.0, 0.5])
        >>> directional_manipulability(j, np.array([[1.0, 0.0], [0.0, 1.0]])).round(6)
        array([2. , 0.5])
    """
    left, sig = task_svd(jac)
    return directional_manipulability_svd(left, sig, u)


def task_svd(jac: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Left singular vectors ``(..., m, m)`` and singular values padded to ``(..., m)``
    (zeros for ``m > n``): what :func:`directional_manipulability_svd` needs."""
    j = np.asarray(jac, dtype=np.float64)
    left, s, _ = np.linalg.svd(j, full_matrices=True)
    m = j.shape[-2]
    if s.shape[-1] == m:
        return left, s
    sig = np.zeros((*j.shape[:-2], m))
    sig[..., : s.shape[-1]] = s
    return left, sig


def directional_manipulability_svd(left: FloatArray, sig: FloatArray, u: FloatArray
                                   ) -> FloatArray:
    """:func:`directional_manipulability` from a precomputed :func:`task_svd`."""
    uu = np.asarray(u, dtype=np.float64)
    lost = sig < 1e-9 * np.maximum(sig[..., :1], _EPS)     # directions J cannot produce
    comp = np.einsum("...ki,...ij->...kj", uu, left)        # (..., k, m) components on U
    comp2 = comp * comp
    inv_s2 = np.where(lost, 0.0, 1.0 / np.maximum(sig * sig, _EPS * _EPS))
    quad = np.sum(comp2 * inv_s2[..., None, :], axis=-1)
    leak = np.sum(np.where(lost[..., None, :], comp2, 0.0), axis=-1)
    with np.errstate(divide="ignore"):
        psi = np.where(quad > 0.0, 1.0 / np.sqrt(np.maximum(quad, _EPS * _EPS)), 0.0)
    return np.where(leak > 1e-12, 0.0, psi)
