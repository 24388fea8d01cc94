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

from vasim.core.kernel_args import readonly_c, writable_c
from vasim.mrcp.indices._theta_kernels import (
    sample_configs,
    sigma_min_at_least,
    sigma_min_many,
    theta_dh_many,
    theta_dh_segments,
    theta_segments,
)
from vasim.mrcp.indices.base import INDICES, EvalContext, prediction_weights
from vasim.mrcp.indices.measures import (
    directional_manipulability,
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
        rows: the task-space rows of the geometric Jacobian for ψ (default the
            translation: ψ is measured along the predicted motion of the task point).
        threshold_rows: the rows whose σ_min is held against the threshold. **Decision**:
            default the whole geometric Jacobian, so a wrist singularity (the seed's
            joint-3/5 alignment, 0-based: joints 4 and 6 aligned at θ5 = 0 on the RX60B),
            invisible to the translation, still zeroes Θ (seed Fig. 3.11).
        seed: seed of the fixed standard-normal draws.
    """

    name = "theta"

    def __init__(self, n_samples: int = 6, sigma_min_threshold: float = 0.01,
                 rows: Sequence[int] = (0, 1, 2),
                 threshold_rows: Sequence[int] = (0, 1, 2, 3, 4, 5), seed: int = 0) -> None:
        if n_samples < 1:
            raise ValueError(f"theta: n_samples must be >= 1, got {n_samples!r}")
        if sigma_min_threshold < 0.0:
            raise ValueError(f"theta: sigma_min_threshold must be >= 0, got "
                             f"{sigma_min_threshold!r}")
        self.rows = tuple(int(r) for r in rows)
        self.threshold_rows = tuple(int(r) for r in threshold_rows)
        self.sigma_min_threshold = float(sigma_min_threshold)
        self.samples = _Samples(int(n_samples), len(self.rows), seed)
        self._rows = np.array(self.rows, dtype=np.int64)
        self._tr = np.array(self.threshold_rows, dtype=np.int64)

    def evaluate(self, ctx: EvalContext) -> float:
        reach = ctx.reachable
        kk = ctx.horizon
        if not reach[0] or kk < 1:
            return 0.0
        rows = list(self.rows)
        m, n = len(rows), ctx.arm.n_joints
        z, dens = self.samples.z, self.samples.weight
        s_count = z.shape[0]
        pos = np.ascontiguousarray(ctx.positions[:, rows], dtype=np.float64)
        std = np.ascontiguousarray(ctx.std[:, rows], dtype=np.float64)
        configs = np.ascontiguousarray(
            np.where(reach[:, None], ctx.configs, ctx.configs[0][None, :]), dtype=np.float64)
        chain = getattr(ctx.arm, "dh_chain", None)
        if chain is not None:
            # **Decision** (cost, issue #17 §4): an arm that exposes its compiled DH chain
            # (``dh_chain() -> (table, tcp, base)``, PybulletArm) gets the whole index in
            # one compiled call, the same steps as below (the tests hold the two equal)
            table, tcp, base = chain()
            seg = theta_dh_segments(readonly_c(table), readonly_c(tcp), writable_c(base),
                                    configs, pos, std, z, dens,
                                    np.ascontiguousarray(reach), self._rows, self._tr,
                                    self.sigma_min_threshold, len(self.threshold_rows) <= n)
            w = prediction_weights(kk)
            return float((w * seg).sum() / w.sum())
        full = jacobians(ctx.arm, configs)                                 # (K+1, 6, n)
        jac = np.ascontiguousarray(full[:, rows, :])                        # (K+1, m, n)
        q_samp = sample_configs(std, z, configs, jac)                       # (K, S, n)
        full_s = jacobians(ctx.arm, q_samp.reshape(-1, n))                  # (K S, 6, n)
        tr = list(self.threshold_rows)
        thr = self.sigma_min_threshold
        passes = sigma_min_at_least(np.ascontiguousarray(
            np.concatenate([full[:1, tr, :], full_s[:, tr, :]])), thr) if len(tr) <= n \
            else sigma_min_many(np.ascontiguousarray(
                np.concatenate([full[:1, tr, :], full_s[:, tr, :]]))) >= thr
        ok = passes[1:].reshape(kk, s_count) & reach[1:, None]
        jac_s = np.ascontiguousarray(full_s[:, rows, :].reshape(kk, s_count, m, n))
        seg = theta_segments(pos, std, z, dens, reach, jac, jac_s, bool(passes[0]), ok)
        w = prediction_weights(kk)
        return float((w * seg).sum() / w.sum())


    def evaluate_many(self, contexts: Sequence[EvalContext]) -> list[float]:
        """:meth:`evaluate` of every context, bit for bit, with the contexts of arms that
        expose their DH chain (of one joint count and horizon) in one compiled call
        (:func:`~vasim.mrcp.indices._theta_kernels.theta_dh_many`).

        **Decision** (issue #17 §4, cost): the cycle's Θ — the Jacobians at every
        predicted point and sample of every (robot, point) — is one compiled call for all
        robots instead of one per (robot, point); the per-call Python (chains, contiguous
        copies, the call) was a quarter of Θ's time. The weighted mean over the segments
        stays :meth:`evaluate`'s numpy expression per context (its summation order).
        """
        out: list[float | None] = [None] * len(contexts)
        groups: dict[tuple[int, int], list[int]] = {}
        for i, ctx in enumerate(contexts):
            if (not ctx.reachable[0] or ctx.horizon < 1
                    or getattr(ctx.arm, "dh_chain", None) is None):
                out[i] = self.evaluate(ctx)         # 0, or the general path
            else:
                groups.setdefault((ctx.arm.n_joints, ctx.horizon), []).append(i)
        rows = list(self.rows)
        for (n, kk), members in groups.items():
            arms: dict[int, int] = {}
            chains = []
            for i in members:
                arm = contexts[i].arm
                if id(arm) not in arms:
                    arms[id(arm)] = len(arms)
                    chains.append(arm.dh_chain())  # type: ignore[attr-defined]  # checked
            reach = np.ascontiguousarray([contexts[i].reachable for i in members])
            configs = np.ascontiguousarray(
                [np.where(contexts[i].reachable[:, None], contexts[i].configs,
                          contexts[i].configs[0][None, :]) for i in members], dtype=np.float64)
            segs = np.empty((len(members), kk))
            # read-only, as a robot's own: theta_dh_segments, which this calls per arm, is
            # then compiled once for both calls (vasim.core.kernel_args)
            theta_dh_many(readonly_c([c[0] for c in chains]), readonly_c([c[1] for c in chains]),
                          np.ascontiguousarray([c[2] for c in chains], dtype=np.float64),
                          np.array([arms[id(contexts[i].arm)] for i in members],
                                   dtype=np.int64), configs,
                          np.ascontiguousarray([contexts[i].positions[:, rows] for i in members],
                                               dtype=np.float64),
                          np.ascontiguousarray([contexts[i].std[:, rows] for i in members],
                                               dtype=np.float64),
                          self.samples.z, self.samples.weight, reach, self._rows, self._tr,
                          self.sigma_min_threshold, len(self.threshold_rows) <= n, segs)
            w = prediction_weights(kk)
            for i, seg in zip(members, segs, strict=True):
                out[i] = float((w * seg).sum() / w.sum())
        return [float(v) for v in out]  # type: ignore[arg-type]  # every slot filled


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
