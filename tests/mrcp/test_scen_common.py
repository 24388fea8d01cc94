"""The scenario machinery: registry, runner invariants, event log, plot, command line.

``scenario_run(name, duration)`` runs a scenario once per test session in the coarse mode
(36 ms period) and is shared by the per-scenario test modules.
"""

from __future__ import annotations

import functools
import io
import json
from pathlib import Path

import numpy as np
import pytest

from vasim.cli import main
from vasim.cli.mrcp import format_events
from vasim.core.errors import ConfigError
from vasim.mrcp.kernel import CycleRecord
from vasim.mrcp.modes import KernelState
from vasim.mrcp.scenarios import SCENARIOS, get_scenario
from vasim.mrcp.scenarios.base import ScenarioOptions
from vasim.mrcp.scenarios.runner import RunResult, check_invariants, run


@functools.cache
def scenario_run(name: str, duration: float) -> RunResult:
    return run(get_scenario(name), ScenarioOptions(coarse=True, duration=duration))


def joint_margins(q: np.ndarray) -> np.ndarray:
    """Distance of each RX60B joint to its nearest limit, in units of its half range."""
    from vasim.mrcp.scenarios.base import rx60b_model

    m = rx60b_model()
    return np.minimum(q - m.lower, m.upper - q) / ((m.upper - m.lower) / 2)


def test_registry_names_every_scenario_and_rejects_unknown() -> None:
    assert set(SCENARIOS) >= {"cube_rotation", "cube_translation", "obstacle_hole",
                              "laparoscopic_rings", "faucet"}
    with pytest.raises(ConfigError, match="field 'scenario': got 'nope', expected one of"):
        get_scenario("nope")


def test_invariant_checker_catches_each_violation() -> None:
    """The runner's checks fire: an ungrasped task, RSel off its point, a joint beyond its
    limit (on a real built station)."""
    setup = get_scenario("cube_rotation").build(ScenarioOptions())
    try:
        from vasim.mrcp.kernel import MRCPKernel

        pos, rot = setup.operator(0.0)
        k = MRCPKernel(setup.arms, setup.world, setup.task_points, setup.rsel, setup.cutp,
                       pos, rot, config=setup.config)
        cmds = {r: setup.world.configuration(r) for r in setup.arms}
        good = CycleRecord(0.0, KernelState.TOP, "R1", 0, ("R1",), pos, rot, cmds, {}, None,
                           None, None, [])
        assert check_invariants(k, setup, good) == []
        bad = CycleRecord(0.0, KernelState.TOP, "R1", 0, (), pos + 0.01, rot, cmds, {}, None,
                          None, None, [])
        found = " ".join(check_invariants(k, setup, bad))
        assert "ungrasped" in found and "not among the holders" in found
        assert "10.0 mm off its task point" in found or "mm off" in found
        q = setup.world.configuration("R0").copy()
        q[4] = setup.arms["R0"].joint_upper[4] + 0.05
        setup.world.set_configuration("R0", q)
        assert any("R0 outside its joint limits" in v for v in check_invariants(k, setup, good))
    finally:
        setup.close()


def test_event_log_collapses_repeats() -> None:
    lines = format_events([(1.0, "rsel_hold R0: x"), (1.1, "rsel_hold R0: x"),
                           (1.2, "transfer_start R1@2 (ntt=0.95, cause=rj)")])
    assert lines == ["t=  1.000  rsel_hold R0: x  (x2, until t=1.100)",
                     "t=  1.200  transfer_start R1@2 (ntt=0.95, cause=rj)"]


def test_transfers_are_parsed_from_the_log() -> None:
    res = scenario_run("cube_rotation", 7.0)
    tr = res.transfers()
    assert tr and set(tr[0]) == {"t_start", "from", "to", "point", "ntt", "cause", "t_done"}
    d = res.to_dict()
    assert d["cycles"] == len(res.samples) and d["transfers"] == tr


def test_cli_run_prints_the_log_json_and_saves_the_plot(tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]
                                                         ) -> None:
    png = tmp_path / "run.png"
    code = main(["mrcp", "run", "cube_rotation", "--coarse", "--duration", "1.0",
                 "--plot", str(png), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["scenario"] == "cube_rotation" and out["violations"] == []
    assert out["cycles"] == int(1.0 / 0.036) and png.stat().st_size > 10_000
    assert main(["mrcp", "run", "nope"]) == 2
    assert "field 'scenario': got 'nope', expected one of" in capsys.readouterr().err
    assert main(["mrcp", "list"]) == 0
    assert "cube_rotation" in capsys.readouterr().out


def test_cli_text_log_names_transfer_and_cause(capsys: pytest.CaptureFixture[str]) -> None:
    from vasim.cli.mrcp import cmd_run

    class Args:
        scenario, plot, seed, duration, coarse, json = "cube_rotation", None, 0, 7.0, True, False
        out = io.StringIO()

    code = cmd_run(Args())  # type: ignore[arg-type]
    text = Args.out.getvalue()
    assert code == 0
    assert "transfer_start R0@" in text and "cause=rj" in text
    assert "#1 t=" in text and "R1 -> R0@" in text and "invariants: task always" in text


def test_tracking_operator_steers_toward_the_script_at_a_bounded_rate() -> None:
    from scipy.spatial.transform import Rotation

    from vasim.mrcp.scenarios.runner import TrackingOperator

    op = TrackingOperator(max_speed=0.1, max_rate=1.0)
    last = (np.array([1.0, 0.0, 0.0]), np.eye(3))
    achieved = (np.zeros(3), np.eye(3))
    # Close enough: the increment is exactly the remaining error.
    pos, rot = op.command((np.array([0.001, 0.0, 0.0]), None), achieved, (last[0], None), 0.02)
    np.testing.assert_allclose(pos, [1.001, 0.0, 0.0])
    assert rot is None
    # Far: 0.1 m/s x 0.02 s = 2 mm along the error; rotation 1 rad/s x 0.02 s = 0.02 rad.
    target_rot = Rotation.from_rotvec([0.0, 0.0, 0.5]).as_matrix()
    pos, rot = op.command((np.array([0.0, 0.3, 0.4]), target_rot), achieved, last, 0.02)
    np.testing.assert_allclose(pos - last[0], [0.0, 0.0012, 0.0016], atol=1e-12)
    assert rot is not None
    np.testing.assert_allclose(Rotation.from_matrix(rot).as_rotvec(), [0.0, 0.0, 0.02],
                               atol=1e-12)


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_every_registered_scenario_starts_clean(name: str) -> None:
    """Any scenario (a new one too): it builds, its start pose is held, the first 1.5 s keep
    every invariant and nobody touches anything; the log and plot data are complete."""
    res = scenario_run(name, 1.5)
    assert res.violations == [] and not [s.t for s in res.samples if s.colliding]
    assert len(res.samples) == int(1.5 / 0.036)
    first = res.samples[0]
    if first.subtask is None:
        assert first.state == "TOp" and first.rsel in res.robots and first.robots
    else:   # a state graph of subtasks (suture_combined) starts in StdT: no kernel yet
        assert first.state == first.mode == "StdT" and first.rsel in res.robots
        assert any(s.robots for s in res.samples)       # the kernel ran once in MRCP
    assert not res.events("rsel_collision") and not res.events("rsel_hold")
