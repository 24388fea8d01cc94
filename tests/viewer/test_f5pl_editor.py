"""The experimenter's f5PL editor reads like a lab's (issue #26 §5): axis titles with units
(the fixture's input in mm, its output with its unit), the shipped curve as a reference, one
line per parameter, the current operating point, and in protocol mode the running trial's
condition (vasim/viewer/f5pl_view.py, vasim/viewer/panel.py)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
import viser

from vasim.fixtures.ff import FFParams
from vasim.fixtures.logistic import Logistic5
from vasim.fixtures.schema import load_schema
from vasim.fixtures.vg import VGParams
from vasim.trials.vf import TrialConfig
from vasim.viewer.controller import Command, PanelState
from vasim.viewer.f5pl_view import editor_data, fixture_axes, parameter_lines
from vasim.viewer.panel import ExperimenterPanel
from vasim.viewer.state import f5pl_fields

POINTS = np.array([[0.01, 0.0, 0.0], [0.02, 0.0, 0.0]])


def test_axes_name_the_input_in_mm_and_the_output_with_its_unit() -> None:
    ff = fixture_axes("ff", FFParams(), "trajectory", 0.03)
    assert ff.x_label == "distance to the path, per axis [mm]"
    assert ff.y_label == "spring stiffness K [N/mm]"
    assert ff.factor == pytest.approx(2.5 / 0.03 / 1000.0)       # k / D in N/mm
    vg = fixture_axes("vg", VGParams(scale_m=0.05), "point", 0.03)
    assert vg.x_label == "distance to the target [mm]" and vg.scale_m == 0.05
    assert vg.y_label == "arrow opacity [0-1]"


def test_curve_in_mm_with_reference_and_operating_point() -> None:
    p = Logistic5(a=0.0, b=2.0, c=0.15, d=1.0)
    ref = Logistic5(a=0.0, b=4.0, c=0.3, d=1.0)
    ax = fixture_axes("ff", FFParams(), "trajectory", 0.03)
    x, _y, r, op = editor_data(p, ref, ax, operating_m=0.0045)
    assert x[-1] == pytest.approx(3 * 0.3 * 30.0)               # 3 c·D of the wider curve
    k = int(np.flatnonzero(np.isfinite(op))[0])
    assert np.count_nonzero(np.isfinite(op)) == 1 and x[k] == pytest.approx(4.5)
    # At the midpoint c·D = 4.5 mm the symmetric logistic is half-way: (a + d) / 2 · k / D.
    assert op[k] == pytest.approx(0.5 * ax.factor)
    assert r[k] == pytest.approx(ax.factor * float(ref(0.15)))


def test_one_line_per_parameter_in_the_fixtures_units() -> None:
    p = Logistic5(a=0.0, b=2.0, c=0.15, d=1.0)
    ax = fixture_axes("ff", FFParams(), "trajectory", 0.03)
    text = parameter_lines(p, Logistic5(a=0.0, b=2.0, c=0.2, d=1.0), ax, 0.0045)
    for k in "abcdg":
        assert f"- **{k}** = " in text
    assert "c·D" in text and "→ 4.5 mm" in text and "(shipped: 0.2)" in text
    assert "(as shipped)" in text and "**now**: 4.5 mm" in text


@pytest.fixture()
def server() -> viser.ViserServer:
    s = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield s
    s.stop()


def _panel(server: viser.ViserServer, state: PanelState) -> tuple[ExperimenterPanel, list]:
    sent: list[Command] = []
    panel = ExperimenterPanel(server, sent.append, lambda f: f, state,
                              ("trajectory_following", "ff", "vg"), ("vf_learning_curve",))
    return panel, sent


def _info(schema: str, mode: str) -> SimpleNamespace:
    return SimpleNamespace(number=1, mode=mode, trial_id=3, points=POINTS, start=np.zeros(3),
                           title="trial 1 of 38", config=TrialConfig(schema=schema),
                           fixtures=(), gain_plan="constant", schema=schema)


def _frame(tcp: list[float]) -> SimpleNamespace:
    return SimpleNamespace(t=1.0, tcp=np.array(tcp), goal=POINTS[0], goal_index=0,
                           n_points=2, done=False, gain=1.0, last_latency=None)


def test_the_panel_labels_the_curve_and_shows_the_shipped_reference(server) -> None:
    tf = "trajectory_following"
    panel, _ = _panel(server, PanelState(mode="free", schema=tf,
                                         f5pl=f5pl_fields(load_schema(tf)), version=1))
    panel.fixture.value = "ff"
    assert [a["label"] for a in panel.curve.axes] == ["distance to the path, per axis [mm]",
                                                      "spring stiffness K [N/mm]"]
    _, y, ref, _ = panel.curve.data
    np.testing.assert_array_equal(y, ref)                        # unedited: on the reference
    assert panel.numbers["a"].label == "a (at 0 mm)" and panel.numbers["c"].hint
    panel.numbers["c"].value = 0.3                               # an edit, previewed
    _x, y, ref, _ = panel.curve.data
    assert not np.allclose(y, ref) and "(shipped: 0.15)" in panel.f5pl_text.content


def test_the_operating_point_follows_the_tool(server) -> None:
    tf = "trajectory_following"
    panel, _ = _panel(server, PanelState(mode="free", schema=tf,
                                         f5pl=f5pl_fields(load_schema(tf)), version=1))
    panel.fixture.value = "vg"                                   # Euclidean distance
    panel.show_live(_info(tf, "free"), _frame([0.005, 0.003, 0.004]), now=10.0, force=True)
    x, _y, _, op = panel.curve.data
    # the one "now" value inside the chart's y range (panel.plot_data: no NaN is sent)
    k = int(np.flatnonzero(op <= panel.curve.scales["y"]["range"][1])[0])
    assert x[k] == pytest.approx(5.0)                            # |(0, 3, 4)| mm off the path
    assert "**now**: 5 mm" in panel.f5pl_text.content


def test_protocol_mode_shows_the_trials_condition_greyed(server) -> None:
    ff = load_schema("ff")
    state = PanelState(mode="protocol", schema="trajectory_following", f5pl=f5pl_fields(ff),
                       running=True, version=2)
    panel, sent = _panel(server, state)
    panel.show_live(_info("ff", "protocol"), _frame([0.005, 0.0, 0.0]), now=10.0, force=True)
    panel.show(PanelState(**{**state.__dict__, "version": 3}))
    assert panel.shown_schema() == "ff" and panel.fixture.value == "ff"
    p = dict(f5pl_fields(ff))["ff"]
    assert [panel.numbers[k].value for k in "abcdg"] == [p.a, p.b, p.c, p.d, p.g]
    assert all(h.disabled for h in panel.numbers.values()) and panel.apply.disabled
    _, y, ref, _ = panel.curve.data
    np.testing.assert_array_equal(y, ref)
    assert not sent
    assert not math.isnan(float(np.nanmax(y)))
