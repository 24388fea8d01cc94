"""Laparoscopic tools through a fulcrum: the shaft always passes through the trocar, the tip
lands on the target, and the tip Jacobian is the mount's shifted along the shaft."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.mrcp import dh
from vasim.mrcp.backend import PybulletArm
from vasim.mrcp.fulcrum import (
    Fulcrum,
    LaparoscopicArm,
    LaparoscopicTool,
    endoscope_view,
    fulcrum_offset,
    polar_azimuth,
    tool_pose_through_fulcrum,
)
from vasim.mrcp.interfaces import ArmKinematics

RX = dh.load_robot("rx60b")
TOOL = LaparoscopicTool(length=0.30)
# at home the flange points straight down from (0.31, 0.049, 0.225): a trocar 0.2 m below
# the flange puts the tip 0.1 m inside the body
WALL = Fulcrum(point=np.array([0.31, 0.049, 0.025]), normal=np.array([0.0, 0.0, 1.0]))

offsets = st.tuples(st.floats(-0.05, 0.05), st.floats(-0.05, 0.05), st.floats(-0.2, -0.01))


@settings(max_examples=60, deadline=None)
@given(offsets)
def test_the_shaft_passes_through_the_fulcrum_and_reaches_the_tip(d: tuple) -> None:
    tip = WALL.point + np.array(d)
    pose = tool_pose_through_fulcrum(tip, WALL, TOOL)
    assert fulcrum_offset(pose.mount, pose.rotation, WALL.point) < 1e-12
    np.testing.assert_allclose(pose.mount + TOOL.length * pose.rotation[:, 2], tip,
                               atol=1e-12)
    assert pose.insertion == pytest.approx(np.linalg.norm(np.array(d)), abs=1e-12)
    np.testing.assert_allclose(pose.rotation.T @ pose.rotation, np.eye(3), atol=1e-12)
    assert np.linalg.det(pose.rotation) == pytest.approx(1.0)


def test_impossible_tips_are_refused() -> None:
    with pytest.raises(ValueError, match="not inside the body"):
        tool_pose_through_fulcrum(WALL.point + np.array([0, 0, 0.05]), WALL, TOOL)
    with pytest.raises(ValueError, match="reaches"):
        tool_pose_through_fulcrum(WALL.point - [0, 0, 0.26], WALL, TOOL)   # > 0.25 m
    with pytest.raises(ValueError, match="at the fulcrum"):
        tool_pose_through_fulcrum(WALL.point, WALL, TOOL)


def test_polar_angle_and_azimuth() -> None:
    assert polar_azimuth(np.array([0.0, 0.0, -1.0]), WALL)[0] == pytest.approx(0.0)
    alpha, theta = polar_azimuth(np.array([0.0, math.sin(0.3), -math.cos(0.3)]), WALL)
    assert alpha == pytest.approx(0.3)
    assert theta == pytest.approx(math.pi / 2)


@pytest.fixture(scope="module")
def lap() -> LaparoscopicArm:
    return LaparoscopicArm(PybulletArm(RX), TOOL, WALL)


def test_laparoscopic_arm_is_an_arm_whose_tcp_is_the_tip(lap: LaparoscopicArm) -> None:
    assert isinstance(lap, ArmKinematics)
    tip, _ = lap.tcp_pose(RX.home)
    np.testing.assert_allclose(tip, [0.31, 0.049, 0.225 - 0.30], atol=1e-12)
    assert lap.fulcrum_error(RX.home) < 1e-12
    assert lap.insertion(RX.home) == pytest.approx(0.10)


def test_tip_ik_keeps_the_fulcrum(lap: LaparoscopicArm) -> None:
    rng = np.random.default_rng(2)
    q = RX.home
    for _ in range(15):      # a wandering tip, tracked from the previous solution
        target = WALL.point + np.array([*rng.uniform(-0.04, 0.04, 2), -rng.uniform(0.05, 0.15)])
        sol = lap.ik(target, q_seed=q)
        assert sol is not None
        assert RX.within_limits(sol)
        np.testing.assert_allclose(lap.tcp_pose(sol)[0], target, atol=1e-6)
        assert lap.fulcrum_error(sol) < 1e-6
        q = sol


def test_tip_ik_returns_none_when_it_must(lap: LaparoscopicArm) -> None:
    assert lap.ik(WALL.point + np.array([0.0, 0.0, 0.05])) is None      # outside the body
    assert lap.ik(WALL.point + np.array([0.0, 0.0, -0.3])) is None      # beyond the tool
    tilted = dh.rot_x(0.5)                                                # not the shaft axis
    assert lap.ik(WALL.point + np.array([0.0, 0.0, -0.1]), tilted) is None


def test_tip_jacobian_matches_finite_differences(lap: LaparoscopicArm) -> None:
    q = RX.home + np.array([0.1, -0.2, 0.15, 0.3, -0.25, 0.2])
    jac = lap.jacobian(q)
    h = 1e-6
    for i in range(6):
        dq = np.zeros(6)
        dq[i] = h
        num = (lap.tcp_pose(q + dq)[0] - lap.tcp_pose(q - dq)[0]) / (2 * h)
        np.testing.assert_allclose(jac[:3, i], num, atol=1e-7)


def test_endoscope_view_tilts_toward_the_tool_x_axis() -> None:
    pose = tool_pose_through_fulcrum(WALL.point + np.array([0.02, 0.0, -0.1]), WALL, TOOL)
    np.testing.assert_allclose(endoscope_view(pose.rotation), pose.rotation[:, 2])
    view = endoscope_view(pose.rotation, math.radians(30))
    assert math.degrees(math.acos(view @ pose.rotation[:, 2])) == pytest.approx(30.0)
    assert view @ pose.rotation[:, 1] == pytest.approx(0.0, abs=1e-12)
