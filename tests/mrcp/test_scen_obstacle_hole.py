"""Obstacle with a hole (seed Fig. 4.22): a bar carried three times through the hole of a
moving wall; each pass ends in a CR-driven transfer to the robot on the other side, which
has moved to the end that came through without touching the wall or the other robot."""

from __future__ import annotations

from tests.mrcp.test_scen_common import scenario_run
from vasim.mrcp.scenarios.obstacle_hole import HALF_BAR, PASSES, SPEED, Y_END


def test_three_collision_risk_transfers_through_the_moving_hole() -> None:
    res = scenario_run("obstacle_hole", PASSES * 2 * Y_END / SPEED)
    assert res.violations == []
    tr = res.transfers()
    assert [(x["from"], x["to"], x["point"]) for x in tr] == [
        ("R0", "R1", 1), ("R1", "R0", 0), ("R0", "R1", 1)]
    assert all(x["cause"] == "cr" and x["t_done"] is not None for x in tr)
    # One transfer per pass, while the bar straddles the wall: the receiver's end is
    # through the hole on its side, the giver's still on its own.
    for k, x in enumerate(tr):
        s = next(s for s in res.samples if s.t == x["t_start"])
        assert k * 2 * Y_END / SPEED < x["t_start"] < (k + 1) * 2 * Y_END / SPEED
        y = s.task_position[1]
        ends = {0: y - HALF_BAR, 1: y + HALF_BAR}
        sign = 1.0 if x["to"] == "R1" else -1.0
        assert sign * ends[x["point"]] > 0.05 and sign * ends[1 - x["point"]] < 0.0
    # Nobody ever touched the wall or the other robot (candidates included).
    assert not [s.t for s in res.samples if s.colliding]
    assert not res.events("rsel_hold") and not res.events("transfer_abort")
