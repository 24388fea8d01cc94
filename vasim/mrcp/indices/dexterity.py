"""ψ_u and Θ — directional manipulability along the predicted trajectory (spec/mrcp.md §4,
seed eq. 3.21-3.26, Fig. 3.11), plus the classic measures as indices for analysis.

For the segment from predicted point ``k`` to ``k+1``:

* ``φ_k^{k+1}`` (origin known): sample ``p'_b ~ N(p_{k+1}, d_{k+1})``; ``u_b`` the unit
  direction from the origin to ``p'_b``; ``φ = Σ_b ψ_{u_b} P(p'_b) / Σ_b P(p'_b)``.
* ``Φ_k^{k+1}`` (origin uncertain): the same from origin samples ``p'_a ~ N(p_k, d_k)``,
  ``Φ = Σ_a φ(p'_a) P(p'_a) / Σ_a P(p'_a)``; segment 0 starts at the observed pose (φ).
* **Decision** (spec §4, no closed formula in the seed): ``Θ = Σ_k w_k Φ_k / Σ_k w_k`` with
  ``w_k = 1/(k+1)`` over the predicted segments.

A sample whose configuration has ``σ_min(J) < sigma_min_threshold`` counts ``ψ = 0``
(a singularity inside Ω cannot be excluded otherwise); an unreachable predicted point
makes its segments 0.

**Decisions** taken to keep Θ real-time and smooth:

* The samples of ``N(p_k, d_k)`` are the *same* set when ``p_k`` is a destination (segment
  ``k-1``) and an origin (segment ``k``), so every sample needs one Jacobian.
* A sample's configuration is the first-order IK around the predicted configuration,
  ``q' = q_k + J_k⁺ (p' - p_k)`` (the samples lie within a few σ of ``p_k``).
* The standard-normal draws are fixed (seeded once), so Θ is a smooth function of the state
  and its polynomial extrapolation (texec) sees no Monte-Carlo noise.
* A segment with no motion (origin and destination closer than 1e-9 m) has no direction; it
  scores the order-independent manipulability ``M`` (geometric mean of the σ's).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from vasim.mrcp.indices.base import INDICES, EvalContext, prediction_weights
from vasim.mrcp.indices.measures import (
    directional_manipulability,
    directional_manipulability_svd,
    isotropy,
    manipulability,
    order_independent_manipulability,
    reciprocal_condition_number,
    sigma_min,
)
from vasim.mrcp.interfaces import ArmKinematics

FloatArray = NDArray[np.float64]


def jacobians(arm: ArmKinematics, qs: FloatArray) -> FloatArray:
    """``(N, 6, n)`` Jacobians at ``(N, n)`` configurations; uses a batched method the arm
    may add (``jacobians`` or ``jacobian_batch``) when present, else one ``arm.jacobian``
    call each."""
    batched = getattr(arm, "jacobians", None) or getattr(arm, "jacobian_batch", None)
    if batched is not None:
        return np.asarray(batched(qs), dtype=np.float64)
    return np.stack([arm.jacobian(q) for q in qs])


class _Samples:
    """Fixed standard-normal draws and their (unnormalised) densities."""

    def __init__(self, count: int, dim: int, seed: int) -> None:
        rng = np.random.default_rng(seed)
        self.z = rng.standard_normal((count, dim))
        self.weight = np.exp(-0.5 * np.sum(self.z * self.z, axis=1))


@INDICES.add("theta")
class AnisotropicDexterityIndex:
    """Θ: sampled directional manipulability along the predicted trajectory.

    Args:
        n_samples: samples of each predicted point's distribution (origins and
            destinations alike).
        sigma_min_threshold: below this smallest singular value of the task Jacobian a
            sample scores ψ = 0 [m/rad].
        rows: the task-space rows of the geometric Jacobian (default the translation).
        seed: seed of the fixed standard-normal draws.
    """

    name = "theta"

    def __init__(self, n_samples: int = 6, sigma_min_threshold: float = 0.01,
                 rows: Sequence[int] = (0, 1, 2), seed: int = 0) -> None:
        if n_samples < 1:
            raise ValueError(f"theta: n_samples must be >= 1, got {n_samples!r}")
        if sigma_min_threshold < 0.0:
            raise ValueError(f"theta: sigma_min_threshold must be >= 0, got "
                             f"{sigma_min_threshold!r}")
        self.rows = tuple(int(r) for r in rows)
        self.sigma_min_threshold = float(sigma_min_threshold)
        self.samples = _Samples(int(n_samples), len(self.rows), seed)

    def evaluate(self, ctx: EvalContext) -> float:
        reach = ctx.reachable
        kk = ctx.horizon
        if not reach[0] or kk < 1:
            return 0.0
        rows = list(self.rows)
        m, n = len(rows), ctx.arm.n_joints
        thr = self.sigma_min_threshold
        z, dens = self.samples.z, self.samples.weight
        s_count = z.shape[0]
        pos = ctx.positions[:, rows]
        configs = np.where(reach[:, None], ctx.configs, ctx.configs[0][None, :])
        jac = jacobians(ctx.arm, configs)[:, rows, :]                      # (K+1, m, n)
        u_pts, s_pts, vt_pts = np.linalg.svd(jac)
        r = s_pts.shape[-1]
        inv = np.where(s_pts > 1e-10 * s_pts[:, :1], 1.0 / np.maximum(s_pts, 1e-300), 0.0)
        # samp[j]: samples of predicted point j + 1; first-order IK q' = q + J⁺ (p' - p).
        delta = ctx.std[1:, None, :][..., rows] * z[None, :, :]              # (K, S, m)
        samp = pos[1:, None, :] + delta
        coef = np.einsum("kmr,ksm->ksr", u_pts[1:, :, :r], delta) * inv[1:, None, :]
        q_samp = configs[1:, None, :] + np.einsum("krn,ksr->ksn", vt_pts[1:, :r, :], coef)
        jac_s = jacobians(ctx.arm, q_samp.reshape(-1, n))[:, rows, :]
        u_s, s_s, _ = np.linalg.svd(jac_s.reshape(kk, s_count, m, n))
        sig_s = _pad(s_s, m)                                                  # (K, S, m)
        ok = (sig_s[..., -1] >= thr) & reach[1:, None]                        # (K, S)
        sig0 = _pad(s_pts[0], m)
        # Every segment k at once: origins (K, S, m) — segment 0's single known origin is
        # repeated S times (an average of equal values) — and destinations samp[k].
        org = np.concatenate([np.repeat(pos[None, :1, :], s_count, axis=1), samp[:-1]])
        org_u = np.concatenate([np.repeat(u_pts[None, :1], s_count, axis=1), u_s[:-1]])
        org_sig = np.concatenate([np.repeat(sig0[None, None, :], s_count, axis=1),
                                  sig_s[:-1]])
        org_ok = np.concatenate([np.full((1, s_count), sig0[-1] >= thr), ok[:-1]])
        diff = samp[:, None, :, :] - org[:, :, None, :]                      # (K, S, S, m)
        norm = np.sqrt(np.einsum("...i,...i->...", diff, diff))
        moving = norm > 1e-9
        u = diff / np.where(moving, norm, 1.0)[..., None]
        psi = directional_manipulability_svd(org_u, org_sig, u)             # (K, S, S)
        still = np.prod(org_sig, axis=-1) ** (1.0 / m)
        psi = np.where(moving, psi, still[..., None])
        total = dens.sum()
        per_origin = np.einsum("kab,kb->ka", psi, dens[None, :] * ok) / total
        seg = np.einsum("ka,ka->k", per_origin, dens[None, :] * org_ok) / total
        seg = np.where(reach[:-1] & reach[1:], seg, 0.0)
        w = prediction_weights(kk)
        return float((w * seg).sum() / w.sum())


def _pad(sig: FloatArray, m: int) -> FloatArray:
    """Singular values padded with zeros to ``m`` (a tall Jacobian has m - n lost ones)."""
    if sig.shape[-1] == m:
        return sig
    out = np.zeros((*sig.shape[:-1], m))
    out[..., : sig.shape[-1]] = sig
    return out


@INDICES.add("psi")
class DirectionalManipulabilityIndex:
    """ψ_u at the current configuration toward the next predicted point (no sampling).

    Args:
        rows: the task-space rows of the geometric Jacobian.
    """

    name = "psi"

    def __init__(self, rows: Sequence[int] = (0, 1, 2)) -> None:
        self.rows = list(rows)

    def evaluate(self, ctx: EvalContext) -> float:
        if not ctx.reachable[0]:
            return 0.0
        jac = ctx.arm.jacobian(ctx.configs[0])[self.rows, :]
        d = ctx.positions[min(1, ctx.horizon), self.rows] - ctx.positions[0, self.rows]
        nd = float(np.linalg.norm(d))
        if nd <= 1e-9:
            return float(order_independent_manipulability(jac))
        return float(directional_manipulability(jac, (d / nd)[None, :])[0])


_MEASURES = {
    "manipulability": manipulability,
    "order_independent_manipulability": order_independent_manipulability,
    "sigma_min": sigma_min,
    "reciprocal_condition_number": reciprocal_condition_number,
    "isotropy": isotropy,
}


class MeasureIndex:
    """A classic dexterity measure at the current configuration (for analysis/plots)."""

    def __init__(self, measure: str, rows: Sequence[int] = (0, 1, 2)) -> None:
        if measure not in _MEASURES:
            raise ValueError(f"unknown measure {measure!r}; known: {sorted(_MEASURES)}")
        self.name = measure
        self._fn = _MEASURES[measure]
        self.rows = list(rows)

    def evaluate(self, ctx: EvalContext) -> float:
        if not ctx.reachable[0]:
            return 0.0
        return float(self._fn(ctx.arm.jacobian(ctx.configs[0])[self.rows, :]))


def _register_measures() -> None:
    for measure in _MEASURES:
        def factory(rows: Sequence[int] = (0, 1, 2), _m: str = measure) -> MeasureIndex:
            return MeasureIndex(_m, rows)
        INDICES.add(measure)(factory)


_register_measures()
