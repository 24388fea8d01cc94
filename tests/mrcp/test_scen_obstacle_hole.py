"""Obstacle with a hole (seed sec. 4.5.1, Figs. 4.22-4.26): a bar carried through the hole
of a moving wall, back, and through again. The seed's sequence: three transfers at about
5.5, 11.5 and 15.5 s, the first two on collision risk against the moving obstacle (the
bar straddling the wall), the third forced by R0's wrist θ5 nearing its limit."""

from __future__ import annotations

import numpy as np

from tests.mrcp.test_scen_common import joint_margins, scenario_run
from vasim.mrcp.scenarios.obstacle_hole import HALF_BAR, bar_roll

#: The seed's transfer times [s] (sec. 4.5.1: "t ≈ 5.5s, t ≈ 11.5s and t ≈ 15.5s").
SEED_TIMES = (5.5, 11.5, 15.5)
#: Tolerance [s]: the seed gives the times to half a second ("≈ 5.5 s" read off Fig. 4.26's
#: time axis) and the coarse run decides on a 36 ms grid.
TOL = 0.5


def test_the_seeds_sequence_cr_cr_then_r0s_theta5_limit() -> None:
    res = scenario_run("obstacle_hole", 16.2)      # just past the third hand-over
    assert res.violations == []
    tr = res.transfers()
    assert [(x["from"], x["to"], x["point"], x["cause"]) for x in tr] == [
        ("R0", "R1", 1, "cr"), ("R1", "R0", 0, "cr"), ("R0", "R1", 1, "rj")]
    assert all(x["t_done"] is not None for x in tr)
    for x, t_seed in zip(tr, SEED_TIMES, strict=True):
        assert abs(x["t_start"] - t_seed) < TOL, (x["t_start"], t_seed)
    # The CR hand-overs come while the bar straddles the wall: the receiver's end is
    # through the hole on its side, the giver's still on its own.
    for x in tr[:2]:
        s = next(s for s in res.samples if s.t == x["t_start"])
        y = s.task_position[1]
        ends = {0: y - HALF_BAR, 1: y + HALF_BAR}
        sign = 1.0 if x["to"] == "R1" else -1.0
        assert sign * ends[x["point"]] > 0.05 and sign * ends[1 - x["point"]] < 0.0
    # The third: R0's joint nearest its limit is θ5 (the wrist, bent by the bar's roll),
    # within 10 % of its half range, the roll under way and the far end through the hole.
    last = tr[2]
    s = next(s for s in res.samples if s.t == last["t_start"])
    m = joint_margins(s.configs["R0"])
    assert int(np.argmin(m)) == 4 and 0.0 < m[4] < 0.1
    assert bar_roll(last["t_start"]) > np.radians(10.0)
    assert s.task_position[1] + HALF_BAR > 0.05
    # Nobody ever touched the wall or the other robot (candidates included).
    assert not [s.t for s in res.samples if s.colliding]
    assert not res.events("rsel_hold") and not res.events("transfer_abort")


def test_the_operators_script_holds_passes_and_rolls_as_documented() -> None:
    from vasim.mrcp.scenarios.obstacle_hole import HOLD, ROLL_MAX, SPEED, Y_END, bar_y

    assert SPEED * 6.0 == 2 * Y_END                              # a pass takes 6 s
    assert bar_y(0.0) == bar_y(HOLD) == -Y_END                   # the initial hold
    assert abs(bar_y(HOLD + 3.0)) < 1e-12                        # mid first pass: y = 0
    assert bar_y(HOLD + 6.0) == Y_END and abs(bar_y(HOLD + 9.0)) < 1e-12
    t3 = HOLD + 12.0                                             # the third pass starts
    assert bar_roll(t3) == 0.0 and bar_roll(t3 - 5.0) == 0.0
    assert abs(bar_roll(t3 + 1.0) - np.radians(12.0)) < 1e-12    # 12 deg/s
    assert bar_roll(t3 + 5.0) == ROLL_MAX == np.radians(30.0)    # capped
    assert bar_y(HOLD + 18.0) == bar_y(20.5) == Y_END            # ends through the hole
