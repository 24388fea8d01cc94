"""The controller emulator: limits never exceeded whatever the commands, and the motion
profile of a bang-bang joint (closed-form times)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.core.errors import ConfigError
from vasim.mrcp.backend import PybulletArm
from vasim.mrcp.controller import (
    DEFAULT_CYCLE,
    EmulatedController,
    JointLimits,
    RobotDriver,
    limited_step,
    stopping_speed,
)
from vasim.mrcp.dh import load_robot

RX = load_robot("rx60b")
LIMITS = JointLimits(RX.lower, RX.upper, RX.max_velocity, RX.max_acceleration)
DT = DEFAULT_CYCLE


def test_default_cycle_is_the_seeds_18_ms_and_the_driver_seam_holds() -> None:
    ctrl = EmulatedController(PybulletArm(RX))
    assert ctrl.cycle_time == 0.018
    assert isinstance(ctrl, RobotDriver)
    np.testing.assert_array_equal(ctrl.read_state().q, RX.home)


def test_stopping_speed_brakes_exactly_within_the_distance() -> None:
    # from v = n a dt, braking by a dt per cycle covers a dt^2 n (n + 1) / 2
    a = np.array([20.0])
    for n in range(0, 12):
        dist = a * DT**2 * n * (n + 1) / 2
        np.testing.assert_allclose(stopping_speed(dist, a, DT), n * a * DT, rtol=1e-12)


targets = st.lists(st.lists(st.floats(-5.0, 5.0), min_size=6, max_size=6),
                   min_size=1, max_size=8)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(0, 1), min_size=6, max_size=6), targets,
       st.integers(1, 40))
def test_limits_are_never_exceeded(start: list[float], cmds: list[list[float]],
                                   hold: int) -> None:
    q = RX.lower + np.array(start) * (RX.upper - RX.lower)
    qd = np.zeros(6)
    for cmd in cmds:
        for _ in range(hold):
            q_next, qd_next, tgt = limited_step(q, qd, np.array(cmd), LIMITS, DT)
            assert np.all(q_next >= RX.lower) and np.all(q_next <= RX.upper)
            assert np.all(np.abs(qd_next) <= RX.max_velocity * (1 + 1e-12))
            assert np.all(np.abs(qd_next - qd) <= RX.max_acceleration * DT * (1 + 1e-9))
            np.testing.assert_allclose(q_next, q + qd_next * DT, atol=1e-12)
            assert np.all(tgt >= RX.lower) and np.all(tgt <= RX.upper)
            q, qd = q_next, qd_next


def _time_to_reach(distance: float, vmax: float, amax: float) -> float:
    lim = JointLimits(np.array([-10.0]), np.array([10.0]), np.array([vmax]), np.array([amax]))
    q, qd = np.zeros(1), np.zeros(1)
    for k in range(1, 10_000):
        q, qd, _ = limited_step(q, qd, np.array([distance]), lim, DT)
        assert q[0] <= distance + 1e-12          # no overshoot
        if abs(q[0] - distance) < 1e-12 and qd[0] == 0.0:
            return k * DT
    raise AssertionError("never settled")


@pytest.mark.parametrize(("distance", "vmax", "amax"), [
    (2.0, 5.0, 20.0),      # trapezoid: cruise at vmax
    (3.0, 5.5676, 22.27),  # RX60B joint 3
    (0.2, 5.0, 20.0),      # triangle: never reaches vmax
])
def test_motion_time_matches_the_bang_bang_closed_form(distance: float, vmax: float,
                                                       amax: float) -> None:
    if distance >= vmax**2 / amax:
        expect = distance / vmax + vmax / amax
    else:
        expect = 2.0 * math.sqrt(distance / amax)
    # the discrete profile quantises the accelerating and braking phases to whole cycles
    assert _time_to_reach(distance, vmax, amax) == pytest.approx(expect, abs=3 * DT)


def test_out_of_range_targets_are_clamped_and_reported() -> None:
    ctrl = EmulatedController(PybulletArm(RX))
    target = RX.home.copy()
    target[4] = 3.0                            # beyond joint 5's 2.01
    ctrl.send_target(target)
    for _ in range(200):
        state = ctrl.sync()
    assert state.clamped.tolist() == [False, False, False, False, True, False]
    assert state.q[4] == pytest.approx(RX.upper[4], abs=1e-12)
    assert state.t == pytest.approx(200 * DT)


def test_reversing_at_full_speed_respects_the_limits() -> None:
    # run joint 1 toward its upper limit at full speed, then command the lower limit
    ctrl = EmulatedController(PybulletArm(RX), q0=np.where(np.arange(6) == 0, -2.0, RX.home))
    ctrl.send_target(np.where(np.arange(6) == 0, 2.79, RX.home))
    speeds = [ctrl.sync().qd[0] for _ in range(40)]
    assert max(speeds) == pytest.approx(RX.max_velocity[0])
    ctrl.send_target(np.where(np.arange(6) == 0, -2.79, RX.home))
    prev = ctrl.read_state()
    for _ in range(200):
        s = ctrl.sync()
        assert abs(s.qd[0] - prev.qd[0]) <= RX.max_acceleration[0] * DT * (1 + 1e-9)
        assert RX.lower[0] <= s.q[0] <= RX.upper[0]
        prev = s


def test_bad_commands_and_settings_are_refused() -> None:
    arm = PybulletArm(RX)
    ctrl = EmulatedController(arm)
    with pytest.raises(ValueError, match="finite"):
        ctrl.send_target(np.full(6, np.nan))
    with pytest.raises(ValueError, match="6 finite"):
        ctrl.send_target(np.zeros(5))
    with pytest.raises(ConfigError, match="cycle"):
        EmulatedController(arm, cycle=0.0)
    with pytest.raises(ConfigError, match="q0"):
        EmulatedController(arm, q0=np.zeros(6))      # joint 3 below 1.66
    with pytest.raises(ConfigError, match="max_velocity"):
        JointLimits(RX.lower, RX.upper, -RX.max_velocity, RX.max_acceleration)
