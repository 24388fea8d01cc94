"""The operator model of the teleoperation modes (vasim.operator.teleop_profile)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.operator.needle import grasp_sigma
from vasim.operator.profile import OperatorProfile
from vasim.operator.teleop_profile import (
    NEUTRAL,
    SEED_TELEOP,
    TeleopEffects,
    secant_fit,
    teleop_adjustment,
)

P = OperatorProfile.intermediate()


@pytest.mark.parametrize("mode", ["stdt", "mrcp", "mrcp_cam"])
def test_neutral_effects_leave_the_person_as_it_is(mode: str) -> None:
    adj = teleop_adjustment(mode, 3, P, NEUTRAL)
    assert adj.carry == P and adj.handover == P


def test_stdt_noise_decays_with_the_modes_practice_at_the_persons_rate() -> None:
    eff = TeleopEffects(stdt_noise=0.8)
    for m in (0, 1, 5):
        adj = teleop_adjustment("stdt", m, P, eff)
        factor = 1.0 + 0.8 * (1.0 + m) ** -P.learning_rate     # 6 ** -0.25 = 0.639 at m = 5
        for name in ("noise", "gain_noise", "perception_noise"):
            assert getattr(adj.handover, name) == pytest.approx(getattr(P, name) * factor)
            assert getattr(adj.carry, name) == pytest.approx(getattr(P, name) * factor)
        assert adj.handover.fitts_a == P.fitts_a and adj.handover.fitts_b == P.fitts_b
        # the manual transfer's jaw error follows the noisier perception
        assert grasp_sigma(adj.handover, 0) == pytest.approx(grasp_sigma(P, 0) * factor)
    assert teleop_adjustment("stdt", 5, P, eff).mode_factor == pytest.approx(6 ** -0.25)


def test_threading_slows_only_the_carry_to_a_ring_and_the_camera_costs_only_in_mrcp_cam() -> None:
    eff = TeleopEffects(thread_time=2.5, stdt_noise=0.4, camera_cost=0.3)
    mrcp = teleop_adjustment("mrcp", 0, P, eff)
    assert mrcp.carry.fitts_a == pytest.approx(2.5 * P.fitts_a)
    assert mrcp.carry.fitts_b == pytest.approx(2.5 * P.fitts_b)
    assert mrcp.handover == P and mrcp.carry.noise == P.noise
    cam = teleop_adjustment("mrcp_cam", 2, P, eff)
    c = 1.0 + 0.3 * 3.0 ** -P.learning_rate
    assert cam.handover.fitts_b == pytest.approx(c * P.fitts_b)
    assert cam.carry.fitts_a == pytest.approx(2.5 * c * P.fitts_a)
    assert cam.carry.perception_noise == pytest.approx(c * P.perception_noise)
    stdt = teleop_adjustment("stdt", 0, P, eff)
    assert stdt.carry.fitts_a == pytest.approx(2.5 * P.fitts_a)   # threading as in MRCP


def test_bad_inputs_name_what_was_expected() -> None:
    with pytest.raises(ValueError, match="mode must be one of"):
        teleop_adjustment("vf", 0, P)
    with pytest.raises(ValueError, match="mode_practice"):
        teleop_adjustment("mrcp", -1, P)
    with pytest.raises(ValueError, match=r"TeleopEffects.stdt_noise .* got -0.1"):
        TeleopEffects(stdt_noise=-0.1)
    with pytest.raises(ValueError, match="thread_time"):
        TeleopEffects(thread_time=float("nan"))
    with pytest.raises(ValueError, match="did not move"):
        secant_fit(0.0, 1.0, 1.0, 1.0, 1.2, lo=0.0, hi=5.0)


@settings(max_examples=60, deadline=None)
@given(st.floats(-3, 3), st.floats(0.2, 4), st.floats(0.0, 2.0), st.floats(2.5, 4.0),
       st.floats(0.0, 4.0))
def test_the_secant_step_recovers_the_root_of_a_linear_moment(a: float, b: float, x0: float,
                                                            x1: float, x_true: float) -> None:
    def y(x: float) -> float:
        return a + b * x

    got = secant_fit(x0, y(x0), x1, y(x1), y(x_true), lo=-10.0, hi=10.0)
    assert got == pytest.approx(x_true, abs=1e-9)
    assert secant_fit(x0, y(x0), x1, y(x1), y(20.0), lo=-10.0, hi=10.0) == 10.0  # clipped


def test_the_seed_calibration_is_a_valid_model_that_does_something() -> None:
    assert SEED_TELEOP.thread_time > 1.0 and SEED_TELEOP.stdt_noise > 0.0
    assert SEED_TELEOP.camera_cost > 0.0
