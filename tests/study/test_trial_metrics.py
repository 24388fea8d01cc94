"""Per-trial metrics (vasim/records/trial_metrics.py) against hand-computed values, and the
trial runner's new sample columns (in_view)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.core.errors import ConfigError
from vasim.records.point_metrics import path_lengths
from vasim.records.trial_metrics import (
    TRIAL_METRICS,
    MetricParams,
    accumulated_norm,
    episode_count,
    flag_time,
    kinematic_metrics,
    lowpass,
    movement_count,
    sample_durations,
    threshold_episodes,
    trial_metrics,
)
from vasim.tasks import TRAJECTORY_VARIANTS, point_task, trajectory_task
from vasim.trials.endoscope import DEFAULT_ENDOSCOPE, in_view_cone
from vasim.trials.vf import TrialConfig, TrialRunner

DT = 1e-3
UNFILTERED = MetricParams(filter_cutoff_hz=None)


def min_jerk_track(t: np.ndarray, starts: list[float], duration: float, amplitude: float,
                   direction=(1.0, 2.0, 2.0)) -> np.ndarray:
    """Sum of minimum-jerk movements (Flash & Hogan 1985) of ``amplitude`` [m] and
    ``duration`` [s] starting at ``starts`` [s], along ``direction``; (n, 3) [m]."""
    u = np.asarray(direction, dtype=float)
    u = u / np.linalg.norm(u)
    s = np.zeros_like(t)
    for t0 in starts:
        tau = np.clip((t - t0) / duration, 0.0, 1.0)
        s += tau**3 * (10 - 15 * tau + 6 * tau**2)
    return np.outer(amplitude * s, u) + np.array([0.01, 0.02, 0.1])


# ------------------------------------------------------------------------- smoothness
def test_min_jerk_mean_jerk_and_ldlj_match_closed_form() -> None:
    # One min-jerk movement of D over T inside a window of rest. Per unit time over the
    # movement, |jerk| = D/T^3 |60 - 360 tau + 360 tau^2|, whose integral over [0, 1] is
    # 60 * 2 sqrt(3)/9 (roots of 6 tau^2 - 6 tau + 1 at (3 -+ sqrt 3)/6), so
    # integral |jerk| dt = (40 sqrt(3)/3) D / T^2, and integral |jerk|^2 dt = 720 D^2 / T^5
    # (the min-jerk cost); v_peak = 1.875 D / T.
    D, T, rest = 0.05, 1.0, 0.5
    t = np.arange(1, 2001) * DT
    x = min_jerk_track(t, [rest], T, D)
    m = kinematic_metrics(t, x, UNFILTERED)
    span = t[-1] - t[0]
    mean_jerk = 40 * math.sqrt(3) / 3 * D / T**2 / (len(t) * DT)
    assert m["mean_jerk"] == pytest.approx(mean_jerk, rel=1e-3)
    ldlj = -math.log(span**3 / (1.875 * D / T) ** 2 * 720 * D**2 / T**5)
    assert m["log_dimensionless_jerk"] == pytest.approx(ldlj, abs=0.01)
    assert m["peak_speed"] == pytest.approx(1.875 * D / T, rel=1e-4)
    assert m["path_l2"] == pytest.approx(D, rel=1e-9)
    # path_l1 along (1, 2, 2)/3: D (1 + 2 + 2) / 3
    assert m["path_l1"] == pytest.approx(D * 5 / 3, rel=1e-9)
    # a movement that fills the window: LDLJ = -ln(720 / 1.875^2) = -ln(204.8), for any D, T
    tt = np.arange(0, 1001) * DT
    whole = kinematic_metrics(tt, min_jerk_track(tt, [0.0], 1.0, 0.02), UNFILTERED)
    assert whole["log_dimensionless_jerk"] == pytest.approx(-math.log(204.8), abs=0.01)
    # The default low-pass (5 Hz) barely changes a 1 s movement (< 10 %).
    f = kinematic_metrics(t, x)
    assert f["mean_jerk"] == pytest.approx(mean_jerk, rel=0.1)
    assert f["log_dimensionless_jerk"] == pytest.approx(ldlj, abs=0.2)


def test_lowpass_has_the_butterworth_forward_backward_gain() -> None:
    # filtfilt of an order-4 Butterworth: |H(f)|^2 = 1 / (1 + (f / fc)^8); at fc: 0.5.
    t = np.arange(1, 8001) * DT
    for f_hz, gain in ((1.0, 1 / (1 + (1 / 5) ** 8)), (5.0, 0.5), (10.0, 1 / (1 + 2**8))):
        x = np.zeros((len(t), 3))
        x[:, 1] = np.sin(2 * math.pi * f_hz * t)
        y = lowpass(t, x)[:, 1]
        mid = slice(3000, 5000)  # away from the ends
        amp = np.sqrt(2 * np.mean(y[mid] ** 2))
        assert amp == pytest.approx(gain, rel=0.01, abs=1e-4)
    assert np.array_equal(lowpass(t[:3], x[:3]), x[:3])  # too short: unfiltered copy


# -------------------------------------------------------------------------- movements
def test_two_separated_bumps_are_two_movements_even_with_tremor() -> None:
    t = np.arange(1, 4001) * DT
    x = min_jerk_track(t, [0.5, 2.5], 1.0, 0.02)  # peak speed 37.5 mm/s, rest between
    assert kinematic_metrics(t, x)["n_movements"] == 2.0
    # 10 Hz physiological tremor of 0.1 mm: its speed (6 mm/s peak) must not add movements
    tremor = 1e-4 * np.sin(2 * math.pi * 10 * t)[:, None] * np.array([1.0, 0.0, 0.0])
    assert kinematic_metrics(t, x + tremor)["n_movements"] == 2.0
    assert kinematic_metrics(t, min_jerk_track(t, [1.0], 1.0, 0.02))["n_movements"] == 1.0
    assert kinematic_metrics(t, np.zeros((len(t), 3)))["n_movements"] == 0.0
    # Two movements overlapping so the speed never drops below 5 mm/s: one movement.
    assert kinematic_metrics(t, min_jerk_track(t, [1.0, 1.6], 1.0, 0.02))["n_movements"] == 1


@settings(max_examples=20, deadline=None)
@given(k=st.integers(0, 5), gap=st.floats(0.3, 1.0))
def test_k_separated_bumps_are_k_movements(k: int, gap: float) -> None:
    T = 0.6
    starts = [0.2 + i * (T + gap) for i in range(k)]
    t = np.arange(1, round((0.4 + k * (T + gap)) / DT) + 1) * DT
    assert kinematic_metrics(t, min_jerk_track(t, starts, T, 0.015))["n_movements"] == k


def test_movement_hysteresis_rule() -> None:
    # peaks at 20 mm/s separated by 7 mm/s (not below off = 5 mm/s): one movement; then a
    # drop to 1 mm/s and a new peak: a second movement.
    assert movement_count([0, 0.02, 0.007, 0.02, 0.001, 0.03, 0.0]) == 2
    assert movement_count([0.02, 0.02]) == 1  # moving from the first sample
    assert movement_count([0.008, 0.009, 0.008]) == 0  # never above on
    with pytest.raises(ValueError):
        movement_count([0.0], on=0.005, off=0.01)


# ------------------------------------------------------------------- contact, force, view
def _runs(flag) -> int:
    return sum(1 for v, _ in itertools.groupby(flag) if v)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.integers(0, 1), max_size=60))
def test_episode_count_is_the_number_of_runs(flag: list[int]) -> None:
    assert episode_count(flag) == _runs(flag)


def test_contact_force_and_view_metrics_on_synthetic_signals() -> None:
    # Irregular steps: sample j covers (t_(j-1), t_j], t_(-1) = 0.
    t = np.array([0.1, 0.2, 0.4, 0.5, 0.8, 1.0])
    w = sample_durations(t)
    assert w.tolist() == pytest.approx([0.1, 0.1, 0.2, 0.1, 0.3, 0.2])
    contact = np.array([1, 0, 1, 1, 0, 1])
    assert flag_time(t, contact) == pytest.approx(0.1 + 0.2 + 0.1 + 0.2)
    f = np.zeros((6, 3))
    f[:, 2] = [3.0, 0.0, 2.5, 1.0, 0.0, 4.0]  # above 2 N on samples 0, 2, 5
    assert threshold_episodes(t, f, 2.0) == (pytest.approx(0.1 + 0.2 + 0.2), 3)
    assert accumulated_norm(t, f) == pytest.approx(3 * 0.1 + 2.5 * 0.2 + 1 * 0.1 + 4 * 0.2)
    tau = np.tile([0.0, 0.03, 0.04], (6, 1))  # |tau| = 0.05 N m throughout
    in_view = np.array([1, 0, 0, 1, 0, 1])
    m = trial_metrics({"t": t, "x": np.zeros((6, 3)), "contact": contact, "f_contact": f,
                       "tau_contact": tau, "delicate": np.array([0, 0, 1, 1, 0, 0]),
                       "clutch": np.array([0, 1, 1, 0, 1, 0]), "in_view": in_view},
                      summary={"completion_time": 0.9, "points_reached": 3})
    assert list(m) == list(TRIAL_METRICS)
    assert m["contact_time"] == pytest.approx(0.6) and m["contact_count"] == 3
    assert m["delicate_contact_time"] == pytest.approx(0.3)
    assert m["delicate_contact_count"] == 1
    assert m["excessive_force_time"] == pytest.approx(0.5)
    assert m["excessive_force_count"] == 3 and m["max_force"] == 4.0
    assert m["accumulated_force"] == pytest.approx(1.7)
    assert m["accumulated_torque"] == pytest.approx(0.05 * 1.0)
    assert m["out_of_view_time"] == pytest.approx(0.1 + 0.2 + 0.3)
    assert m["out_of_view_count"] == 2
    assert m["clutch_count"] == 2 and m["clutch_time"] == pytest.approx(0.6)
    assert m["completion_time"] == 0.9 and m["points_reached"] == 3
    assert math.isnan(m["mean_latency"])  # not in the summary
    assert m["duration"] == 1.0 and m["path_l1"] == 0.0
    # the rendered force instead of the contact force
    rendered = trial_metrics({"t": t, "x": np.zeros((6, 3)), "force": f},
                             params=MetricParams(force_source="rendered"))
    assert rendered["excessive_force_count"] == 3
    # visibility not determined (-1, the default) -> NaN, never 0
    m2 = trial_metrics({"t": t, "x": np.zeros((6, 3))})
    assert math.isnan(m2["out_of_view_time"]) and math.isnan(m2["out_of_view_count"])
    assert m2["contact_time"] == 0.0 and m2["accumulated_force"] == 0.0


def test_path_lengths_agree_with_the_eq65_module() -> None:
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.normal(scale=1e-3, size=(500, 3)), axis=0)
    t = np.arange(1, 501) * DT
    m = kinematic_metrics(t, x)
    assert (m["path_l1"], m["path_l2"]) == pytest.approx(path_lengths(x), rel=1e-12)


@pytest.mark.parametrize(("kw", "field"), [
    ({"filter_cutoff_hz": 0.0}, "filter_cutoff_hz"),
    ({"filter_order": 9}, "filter_order"),
    ({"movement_on_speed": -1.0}, "movement_on_speed"),
    ({"movement_off_speed": 0.02}, "movement_off_speed"),
    ({"excessive_force_n": float("nan")}, "excessive_force_n"),
    ({"force_source": "tool"}, "force_source"),
])
def test_metric_params_are_validated(kw: dict, field: str) -> None:
    with pytest.raises(ConfigError, match=field):
        MetricParams(**kw)


def test_bad_columns_are_refused() -> None:
    with pytest.raises(ValueError, match="'t' and 'x'"):
        trial_metrics({"t": [0.1]})
    with pytest.raises(ValueError, match="contact"):
        trial_metrics({"t": [0.1, 0.2], "x": np.zeros((2, 3)), "contact": [1]})
    with pytest.raises(ValueError, match="non-decreasing"):
        sample_durations([0.2, 0.1])


# ------------------------------------------------------------------------ camera view
def test_default_endoscope_frames_every_task() -> None:
    for v in range(TRAJECTORY_VARIANTS):
        task = trajectory_task(v)
        assert DEFAULT_ENDOSCOPE.contains(np.vstack([task.points, task.start])).all()
    pt = point_task()
    assert DEFAULT_ENDOSCOPE.contains(np.vstack([pt.points, pt.start])).all()
    # behind the lens is never in view
    behind = 2 * np.asarray(DEFAULT_ENDOSCOPE.position) - np.asarray(DEFAULT_ENDOSCOPE.look_at)
    assert not DEFAULT_ENDOSCOPE.contains(behind[None, :])[0]


def test_in_view_cone_boundary() -> None:
    fov = math.radians(90.0)  # half-angle 45 deg
    pts = np.array([[math.tan(math.radians(a)), 0.0, 1.0] for a in (44.0, 46.0)])
    assert in_view_cone(pts, (0, 0, 0), (0, 0, 2), fov).tolist() == [True, False]


@pytest.mark.parametrize("schema", ["vg", "mag"])
def test_runner_fills_in_view_and_trial_metrics(schema: str) -> None:
    r = TrialRunner(TrialConfig(schema=schema, seed=2, max_time=1.0))
    r.advance(1.0)
    res = r.result()
    iv = res.samples.view()["in_view"]
    assert set(np.unique(iv).tolist()) <= {0, 1}  # determined for every sample
    if schema == "vg":  # the fixed camera, recomputed independently
        expected = DEFAULT_ENDOSCOPE.contains(res.samples.view()["x"]).astype(np.int8)
        assert np.array_equal(iv, expected)
    else:  # Mag keeps the tool in its view
        assert iv.all()
    m = res.trial_metrics
    assert list(m) == list(TRIAL_METRICS)
    assert m["duration"] == pytest.approx(1.0)
    assert m["out_of_view_time"] == pytest.approx(float((iv == 0).sum()) * DT)
    assert m["path_l1"] == pytest.approx(res.summary["total_path_l1"], rel=1e-12)
