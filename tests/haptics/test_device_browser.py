"""Tests of browser input (vasim/haptics/devices/browser.py): linear interpolation between
samples, dropped out-of-order/duplicate samples, bounded extrapolation, clock mapping."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.core.errors import ConfigError, DeviceError
from vasim.haptics.devices.browser import (
    BROWSER_LIMITS,
    BROWSER_WORKSPACE_HALF_M,
    BrowserDevice,
    interpolate_stream,
)
from vasim.haptics.servo import ServoLoop
from vasim.trials.realtime import RealtimeTrial
from vasim.trials.vf import TrialConfig


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_linear_between_samples() -> None:
    times = [0.0, 0.02, 0.05]
    pos = [[0.0, 0.0, 0.0], [0.02, -0.01, 0.0], [0.02, 0.02, 0.03]]
    for t in np.linspace(0.0, 0.05, 51):
        x, mode = interpolate_stream(times, pos, float(t), 1 / 30)
        j = 1 if t >= 0.02 else 0
        u = (t - times[j]) / (times[j + 1] - times[j])
        expect = (1 - u) * np.array(pos[j]) + u * np.array(pos[j + 1])
        np.testing.assert_allclose(x, expect, atol=1e-15)
        assert mode in ("interpolate", "before", "hold")


def test_modes_at_the_ends() -> None:
    assert interpolate_stream([], [], 0.0, 0.03) == (None, "empty")
    assert interpolate_stream([1.0], [[1, 2, 3]], 5.0, 0.03) == ((1.0, 2.0, 3.0), "hold")
    assert interpolate_stream([1.0, 2.0], [[0, 0, 0], [1, 0, 0]], 0.5, 0.03)[1] == "before"


def test_extrapolation_is_bounded_by_time_and_by_one_step() -> None:
    times, pos = [0.0, 0.02], [[0.0, 0.0, 0.0], [0.01, 0.0, 0.0]]  # 0.5 m/s
    x, mode = interpolate_stream(times, pos, 0.03, 1.0)            # 10 ms late: half a step
    assert mode == "extrapolate" and x[0] == pytest.approx(0.015)
    x, _ = interpolate_stream(times, pos, 0.5, 1.0)                 # very late: one step at most
    assert x[0] == pytest.approx(0.02)
    x, _ = interpolate_stream(times, pos, 0.5, 0.004)               # horizon h = 4 ms
    assert x[0] == pytest.approx(0.012)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.floats(0.001, 0.1), st.floats(-0.1, 0.1)), min_size=2,
                max_size=20), st.floats(0.0, 3.0), st.floats(0.0, 0.1))
def test_never_overshoots_wildly(steps: list, frac: float, horizon: float) -> None:
    """Any jittery stream: inside it, the output lies between the bracketing samples;
    past it, within one last step of the newest sample."""
    times = list(np.cumsum([dt for dt, _ in steps]))
    xs = list(np.cumsum([dx for _, dx in steps]))
    pos = [[x, 0.0, 0.0] for x in xs]
    t = times[0] + frac * (times[-1] - times[0]) * 1.5
    x, _ = interpolate_stream(times, pos, t, horizon)
    if t <= times[-1]:
        j = max(1, int(np.searchsorted(times, t)))
        lo, hi = sorted((xs[j - 1], xs[j]))
        assert lo - 1e-12 <= x[0] <= hi + 1e-12
    else:
        assert abs(x[0] - xs[-1]) <= abs(xs[-1] - xs[-2]) + 1e-12


def test_out_of_order_and_duplicates_are_dropped() -> None:
    clock = Clock()
    dev = BrowserDevice(delay_s=0.0, clock=clock)
    dev.start()
    assert dev.push(0.0, [0.0, 0.0, 0.0])
    clock.now = 0.033
    assert dev.push(0.033, [0.033, 0.0, 0.0])
    assert not dev.push(0.033, [5.0, 5.0, 5.0])    # duplicate
    assert not dev.push(0.010, [5.0, 5.0, 5.0])    # out of order (late)
    assert not dev.push(0.050, [math.nan, 0.0, 0.0])  # non-finite never enters
    assert dev.accepted == 2 and dev.dropped == 3
    clock.now = 0.0165
    assert dev.read().position[0] == pytest.approx(0.0165)


def test_fixed_delay_and_clock_offset() -> None:
    # Browser clock = local clock + 100 s; samples arrive 5-25 ms late. The least-delayed
    # sample fixes the offset; the output is the stream 40 ms ago, interpolated.
    clock = Clock()
    dev = BrowserDevice(clock=clock)  # delay 40 ms
    dev.start()
    rng = np.random.default_rng(0)
    t_browser = 100.0
    samples = []
    for _ in range(30):
        samples.append((t_browser, t_browser - 100.0))
        t_browser += 1 / 30
    for tb, t_local in samples:
        lat = 0.005 if tb == samples[0][0] else rng.uniform(0.005, 0.025)
        clock.now = t_local + lat
        dev.push(tb, [tb - 100.0, 0.0, 0.0])  # position = local time of the sample
        s = dev.read()
        assert s.valid and dev.last_mode in ("interpolate", "extrapolate", "before")
        if dev.last_mode == "interpolate":
            assert s.position[0] == pytest.approx(clock.now - 0.040 - 0.005, abs=1e-9)


def test_invalid_before_the_first_sample_then_holds() -> None:
    clock = Clock()
    dev = BrowserDevice(clock=clock, delay_s=0.01)
    dev.start()
    assert not dev.read().valid
    dev.push(0.0, [0.01, 0.02, 0.03], buttons=2)
    clock.now = 10.0  # the user paused: hold the last position, keep it valid
    s = dev.read()
    assert s.valid and s.position.tolist() == [0.01, 0.02, 0.03] and s.buttons == 2


def test_in_the_servo_loop_a_browser_renders_no_force() -> None:
    clock = Clock()
    dev = BrowserDevice(clock=clock, delay_s=0.0)

    class Push:
        def on_start(self, t: float) -> None:
            pass

        def tick(self, t: float, master: np.ndarray, buttons: int) -> np.ndarray:
            return np.array([1.0, 0.0, 0.0])

        def on_stop(self) -> None:
            pass

    loop = ServoLoop(dev, Push(), home=[0.0, 0.0, 0.0])
    loop.run_ticks(3)  # no sample yet: invalid, held at home
    assert loop.guard.counts["invalid_sample"] == 3
    dev.push(0.0, [0.1, 0.0, 0.0])
    loop.run_ticks(3)
    loop.stop()
    assert dev.last_force.tolist() == [0.0, 0.0, 0.0]
    assert loop.latest.master == (0.0, 0.0, 0.0)  # first sample indexed onto home


def test_bad_configuration() -> None:
    with pytest.raises(ConfigError, match="delay_s"):
        BrowserDevice(delay_s=-0.1)
    with pytest.raises(ConfigError, match="history"):
        BrowserDevice(history=1)
    with pytest.raises(DeviceError, match="before start"):
        BrowserDevice().read()
    with pytest.raises(ValueError, match="3 coordinates"):
        BrowserDevice().push(0.0, [1.0, 2.0])


# -- Workspace box: huge but finite browser coordinates (1e200) passed the NaN guard and
# reached the physics; the device clamps to a finite box (BROWSER_WORKSPACE_HALF_M) around the
# scene origin.
H = BROWSER_WORKSPACE_HALF_M


def test_the_browser_workspace_is_a_finite_box_around_the_scene() -> None:
    assert BROWSER_LIMITS.workspace_min == (-H, -H, -H)
    assert BROWSER_LIMITS.workspace_max == (H, H, H)
    # The default abdomen (about x +-0.15, y -0.12..0.18, z 0..0.16 m) lies well inside.
    assert BROWSER_LIMITS.contains([0.15, 0.18, 0.16])
    assert BROWSER_LIMITS.contains([-0.15, -0.12, 0.0])


def test_huge_finite_samples_are_clamped_to_the_box() -> None:
    now = [0.0]
    dev = BrowserDevice(delay_s=0.0, clock=lambda: now[0])
    dev.start()
    assert dev.push(0.0, [1e200, -1e200, 0.1], arrival=0.0)
    s = dev.read()
    assert s.valid
    np.testing.assert_array_equal(s.position, [H, -H, 0.1])
    assert dev.accepted == 1 and dev.dropped == 0


def test_extrapolation_never_leaves_the_box() -> None:
    now = [0.0]
    dev = BrowserDevice(delay_s=0.0, max_extrapolation_s=1.0, clock=lambda: now[0])
    dev.start()
    dev.push(0.0, [0.6 * H, 0.0, 0.0], arrival=0.0)
    dev.push(0.1, [0.98 * H, 0.0, 0.0], arrival=0.1)
    now[0] = 0.2  # one full step past the newest sample: 1.36 H unclamped
    s = dev.read()
    assert dev.last_mode == "extrapolate"
    assert s.position[0] == H


def test_a_huge_gizmo_position_keeps_the_trial_finite() -> None:
    """The reviewer's big.py: a 1e200 sample in a live trajectory trial with physics."""
    now = [0.0]
    dev = BrowserDevice(clock=lambda: now[0])
    trial = RealtimeTrial(TrialConfig(schema="trajectory_following", max_time=2.0), dev,
                          physics="inline")
    dev.start()
    dev.push(0.0, [0.0, 0.0, 0.0], arrival=0.0)
    try:
        for k in range(300):
            now[0] = k * 1e-3
            if k == 100:
                dev.push(0.1, [1e200, 0.0, 0.0], arrival=0.1)
            if k == 101:
                dev.push(0.101, [1e200, 0.0, 0.0], arrival=0.101)
            trial.run_ticks(1)
        tcp = np.asarray(trial.frame().tcp)
        assert np.isfinite(tcp).all() and np.abs(tcp).max() <= H + 1e-9
        assert trial.error is None
    finally:
        trial.stop()
    summary = trial.result().summary
    assert math.isfinite(summary["total_path_l2"])
    assert summary["total_path_l2"] < 2 * math.sqrt(3) * 2 * H
