"""Laparoscopic set-up (seed sec. 5.2): two tool robots through trocars and a camera robot.
The object is carried out from under an intestine loop (the first tool's shaft passes under
it, near its tip) and through two rings: the holder's shaft would hit the first ring, so the
task goes to the other tool (CR) while the rod straddles it, its leading end at the second
ring; that tool takes that end and carries the rest through with no further hand-over; the fulcrum
constraint holds throughout and the tool-orientation cone rules out the tool whose trocar is
left behind."""

from __future__ import annotations

import numpy as np

from tests.mrcp.test_scen_common import scenario_run
from vasim.mrcp.scenarios import get_scenario
from vasim.mrcp.scenarios.base import ScenarioOptions
from vasim.mrcp.scenarios.laparoscopic_rings import (
    HALF_ROD,
    LOOP_X,
    RING_X,
    RING_X2,
    SPEED,
    X_GOAL,
    X_START,
)


def test_the_ring_hands_the_object_to_the_other_tool() -> None:
    sc = get_scenario("laparoscopic_rings")
    res = scenario_run("laparoscopic_rings", (X_GOAL - X_START) / SPEED + 0.5)
    assert res.violations == []
    assert not [s.t for s in res.samples if s.colliding]          # shafts included
    tr = res.transfers()
    assert [(x["from"], x["to"], x["point"], x["cause"]) for x in tr] == [
        ("R0", "R1", 1, "cr")]
    assert tr[0]["t_done"] is not None
    s = next(s for s in res.samples if s.t == tr[0]["t_start"])
    x = s.task_position[0]
    assert x - HALF_ROD < RING_X < x + HALF_ROD            # the rod straddles ring 1 ...
    assert abs(x + HALF_ROD - RING_X2) < 0.01              # ... its leading end at ring 2
    # Roughly when: the far end reaches the first ring at (RING_X - HALF_ROD - X_START) / SPEED
    # = 1.1 s; CR sees the holder's shaft close in on the rim once the rod straddles it.
    assert (RING_X - HALF_ROD - X_START) / SPEED < tr[0]["t_start"] < \
        (RING_X + HALF_ROD - X_START) / SPEED
    # R1 carried the object to the goal; R0's trocar is then too far: its cone rules it out.
    last = res.samples[-1]
    assert last.rsel == "R1" and abs(last.task_position[0] - X_GOAL) < 0.01
    # The rod's trailing end started under the loop; the whole rod ends past both rings.
    first = res.samples[0]
    assert first.task_position[0] - HALF_ROD < LOOP_X < first.task_position[0]
    assert last.task_position[0] - HALF_ROD > max(RING_X, RING_X2)
    assert last.robots["R1"].values["cone"] > 0.5
    assert last.robots["R0"].values["cone"] < 0.05
    # Every commanded configuration keeps each shaft through its trocar.
    setup = sc.build(ScenarioOptions(coarse=True))
    try:
        # The obstacles are close calls, not scenery: R0's shaft passes under the loop a
        # few millimetres from it at the start, R1's shaft is near ring 2 when it grasps.
        def clearance(robot: str, q: np.ndarray, prefix: str) -> float:
            setup.world.set_configuration(robot, q)
            return min(setup.world.min_distance(robot, b).distance
                       for b in setup.world.obstacle_names() if b.startswith(prefix))

        assert 0.0 < clearance("R0", first.configs["R0"], "intestine_loop_") < 0.02
        done = next(s for s in res.samples if s.t == tr[0]["t_done"])
        assert 0.0 < clearance("R1", done.configs["R1"], "ring1_") < 0.03
        for r in ("R0", "R1"):
            err = max(setup.arms[r].fulcrum_error(s.configs[r])     # type: ignore[attr-defined]
                      for s in res.samples)
            assert err < 1e-5, f"{r}: shaft {err * 1e3:.3f} mm off its trocar"
    finally:
        setup.close()
    assert np.isfinite(res.samples[-1].task_position).all()
