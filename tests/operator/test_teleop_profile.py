"""The operator model of the teleoperation modes (vasim.operator.teleop_profile)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.operator.needle import grasp_sigma
from vasim.operator.profile import OperatorProfile
from vasim.operator.teleop_profile import (
    NEUTRAL,
    TeleopEffects,
    scale_teleop,
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
    with pytest.raises(ValueError, match="effect scale"):
        scale_teleop(NEUTRAL, -1.0)


@settings(max_examples=60, deadline=None)
@given(st.floats(0.1, 10.0), st.floats(0.0, 5.0), st.floats(0.0, 5.0), st.floats(0.0, 1.0))
def test_the_effect_scale_moves_every_penalty_linearly_from_neutral(
        k: float, theta: float, c: float, s: float) -> None:
    e = TeleopEffects(thread_time=k, stdt_noise=theta, camera_cost=c)
    assert scale_teleop(e, 0.0) == NEUTRAL
    one = scale_teleop(e, 1.0)
    assert (one.thread_time, one.stdt_noise, one.camera_cost) == pytest.approx((k, theta, c))
    got = scale_teleop(e, s)
    assert got.stdt_noise == pytest.approx(s * theta)
    assert got.camera_cost == pytest.approx(s * c)
    assert got.thread_time == pytest.approx(max(0.1, 1.0 + s * (k - 1.0)))


def test_the_default_is_the_mechanism_alone() -> None:
    # no penalty unless a declared scenario gives one (issue #25 item 6)
    for mode in ("stdt", "mrcp", "mrcp_cam"):
        adj = teleop_adjustment(mode, 0, P)
        assert adj.carry == P and adj.handover == P
