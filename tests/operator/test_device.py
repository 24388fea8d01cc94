"""Tests of the scripted operator as a device (vasim/haptics/devices/scripted.py)."""

from __future__ import annotations

import numpy as np
import pytest

from vasim.core.errors import DeviceError
from vasim.haptics.observation import OperatorObservation
from vasim.haptics.servo import NullPlant, ServoLoop
from vasim.operator.device import ScriptedDevice
from vasim.operator.scripted import OperatorProfile, ScriptedOperator
from vasim.tasks import point_task, trajectory_task


def _obs(k: int, tcp: np.ndarray, goal: np.ndarray) -> OperatorObservation:
    return OperatorObservation(t=k * 1e-3, dt=1e-3, tcp=tcp, goal=goal, goal_index=0,
                               force=np.array([0.0, 0.1, 0.0]), ms_factors=np.full(3, 2.0))


def test_position_is_the_integral_of_the_operator_increments() -> None:
    """Same operator, same observations: the device's positions are the cumulative sum of
    the increments ``ScriptedOperator.step`` returns (an independent run, same seed)."""
    task = point_task()
    start = np.asarray(task.start, dtype=float)
    goal = np.asarray(task.points[0], dtype=float)
    dev = ScriptedDevice(ScriptedOperator(OperatorProfile(), task, seed=5), start)
    ref = ScriptedOperator(OperatorProfile(), task, seed=5)
    ref.reset(start)
    dev.start()
    x_ref = start.copy()
    for k in range(400):
        tcp = start + 0.5 * (x_ref - start)  # any slave the plant reports (MS = 2)
        dev.observe(_obs(k, tcp, goal))
        s = dev.read()
        if k > 0:
            x_ref = x_ref + ref.step(_obs(k, tcp, goal))
        np.testing.assert_array_equal(s.position, x_ref)
        assert s.t == pytest.approx(k * 1e-3)
    assert dev.standalone_steps == 0


def test_standalone_reaches_the_points() -> None:
    task = trajectory_task(0)
    dev = ScriptedDevice(ScriptedOperator(OperatorProfile.expert(), task, seed=2), task.start)
    loop = ServoLoop(dev, NullPlant(), home=task.start)
    loop.run_ticks(4000)
    loop.stop()
    assert dev.goal_index >= 3  # a few POIs of the path reached in 4 s
    assert dev.standalone_steps == 3999
    np.testing.assert_allclose(loop.latest.master, dev.position, atol=1e-12)


def test_start_resets_and_read_needs_start() -> None:
    task = point_task()
    dev = ScriptedDevice(ScriptedOperator(OperatorProfile(), task, seed=1), task.start)
    with pytest.raises(DeviceError, match="before start"):
        dev.read()
    dev.start()
    a = [dev.read().position for _ in range(50)]
    dev.start()
    b = [dev.read().position for _ in range(50)]
    np.testing.assert_array_equal(np.array(a), np.array(b))
    with pytest.raises(ValueError, match="dt"):
        ScriptedDevice(dev.operator, task.start, dt=0.0)
