"""Cube translation (seed sec. 4.5.2, Fig. 4.28): lifted from the table, carried and put back.
The seed's sequence of transfers: RJ (R0's θ5), Θ (R1's links 2-3 alignment), RJ (R0's
θ3), CR (the table) -> R0, which puts the cube down by the top face. The seed gives no
times for this experiment, so the test places each transfer on the path instead."""

from __future__ import annotations

import numpy as np

from tests.mrcp.test_scen_common import joint_margins, scenario_run
from vasim.mrcp.scenarios.cube_translation import END, WAYPOINTS


def test_the_seeds_sequence_rj_theta5_theta_rj_theta3_cr_table() -> None:
    res = scenario_run("cube_translation", 19.6)     # just past the fourth hand-over
    assert res.violations == []
    tr = res.transfers()
    assert [(x["from"], x["to"], x["cause"]) for x in tr] == [
        ("R0", "R1", "rj"), ("R1", "R0", "theta"), ("R0", "R1", "rj"), ("R1", "R0", "cr")]
    assert all(x["t_done"] is not None for x in tr)
    at = [next(s for s in res.samples if s.t == x["t_start"]) for x in tr]
    # (1) lifting by the top grasp, R0's joint nearest its limit is the wrist's θ5
    m = joint_margins(at[0].configs["R0"])
    assert int(np.argmin(m)) == 4 and 0.0 < m[4] < 0.15
    assert WAYPOINTS[0][2] < at[0].task_position[2] <= WAYPOINTS[1][2] + 1e-9
    # (2) high up, R1's arm almost straight: links 2-3 near alignment (θ3 = 90°) and its
    # translational Jacobian near rank loss, no joint at a limit
    from vasim.mrcp.backend import PybulletArm
    from vasim.mrcp.scenarios.base import rx60b_model

    q = at[1].configs["R1"]
    arm = PybulletArm(rx60b_model())
    try:
        smin = np.linalg.svd(arm.jacobian(q)[:3], compute_uv=False)[-1]
    finally:
        arm.close()
    assert abs(q[2] - np.pi / 2) < 0.4 and smin < 0.12
    assert joint_margins(q).min() > 0.1 and at[1].task_position[2] > 0.4
    # (3) coming down toward R0's base, R0's elbow folds to θ3's upper limit (3.92 rad)
    q = at[2].configs["R0"]
    m = joint_margins(q)
    assert int(np.argmin(m)) == 2 and m[2] < 0.15 and q[2] > 3.7
    # (4) near the table, to R0's top grasp (point 4, the +z face), which puts it down
    assert tr[3]["point"] == 4
    assert END[2] < at[3].task_position[2] < END[2] + 0.06
    last = res.samples[-1]
    assert last.rsel == "R0" and last.cutp == 4
    assert not [s.t for s in res.samples if s.colliding]
    assert not res.events("rsel_collision") and not res.events("rsel_hold")
    assert not res.events("transfer_abort")
