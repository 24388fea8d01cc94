"""Cube translation (seed Fig. 4.28): lifted from the table, carried and put back; the task
changes hands for a joint limit (R0's θ5 first, as in the seed), a dexterity loss (Θ) and
collision risk, and the robot placing the cube on the table holds it by the top face."""

from __future__ import annotations

import numpy as np

from tests.mrcp.test_scen_common import joint_margins, scenario_run
from vasim.mrcp.scenarios.cube_translation import WAYPOINTS, CubeTranslation


def test_transfers_for_a_joint_limit_a_singularity_and_the_table() -> None:
    res = scenario_run("cube_translation", CubeTranslation.duration)
    assert res.violations == []
    tr = res.transfers()
    assert all(x["t_done"] is not None for x in tr)
    causes = [x["cause"] for x in tr]
    assert {"rj", "theta", "cr"} <= set(causes)
    # First: R0 (top grasp) lifting the cube runs its wrist θ5 to its upper limit.
    first = tr[0]
    assert (first["from"], first["to"], first["cause"]) == ("R0", "R1", "rj")
    start = next(s for s in res.samples if s.t == first["t_start"])
    m = joint_margins(start.configs["R0"])
    assert int(np.argmin(m[:5])) == 4 and 0.0 < m[4] < 0.15
    # Θ: the first dexterity hand-over comes high up, with the holder's elbow opened toward
    # the straight arm (links 2-3 aligned at θ3 = 90° = 1.571 rad) and its translational
    # Jacobian losing rank (measured σ_min 0.10 there, 0.19-0.20 at the cr hand-overs).
    sing = next(x for x in tr if x["cause"] == "theta")
    s = next(s for s in res.samples if s.t == sing["t_start"])
    q = s.configs[sing["from"]]
    from vasim.mrcp.backend import PybulletArm
    from vasim.mrcp.scenarios.base import rx60b_model

    arm = PybulletArm(rx60b_model())
    try:
        smin = np.linalg.svd(arm.jacobian(q)[:3], compute_uv=False)[-1]
    finally:
        arm.close()
    assert s.task_position[2] > 0.25 and q[2] < 2.3 and smin < 0.12
    # Last: going down to the table, the side grasp's wrist would hit it: the task goes to
    # the top grasp (point 4, +z face) on a CR cause while the cube is still above the table.
    last = tr[-1]
    assert last["cause"] == "cr" and last["point"] == 4
    end = next(s for s in res.samples if s.t == last["t_start"])
    assert end.rsel == last["from"]
    z = end.task_position[2]
    assert WAYPOINTS[-1][2] < z < WAYPOINTS[-2][2]            # in the final descent
    assert np.allclose(end.task_position[:2], WAYPOINTS[-1][:2], atol=0.01)
    # Nobody refused the operator and no safety stop happened.
    assert not res.events("rsel_collision") and not res.events("rsel_hold")
    assert res.samples[-1].rsel == last["to"]
