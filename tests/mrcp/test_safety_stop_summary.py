"""A safety stop ends a scripted run with its cause, and the invariant summary never
contradicts it (issue #26 §4): the runner, ``vasim mrcp run`` (text and JSON)."""

from __future__ import annotations

import json

import pytest

import vasim.mrcp.scenarios as scenarios
from tests.mrcp.colliding import DROP_T, CollidingScenario
from vasim.cli import main
from vasim.mrcp.scenarios.base import ScenarioOptions
from vasim.mrcp.scenarios.runner import run


def test_the_run_ends_at_the_safety_stop_with_its_cause() -> None:
    res = run(CollidingScenario(), ScenarioOptions(coarse=True, duration=2.0))
    assert res.stop is not None and res.stop.startswith("t=")
    assert "rsel_collision R1: safety stop (nearest body ball at" in res.stop
    t_stop = float(res.stop[2:].split(":")[0])
    assert DROP_T <= t_stop < 2.0 and res.samples[-1].t == pytest.approx(t_stop)
    assert res.samples[-1].state == "fault" and not res.violations
    assert not res.events("fault:")                  # no "fault: no motion" after it
    summary = res.invariant_summary()
    assert "RSel never in collision" not in summary and "safety stop" in summary
    d = res.to_dict()
    assert d["safety_stop"] == res.stop and d["invariants"] == summary


def test_a_run_without_a_stop_says_rsel_never_collided() -> None:
    res = run(scenarios.get_scenario("cube_rotation"), ScenarioOptions(coarse=True,
                                                                       duration=0.5))
    assert res.stop is None
    assert res.invariant_summary() == ("invariants: task always grasped, RSel never in "
                                       "collision, joint limits kept")


@pytest.mark.parametrize("as_json", [False, True])
def test_vasim_mrcp_run_prints_the_stop_and_fails(monkeypatch, capsys, as_json: bool) -> None:
    real = scenarios.get_scenario
    monkeypatch.setattr(scenarios, "get_scenario",
                        lambda n: CollidingScenario() if n == "colliding_cube" else real(n))
    argv = ["mrcp", "run", "colliding_cube", "--coarse", "--duration", "2"]
    code = main(argv + (["--json"] if as_json else []))
    out = capsys.readouterr().out
    assert code == 1
    if as_json:
        d = json.loads(out)
        assert "nearest body ball" in d["safety_stop"]
        assert "RSel never in collision" not in d["invariants"]
    else:
        assert "SAFETY STOP t=" in out and "nearest body ball" in out
        assert "RSel never in collision" not in out and "fault: no motion" not in out
