"""Cube rotation (seed sec. 4.5.2, Fig. 4.27): R1 turns the cube until its joint 5 nears its
limit; the task goes to R0 with RJ as the cause, before R1 has to refuse the operator. The
seed's sequence: one transfer (RJ, R1's θ5) and a change of the candidate's best grasp
point (RCan changes its CnTP); it gives no times."""

from __future__ import annotations

import numpy as np

from tests.mrcp.test_scen_common import joint_margins, scenario_run
from vasim.core.geometry import rot_z
from vasim.mrcp.scenarios.base import cube_points
from vasim.mrcp.scenarios.cube_rotation import RATE


def test_r1_hands_the_cube_to_r0_before_its_joint_5_limit() -> None:
    res = scenario_run("cube_rotation", 7.0)
    assert res.violations == []
    tr = res.transfers()
    assert len(tr) == 1
    first = tr[0]
    assert (first["from"], first["to"], first["cause"]) == ("R1", "R0", "rj")
    assert first["ntt"] >= 0.9 and first["t_done"] is not None
    # Roughly when: the wrist reaches θ5 = 2.01 rad after about 100 deg of turning
    # (measured by IK along the rotation: 96-102 deg), i.e. ~6.7 s at 15 deg/s.
    assert 0.7 * np.radians(100) / RATE < first["t_start"] < np.radians(100) / RATE
    # At the start of the transfer joint 5 is R1's joint nearest a limit, close but inside.
    start = next(s for s in res.samples if s.t == first["t_start"])
    m = joint_margins(start.configs["R1"])
    assert int(np.argmin(m)) == 4 and 0.0 < m[4] < 0.15
    # R1 never had to refuse the operator before the hand-over.
    assert not [t for t, _ in res.events("rsel_hold") if t < first["t_start"]]
    assert res.samples[-1].rsel == "R0"
    # R0 does not take the face turned toward the camera (-y): it would occlude the view.
    normal = rot_z(RATE * first["t_start"]) @ cube_points(0.03, 0.04, 0.05)[first["point"]].position
    assert normal[1] / np.linalg.norm(normal) > -0.7


def test_the_candidate_changes_its_best_grasp_point_before_the_transfer() -> None:
    """The seed's second situation of Fig. 4.27: RCan (R0) changes its best evaluated CnTP
    while R1 turns the cube, and takes the cube at the point it ends up preferring."""
    res = scenario_run("cube_rotation", 7.0)
    (tr,) = res.transfers()
    before = [s.robots["R0"].point for s in res.samples
              if s.t < tr["t_start"] and s.rsel == "R1" and "R0" in s.robots]
    changes = [k for k in range(1, len(before)) if before[k] != before[k - 1]]
    assert before[0] == 1 and changes                  # starts at its -x pre-grasp, then moves
    assert before[-1] == tr["point"] != before[0]
