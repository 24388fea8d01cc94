"""Faucet (seed sec. 1.2.2): two robots alternate turning a three-spoke wheel that must
never be released; each hand-over comes as the giver's flange joint θ6 winds up to its
limit (RJ), and the wheel keeps turning the commanded way."""

from __future__ import annotations

import itertools

import numpy as np

from tests.mrcp.test_scen_common import joint_margins, scenario_run


def test_robots_alternate_and_the_faucet_is_never_released() -> None:
    res = scenario_run("faucet", 8.0)
    assert res.violations == []                 # includes: some robot always holds a spoke
    assert all(s.holders for s in res.samples)
    tr = res.transfers()
    assert len(tr) >= 4
    assert all(x["cause"] == "rj" for x in tr), [x["cause"] for x in tr]
    assert all(x["t_done"] is not None for x in tr[:-1])      # the last may be under way
    # They alternate: each transfer goes to the robot that did not hold the wheel.
    assert all(x["from"] != x["to"] for x in tr)
    assert all(a["to"] == b["from"] for a, b in itertools.pairwise(tr))
    # At every hand-over θ6 (clockwise turning winds the flange) is the giver's joint nearest
    # a limit, within a quarter of its half range (RJ alarms earlier the faster the joint
    # approaches: the operator catches up after each transfer, b drops).
    for x in tr:
        s = next(s for s in res.samples if s.t == x["t_start"])
        m = joint_margins(s.configs[x["from"]])
        assert int(np.argmin(m)) == 5 and m[5] < 0.25, (x["t_start"], m)
    # The wheel turned clockwise, most of a revolution in 8 s (480° commanded, minus the
    # transfer cycles during which the operator is decoupled), without a safety stop.
    angles = np.unwrap([np.arctan2(s.task_rotation[1, 0], s.task_rotation[0, 0])
                        for s in res.samples if s.task_rotation is not None])
    assert angles[-1] < -1.5 * np.pi and np.all(np.diff(angles) <= 1e-9)
    assert not res.events("rsel_collision")
