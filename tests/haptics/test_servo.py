"""Tests of the servo loop (vasim/haptics/servo.py): clutch/indexing, saturation, the
plant hooks, determinism of ``run_ticks``, error handling, the observation hook of the
scripted device, the device-scheduler driver and one real-time smoke run (no timing
thresholds: performance is measured by bench/haptics.py)."""

from __future__ import annotations

import math
import sys
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.polling import wait_until
from vasim.core.errors import DeviceError
from vasim.haptics.device import BUTTON_1, BUTTON_2, OMNI_LIMITS, DeviceLimits, DeviceSample
from vasim.haptics.devices.emulator import EmulatorDevice
from vasim.haptics.observation import OperatorObservation
from vasim.haptics.servo import (
    ClutchState,
    CoupledToolPlant,
    NullPlant,
    ServoLoop,
    clutch_update,
)
from vasim.operator.device import ScriptedDevice
from vasim.operator.scripted import OperatorProfile, ScriptedOperator
from vasim.tasks import point_task


class Spy:
    """A plant: a spring toward ``anchor`` (gain ``k``), recording its calls."""

    def __init__(self, k: float = 100.0, anchor=(0.0, 0.0, 0.0),
                 fail_at: int | None = None):
        self.k, self.anchor, self.fail_at = k, np.array(anchor), fail_at
        self.calls: list[str] = []
        self.masters: list[np.ndarray] = []
        self.times: list[float] = []
        self.buttons: list[int] = []

    def on_start(self, t: float) -> None:
        self.calls.append("start")

    def tick(self, t: float, master: np.ndarray, buttons: int) -> np.ndarray:
        if self.fail_at is not None and len(self.masters) == self.fail_at:
            raise RuntimeError("plant exploded")
        self.masters.append(master.copy())
        self.times.append(t)
        self.buttons.append(buttons)
        return -self.k * (master - self.anchor)

    def on_stop(self) -> None:
        self.calls.append("stop")


def _hand(t: float) -> np.ndarray:
    return np.array([0.03 * math.sin(2 * math.pi * t), 0.01 * t, 0.0])


# -- clutch (pure) ------------------------------------------------------------------------

@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(st.floats(-0.05, 0.05), st.floats(-0.05, 0.05),
                          st.floats(-0.05, 0.05), st.booleans()), min_size=2, max_size=60))
def test_clutch_master_moves_only_with_coupled_increments(steps: list) -> None:
    """Master increments equal device increments on coupled ticks (the press tick included:
    the master freezes where it is then), are zero while clutched and at the release, so
    the master never jumps (the offset is re-indexed)."""
    state = ClutchState()
    prev_dev = prev_master = None
    prev_pressed = False
    for x, y, z, pressed in steps:
        dev = (x, y, z)
        state, master = clutch_update(state, dev, pressed)
        if prev_dev is not None:
            dm = np.subtract(master, prev_master)
            if prev_pressed:  # held since the last tick (or released now): frozen
                np.testing.assert_allclose(dm, 0.0, atol=1e-15)
            else:
                np.testing.assert_allclose(dm, np.subtract(dev, prev_dev), atol=1e-12)
        prev_dev, prev_master, prev_pressed = dev, master, pressed
    assert state.count == sum(1 for i, s in enumerate(steps)
                              if s[3] and (i == 0 or not steps[i - 1][3]))


# -- the loop -----------------------------------------------------------------------------

def test_clutch_in_the_loop_freezes_the_master_zeroes_force_and_reindexes() -> None:
    press = (0.2, 0.4)  # clutch held for t in [0.2, 0.4)
    dev = EmulatorDevice(hand=_hand,
                         buttons=lambda t: BUTTON_2 if press[0] <= t < press[1] else 0)
    plant = Spy(k=20.0)
    loop = ServoLoop(dev, plant, record=True)
    loop.run_ticks(700)
    loop.stop()
    m = np.array(plant.masters)
    stream = loop.recording.stream()
    f = loop.trace.array()[:, 5:8]
    i0, i1 = 200, 400  # first clutched tick, first released tick
    # pressing freezes the master where it is (tick i0's position) until the release
    np.testing.assert_array_equal(m[i0:i1 + 1], np.repeat(m[i0:i0 + 1], i1 + 1 - i0, axis=0))
    assert np.all(f[i0:i1] == 0.0) and np.all(np.linalg.norm(f[i1 + 1:], axis=1) > 0)
    assert loop.clutch.count == 1
    # after the release the master continues from where it was frozen, with the device's
    # increments: the offset master - device is re-indexed once
    offset_before = m[i0] - stream.position[i0]
    offset_after = m[i1:] - stream.position[i1:]
    np.testing.assert_allclose(offset_after - offset_after[0], 0.0, atol=1e-15)
    np.testing.assert_allclose(m[i1], m[i0], atol=1e-15)
    assert not np.allclose(offset_after[0], offset_before)


