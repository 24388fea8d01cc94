"""Tests of the virtual coupling (vasim/haptics/coupling.py): the force law, saturation,
the tissue-force extrapolation against ``patch_force``, the implicit proxy step, and —
with the emulated Omni in the 1 kHz loop — passivity, stability and no buzzing at rest."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.abdomen.contact import ContactPatch, ToolPose, patch_force
from vasim.core.errors import ConfigError
from vasim.haptics.coupling import (
    CouplingParams,
    LinearForce,
    PatchForce,
    ProxyState,
    coupling_energy,
    coupling_force,
    critical_damping,
    extrapolate_force,
    proxy_step,
    saturate,
    tissue_force,
    velocity_alpha,
)
from vasim.haptics.device import OMNI_LIMITS
from vasim.haptics.devices.emulator import EmulatorDevice
from vasim.haptics.servo import CoupledToolPlant, ServoLoop

vec = st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3).map(np.array)
DT = 1e-3
R = 0.0025  # tool radius: the tip centre touches a plane at distance R
FULCRUM = np.array([0.0, 0.0, 0.2])


def wall(k: float) -> PatchForce:
    """A plane z = 0 (normal +z) of stiffness k, touched by the tip sphere only."""
    return PatchForce(ContactPatch(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]),
                                   np.array([k]), np.zeros(1), R), FULCRUM)


# -- the force law ------------------------------------------------------------------------

@settings(max_examples=100, deadline=None)
@given(vec, vec, vec, vec, st.floats(0.0, 5e4), st.floats(0.0, 100.0))
def test_coupling_force_is_the_spring_damper(xd, vd, xp, vp, ks, kd) -> None:
    f = coupling_force(xd, vd, xp, vp, ks, kd)
    for a in range(3):  # per component, written out: -ks dx - kd dv
        assert f[a] == pytest.approx(-ks * (xd[a] - xp[a]) - kd * (vd[a] - vp[a]),
                                     rel=1e-12, abs=1e-9)


def test_default_damping_is_critical() -> None:
    p = CouplingParams(stiffness=900.0, proxy_mass=0.04)
    assert p.kd == critical_damping(0.04, 900.0) == pytest.approx(2 * math.sqrt(36.0))
    assert CouplingParams(damping=0.0).kd == 0.0


@settings(max_examples=200, deadline=None)
@given(vec, st.floats(0.51, 10.0), st.floats(0.1, 5.0))
def test_saturation_keeps_direction(d, scale, max_n) -> None:
    # |f| = 2 scale max_n > max_n: saturated
    if np.linalg.norm(d) < 1e-6:
        return
    f = d / np.linalg.norm(d) * scale * 2 * max_n
    out, sat = saturate(f, max_n)
    assert sat and np.linalg.norm(out) == pytest.approx(max_n, rel=1e-12)
    np.testing.assert_allclose(out / np.linalg.norm(out), f / np.linalg.norm(f), atol=1e-12)
    small, sat2 = saturate(f * (0.5 * max_n / np.linalg.norm(f)), max_n)
    assert not sat2 and np.linalg.norm(small) == pytest.approx(0.5 * max_n)


def test_saturation_of_nonfinite_and_huge_forces() -> None:
    assert saturate([math.nan, 0.0, 0.0], 3.3)[0].tolist() == [0.0, 0.0, 0.0]
    out, _ = saturate([1e200, 1e200, 0.0], 3.3)  # |f|^2 overflows; direction still kept
    np.testing.assert_allclose(out, [3.3 / math.sqrt(2), 3.3 / math.sqrt(2), 0.0])


# -- extrapolation vs patch_force ---------------------------------------------------------

def _random_patch(rng: np.random.Generator, tip: np.ndarray, n: int,
                  offsets: np.ndarray) -> ContactPatch:
    """n planes the tool touches (each sphere 0.5-1.5 mm deep) with random normals."""
    normals = rng.normal(size=(n, 3))
    normals[:, 2] = np.abs(normals[:, 2]) + 0.5
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    u = (tip - FULCRUM) / np.linalg.norm(tip - FULCRUM)
    centres = tip[None, :] - offsets[:, None] * u[None, :]
    depth = rng.uniform(0.5e-3, 1.5e-3, n)
    points = centres - (R - depth)[:, None] * normals  # delta_j = depth_j
    return ContactPatch(points, normals, rng.uniform(100, 1000, n), offsets, R)


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_extrapolation_is_exact_for_tip_planes(seed: int) -> None:
    # Planes touched by the tip sphere (offset 0, lever 1): F is affine in x while every
    # plane stays active, so F0 + K dx equals patch_force exactly.
    rng = np.random.default_rng(seed)
    tip = np.array([0.01, -0.02, 0.0])
    patch = _random_patch(rng, tip, 3, np.zeros(3))
    f0, k = patch_force(patch, ToolPose(FULCRUM, tip))
    dx = rng.uniform(-1e-4, 1e-4, 3)  # 0.1 mm: every plane stays 0.3 mm deep or more
    exact, _ = patch_force(patch, ToolPose(FULCRUM, tip + dx))
    np.testing.assert_allclose(extrapolate_force(f0, k, tip, tip + dx), exact,
                               rtol=1e-10, atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_extrapolation_is_second_order_accurate_for_pivoting_moves(seed: int) -> None:
    # Spheres up the shaft: a move of the tip perpendicular to the shaft pivots the tool
    # about the fulcrum (sphere j moves by lambda_j dx to first order, the model behind
    # patch_force's dF/dx); direction and lever change to second order, so the
    # linearisation error must shrink as |dx|^2 (ratio 4 when dx halves).
    rng = np.random.default_rng(seed)
    tip = np.array([0.0, 0.0, 0.0])
    patch = _random_patch(rng, tip, 4, np.array([0.0, 0.0025, 0.005, 0.0075]))
    model = PatchForce(patch, FULCRUM)
    f0, k = tissue_force(model, tip)
    u = (tip - FULCRUM) / np.linalg.norm(tip - FULCRUM)
    d = rng.normal(size=3)
    d -= (d @ u) * u  # perpendicular to the shaft
    d /= np.linalg.norm(d)
    errs = []
    for h in (2e-4, 1e-4, 5e-5):
        exact, _ = tissue_force(model, tip + h * d)
        errs.append(np.linalg.norm(extrapolate_force(f0, k, tip, tip + h * d) - exact))
    assert errs[0] / errs[1] == pytest.approx(4.0, rel=0.05)
    assert errs[1] / errs[2] == pytest.approx(4.0, rel=0.05)


def test_tissue_force_models() -> None:
    lin = LinearForce(np.array([0.0, 0.0, 0.3]), -500.0 * np.eye(3), np.zeros(3))
    f, k = tissue_force(lin, np.array([0.0, 0.0, 1e-3]))
    assert f.tolist() == pytest.approx([0.0, 0.0, -0.2]) and k[2, 2] == -500.0
    f, k = tissue_force(None, np.ones(3))
    assert not f.any() and not k.any()
    f, _ = tissue_force(wall(400.0), np.array([0.0, 0.0, 0.001]))  # 1.5 mm deep
    assert f.tolist() == pytest.approx([0.0, 0.0, 0.6])


# -- the proxy ------------------------------------------------------------------------------

def test_proxy_settles_on_the_series_spring_equilibrium() -> None:
    # Device held at xd, tissue spring k around x0: x_p = (ks xd + k x0) / (ks + k) and the
    # device feels F = ks (x_p - xd) (closed form of two springs in series).
    p = CouplingParams(stiffness=800.0, proxy_mass=0.01)
    k = 2000.0
    x0 = np.array([0.0, 0.0, 0.0])
    xd = np.array([0.002, -0.001, 0.004])
    lin = LinearForce(np.zeros(3), -k * np.eye(3), x0)
    s = ProxyState(xd.copy())
    for _ in range(2000):
        s, f = proxy_step(s, xd, np.zeros(3), lin, p, DT)
    xp = (800.0 * xd + k * x0) / (800.0 + k)
    np.testing.assert_allclose(s.x, xp, atol=1e-12)
    np.testing.assert_allclose(f, 800.0 * (xp - xd), atol=1e-9)


def test_proxy_catches_up_without_overshoot() -> None:
    # Critically damped proxy; backward Euler only adds damping: approach is monotone.
    p = CouplingParams()
    xd = np.array([0.01, 0.0, 0.0])
    s = ProxyState(np.zeros(3))
    xs = []
    for _ in range(500):
        s, _ = proxy_step(s, xd, np.zeros(3), None, p, DT)
        xs.append(s.x[0])
    xs = np.array(xs)
    assert np.all(np.diff(xs) >= 0) and np.all(xs <= 0.01) and xs[-1] == pytest.approx(0.01)


@pytest.mark.parametrize("field, kwargs", [
    ("coupling.stiffness", dict(stiffness=0.0)),
    ("coupling.proxy_mass", dict(proxy_mass=-1.0)),
    ("coupling.damping", dict(damping=-0.1)),
    ("coupling.velocity_cutoff_hz", dict(velocity_cutoff_hz=math.inf)),
])
def test_params_validated(field: str, kwargs: dict) -> None:
    with pytest.raises(ConfigError) as info:
        CouplingParams(**kwargs)
    assert info.value.field == field


# -- with the emulated device in the loop ---------------------------------------------------

EXACT = dataclasses.replace(OMNI_LIMITS, position_resolution_m=0.0)


def _energy(dev: EmulatorDevice, plant: CoupledToolPlant, kw: float) -> float:
    """Stylus + hand spring + coupling spring + proxy + wall [J]."""
    pen = max(0.0, R - float(plant.proxy.x[2]))
    return (dev.mechanical_energy() + coupling_energy(dev.position, plant.proxy, plant.params)
            + 0.5 * kw * pen * pen)


def _bounce(params: CouplingParams, kw: float = 2e4) -> np.ndarray:
    """A free stylus (hand off) thrown at 0.1 m/s onto a stiff wall; energy per tick."""
    dev = EmulatorDevice(EXACT, hand=None, start_position=np.array([0.0, 0.0, 0.01]))
    plant = CoupledToolPlant(params, tissue=wall(kw))
    loop = ServoLoop(dev, plant)
    loop.run_ticks(1)
    v0 = np.array([0.0, 0.0, -0.1])  # everything moving together: no stored coupling energy
    dev.set_state(dev.position, v0)
    plant.reset_proxy(dev.position, v0)
    e = []
    for _ in range(1500):
        loop.run_ticks(1)
        e.append(_energy(dev, plant, kw))
    loop.stop()
    return np.array(e)


def test_bounce_on_a_stiff_wall_does_not_gain_energy() -> None:
    """Passivity, numerically: with the default coupling the total energy never exceeds
    its initial value through the impact (the stylus leaves the wall slower than it came).
    The same test with a coupling 4x stiffer (critically damped, ks T / 2 = 1.5 N s/m
    against the 0.05 N s/m of the free stylus: Colgate & Schenkel's passivity condition
    b > ks T / 2 + kd fails badly) gains energy: the test can tell them apart."""
    e = _bounce(CouplingParams())
    e0 = 0.5 * 0.045 * 0.1**2 + 0.5 * CouplingParams().proxy_mass * 0.1**2
    assert e[0] == pytest.approx(e0, rel=0.02)
    assert e.max() <= e[0] * (1 + 1e-9)
    assert e[-1] < 0.1 * e[0]
    stiff = _bounce(CouplingParams(stiffness=3200.0))
    assert stiff.max() > 1.05 * stiff[0]


@pytest.mark.parametrize("kw", [350.0, 2e3, 2e4])
def test_resting_against_a_wall_converges_without_limit_cycle(kw: float) -> None:
    """The hand pushes the stylus onto a wall (ideal sensor): after the contact transient
    the energy only decreases, the force converges to the static closed form of three
    springs in series (hand, coupling, wall) and does not oscillate (no limit cycle)."""
    hand_k = 300.0
    dev = EmulatorDevice(EXACT, hand=np.zeros(3), start_position=np.array([0.0, 0.0, 0.01]))
    plant = CoupledToolPlant(tissue=wall(kw))
    loop = ServoLoop(dev, plant, record=True)
    e = []
    for _ in range(3000):
        loop.run_ticks(1)
        e.append(_energy(dev, plant, kw))
    loop.stop()
    f = loop.trace.array()[:, 5:8]
    de = np.diff(np.array(e))[300:]
    assert de.max() <= 1e-12
    f_static = R / (1 / hand_k + 1 / plant.params.stiffness + 1 / kw)
    np.testing.assert_allclose(f[-1], [0.0, 0.0, f_static], atol=1e-6)
    assert np.ptp(f[-500:, 2]) < 1e-9


def _at_rest(params: CouplingParams, tissue, hand, n: int = 3000):
    """The quantised emulator (the Omni's 0.055 mm counts) held at rest against ``tissue``;
    returns (force std over the last second [N], counts visited per axis)."""
    dev = EmulatorDevice(hand=np.array(hand, dtype=float),
                         start_position=np.add(hand, (0.0, 0.0, 0.01)))
    loop = ServoLoop(dev, CoupledToolPlant(params, tissue=tissue), record=True)
    loop.run_ticks(n)
    loop.stop()
    f = loop.trace.array()[-1000:, 5:8]
    q = OMNI_LIMITS.position_resolution_m
    x = loop.recording.stream().position[-1000:]
    counts = [len(np.unique(np.round(x[:, a] / q))) for a in range(3)]
    std = float(np.sqrt(((f - f.mean(axis=0)) ** 2).sum(axis=1).mean()))
    return std, counts


def _target(k: float, x0) -> LinearForce:
    """An attractor (FF-like spring of stiffness k toward x0)."""
    return LinearForce(np.zeros(3), -k * np.eye(3), np.array(x0, dtype=float))


# The bound. An encoder count q changes the rendered force by at most
#   Delta = ks q + kd a q / dt
# (spring term, plus the damping term of the low-passed difference, a = velocity_alpha).
# When the rendered stiffness exceeds the hand's, the quantised loop has no fixed point
# (a one-count step moves the stylus by more than a count), so at rest the reading may
# dither between two adjacent counts; a two-level signal with step Delta has a standard
# deviation of at most Delta / 2. With the defaults (ks 800 N/m, kd 5.66 N s/m, 30 Hz):
# Delta = 0.044 + 0.0535 = 0.097 N, so std <= 0.049 N. Anything larger is a limit cycle
# over several counts or a buzz from the velocity estimate.
_P = CouplingParams()
_Q = OMNI_LIMITS.position_resolution_m
BOUND = 0.5 * (_P.stiffness * _Q + _P.kd * velocity_alpha(_P.velocity_cutoff_hz, DT) * _Q / DT)


@pytest.mark.parametrize("name, tissue, hand", [
    ("soft wall", wall(350.0), (0.0, 0.0, 0.0)),
    ("stiff wall", wall(2e4), (0.0, 0.0, -0.001)),
    ("wall, oblique hand", wall(2e3), (0.001, 0.002, 0.0007)),
    ("target", _target(1000.0, (0.003, 0.001, 0.0)), (0.0, 0.0, 0.0)),
    ("weak target", _target(100.0, (0.02, 0.0, 0.0)), (0.0, 0.001, 0.0)),
])
def test_no_buzz_at_rest(name: str, tissue, hand) -> None:
    assert BOUND == pytest.approx(0.0487, abs=1e-4)
    std, counts = _at_rest(CouplingParams(), tissue, hand)
    assert std <= BOUND, name
    assert max(counts) <= 2, name  # at most two adjacent counts per axis


def test_raw_velocity_differences_would_buzz() -> None:
    """The same coupling with an unfiltered velocity (cutoff 1 kHz: a ~ 1) exceeds the
    bound: one encoder count then makes a 0.3 N damping step. The velocity low-pass is
    what keeps the stylus quiet."""
    std, _ = _at_rest(CouplingParams(velocity_cutoff_hz=1000.0), wall(2e4), (0.0, 0.0, -0.001))
    assert std > BOUND
