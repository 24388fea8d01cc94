"""Θ along the seed's Fig. 3.11 trajectory on the RX60B model: a vertical line with the
flange orientation held (15° below horizontal, pointing away from the base). Going up, the
arm leaves the wrist-alignment singularity (the seed's "joints 3 and 5", 0-based joints 4
and 6 aligned as θ5 -> 0) and ends at the boundary singularity (arm stretched, θ3 -> the
straight-arm value): Θ is 0 at both ends, clearly positive in between, and its dips are
where σ_min of the Jacobian dips."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from vasim.mrcp import backend, dh
from vasim.mrcp.indices import EvalContext
from vasim.mrcp.indices.dexterity import AnisotropicDexterityIndex
from vasim.mrcp.scenarios.base import gripper_frame

TILT = np.radians(15.0)
ROT = gripper_frame(np.array([np.cos(TILT), 0.0, -np.sin(TILT)]), np.array([0.0, 0.0, 1.0]))
X, Y = 0.4, 0.049                      # the vertical line (base frame, shoulder at z = 0)


@pytest.fixture(scope="module")
def arm() -> Iterator[Any]:
    a = backend.PybulletArm(dh.load_robot("rx60b"))
    yield a
    a.close()


def theta(arm: Any, q: np.ndarray, direction: np.ndarray) -> float:
    """Θ for the TCP moving 10 mm per predicted point along ``direction`` with the
    orientation held (σ_min threshold 0.05 on the 6 x 6 Jacobian)."""
    p0, _ = arm.tcp_pose(q)
    pos = p0[None, :] + 0.01 * np.arange(4)[:, None] * direction[None, :]
    configs = np.full((4, 6), np.nan)
    reach = np.zeros(4, dtype=bool)
    configs[0], reach[0], seed = q, True, q
    for k in range(1, 4):
        sol = arm.ik(pos[k], ROT, seed)
        if sol is not None:
            configs[k], reach[k], seed = sol, True, sol
    std = np.full((4, 3), 0.002)
    std[0] = 0.0
    ctx = EvalContext(robot="rx60b", arm=arm, point=0, selected=True,
                      times=0.05 * np.arange(4), positions=pos, std=std,
                      rotations=np.repeat(ROT[None], 4, axis=0), configs=configs,
                      reachable=reach, joint_velocity=np.zeros_like(configs), past_configs=[],
                      world=None)  # type: ignore[arg-type]  # Θ needs no world
    return AnisotropicDexterityIndex(sigma_min_threshold=0.05).evaluate(ctx)


def test_theta_along_the_vertical_trajectory_of_fig_3_11(arm: Any) -> None:
    up = np.array([0.0, 0.0, 1.0])
    q = arm.home.copy()
    zs, qs = [], []
    for z in np.arange(0.0, 0.7, 0.025):
        sol = arm.ik(np.array([X, Y, z]), ROT, q)
        if sol is None:
            if qs:
                break                       # past the boundary
            continue                        # below: the wrist would need θ5 < its limit
        q = sol
        zs.append(z)
        qs.append(q)
    assert len(qs) >= 8, f"the vertical line is reachable over {len(qs)} samples only"
    th = np.array([theta(arm, q, up) for q in qs])
    smin = np.array([np.linalg.svd(arm.jacobian(q), compute_uv=False)[-1] for q in qs])
    # Bottom: the wrist alignment (θ5 near its 0.09 rad limit, joints 4 and 6 aligned).
    assert qs[0][4] < 0.2 and th[0] == 0.0
    # Top: the boundary singularity (θ3 near the straight arm at 90 deg = 1.571 rad).
    assert qs[-1][2] < 1.9 and th[-1] == 0.0
    # In between the robot is dexterous, most where the Jacobian is best conditioned.
    mid = th[len(th) // 2]
    assert mid > 0.2
    assert int(np.argmax(smin)) not in (0, len(qs) - 1)
    assert smin[0] < 0.5 * smin.max() and smin[-1] < 0.5 * smin.max()
    # Sideways (y) is dexterous in the middle too, and is lost at both singularities.
    side = [theta(arm, qs[k], np.array([0.0, 1.0, 0.0])) for k in (0, len(qs) // 2, -1)]
    assert side[0] == 0.0 and side[1] > 0.2 and side[2] == 0.0