def test_other_buttons_do_not_clutch_and_reach_the_plant() -> None:
    dev = EmulatorDevice(hand=_hand, buttons=BUTTON_1)
    plant = Spy()
    loop = ServoLoop(dev, plant)
    loop.run_ticks(50)
    loop.stop()
    assert loop.clutch.count == 0 and set(plant.buttons) == {BUTTON_1}


def test_home_indexing_and_simulated_time() -> None:
    dev = EmulatorDevice(hand=_hand)
    plant = Spy()
    loop = ServoLoop(dev, plant, home=[0.1, 0.2, 0.3], rate_hz=500.0)
    loop.run_ticks(10)
    assert plant.times == [k / 500.0 for k in range(10)]
    np.testing.assert_allclose(plant.masters[0], [0.1, 0.2, 0.3], atol=1e-15)
    loop.run_ticks(5)  # continues the same run
    assert plant.times[-1] == 14 / 500.0 and plant.calls == ["start"]
    loop.stop()
    assert plant.calls == ["start", "stop"] and not loop.running


def test_forces_are_saturated_keeping_direction() -> None:
    dev = EmulatorDevice(hand=np.array([0.05, -0.05, 0.0]))
    loop = ServoLoop(dev, Spy(k=1e4), record=True)
    loop.run_ticks(20)
    loop.stop()
    tr = loop.trace.array()
    f = tr[:, 5:8]
    m = tr[:, 2:5]
    np.testing.assert_allclose(np.linalg.norm(f, axis=1), OMNI_LIMITS.max_force_n)
    np.testing.assert_allclose(f / np.linalg.norm(f, axis=1)[:, None],
                               -m / np.linalg.norm(m, axis=1)[:, None], atol=1e-12)
    assert loop.saturated_ticks == 20 and np.all(tr[:, 8].astype(int) & 4)


def test_run_ticks_is_deterministic() -> None:
    def run() -> np.ndarray:
        dev = EmulatorDevice(hand=_hand, buttons=lambda t: BUTTON_2 if 0.3 < t < 0.35 else 0)
        loop = ServoLoop(dev, CoupledToolPlant(), record=True)
        loop.run_ticks(600)
        loop.stop()
        return loop.trace.array()[:, 1:]

    a, b = run(), run()
    assert np.array_equal(a, b)


def test_plant_error_stops_cleanly_with_zero_force() -> None:
    dev = EmulatorDevice(hand=np.array([0.02, 0.0, 0.0]))
    plant = Spy(k=50.0, fail_at=5)
    loop = ServoLoop(dev, plant)
    assert loop.run_ticks(100) == 5
    assert isinstance(loop.error, RuntimeError) and not loop.running
    assert loop.events[-1].kind == "error" and "plant exploded" in loop.events[-1].message
    assert plant.calls == ["start", "stop"]
    assert dev.applied_force.tolist() == [0.0, 0.0, 0.0]
    with pytest.raises(DeviceError, match="before start"):
        dev.read()  # the loop stopped the device


def test_device_error_stops_cleanly() -> None:
    class Dying(EmulatorDevice):
        def read(self) -> DeviceSample:
            if self.t >= 0.004:
                raise DeviceError("cable unplugged")
            return super().read()

    loop = ServoLoop(Dying(), NullPlant())
    assert loop.run_ticks(50) == 5
    assert isinstance(loop.error, DeviceError)


def test_bad_arguments() -> None:
    dev = EmulatorDevice()
    with pytest.raises(ValueError, match="rate_hz"):
        ServoLoop(dev, NullPlant(), rate_hz=0.0)
    with pytest.raises(ValueError, match="spin_s"):
        ServoLoop(dev, NullPlant(), spin_s=-1.0)
    loop = ServoLoop(dev, NullPlant())
    with pytest.raises(ValueError, match="driver"):
        loop.start(driver="timer")  # type: ignore[arg-type]
    with pytest.raises(DeviceError, match="no scheduler"):
        loop.start(driver="device")
    with pytest.raises(ValueError, match="n must be"):
        loop.run_ticks(-1)


# -- the scripted operator as an observing device ----------------------------------------

class TaskPlant:
    """A minimal trial: slave = master, goal = the task's POI, no fixtures."""

    def __init__(self, task):
        self.task = task
        self.tcp = np.array(task.start, dtype=float)
        self.t = 0.0
        self.observed = 0

    def on_start(self, t: float) -> None:
        pass

    def tick(self, t: float, master: np.ndarray, buttons: int) -> np.ndarray:
        self.tcp, self.t = master.copy(), t
        return np.zeros(3)

    def on_stop(self) -> None:
        pass

    def observation(self) -> OperatorObservation:
        self.observed += 1
        return OperatorObservation(t=self.t, dt=1e-3, tcp=self.tcp.copy(),
                                   goal=np.asarray(self.task.points[0]), goal_index=0)


