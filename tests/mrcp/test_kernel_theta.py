"""The compiled Θ against an independent, vectorised numpy implementation of the same
definition (random planar trajectories with uncertainty, both threshold choices)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.mrcp.planar import PlanarArm, PlanarWorld, make_context
from vasim.mrcp.indices import EvalContext
from vasim.mrcp.indices.base import prediction_weights
from vasim.mrcp.indices.dexterity import AnisotropicDexterityIndex, jacobians
from vasim.mrcp.indices.measures import directional_manipulability_svd, sigma_min


def _pad(sig: np.ndarray, m: int) -> np.ndarray:
    out = np.zeros((*sig.shape[:-1], m))
    out[..., : sig.shape[-1]] = sig
    return out


def theta_numpy(ix: AnisotropicDexterityIndex, ctx: EvalContext) -> float:
    """Θ written with numpy broadcasting over all segments (SVD-based ψ and pinv)."""
    reach, kk = ctx.reachable, ctx.horizon
    if not reach[0] or kk < 1:
        return 0.0
    rows, tr = list(ix.rows), list(ix.threshold_rows)
    m, n = len(rows), ctx.arm.n_joints
    z, dens = ix.samples.z, ix.samples.weight
    s_count = z.shape[0]
    pos = ctx.positions[:, rows]
    configs = np.where(reach[:, None], ctx.configs, ctx.configs[0][None, :])
    full = jacobians(ctx.arm, configs)
    pinv = np.linalg.pinv(full[:, rows, :])
    delta = ctx.std[1:, None, :][..., rows] * z[None]
    samp = pos[1:, None, :] + delta
    q_samp = configs[1:, None, :] + np.einsum("kij,ksj->ksi", pinv[1:], delta)
    full_s = jacobians(ctx.arm, q_samp.reshape(-1, n))
    u_pts, s_pts, _ = np.linalg.svd(full[:, rows, :])
    u_s, s_s, _ = np.linalg.svd(full_s[:, rows, :].reshape(kk, s_count, m, n))
    sig_s = _pad(s_s, m)
    smin_all = sigma_min(np.concatenate([full[:1, tr, :], full_s[:, tr, :]]))
    thr = ix.sigma_min_threshold
    ok = (smin_all[1:].reshape(kk, s_count) >= thr) & reach[1:, None]
    sig0 = _pad(s_pts[0], m)
    org = np.concatenate([np.repeat(pos[None, :1, :], s_count, axis=1), samp[:-1]])
    org_u = np.concatenate([np.repeat(u_pts[None, :1], s_count, axis=1), u_s[:-1]])
    org_sig = np.concatenate([np.repeat(sig0[None, None, :], s_count, axis=1), sig_s[:-1]])
    org_ok = np.concatenate([np.full((1, s_count), smin_all[0] >= thr), ok[:-1]])
    diff = samp[:, None, :, :] - org[:, :, None, :]
    norm = np.linalg.norm(diff, axis=-1)
    moving = norm > 1e-9
    u = diff / np.where(moving, norm, 1.0)[..., None]
    psi = directional_manipulability_svd(org_u, org_sig, u)
    psi = np.where(moving, psi, (np.prod(org_sig, axis=-1) ** (1.0 / m))[..., None])
    per_origin = np.einsum("kab,kb->ka", psi, dens[None, :] * ok) / dens.sum()
    seg = np.einsum("ka,ka->k", per_origin, dens[None, :] * org_ok) / dens.sum()
    seg = np.where(reach[:-1] & reach[1:], seg, 0.0)
    w = prediction_weights(kk)
    return float((w * seg).sum() / w.sum())


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("threshold_rows", [(0, 1, 2), (0, 1, 2, 3, 4, 5)])
@pytest.mark.parametrize("threshold", [0.05, 0.2])     # 0.2: some samples are zeroed
def test_compiled_theta_equals_numpy(seed: int, threshold_rows: tuple[int, ...],
                                     threshold: float) -> None:
    rng = np.random.default_rng(seed)
    arm = PlanarArm("a")
    q = np.array([rng.uniform(-2, 2), rng.uniform(0.2, 2.5), rng.uniform(-0.1, 0.1)])
    world = PlanarWorld({"a": arm}, {"a": q})
    p0, _ = arm.tcp_pose(q)
    direction = rng.standard_normal(3)
    direction /= np.linalg.norm(direction)
    pos = p0[None, :] + 0.01 * np.arange(4)[:, None] * direction[None, :]
    std = np.abs(rng.normal(0.003, 0.001, (4, 3)))
    std[0] = 0.0
    ctx = make_context(arm, world, pos, std=std, seed=q)
    ix = AnisotropicDexterityIndex(threshold_rows=threshold_rows, sigma_min_threshold=threshold)
    assert ix.evaluate(ctx) == pytest.approx(theta_numpy(ix, ctx), rel=1e-8, abs=1e-12)
