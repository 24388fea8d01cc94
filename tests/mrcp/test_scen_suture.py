"""The combined StdT/MRCP suture (issue #28 item 1; seed sec. 5.5): one coarse run checked
for the subtask graph, the needle transfers, the needle against the robots (an independent
pybullet query), the thread's length, the stitches' entry and exit points."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from vasim.mrcp.modes import SUTURE_SUBTASK_MODE
from vasim.mrcp.scenarios import get_scenario
from vasim.mrcp.scenarios import suture_geometry as g
from vasim.mrcp.scenarios.base import ScenarioOptions
from vasim.mrcp.scenarios.runner import RunResult, run
from vasim.mrcp.scenarios.suture_combined import (
    RELEASE_S,
    THREAD_LENGTH,
    subtask_sequence,
)


@pytest.fixture(scope="module")
def result() -> RunResult:
    return run(get_scenario("suture_combined"), ScenarioOptions(coarse=True))


def test_subtasks_in_the_seed_order_with_their_modes(result: RunResult) -> None:
    subs = result.extra["subtasks"]
    assert [s["name"] for s in subs] == subtask_sequence(3)
    assert subs[0]["name"] == "pre_suture" and subs[-1]["name"] == "knot_tying"
    for s in subs:
        assert s["mode"] == SUTURE_SUBTASK_MODE[s["name"]].value.lower()
        assert s["mode"] in ("stdt", "mrcp")
        assert s["t_end"] > s["t_start"]
    for a, b in itertools.pairwise(subs):
        assert b["t_start"] == a["t_end"]           # contiguous
    # the samples carry the same graph: StdT first and last, MRCP in between
    modes = [s.mode for s in result.samples]
    assert modes[0] == "StdT" and modes[-1] == "StdT" and "MRCP" in modes


def test_every_needle_transfer_holds_a_transfer_from_r0_to_r1(result: RunResult) -> None:
    subs = result.extra["subtasks"]
    transfers = result.transfers()
    passes = [s for s in subs if s["name"] == "pass_through"]
    needle = [s for s in subs if s["name"] == "needle_transfer"]
    assert len(needle) == 3
    for p, n in zip(passes, needle, strict=True):
        inside = [tr for tr in transfers if tr["t_done"] is not None
                  and n["t_start"] < tr["t_done"] <= n["t_end"] + 1e-9]
        assert len(inside) == 1, (n, transfers)
        tr = inside[0]
        assert (tr["from"], tr["to"], tr["point"]) == ("R0", "R1", 1)
        # the transfer was started by the kernel at the end of the pass-through: the
        # tissue approaching the holding tool (collision risk), not by the script
        assert math.isclose(tr["t_start"], p["t_end"], abs_tol=1e-9)
        assert tr["cause"] == "cr"
    # the needle goes back to R0 in every needle return
    for r in (s for s in subs if s["name"] == "needle_return"):
        back = [tr for tr in transfers if tr["t_done"] is not None and tr["to"] == "R0"
                and r["t_start"] < tr["t_done"] <= r["t_end"] + 1e-9]
        assert back, r


def test_the_run_has_no_violations(result: RunResult) -> None:
    assert result.violations == []


def test_needle_never_inside_a_robot_by_pybullet(result: RunResult) -> None:
    """Independent of the run's own capsule test: a 0.1 mm probe sphere at needle points,
    pybullet's distance to each robot's collision geometry; points in the jaws of a robot
    on the needle (holder, receiving robot, or one that let go within RELEASE_S) exempt."""
    setup = get_scenario("suture_combined").build(ScenarioOptions(coarse=True))
    world = setup.world
    try:
        world.add_sphere("probe", 1e-4, np.zeros(3))
        jaws: dict[str, float] = {}
        checked = 0
        for s in result.samples:
            for r in s.holders:
                jaws[r] = s.t
            if s.rcnt is not None:
                jaws[s.rcnt] = s.t
            if round(s.t / 0.036) % 4:
                continue
            for r, q in s.configs.items():
                world.set_configuration(r, q)
            pts = s.task_position + g.needle_points(19) @ s.task_rotation.T
            for r in world.robot_names():
                tip = setup.arms[r].tcp_pose(s.configs[r])[0] if r in setup.arms else None
                exempt = r in jaws and s.t - jaws[r] <= RELEASE_S + 1e-9
                for p in pts:
                    if exempt and tip is not None and np.linalg.norm(p - tip) <= g.JAW:
                        continue
                    world.set_obstacle_pose("probe", p)
                    d = world.min_distance(r, "probe", 0.05).distance
                    assert d > 0.0, (s.t, r, p)
                    checked += 1
        assert checked > 1000
    finally:
        world.close()


def test_thread_length_is_kept_and_each_stitch_tightened(result: RunResult) -> None:
    for s in result.samples:
        sc = s.scene
        nodes = np.asarray(sc["thread"])
        pinned = np.asarray(sc["pinned"])
        seg = np.linalg.norm(np.diff(nodes, axis=0), axis=1)
        assert np.allclose(seg, sc["free_length"] / len(seg), rtol=0, atol=1e-9)
        path = float(np.linalg.norm(np.diff(pinned, axis=0), axis=1).sum()) if len(
            pinned) > 1 else 0.0
        assert path + sc["slack"] + seg.sum() + sc["reserve"] == pytest.approx(
            THREAD_LENGTH, abs=1e-9)
        assert sc["attach_gap"] <= 5e-4
        tail = s.task_position + s.task_rotation @ g.TAIL
        assert np.linalg.norm(nodes[-1] - tail) <= 5e-4
    ends = {s["t_end"] for s in result.extra["subtasks"] if s["name"] == "tighten_thread"}
    tightened = [s for s in result.samples if any(math.isclose(s.t, e) for e in ends)]
    assert len(tightened) == 3
    assert all(s.scene["slack"] == 0.0 for s in tightened)
    assert len(result.samples[-1].scene["pinned"]) == 1 + 2 * 3      # anchor + 3 stitches


def test_each_stitch_enters_the_left_lip_and_exits_the_right(result: RunResult) -> None:
    for k, st in enumerate(result.extra["stitches"]):
        entry, exit_ = np.asarray(st["entry"]), np.asarray(st["exit"])
        assert entry[0] < -g.INCISION_GAP / 2 and exit_[0] > g.INCISION_GAP / 2
        assert entry[1] == pytest.approx(g.STITCH_Y[k], abs=1e-3)
        assert exit_[1] == pytest.approx(g.STITCH_Y[k], abs=1e-3)
        assert st["t_entry"] < st["t_exit"]
        nominal_in, nominal_out = g.entry_exit(k)
        assert np.linalg.norm(entry - nominal_in) < 0.004
        assert np.linalg.norm(exit_ - nominal_out) < 0.004


def test_json_summary_has_subtasks_transfers_and_violations(result: RunResult) -> None:
    d = result.to_dict()
    for key in ("subtasks", "transfers", "violations", "stitches", "thread"):
        assert key in d
    assert set(d["subtasks"][0]) >= {"name", "mode", "t_start", "t_end"}


def test_cli_text_lists_the_subtasks_and_a_cut_run_is_not_a_violation(
        capsys: pytest.CaptureFixture[str]) -> None:
    from vasim.cli import main

    code = main(["mrcp", "run", "suture_combined", "--coarse", "--duration", "1.2"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "subtasks:" in out and "stdt  pre_suture" in out
    assert "invariants: task always grasped" in out
