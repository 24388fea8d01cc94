"""Tests of recording and replay (vasim/haptics/devices/replay.py): a replayed run gives
bit-identical loop outputs; the .npz format round-trips exactly and is validated."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vasim.abdomen.contact import ContactPatch
from vasim.core.errors import DeviceError
from vasim.haptics.coupling import PatchForce
from vasim.haptics.device import BUTTON_2, OMNI_LIMITS, DeviceSample
from vasim.haptics.devices.emulator import EmulatorDevice
from vasim.haptics.devices.replay import (
    DeviceStream,
    ReplayDevice,
    StreamRecorder,
    stream_path,
)
from vasim.haptics.servo import CoupledToolPlant, NullPlant, ServoLoop


def _hand(t: float) -> np.ndarray:
    return np.array([0.02 * math.sin(3.0 * t), 0.01 * math.cos(5.0 * t), -0.004 + 0.002 * t])


def _plant() -> CoupledToolPlant:
    wall = PatchForce(ContactPatch(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]),
                                   np.array([2000.0]), np.zeros(1), 0.0025),
                      np.array([0.0, 0.0, 0.2]))
    return CoupledToolPlant(tissue=wall,
                            extra_force=lambda t, x, v: -30.0 * (x - [0.01, 0.0, 0.0]))


class Glitchy(EmulatorDevice):
    """An emulator whose reading at tick 300 is NaN (so the replay must reproduce it)."""

    def read(self) -> DeviceSample:
        s = super().read()
        if abs(s.t - 0.3) < 1e-9:
            return DeviceSample(t=s.t, position=np.array([math.nan, 0.0, 0.0]))
        return s


def test_replay_reproduces_the_outputs_bit_for_bit(tmp_path) -> None:
    dev = Glitchy(hand=_hand, buttons=lambda t: BUTTON_2 if 0.5 <= t < 0.6 else 0)
    loop = ServoLoop(dev, _plant(), record=True)
    assert loop.run_ticks(1200) == 1200
    loop.stop()
    original = loop.trace.array()
    assert loop.guard.counts["nonfinite_position"] == 1 and loop.clutch.count == 1
    path = loop.recording.save(tmp_path / "run.npz")

    replay = ReplayDevice(path)
    loop2 = ServoLoop(replay, _plant(), record=True)
    assert loop2.run_ticks(1200) == 1200
    loop2.stop()
    again = loop2.trace.array()
    assert np.array_equal(original[:, 1:], again[:, 1:])  # t, master, force, flags
    np.testing.assert_array_equal(np.array(replay.forces)[:1200], original[:, 5:8])
    assert loop2.guard.counts == loop.guard.counts and loop2.clutch == loop.clutch


def test_end_of_recording_stops_the_loop_cleanly() -> None:
    rec = StreamRecorder("x", OMNI_LIMITS, 1000.0)
    for k in range(10):
        rec.append(k, DeviceSample(t=k * 1e-3, position=np.full(3, 1e-3 * k)))
    dev = ReplayDevice(rec.stream())
    loop = ServoLoop(dev, NullPlant())
    assert loop.run_ticks(50) == 10
    assert isinstance(loop.error, DeviceError) and "end of the recording" in str(loop.error)
    assert dev.exhausted and dev.forces[-1].tolist() == [0.0, 0.0, 0.0]
    dev.rewind()
    assert not dev.exhausted and dev.forces == []


def test_format_round_trip_and_validation(tmp_path) -> None:
    rec = StreamRecorder("emu", OMNI_LIMITS, 500.0, chunk=3)
    rng = np.random.default_rng(0)
    for k in range(10):
        q = rng.normal(size=4)
        rec.append(2 * k, DeviceSample(t=float(rng.random()), position=rng.normal(size=3),
                                       orientation=q / np.linalg.norm(q), buttons=k % 4,
                                       valid=k != 3))
    s = rec.stream()
    path = s.save(tmp_path / "stream")  # suffix added
    assert path.name == "stream.npz" and path.exists()
    back = DeviceStream.load(path)
    for name in ("tick", "t", "position", "orientation", "buttons", "valid"):
        assert np.array_equal(getattr(back, name), getattr(s, name)), name
    assert back.tick.tolist() == list(range(0, 20, 2)) and not back.valid[3]
    assert back.limits == OMNI_LIMITS and back.rate_hz == 500.0 and back.device == "emu"

    np.savez(tmp_path / "other.npz", format=np.array("something else"))
    with pytest.raises(DeviceError, match="not a vasim device stream"):
        DeviceStream.load(tmp_path / "other.npz")
    with pytest.raises(DeviceError, match="cannot read"):
        DeviceStream.load(tmp_path / "missing.npz")
    bad = dict(np.load(path))
    bad["version"] = np.int64(99)
    np.savez(tmp_path / "v99.npz", **bad)
    with pytest.raises(DeviceError, match="version 99"):
        DeviceStream.load(tmp_path / "v99.npz")


def test_stream_path_is_next_to_the_database(tmp_path) -> None:
    p = stream_path(tmp_path / "study.sqlite", 42)
    assert p.parent == tmp_path and p.name == "study_trial000042_device.npz"
