"""The laparoscopic instrument: 4 DOF about its trocar, the fulcrum effect, the device."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from vasim.abdomen.anatomy import trocar_points
from vasim.core.errors import ConfigError, DeviceError
from vasim.haptics.devices.laparoscopic import LaparoscopicDevice
from vasim.haptics.laparoscopic import (
    Increment,
    InputMapping,
    InstrumentPose,
    Port,
    clamp,
    orientation,
    shaft_direction,
    tip_position,
)
from vasim.haptics.servo import ServoLoop

PORT = Port.toward(trocar_points()[1], (0.0, 0.03, 0.06))   # the right working port
angles = st.floats(-3.0, 3.0, allow_nan=False)
poses = st.builds(InstrumentPose, yaw=angles, pitch=angles,
                  insertion=st.floats(-1.0, 1.0, allow_nan=False), roll=st.floats(-20, 20))


def test_neutral_pose_points_along_the_axis() -> None:
    pose = InstrumentPose(insertion=0.1)
    np.testing.assert_allclose(tip_position(PORT, pose), PORT.fulcrum + 0.1 * PORT.axis,
                               atol=1e-12)
    # yaw alone turns the shaft in the port's x-z plane by exactly that angle.
    d = shaft_direction(PORT, InstrumentPose(yaw=0.3))
    assert math.isclose(float(d @ PORT.axis), math.cos(0.3), abs_tol=1e-12)
    assert math.isclose(float(d @ PORT.frame[:, 0]), math.sin(0.3), abs_tol=1e-12)


@settings(max_examples=200, deadline=None)
@given(poses)
def test_clamped_poses_respect_the_port(pose: InstrumentPose) -> None:
    c = clamp(PORT, pose)
    d = shaft_direction(PORT, c)
    assert math.isclose(float(np.linalg.norm(d)), 1.0, abs_tol=1e-12)
    assert math.acos(min(1.0, float(d @ PORT.axis))) <= PORT.max_angle_rad + 1e-9
    assert PORT.min_insertion_m <= c.insertion <= PORT.max_insertion_m
    assert -math.pi <= c.roll <= math.pi
    # The tip lies on the shaft line through the fulcrum, at the insertion depth.
    tip = tip_position(PORT, c)
    assert math.isclose(float(np.linalg.norm(tip - PORT.fulcrum)), c.insertion, rel_tol=1e-12)
    # Clamping is idempotent.
    c2 = clamp(PORT, c)
    np.testing.assert_allclose([c2.yaw, c2.pitch, c2.insertion, c2.roll],
                               [c.yaw, c.pitch, c.insertion, c.roll], atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(poses)
def test_orientation_z_axis_is_the_shaft_and_roll_turns_about_it(pose: InstrumentPose) -> None:
    c = clamp(PORT, pose)
    q = orientation(PORT, c)
    r = Rotation.from_quat([q[1], q[2], q[3], q[0]])
    np.testing.assert_allclose(r.apply([0, 0, 1]), shaft_direction(PORT, c), atol=1e-9)
    rolled = replace_roll(c, c.roll + 0.5)
    r2 = Rotation.from_quat(np.roll(orientation(PORT, rolled), -1))
    x1, x2 = r.apply([1, 0, 0]), r2.apply([1, 0, 0])
    assert math.isclose(float(x1 @ x2), math.cos(0.5), abs_tol=1e-9)


def replace_roll(pose: InstrumentPose, roll: float) -> InstrumentPose:
    return clamp(PORT, InstrumentPose(pose.yaw, pose.pitch, pose.insertion, roll))


SCREEN = (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))   # endoscope looking down


@pytest.mark.parametrize("fulcrum_effect, sign", [(True, -1.0), (False, 1.0)])
def test_fulcrum_effect_mirrors_the_hand(fulcrum_effect: bool, sign: float) -> None:
    mapping = InputMapping(fulcrum_effect=fulcrum_effect)
    start = InstrumentPose(insertion=0.1)
    tip0 = tip_position(PORT, start)
    right = mapping.apply(PORT, start, Increment(dx_px=40.0), SCREEN)
    down = mapping.apply(PORT, start, Increment(dy_px=40.0), SCREEN)
    d_right = tip_position(PORT, right) - tip0
    d_down = tip_position(PORT, down) - tip0
    # Hand right: the tip goes right without, left with the fulcrum effect (and the same
    # for down / up). 40 px at 1.5 mrad/px asks 0.06 rad along the screen axis; the shaft
    # turns by the part perpendicular to it, and the tip moves along a chord of the circle
    # of radius = insertion about the fulcrum.
    assert sign * d_right[0] > 0.003
    assert sign * d_down[1] < -0.003
    d = shaft_direction(PORT, start)
    for axis, moved in ((SCREEN[0], d_right), (SCREEN[1], d_down)):
        angle = 0.06 * math.sqrt(1.0 - float(axis @ d) ** 2)
        assert math.isclose(float(np.linalg.norm(moved)), 2 * 0.1 * math.sin(angle / 2),
                            rel_tol=1e-9)
    # Depth is unchanged by a lateral stroke; insertion needs the wheel or keys.
    assert math.isclose(right.insertion, 0.1, abs_tol=1e-12)


def test_insertion_roll_sensitivity_and_bad_input() -> None:
    m = InputMapping()
    start = InstrumentPose(insertion=0.1)
    assert math.isclose(m.apply(PORT, start, Increment(wheel=2.0)).insertion, 0.108)
    assert math.isclose(m.apply(PORT, start, Increment(insert_s=-0.2)).insertion, 0.09)
    assert math.isclose(m.apply(PORT, start, Increment(roll_s=0.5)).roll, math.radians(45))
    fast = InputMapping(sensitivity=2.0)
    assert math.isclose(fast.apply(PORT, start, Increment(wheel=2.0)).insertion, 0.116)
    assert m.apply(PORT, start, Increment(dx_px=math.nan)) == start
    assert m.apply(PORT, start, Increment(wheel=math.inf)) == start
    huge = m.apply(PORT, start, Increment(dx_px=1e300, wheel=1e300), SCREEN)
    assert huge.insertion <= PORT.max_insertion_m
    assert np.isfinite(tip_position(PORT, huge)).all()
    with pytest.raises(ConfigError, match="sensitivity"):
        InputMapping(sensitivity=100.0)
    with pytest.raises(ConfigError, match="axis"):
        Port(fulcrum=(0, 0, 0), axis=(0, 0, 0))
    with pytest.raises(ConfigError, match="fulcrum"):
        Port(fulcrum=(1e200, 0, 0), axis=(0, 0, 1))


def test_device_smooths_toward_the_target_and_drops_non_finite_batches() -> None:
    now = [0.0]
    dev = LaparoscopicDevice(PORT, start=InstrumentPose(insertion=0.1), clock=lambda: now[0])
    with pytest.raises(DeviceError, match="before start"):
        dev.read()
    dev.start()
    dev.set_screen(*SCREEN)
    tip0 = dev.read().position
    assert dev.push(Increment(dx_px=50.0), buttons=1)
    target = tip_position(PORT, dev.target)
    now[0] = 0.015                                      # one time constant
    mid = dev.read().position
    frac = float(np.linalg.norm(mid - tip0) / np.linalg.norm(target - tip0))
    assert math.isclose(frac, 1 - math.exp(-1), abs_tol=0.02)
    now[0] = 0.2
    np.testing.assert_allclose(dev.read().position, target, atol=1e-6)
    assert dev.read().buttons == 1
    assert not dev.push(Increment(dy_px=math.nan))
    assert dev.dropped == 1 and dev.pushed == 1
    assert dev.limits.max_force_n == 0.0


def test_device_runs_in_the_servo_loop() -> None:
    dev = LaparoscopicDevice(PORT, start=InstrumentPose(insertion=0.1))

    class Hold:
        def on_start(self, t: float) -> None:
            pass

        def tick(self, t: float, master: np.ndarray, buttons: int) -> np.ndarray:
            return np.zeros(3)

        def on_stop(self) -> None:
            pass

    dev.start()
    dev.push(Increment(wheel=3.0))
    loop = ServoLoop(dev, Hold(), record=True)
    loop.run_ticks(50)
    loop.stop()
    assert loop.guard.counts.get("invalid_sample", 0) == 0
    assert np.isfinite(np.asarray(loop.latest.master)).all()
