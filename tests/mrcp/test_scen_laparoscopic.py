"""Laparoscopic set-up (seed sec. 5.2): two tool robots through trocars and a camera robot.
The object is carried through a ring: the holder's shaft would hit the ring, so the task
goes to the other tool (CR) once the far end is through; the fulcrum constraint holds
throughout and the tool-orientation cone rules out the tool whose trocar is left behind."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("vasim.mrcp.backend")

from tests.mrcp.test_scen_common import scenario_run
from vasim.mrcp.scenarios import get_scenario
from vasim.mrcp.scenarios.base import ScenarioOptions
from vasim.mrcp.scenarios.laparoscopic_rings import (
    HALF_ROD,
    RING_X,
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
    assert x - HALF_ROD < RING_X < x + HALF_ROD            # the rod straddles the ring
    # R1 carried the object to the goal; R0's trocar is then too far: its cone rules it out.
    last = res.samples[-1]
    assert last.rsel == "R1" and abs(last.task_position[0] - X_GOAL) < 0.01
    assert last.robots["R1"].values["cone"] > 0.5
    assert last.robots["R0"].values["cone"] < 0.05
    # Every commanded configuration keeps each shaft through its trocar.
    setup = sc.build(ScenarioOptions(coarse=True))
    try:
        for r in ("R0", "R1"):
            err = max(setup.arms[r].fulcrum_error(s.configs[r])     # type: ignore[attr-defined]
                      for s in res.samples)
            assert err < 1e-5, f"{r}: shaft {err * 1e3:.3f} mm off its trocar"
    finally:
        setup.close()
    assert np.isfinite(res.samples[-1].task_position).all()
