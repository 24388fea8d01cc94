"""Physiological motion: the prescribed offsets, and a liver that follows them."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.abdomen.integrate import OrganSolver
from vasim.abdomen.model import build_organ
from vasim.abdomen.motion import (
    Breathing,
    Heartbeat,
    PhysioMotion,
    PointMotion,
    anchor_offsets,
    point_offsets,
    point_velocities,
)
from vasim.abdomen.scene import load_scene
from vasim.core.errors import ConfigError

MOTION = PhysioMotion(Breathing(0.25, (0.0, 0.012, 0.002), phase=0.3),
                      Heartbeat(1.2, (0.0, 0.0, 0.0015), (0.0, 0.17, 0.05), 0.08))
POINTS = np.random.default_rng(0).uniform([-0.15, -0.12, 0.0], [0.15, 0.18, 0.16], (20, 3))


def test_breathing_alone_is_a_sinusoid_of_the_given_amplitude_and_period() -> None:
    m = PhysioMotion(Breathing(0.25, (0.0, 0.01, 0.0)), Heartbeat(1.2, (0.0, 0.0, 0.0)))
    t = np.linspace(0.0, 8.0, 801)
    y = np.array([point_offsets(m, POINTS[:1], ti)[0, 1] for ti in t])
    np.testing.assert_allclose(y, 0.01 * np.sin(2 * np.pi * 0.25 * t), atol=1e-15)
    np.testing.assert_allclose(point_offsets(m, POINTS, 1.0), [[0.0, 0.01, 0.0]] * 20,
                               atol=1e-15)


def test_heartbeat_fades_with_a_gaussian_of_the_distance_to_the_heart() -> None:
    h = MOTION.heartbeat
    centre = np.array(h.centre)
    pts = centre + np.array([[0.0, 0.0, 0.0], [0.08, 0.0, 0.0], [0.0, 0.16, 0.0]])
    np.testing.assert_allclose(h.weight(pts), [1.0, math.exp(-0.5), math.exp(-2.0)])
    uniform = Heartbeat(1.2, (0.0, 0.0, 0.001), falloff_m=None)
    np.testing.assert_array_equal(uniform.weight(pts), 1.0)


@settings(max_examples=50, deadline=None)
@given(t=st.floats(0.0, 100.0))
def test_motion_is_periodic_and_velocity_is_the_derivative(t: float) -> None:
    # periods 4 s (0.25 Hz) and 5/6 s (1.2 Hz): their sum repeats every 20 s
    np.testing.assert_allclose(point_offsets(MOTION, POINTS, t + 20.0),
                               point_offsets(MOTION, POINTS, t), atol=1e-12)
    h = 1e-6
    after, before = point_offsets(MOTION, POINTS, t + h), point_offsets(MOTION, POINTS, t - h)
    numeric = (after - before) / (2 * h)
    np.testing.assert_allclose(point_velocities(MOTION, POINTS, t), numeric, atol=1e-8)
    cached = PointMotion(MOTION, POINTS)
    np.testing.assert_allclose(cached.offsets(t), point_offsets(MOTION, POINTS, t), atol=1e-15)
    np.testing.assert_allclose(cached.velocities(t), point_velocities(MOTION, POINTS, t),
                               atol=1e-15)
    np.testing.assert_array_equal(anchor_offsets(MOTION, POINTS, t),
                                  point_offsets(MOTION, POINTS, t))


def test_a_point_of_the_liver_moves_with_the_breathing_period_and_amplitude() -> None:
    scene = load_scene("default")
    liver_cfg = scene.organ("liver")
    mesh = scene.meshes()["liver"]
    model = build_organ(mesh, liver_cfg.params, name="liver", gravity=scene.physics.gravity)
    motion = PhysioMotion(Breathing(0.25, liver_cfg.breathing_m), Heartbeat(1.2, (0, 0, 0)))
    solver = OrganSolver(model, scene.physics.dt, **scene.solver_options())
    state = solver.initial_state()
    anchors = PointMotion(motion, model.rest[model.anchors])
    nodes = PointMotion(motion, model.rest)
    # the free node farthest from every anchor: it moves only through the tissue
    free = np.flatnonzero(model.free)
    d = np.linalg.norm(model.rest[free, None] - model.rest[None, model.anchors], axis=2).min(1)
    probe = free[np.argmax(d)]
    dt, n = scene.physics.dt, 2500  # 10 s: 2.5 breaths
    y = np.empty(n)
    for i in range(n):
        t1 = (i + 1) * dt
        report = solver.step(state, anchors.points + anchors.offsets(t1),
                             v_frame=nodes.velocities(t1))
        assert report.ok
        y[i] = state.x[probe, 1]
    t = dt * np.arange(1, n + 1)
    keep = t > 2.0  # after the settling under gravity: two whole breaths
    # least squares: y = a sin(w t) + b cos(w t) + c, w = 2 pi 0.25
    w = 2 * np.pi * 0.25
    basis = np.column_stack([np.sin(w * t[keep]), np.cos(w * t[keep]), np.ones(keep.sum())])
    coef, *_ = np.linalg.lstsq(basis, y[keep], rcond=None)
    amplitude = math.hypot(coef[0], coef[1])
    assert amplitude == pytest.approx(liver_cfg.breathing_m[1], rel=0.1)
    residual = y[keep] - basis @ coef
    assert np.abs(residual).max() < 0.1 * amplitude  # it is that sinusoid
    spectrum = np.abs(np.fft.rfft(y[keep] - y[keep].mean()))
    freqs = np.fft.rfftfreq(int(keep.sum()), dt)
    assert freqs[np.argmax(spectrum)] == pytest.approx(0.25, abs=0.02)


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: Breathing(-0.1, (0, 0.01, 0)), "frequency_hz"),
        (lambda: Breathing(0.25, (0, 0.01)), "amplitude_m"),
        (lambda: Heartbeat(1.2, (0, 0, 0.001), falloff_m=0.0), "falloff_m"),
        (lambda: Heartbeat(1.2, (0, 0, 0.001), centre=(0, float("inf"), 0)), "centre"),
    ],
)
def test_bad_motion_parameters_are_refused(make, field: str) -> None:
    with pytest.raises(ConfigError) as info:
        make()
    assert info.value.field == field
