"""Tests of the emulated Omni (vasim/haptics/devices/emulator.py): dynamics against closed
form, the peak and continuous (thermal) force limits, quantisation and end stops."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.core.errors import ConfigError, DeviceError
from vasim.haptics.device import OMNI_LIMITS
from vasim.haptics.devices.emulator import EmulatorDevice, EmulatorParams, zoh_matrices

EXACT = dataclasses.replace(OMNI_LIMITS, position_resolution_m=0.0)
DT = 1e-3


def _run(dev: EmulatorDevice, n: int, force: np.ndarray | None = None) -> list:
    out = []
    for _ in range(n):
        out.append(dev.read())
        if force is not None:
            dev.write_force(force)
    return out


def test_free_mass_under_constant_force_is_a_parabola() -> None:
    # No hand, no friction: x(t) = x0 + F t^2 / (2 m), exactly (the ZOH discretisation is
    # exact for a constant force).
    p = EmulatorParams(free_damping=0.0)
    dev = EmulatorDevice(EXACT, p, start_position=np.zeros(3))
    dev.start()
    f = np.array([0.0, 0.2, 0.0])
    samples = _run(dev, 101, f)
    t = samples[-1].t
    assert t == pytest.approx(0.1)
    assert samples[-1].position[1] == pytest.approx(0.2 * t**2 / (2 * p.stylus_mass_kg),
                                                    rel=1e-12)
    assert dev.velocity[1] == pytest.approx(0.2 * t / p.stylus_mass_kg, rel=1e-12)


def test_undamped_hand_spring_oscillates_at_sqrt_k_over_m() -> None:
    # x(t) = x0 cos(omega t), omega = sqrt(k_h / m): brax-style closed-form check.
    p = EmulatorParams(hand_damping=0.0)
    x0 = 0.004
    dev = EmulatorDevice(EXACT, p, hand=np.zeros(3), start_position=np.array([x0, 0.0, 0.0]))
    dev.start()
    omega = math.sqrt(p.hand_stiffness / p.stylus_mass_kg)
    xs = np.array([s.position[0] for s in _run(dev, 400)])
    t = np.arange(400) * DT
    np.testing.assert_allclose(xs, x0 * np.cos(omega * t), atol=1e-12)


def test_zoh_matrices_match_the_analytic_spring_mass() -> None:
    m, k, dt = 0.045, 300.0, 1e-3
    w = math.sqrt(k / m)
    phi, gam = zoh_matrices(m, k, 0.0, dt)
    np.testing.assert_allclose(phi, [[math.cos(w * dt), math.sin(w * dt) / w],
                                     [-w * math.sin(w * dt), math.cos(w * dt)]], atol=1e-12)
    np.testing.assert_allclose(gam, [(1 - math.cos(w * dt)) / k, math.sin(w * dt) / (m * w)],
                               atol=1e-15)


def test_static_push_against_the_hand() -> None:
    dev = EmulatorDevice(EXACT, hand=np.zeros(3))
    dev.start()
    _run(dev, 1000, np.array([0.0, 0.0, 0.6]))
    assert dev.position[2] == pytest.approx(0.6 / 300.0, rel=1e-6)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3).filter(
    lambda v: np.linalg.norm(v) > 1e-3), st.floats(0.01, 50.0))
def test_peak_force_is_clipped_keeping_direction(direction: list, magnitude: float) -> None:
    d = np.array(direction) / np.linalg.norm(direction)
    dev = EmulatorDevice()
    dev.start()
    dev.read()
    dev.write_force(magnitude * d)
    out = dev.applied_force
    assert np.linalg.norm(out) == pytest.approx(min(magnitude, 3.3), rel=1e-12)
    np.testing.assert_allclose(out / np.linalg.norm(out), d, atol=1e-12)


def test_continuous_limit_starts_at_the_closed_form_time_and_settles_at_fc() -> None:
    # Constant 2 N demand from cold. H_k = F^2 (1 - rho^k) reaches Fc^2 at
    # t* = -tau ln(1 - (Fc / F)^2) (module docstring), then the output is exactly Fc.
    tau, fc, f = 1.0, 0.88, 2.0
    lim = dataclasses.replace(OMNI_LIMITS, continuous_window_s=tau)
    dev = EmulatorDevice(lim, hand=np.zeros(3))
    dev.start()
    cmd = np.array([f, 0.0, 0.0])
    first_limited = None
    for k in range(4000):
        dev.read()
        dev.write_force(cmd)
        if first_limited is None and np.linalg.norm(dev.applied_force) < f - 1e-12:
            first_limited = k
        assert dev.heat <= fc * fc * (1 + 1e-12)
    t_star = -tau * math.log(1.0 - (fc / f) ** 2)
    assert first_limited is not None
    assert abs(first_limited * DT - t_star) <= 1.5 * DT
    assert np.linalg.norm(dev.applied_force) == pytest.approx(fc, rel=1e-9)
    np.testing.assert_allclose(dev.applied_force / np.linalg.norm(dev.applied_force),
                               [1.0, 0.0, 0.0])


def test_force_below_the_continuous_rating_is_never_limited() -> None:
    lim = dataclasses.replace(OMNI_LIMITS, continuous_window_s=0.05)  # 100 windows below
    dev = EmulatorDevice(lim, hand=np.zeros(3))
    dev.start()
    cmd = np.array([0.0, 0.5, 0.7])  # |F| = 0.86 N < 0.88 N
    for _ in range(5000):
        dev.read()
        dev.write_force(cmd)
        assert dev.applied_force.tolist() == cmd.tolist()


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(0.0, 10.0), min_size=50, max_size=400),
       st.floats(0.005, 0.2))
def test_heat_never_exceeds_the_continuous_rating(mags: list, tau: float) -> None:
    lim = dataclasses.replace(OMNI_LIMITS, continuous_window_s=tau)
    dev = EmulatorDevice(lim, hand=np.zeros(3))
    dev.start()
    for m in mags:
        dev.read()
        dev.write_force(np.array([m, 0.0, 0.0]))
        assert dev.heat <= 0.88**2 * (1 + 1e-12)
        assert np.linalg.norm(dev.applied_force) <= min(m, 3.3) + 1e-12


def test_readings_are_quantised_to_the_resolution() -> None:
    q = OMNI_LIMITS.position_resolution_m
    dev = EmulatorDevice(hand=lambda t: np.array([0.01 * math.sin(7 * t), 0.002 * t, 0.0]))
    dev.start()
    for _ in range(300):
        s = dev.read()
        counts = s.position / q
        np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
        assert np.all(np.abs(s.position - dev.position) <= q / 2 + 1e-12)


def test_end_stops_hold_the_stylus_inside_the_mechanical_range() -> None:
    p = EmulatorParams()
    dev = EmulatorDevice(EXACT, p, hand=np.array([0.5, 0.0, -0.5]))  # far outside
    dev.start()
    _run(dev, 500)
    assert dev.position[0] == pytest.approx(0.080 + p.end_stop_margin_m)
    assert dev.position[2] == pytest.approx(-0.035 - p.end_stop_margin_m)
    assert dev.velocity[0] == 0.0 and dev.velocity[2] == 0.0


def test_same_inputs_same_readings() -> None:
    def run() -> np.ndarray:
        dev = EmulatorDevice(hand=lambda t: np.array([0.02 * math.sin(3 * t), 0.0, 0.01 * t]))
        dev.start()
        out = []
        for k in range(500):
            out.append(dev.read().position)
            dev.write_force(np.array([0.0, 0.001 * k, -0.5]))
        return np.array(out)

    assert np.array_equal(run(), run())


def test_buttons_follow_a_schedule() -> None:
    dev = EmulatorDevice(buttons=lambda t: 2 if 0.01 <= t < 0.02 else 0)
    dev.start()
    b = [s.buttons for s in _run(dev, 30)]
    assert b[:10] == [0] * 10 and b[10:20] == [2] * 10 and b[20:] == [0] * 10


def test_misuse_raises() -> None:
    dev = EmulatorDevice()
    with pytest.raises(DeviceError, match="before start"):
        dev.read()
    dev.start()
    with pytest.raises(DeviceError, match="non-finite"):
        dev.write_force(np.array([0.0, math.nan, 0.0]))
    with pytest.raises(ValueError, match="3 components"):
        dev.write_force(np.zeros(2))
    dev.write_force(np.array([1.0, 0.0, 0.0]))
    dev.stop()
    assert dev.applied_force.tolist() == [0.0, 0.0, 0.0]


@pytest.mark.parametrize("field, value", [("stylus_mass_kg", 0.0), ("dt", -1e-3),
                                          ("hand_damping", -1.0), ("hand_stiffness", math.nan)])
def test_params_validated(field: str, value: float) -> None:
    with pytest.raises(ConfigError, match=field):
        EmulatorParams(**{field: value})
