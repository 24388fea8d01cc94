"""Tests of the guard (vasim/haptics/guard.py) and of what the servo loop does with it:
NaN/inf/out-of-workspace readings and non-finite plant forces never reach the plant or the
device; the loop holds the last good state, renders zero force and logs an event."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.haptics.device import OMNI_LIMITS, DeviceLimits, DeviceSample
from vasim.haptics.devices.emulator import EmulatorDevice
from vasim.haptics.guard import GuardEvent, GuardLog, check_force, check_sample, should_log
from vasim.haptics.servo import ServoLoop

NAN, INF = math.nan, math.inf


def _s(p, q=(1.0, 0.0, 0.0, 0.0), valid=True) -> DeviceSample:
    return DeviceSample(t=0.0, position=np.array(p, dtype=float),
                        orientation=np.array(q, dtype=float), valid=valid)


@pytest.mark.parametrize("sample, kind", [
    (_s([0.0, NAN, 0.0]), "nonfinite_position"),
    (_s([INF, 0.0, 0.0]), "nonfinite_position"),
    (_s([0.0, 0.0, -INF]), "nonfinite_position"),
    (_s([0.0, 0.0, 0.0], q=(NAN, 0, 0, 0)), "nonfinite_orientation"),
    (_s([0.0, 0.0, 0.0], valid=False), "invalid_sample"),
    (_s([0.0, 0.0, 0.2]), "out_of_workspace"),
    (_s([-0.0901, 0.0, 0.0]), "out_of_workspace"),
])
def test_bad_samples_are_named(sample: DeviceSample, kind: str) -> None:
    ev = check_sample(sample, OMNI_LIMITS, tick=7, margin=0.01)
    assert ev is not None and ev.kind == kind and ev.tick == 7
    if kind != "nonfinite_orientation":
        np.testing.assert_array_equal(np.array(ev.value), sample.position)


def test_margin_accepts_readings_just_outside_the_box() -> None:
    s = _s([0.0849, 0.0, 0.0])  # 4.9 mm outside the 80 mm half-width
    assert check_sample(s, OMNI_LIMITS, 0, margin=0.005) is None
    assert check_sample(s, OMNI_LIMITS, 0, margin=0.0).kind == "out_of_workspace"


@settings(max_examples=200, deadline=None)
@given(st.tuples(st.floats(-0.08, 0.08), st.floats(-0.06, 0.06), st.floats(-0.035, 0.035)),
       st.integers(0, 2), st.sampled_from([NAN, INF, -INF]))
def test_finite_inside_passes_and_any_nonfinite_fails(p: tuple, axis: int, bad: float) -> None:
    assert check_sample(_s(p), OMNI_LIMITS, 0) is None
    q = list(p)
    q[axis] = bad
    assert check_sample(_s(q), OMNI_LIMITS, 0).kind == "nonfinite_position"


def test_check_force() -> None:
    assert check_force(1.0, -2.0, 3.3, 0) is None
    ev = check_force(0.0, NAN, 1.0, 12)
    assert ev.kind == "nonfinite_force" and ev.tick == 12
    assert ev.value[0] == 0.0 and math.isnan(ev.value[1]) and ev.value[2] == 1.0
    assert "tick 12: nonfinite_force" in ev.describe()


def test_log_rate_limits_but_counts_everything() -> None:
    log = GuardLog(first=3, every=100)
    for tick in range(1000):
        log.add(GuardEvent("nonfinite_force", tick, (NAN, 0.0, 0.0)))
    assert log.counts["nonfinite_force"] == 1000 and log.total == 1000
    # 3 one by one (ticks 0-2), then ticks 100, 200, ..., 900
    assert [e.tick for e in log.events] == [0, 1, 2, *range(100, 1000, 100)]
    assert should_log(1, 5) and not should_log(11, 5) and should_log(11, 2000)


# -- the loop ---------------------------------------------------------------------------

class Faulty:
    """Wraps a device and replaces the readings at chosen ticks (fault injection)."""

    def __init__(self, inner: EmulatorDevice, faults: dict[int, DeviceSample]):
        self.inner, self.faults, self.name = inner, faults, "faulty"
        self.k = 0
        self.forces: list[np.ndarray] = []

    @property
    def limits(self) -> DeviceLimits:
        return self.inner.limits

    def start(self) -> None:
        self.inner.start()

    def stop(self) -> None:
        self.inner.stop()

    def read(self) -> DeviceSample:
        s = self.inner.read()
        k, self.k = self.k, self.k + 1
        return self.faults.get(k, s)

    def write_force(self, force: np.ndarray) -> None:
        self.forces.append(np.array(force))
        self.inner.write_force(force)


class Recorder:
    """A plant that renders a spring toward the origin and remembers what it saw."""

    def __init__(self, bad_force_ticks: tuple[int, ...] = ()):
        self.seen: list[np.ndarray] = []
        self.bad = bad_force_ticks

    def on_start(self, t: float) -> None:
        pass

    def tick(self, t: float, master: np.ndarray, buttons: int) -> np.ndarray:
        k = len(self.seen)
        self.seen.append(master.copy())
        if k in self.bad:
            return np.array([NAN, 0.0, INF])
        return -50.0 * master

    def on_stop(self) -> None:
        pass


def test_loop_holds_the_last_good_state_and_zeroes_the_force() -> None:
    faults = {5: _s([0.0, NAN, 0.0]), 6: _s([INF, 0.0, 0.0]), 9: _s([0.0, 0.0, 0.5]),
              12: _s([0.0, 0.0, 0.0], valid=False)}
    dev = Faulty(EmulatorDevice(hand=lambda t: np.array([0.01 + t, 0.0, 0.0])), faults)
    plant = Recorder()
    loop = ServoLoop(dev, plant)
    assert loop.run_ticks(20) == 20
    seen = np.array(plant.seen)
    assert np.all(np.isfinite(seen))
    for k in (5, 6):
        np.testing.assert_array_equal(seen[k], seen[4])  # held
    np.testing.assert_array_equal(seen[9], seen[8])
    np.testing.assert_array_equal(seen[12], seen[11])
    for k in range(20):
        if k in faults:
            assert dev.forces[k].tolist() == [0.0, 0.0, 0.0]
        else:
            assert np.linalg.norm(dev.forces[k]) > 0
    kinds = [(e.kind, e.tick) for e in loop.guard.events]
    assert kinds == [("nonfinite_position", 5), ("nonfinite_position", 6),
                     ("out_of_workspace", 9), ("invalid_sample", 12)]
    assert loop.guard.events[2].value == (0.0, 0.0, 0.5)
    assert loop.trace is None and loop.error is None
    loop.stop()


def test_nonfinite_plant_force_is_zeroed_and_logged() -> None:
    dev = Faulty(EmulatorDevice(hand=np.array([0.01, 0.0, 0.0])), {})
    loop = ServoLoop(dev, Recorder(bad_force_ticks=(3, 4)), record=True)
    loop.run_ticks(8)
    loop.stop()
    assert dev.forces[3].tolist() == [0.0, 0.0, 0.0] and dev.forces[4].tolist() == [0, 0, 0]
    assert np.linalg.norm(dev.forces[5]) > 0
    assert [(e.kind, e.tick) for e in loop.guard.events] == [("nonfinite_force", 3),
                                                             ("nonfinite_force", 4)]
    flags = loop.trace.array()[:, 8].astype(int)
    assert flags[3] & 8 and flags[4] & 8 and not flags[5] & 8


def test_nothing_good_yet_means_home_and_no_force() -> None:
    bad = _s([0.0, 0.0, 0.0], valid=False)
    dev = Faulty(EmulatorDevice(start_position=np.array([0.01, 0.0, 0.0])), {0: bad, 1: bad})
    plant = Recorder()
    loop = ServoLoop(dev, plant, home=[0.1, 0.2, 0.3])
    loop.run_ticks(4)
    loop.stop()
    assert plant.seen[0].tolist() == [0.1, 0.2, 0.3] == plant.seen[1].tolist()
    # the first good reading (tick 2) is indexed onto home
    np.testing.assert_allclose(plant.seen[2], [0.1, 0.2, 0.3], atol=1e-12)
    assert dev.forces[0].tolist() == [0.0, 0.0, 0.0]
    assert [e.kind for e in loop.events] == ["indexed"]
