"""The experimenter page shows the running trial's fixture gain: its current value and how
it is set (vasim/viewer/panel.py ``gain_text``, vasim/viewer/state.py ``gain_plan``, the
frame's ``gain`` from vasim/trials/vf.py, the controller's ``_gain_plan``)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from vasim.fixtures.gain import AdaptiveRule
from vasim.study.protocol import generate_schedule, load_protocol
from vasim.trials.vf import TrialConfig, TrialRunner
from vasim.viewer.controller import TrainingController
from vasim.viewer.panel import gain_text, metrics_text
from vasim.viewer.state import gain_plan

RULE = AdaptiveRule(gain_min=0.25, gain_max=1.0, tau_s=0.3, deviation_full_m=0.003,
                    initial=0.5)
POINTS = np.array([[0.01, 0.0, 0.0], [0.02, 0.0, 0.0]])


def _info(fixtures: tuple[str, ...], plan: str) -> SimpleNamespace:
    return SimpleNamespace(number=1, mode="protocol", trial_id=7, points=POINTS,
                           start=np.zeros(3), title="trial 7",
                           config=SimpleNamespace(max_time=60.0), fixtures=fixtures,
                           gain_plan=plan)


def _frame(gain: float) -> SimpleNamespace:
    return SimpleNamespace(t=0.5, tcp=np.zeros(3), goal=POINTS[0], goal_index=0,
                           n_points=2, done=False, gain=gain)


def test_gain_plans_name_constant_scheduled_and_adaptive() -> None:
    assert gain_plan(1.0) == "constant" and gain_plan(0.4) == "constant"
    assert gain_plan(0.75, "gain 75 %") == "scheduled (gain 75 %)"
    assert gain_plan(RULE) == "adaptive 25-100 %"


def test_the_live_metrics_show_the_current_gain_and_its_plan() -> None:
    text = metrics_text(_info(("ff",), "adaptive 25-100 %"), _frame(0.6342), [])
    # markdown-escaped (md_escape): "25\-100" renders as "25-100"
    assert "| Fixture gain | 0.63 (adaptive 25\\-100 %) |" in text
    assert gain_text(_info(("ff",), "scheduled (gain 50 %)"), _frame(0.5)) == \
        "0.50 (scheduled \\(gain 50 %\\))"
    # a fixture-free trial (a VF-free probe) has nothing to scale
    assert gain_text(_info((), "constant"), _frame(1.0)) == "— (no fixtures)"


@pytest.mark.parametrize(("gain", "const"), [(0.5, True), (RULE, False)])
def test_the_frame_carries_the_gain_of_its_render(gain, const: bool) -> None:
    r = TrialRunner(TrialConfig(schema="ff", seed=4, max_time=1.0, scene="none", gain=gain))
    frame = r.advance(0.6)
    logged = r.samples.view()["gain"]
    assert frame.gain == pytest.approx(float(logged[-1]), abs=0.0)   # the last sample's
    if const:
        assert frame.gain == 0.5
    else:  # assist-as-needed moved away from its start gain 0.5, within its bounds
        assert 0.25 <= frame.gain <= 1.0 and frame.gain != 0.5
    plain = TrialRunner(TrialConfig(schema="ff", seed=4, max_time=1.0, scene="none"))
    assert plain.advance(0.1).gain == 1.0


def test_a_protocol_trial_gets_its_block_gain_plan() -> None:
    p = load_protocol("vf_fading")
    session = SimpleNamespace(protocol=p)
    plans = {}
    for st in generate_schedule(p, 7):
        cfg = SimpleNamespace(gain=p.blocks[[b.name for b in p.blocks].index(st.block)]
                              .trial_gain(st.trial_in_block) if not st.probe else 1.0)
        plans.setdefault(st.condition, set()).add(
            TrainingController._gain_plan(cfg, session, st))  # type: ignore[arg-type]
    assert plans["ff_faded"] == {f"scheduled (gain {g} %)" for g in (100, 75, 50, 25)}
    assert plans["mag_adaptive"] == {"adaptive 25-100 %"}
    assert plans["ff"] == {"constant"} and plans["none"] == {"constant"}
