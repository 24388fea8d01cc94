"""The compiled RJ and tool-cone evaluations against the numpy pure functions."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.mrcp.planar import PlanarArm, PlanarWorld, make_context
from vasim.mrcp.indices.base import prediction_weights
from vasim.mrcp.indices.cone import ConeSector, ToolCone, ToolConeIndex
from vasim.mrcp.indices.joint_limits import (
    JointLimitIndex,
    jeval,
    modulation_b,
    prediction_errors,
    rj_trajectory,
)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 100_000), st.booleans())
def test_compiled_rj_equals_numpy(seed: int, drop_one: bool) -> None:
    rng = np.random.default_rng(seed)
    arm = PlanarArm("a", lower=np.array([-2.0, 0.1, -0.2]), upper=np.array([2.0, 2.8, 0.2]))
    world = PlanarWorld({"a": arm}, {"a": np.array([0.0, 1.0, 0.0])})
    q = rng.uniform(arm.lower, arm.upper)
    p0, _ = arm.tcp_pose(q)
    pos = p0[None, :] + rng.normal(0.0, 0.03, 3)[None, :] * np.arange(4)[:, None]
    past = [rng.uniform(arm.lower, arm.upper, (4, 3)) for _ in range(3)]
    ctx = make_context(arm, world, pos, seed=q, past=past)
    if drop_one and ctx.reachable[0]:
        ctx.reachable[2] = False
    ix = JointLimitIndex(b_min=1.5, b_max=5.0)
    if not ctx.reachable[0]:
        assert ix.evaluate(ctx) == 0.0
        return
    configs = np.where(ctx.reachable[:, None], ctx.configs, ctx.configs[0][None, :])
    b = modulation_b(configs, ctx.joint_velocity, arm.lower, arm.upper, arm.vmax, 1.5, 5.0)
    ref = rj_trajectory(configs, ctx.reachable, arm.lower, arm.upper, b,
                        prediction_errors(configs, past))
    assert ix.evaluate(ctx) == pytest.approx(ref, abs=1e-12)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 100_000))
def test_compiled_cone_equals_numpy(seed: int) -> None:
    rng = np.random.default_rng(seed)
    normal = rng.standard_normal(3)
    cone = ToolCone(rng.normal(0.0, 0.1, 3), normal, rng.standard_normal(3),
                    (ConeSector(0.0, 2.0, 0.8, 1.0), ConeSector(2.0, 2 * np.pi, 0.6, 0.9)))
    arm = PlanarArm("a")
    world = PlanarWorld({"a": arm}, {"a": np.array([0.0, 1.0, 0.0])})
    tips = cone.fulcrum[None, :] + 0.1 * (normal / np.linalg.norm(normal))[None, :] \
        + rng.normal(0.0, 0.06, (4, 3))
    ctx = make_context(arm, world, tips)
    reach = rng.random(4) > 0.3
    ctx.reachable[:] = reach
    w = prediction_weights(4)
    ref = float((w * np.where(reach, jeval(cone.margins(tips), 2.0), 0.0)).sum() / w.sum())
    assert ToolConeIndex({"a": cone}, b=2.0).evaluate(ctx) == pytest.approx(ref, abs=1e-12)


def test_uncovered_azimuth_is_named() -> None:
    cone = ToolCone(np.zeros(3), np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0]),
                    (ConeSector(0.0, np.pi, 0.8, 1.0),))
    arm = PlanarArm("a")
    world = PlanarWorld({"a": arm}, {"a": np.array([0.0, 1.0, 0.0])})
    # y = normal x x_axis = (0, -1, 0): this tip lies at azimuth 3π/2, outside [0, π).
    ctx = make_context(arm, world, np.array([[0.0, 0.05, -0.1]] * 2))
    ctx.reachable[:] = True
    with pytest.raises(ValueError, match="not covered"):
        ToolConeIndex({"a": cone}).evaluate(ctx)
