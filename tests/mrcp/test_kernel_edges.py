"""Edge cases of the kernel, the planner and `vasim mrcp run`: a linear trajectory step after
an unreachable point, no random force without an attraction, unmeasured points in the
visibility index, configuration and time checks, operator input during a safety stop,
strict JSON and bad command-line values refused before a run."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from vasim.cli import main
from vasim.mrcp.indices import EvalContext
from vasim.mrcp.indices.visibility import VisibilityIndex
from vasim.mrcp.interfaces import Proximity
from vasim.mrcp.kernel import KernelConfig, KernelParts, KernelState, MRCPKernel, TaskPoint
from vasim.mrcp.planner import (
    Mover,
    ObstacleMemory,
    PlannerParams,
    guidance,
    move_candidate,
)


class PointArm:
    """A 3-joint arm whose TCP is its configuration, joints within [-1, 1]."""

    n_joints = 3
    joint_lower = np.full(3, -1.0)
    joint_upper = np.full(3, 1.0)
    max_velocity = np.full(3, 1.0)
    max_acceleration = np.full(3, 10.0)

    def __init__(self, name: str) -> None:
        self.name = name

    def tcp_pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.array(q, float), np.eye(3)

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        return np.vstack([np.eye(3), np.zeros((3, 3))])

    def ik(self, p: np.ndarray, rotation: np.ndarray | None = None,
           q_seed: np.ndarray | None = None) -> np.ndarray | None:
        return np.array(p, float) if np.all(np.abs(p) <= 1.0) else None


class EmptyWorld:
    """Two point robots, nothing to collide with (unless ``wall_x`` is set for "a")."""

    def __init__(self, wall_x: float | None = None, cone: bool = False) -> None:
        self.q = {"a": np.zeros(3), "b": np.array([0.3, 0.0, 0.0])}
        self.wall_x, self.cone = wall_x, cone

    def robot_names(self) -> list[str]:
        return list(self.q)

    def obstacle_names(self) -> list[str]:
        return ["view_cone"] if self.cone else []

    def set_configuration(self, r: str, q: np.ndarray) -> None:
        self.q[r] = np.array(q, float)

    def configuration(self, r: str) -> np.ndarray:
        return self.q[r].copy()

    def min_distance(self, a: str, b: str, max_distance: float = 1.0) -> Proximity:
        if self.cone:
            return Proximity(min(0.5, max_distance), np.zeros(3), np.array([0.5, 0.0, 0.0]))
        nan = np.full(3, np.nan)
        return Proximity(max_distance, nan, nan)

    def in_collision(self, r: str) -> bool:
        return self.wall_x is not None and r == "a" and self.q["a"][0] > self.wall_x


POINTS = [TaskPoint(np.zeros(3)), TaskPoint(np.array([0.1, 0.0, 0.0]))]


class Constant:
    name = "constant"

    def evaluate(self, ctx: EvalContext) -> float:
        return 1.0


def kernel(world: EmptyWorld, **cfg: object) -> MRCPKernel:
    return MRCPKernel({"a": PointArm("a"), "b": PointArm("b")}, world, POINTS, "a", 0,
                      np.zeros(3), parts=KernelParts(indices=[Constant()]),
                      config=KernelConfig(**cfg))


def test_linear_trajectory_steps_from_the_last_reachable_point() -> None:
    """x = 0.9, 1.05, 1.1, 1.15 with joints limited to 1: only the first is reachable. The
    old rule stepped from 0.9 by the 1.05 -> 1.1 increment and called 0.95 'x = 1.1'."""
    positions = np.array([[0.9, 0, 0], [1.05, 0, 0], [1.1, 0, 0], [1.15, 0, 0]])
    q0 = np.array([0.9, 0.0, 0.0])
    for ik in ("exact", "linear"):
        k = kernel(EmptyWorld(), trajectory_ik=ik)
        configs, reach = k._trajectory_configs(PointArm("a"), ("a", 0), q0, q0, positions,
                                               [None] * 4)
        assert reach.tolist() == [True, False, False, False], ik
    # ... and a point back inside the limits is reached again, at the right place.
    back = np.array([[0.9, 0, 0], [1.05, 0, 0], [0.95, 0, 0]])
    k = kernel(EmptyWorld(), trajectory_ik="linear")
    configs, reach = k._trajectory_configs(PointArm("a"), ("a", 0), q0, q0, back, [None] * 3)
    assert reach.tolist() == [True, False, True]
    np.testing.assert_allclose(configs[2], [0.95, 0.0, 0.0])


def test_no_random_force_without_an_attraction() -> None:
    p = PlannerParams(w_rand=0.2)
    rng = np.random.default_rng(0)
    np.testing.assert_array_equal(guidance(np.zeros(3), [], p, rng), np.zeros(3))
    # A real deadlock (attraction cancelled by a repulsion) still gets its random push.
    f = guidance(np.array([0.01, 0, 0]), [np.array([-0.01, 0, 0])], p, rng)
    assert np.linalg.norm(f) == pytest.approx(0.2 * p.dr_max)
    # An idle candidate with no goal, or sitting on it, stays where it is.
    world = EmptyWorld()
    arm, mem = PointArm("b"), ObstacleMemory()
    q0 = world.configuration("b")
    for goal in (None, q0.copy()):
        q = q0.copy()
        for _ in range(200):
            q = move_candidate(Mover(world, arm, "b"), q, goal, None, ["a"], mem, p, 0.018, rng)
        np.testing.assert_array_equal(q, q0)


def test_visibility_leaves_unmeasured_points_out() -> None:
    """Every measured point is 0.5 m clear of the view cone: the index is 1 whether the
    distances were queried at every point or only at the ends (they used to count as 0)."""
    world = EmptyWorld(cone=True)
    n = 5

    def ctx(points: str) -> EvalContext:
        return EvalContext(robot="a", arm=PointArm("a"), point=0, selected=True,
                           times=np.arange(n) * 0.05, positions=np.zeros((n, 3)),
                           std=np.zeros((n, 3)), rotations=None, configs=np.zeros((n, 3)),
                           reachable=np.ones(n, bool), joint_velocity=np.zeros((n, 3)),
                           past_configs=[], world=world, distance_points=points)

    assert VisibilityIndex().evaluate(ctx("all")) == pytest.approx(1.0)
    assert VisibilityIndex().evaluate(ctx("ends")) == pytest.approx(1.0)


@pytest.mark.parametrize("field, value", [
    ("ntt_threshold", math.nan), ("dt", math.nan), ("dt", math.inf), ("texec_degree", -1),
    ("grasp_cycles", 0), ("abort_cooldown", -1.0), ("seed", -1), ("texec_min_samples", 50),
    ("max_tcp_speed", {"a": 0.0})])
def test_bad_kernel_configuration_is_refused(field: str, value: object) -> None:
    name = field if field != "max_tcp_speed" else "max_tcp_speed['a']"
    with pytest.raises(ValueError, match=re.escape(f"KernelConfig.{name} must be")):
        KernelConfig(**{field: value})  # type: ignore[arg-type]


def test_cycle_times_must_increase() -> None:
    k = kernel(EmptyWorld())
    with pytest.raises(ValueError, match="cycle times must increase"):
        k.step(0.0, np.zeros(3))                  # the kernel started at t0 = 0
    k.step(0.018, np.zeros(3))
    with pytest.raises(ValueError, match=r"t = 0\.018 is not after"):
        k.step(0.018, np.zeros(3))


def test_operator_motion_during_a_safety_stop_is_not_stored_up() -> None:
    """RSel runs into a wall at x > 5 cm: safety stop. The operator backs off 15 mm while
    stopped; after the reset the task moves by the next 1 mm command only."""
    k = kernel(EmptyWorld(wall_x=0.05))
    step = np.array([0.001, 0.0, 0.0])
    cmd, t = np.zeros(3), 0.0
    while k.state is not KernelState.FAULT:
        t += 0.018
        cmd = cmd + step
        k.step(t, cmd)
        assert t < 2.0
    for _ in range(15):
        t += 0.018
        cmd = cmd - step
        k.step(t, cmd)
    k.reset_fault()
    x0 = k.task_pose()[0][0]
    t += 0.018
    rec = k.step(t, cmd - step)
    assert rec.task_position[0] == pytest.approx(x0 - 0.001, abs=1e-9)


def test_cli_refuses_bad_values_before_running(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    cases = [(["--duration", "nan"], "argument --duration: got nan, expected a finite number"),
             (["--duration", "inf"], "argument --duration: got inf, expected a finite number"),
             (["--seed", "-1"], "argument --seed: got -1, expected an integer in [0,"),
             (["--plot", str(tmp_path / "run.txt")], "expected a .png, .pdf or .svg file"),
             (["--plot", str(tmp_path / "nope" / "run.png")],
              "(no such folder), expected an existing folder for the plot")]
    for extra, message in cases:
        assert main(["mrcp", "run", "cube_rotation", *extra]) == 2, extra
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err, extra


def test_cli_json_is_strict(capsys: pytest.CaptureFixture[str],
                            monkeypatch: pytest.MonkeyPatch) -> None:
    """NTT is inf whenever RSel has no useful time left: the JSON says null, not Infinity.

    (Since issue #17 no scenario's short run hands over at an infinite NTT, so the run's
    transfer list gets one more, with the NTT an RSel at texec = 0 gives.)"""
    from vasim.mrcp.scenarios.runner import RunResult

    real = RunResult.transfers

    def with_inf(self: RunResult) -> list[dict[str, object]]:
        return [*real(self), {"t_start": 1.0, "from": "R0", "to": "R1", "point": 0,
                              "ntt": math.inf, "cause": "rj", "t_done": None}]

    monkeypatch.setattr(RunResult, "transfers", with_inf)
    assert main(["mrcp", "run", "cube_translation", "--coarse", "--duration", "6",
                 "--json"]) == 0

    def refuse(token: str) -> None:
        raise AssertionError(f"non-standard JSON constant {token}")

    out = json.loads(capsys.readouterr().out, parse_constant=refuse)
    assert any(tr["ntt"] is None for tr in out["transfers"])
