"""Θ on the Stäubli RX60B model of ``vasim.mrcp.backend`` (seed Fig. 3.11): it drops at the
workspace boundary (arm stretched, joint 3 at its limit by the straight-arm singularity) in
the lost direction only, and at the wrist singularity (the seed's joint-3/5 alignment,
0-based: joints 4 and 6 aligned as θ5 -> 0)."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from vasim.mrcp import backend, dh
from vasim.mrcp.indices import EvalContext
from vasim.mrcp.indices.dexterity import AnisotropicDexterityIndex


@pytest.fixture(scope="module")
def arm() -> Iterator[Any]:
    a = backend.PybulletArm(dh.load_robot("rx60b"))
    yield a
    a.close()


def _theta(arm: Any, q: np.ndarray, direction: np.ndarray, step: float = 0.01,
           std: float = 0.002, **kw: Any) -> float:
    """Θ for the task point at the TCP moving ``step`` per predicted point along
    ``direction`` (IK seeded along the way; rotation free, as the seed's experiment)."""
    p0, _ = arm.tcp_pose(q)
    pos = p0[None, :] + step * np.arange(4)[:, None] * direction[None, :]
    configs = np.full((4, arm.n_joints), np.nan)
    reach = np.zeros(4, dtype=bool)
    configs[0], reach[0] = q, True
    seed = q
    for k in range(1, 4):
        sol = arm.ik(pos[k], None, seed)
        if sol is not None:
            configs[k], reach[k], seed = sol, True, sol
    stds = np.full((4, 3), std)
    stds[0] = 0.0
    ctx = EvalContext(robot=arm.name, arm=arm, point=0, selected=True,
                      times=0.05 * np.arange(4), positions=pos, std=stds, rotations=None,
                      configs=configs, reachable=reach, joint_velocity=np.zeros_like(configs),
                      past_configs=[], world=None)  # type: ignore[arg-type]  # Θ: no world
    return AnisotropicDexterityIndex(**kw).evaluate(ctx)


def _climb(arm: Any, dz: float) -> np.ndarray:
    """Configuration after lifting the TCP from home by ``dz`` (rotation free)."""
    q = arm.home.copy()
    p0, _ = arm.tcp_pose(q)
    for z in np.linspace(0.0, dz, round(dz / 0.025) + 1)[1:]:
        sol = arm.ik(p0 + np.array([0.0, 0.0, z]), None, q)
        assert sol is not None, f"lift {z:.3f} m unreachable"
        q = sol
    return q


def test_theta_drops_at_the_workspace_boundary_in_the_lost_direction(arm: Any) -> None:
    up, side = np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])
    home = arm.home.copy()
    stretched = _climb(arm, 0.35)            # joint 3 near its 1.66 rad limit (straight arm)
    assert stretched[2] < 1.75
    ratio_up = _theta(arm, stretched, up, step=0.005) / _theta(arm, home, up, step=0.005)
    ratio_side = _theta(arm, stretched, side, step=0.005) / _theta(arm, home, side, step=0.005)
    assert ratio_up < 0.3                     # moving on into the boundary: Θ collapses
    assert ratio_side > 2.0 * ratio_up        # anisotropic: sideways far less affected


def test_theta_zeroed_near_the_wrist_singularity(arm: Any) -> None:
    side = np.array([0.0, 1.0, 0.0])
    q_ok, q_wrist = arm.home.copy(), arm.home.copy()
    q_wrist[4] = 0.12                         # θ5 near 0: joints 4 and 6 almost aligned
    # Measured σ_min of the 6 x 6 Jacobian: 0.169 at home, 0.025 at θ5 = 0.12.
    kw = {"sigma_min_threshold": 0.05}
    assert _theta(arm, q_ok, side, **kw) > 0.1
    assert _theta(arm, q_wrist, side, **kw) == 0.0
    # The translation alone does not see the wrist singularity.
    assert _theta(arm, q_wrist, side, threshold_rows=(0, 1, 2), **kw) > 0.1
