"""Review fix: huge but finite browser coordinates (1e200) passed the NaN guard and reached
the physics (overflow, an infinite path length). The browser device now has a finite
workspace box (``BROWSER_WORKSPACE_HALF_M`` around the scene origin) and clamps to it."""

from __future__ import annotations

import math

import numpy as np

from vasim.haptics.devices.browser import (
    BROWSER_LIMITS,
    BROWSER_WORKSPACE_HALF_M,
    BrowserDevice,
)
from vasim.trials.realtime import RealtimeTrial
from vasim.trials.vf import TrialConfig

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