def test_scripted_device_sees_the_plant_observation_every_tick() -> None:
    task = point_task()
    dev = ScriptedDevice(ScriptedOperator(OperatorProfile.expert(), task, seed=3), task.start)
    plant = TaskPlant(task)
    loop = ServoLoop(dev, plant, home=task.start)
    loop.run_ticks(1500)
    loop.stop()
    assert plant.observed == 1500 and dev.standalone_steps == 0
    # the expert moves the master toward the POI
    d0 = np.linalg.norm(np.asarray(task.start) - task.points[0])
    assert np.linalg.norm(plant.tcp - task.points[0]) < 0.5 * d0


# -- real time ------------------------------------------------------------------------------

def test_realtime_smoke() -> None:
    """Only that ticks happen and the statistics are finite (no timing thresholds)."""
    dev = EmulatorDevice(hand=_hand)
    plant = CoupledToolPlant()
    before = sys.getswitchinterval()
    loop = ServoLoop(dev, plant, switch_interval_s=5e-4)
    loop.start()
    assert sys.getswitchinterval() == pytest.approx(5e-4)
    wait_until(lambda: loop.ticks >= 2, what="two servo ticks")
    loop.stop()
    assert sys.getswitchinterval() == before  # restored
    st_ = loop.stats()
    assert loop.ticks > 0 and loop.error is None and not loop.running
    assert st_.mode == "realtime" and st_.n_ticks == loop.ticks
    if st_.n_ticks >= 2:
        for v in (st_.achieved_hz, st_.period_p50_ms, st_.period_p99_ms, st_.period_max_ms,
                  st_.jitter_rms_ms, st_.tick_cost_p50_ms):
            assert math.isfinite(v)
    assert dev.applied_force.tolist() == [0.0, 0.0, 0.0]
    with pytest.raises(RuntimeError, match="already"):
        loop2 = ServoLoop(EmulatorDevice(), NullPlant())
        loop2.start()
        try:
            loop2.start()
        finally:
            loop2.stop()


def test_realtime_errors_stay_in_the_thread() -> None:
    plant = Spy(fail_at=3)
    loop = ServoLoop(EmulatorDevice(hand=_hand), plant)
    loop.start()
    wait_until(lambda: not loop.running, what="the servo loop to stop", timeout=30.0)
    loop.stop()
    assert isinstance(loop.error, RuntimeError) and plant.calls == ["start", "stop"]


class Scheduled(EmulatorDevice):
    """An emulator with a driver-side scheduler the test pumps by hand."""

    def __init__(self) -> None:
        super().__init__(hand=_hand)
        self.hook: Callable[[], None] | None = None

    def set_servo_hook(self, hook: Callable[[], None] | None) -> None:
        self.hook = hook


def test_device_driver_runs_the_tick_inside_the_scheduler_callback() -> None:
    dev = Scheduled()
    plant = Spy()
    loop = ServoLoop(dev, plant)
    loop.start(driver="device")
    assert dev.hook is not None
    for _ in range(25):
        dev.hook()
    assert loop.ticks == 25 and len(plant.masters) == 25
    assert loop.stats().mode == "device" and loop.stats().n_ticks == 25
    loop.stop()
    assert dev.hook is None and plant.calls == ["start", "stop"]


def test_limits_of_a_device_are_used_for_saturation() -> None:
    class Weak(EmulatorDevice):
        @property
        def limits(self) -> DeviceLimits:
            return DeviceLimits((-1, -1, -1), (1, 1, 1), max_force_n=0.5,
                                max_continuous_force_n=0.5)

    loop = ServoLoop(Weak(hand=np.array([0.05, 0.0, 0.0])), Spy(k=1e3))
    loop.run_ticks(3)
    assert math.hypot(*loop.latest.force) == pytest.approx(0.5)
    loop.stop()


def test_device_driver_error_unhooks_and_stop_closes() -> None:
    """A failing tick inside the driver's callback zeroes the force and unhooks the loop;
    the driver is not stopped from inside its own callback: ``stop()`` closes it."""
    dev = Scheduled()
    plant = Spy(fail_at=3)
    loop = ServoLoop(dev, plant)
    loop.start(driver="device")
    hook = dev.hook
    for _ in range(3):
        dev.hook()
    dev.hook()  # tick 3 fails
    assert dev.hook is None and not loop.running and isinstance(loop.error, RuntimeError)
    assert dev.applied_force.tolist() == [0.0, 0.0, 0.0]
    hook()  # a callback already in flight does nothing more
    assert loop.ticks == 3 and plant.calls == ["start"]
    dev.read()  # the device is still open
    loop.stop()
    assert plant.calls == ["start", "stop"]
    with pytest.raises(DeviceError):
        dev.read()
