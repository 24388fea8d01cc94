"""Q of the MRCP study: the rings' deformation by contacts (vasim.trials.teleop_quality)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.abdomen.contact import ToolPose
from vasim.abdomen.world import Abdomen
from vasim.operator.needle import RING_CLEARANCE, needle_task
from vasim.trials.teleop import TeleopTrial
from vasim.trials.teleop_config import TeleopTrialConfig
from vasim.trials.teleop_quality import TargetDeformation


def test_q_is_displacement_times_time_summed_over_targets_in_mm_s() -> None:
    q = TargetDeformation()
    q.add(0.004, [0.001, 0.0, 0.003])      # 1 mm + 3 mm for 4 ms = 0.016 mm s
    q.add(0.004, [0.0, 0.0, 0.0])
    q.add(0.002, [0.0005])                 # 0.5 mm for 2 ms = 0.001 mm s
    assert q.total_mm_s == pytest.approx(0.017, rel=1e-12)
    assert q.peak_mm == pytest.approx(3.0)
    assert q.duration == pytest.approx(0.010)
    assert TargetDeformation().as_metrics() == {"target_deformation": 0.0,
                                                "target_deformation_peak": 0.0}
    with pytest.raises(ValueError, match="dt"):
        q.add(0.0, [0.001])
    with pytest.raises(ValueError, match="displacements"):
        q.add(0.004, [-0.001])


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.floats(1e-4, 0.01),
                          st.lists(st.floats(0.0, 0.02), min_size=1, max_size=6)),
                min_size=1, max_size=30))
def test_q_is_the_riemann_sum_and_never_negative(steps: list[tuple[float, list[float]]]) -> None:
    q = TargetDeformation()
    for dt, d in steps:
        q.add(dt, d)
    expected = math.fsum(1e3 * dt * math.fsum(d) for dt, d in steps)
    assert q.total_mm_s == pytest.approx(expected, rel=1e-9, abs=1e-12)
    assert q.peak_mm == pytest.approx(1e3 * max(max(d) for _, d in steps))
    assert q.total_mm_s >= 0.0


def test_a_tool_pressing_under_a_ring_gives_the_displacement_against_a_tool_free_twin() -> None:
    # Independent value: the same abdomen stepped with no tool is where the rings would be
    # with breathing alone; Q = sum dt * sum_j |p_j - p_j(twin)| over the steps [mm s].
    task = needle_task()
    pressed, twin = Abdomen("default"), Abdomen("default")
    pressed.bind_targets(task.rings)
    twin.bind_targets(task.rings)
    surface = task.rings[1] - np.array([0.0, 0.0, RING_CLEARANCE])  # under ring 1 at rest
    tool = ToolPose(surface + np.array([0.04, 0.0, 0.15]),
                    surface - np.array([0.0, 0.0, 0.004]))      # 4 mm into the loop
    q = TargetDeformation()
    independent = 0.0
    for _ in range(100):                                       # 0.4 s at 4 ms
        a = pressed.step({"left": tool})
        b = twin.step(None)
        q.add(pressed.dt, a.target_displacement)
        independent += 1e3 * pressed.dt * float(
            np.linalg.norm(np.asarray(a.targets) - np.asarray(b.targets), axis=1).sum())
    assert a.in_contact
    assert q.total_mm_s > 0.05                                 # the loop under ring 1 moved
    assert q.total_mm_s == pytest.approx(independent, rel=1e-6)
    # the ring rides on the loop the tool pushes 4 mm below its rest surface: it is pushed
    # by about the tool's depth (the tissue wraps the 2.5 mm capsule)
    assert 3.0 < q.peak_mm < 5.0


def test_a_trial_without_contact_has_q_zero_and_with_a_pressing_tool_q_above_zero() -> None:
    free = TeleopTrial(TeleopTrialConfig(mode="mrcp", seed=3, max_time=1.0), n_rings=2)
    m = free.run().trial_metrics
    free.station.close()
    assert m["contact_time"] == 0.0 and m["target_deformation"] == 0.0
    assert m["target_deformation_peak"] == 0.0
    # StdT: the idle left instrument pushed 4 mm into the loop under ring 1
    tr = TeleopTrial(TeleopTrialConfig(mode="stdt", seed=11, max_time=1.0))
    st_ = tr.station
    surface = tr.task.rings[1] - np.array([0.0, 0.0, RING_CLEARANCE])
    qc = st_.arms["left"].ik(surface - np.array([0.0, 0.0, 0.004]), None,
                             st_.world.configuration("left"))
    assert qc is not None
    st_.world.set_configuration("left", qc)
    m = tr.run().trial_metrics
    st_.close()
    assert m["contact_time"] > 0.5
    assert m["target_deformation"] > 0.05
    assert m["target_deformation"] == pytest.approx(tr.deformation.total_mm_s)
