"""Tests of the device protocol's values (vasim/haptics/device.py) and the registry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vasim.core.errors import ConfigError
from vasim.haptics.device import (
    OMNI_LIMITS,
    UNBOUNDED,
    Device,
    DeviceLimits,
    DeviceSample,
    as_force,
)
from vasim.haptics.devices import DEVICES, DeviceInfo, probe_all
from vasim.haptics.devices.browser import BrowserDevice
from vasim.haptics.devices.emulator import EmulatorDevice
from vasim.haptics.devices.openhaptics import OpenHapticsDevice
from vasim.haptics.devices.replay import ReplayDevice, StreamRecorder
from vasim.operator.device import ScriptedDevice
from vasim.operator.scripted import OperatorProfile, ScriptedOperator
from vasim.tasks import point_task


def test_omni_limits_match_the_data_sheet() -> None:
    # Geomagic Touch / Phantom Omni data sheet: 160 W x 120 H x 70 D mm, 3.3 N peak,
    # 0.88 N continuous, > 450 dpi (~0.055 mm).
    np.testing.assert_allclose(OMNI_LIMITS.size, [0.160, 0.120, 0.070], rtol=0, atol=1e-12)
    assert OMNI_LIMITS.max_force_n == 3.3
    assert OMNI_LIMITS.max_continuous_force_n == 0.88
    assert OMNI_LIMITS.position_resolution_m == pytest.approx(25.4e-3 / 450, rel=0.03)


def test_contains_is_the_closed_box() -> None:
    assert OMNI_LIMITS.contains([0.08, -0.06, 0.035])
    assert not OMNI_LIMITS.contains([0.0801, 0.0, 0.0])
    lo, hi = UNBOUNDED
    free = DeviceLimits(lo, hi, 1.0, 0.5)
    assert free.contains([1e9, -1e9, 0.0])


@pytest.mark.parametrize("kwargs, field", [
    (dict(workspace_min=(0, 0, 0), workspace_max=(1, 1, 0)), "workspace"),
    (dict(workspace_min=(0, 0, math.nan), workspace_max=(1, 1, 1)), "workspace"),
    (dict(max_force_n=-1.0), "max_force_n"),
    (dict(max_force_n=math.inf), "max_force_n"),
    (dict(max_continuous_force_n=4.0), "max_continuous_force_n"),
    (dict(continuous_window_s=0.0), "continuous_window_s"),
    (dict(position_resolution_m=-1e-5), "position_resolution_m"),
])
def test_limits_reject_bad_values(kwargs: dict, field: str) -> None:
    base = dict(workspace_min=(-1, -1, -1), workspace_max=(1, 1, 1), max_force_n=3.0,
                max_continuous_force_n=1.0)
    base.update(kwargs)
    with pytest.raises(ConfigError) as info:
        DeviceLimits(**base)
    assert info.value.field == field


def test_limits_round_trip_through_dict() -> None:
    assert DeviceLimits.from_dict(OMNI_LIMITS.to_dict()) == OMNI_LIMITS


def test_as_force_needs_three_components() -> None:
    assert as_force([1, 2, 3]).tolist() == [1.0, 2.0, 3.0]
    with pytest.raises(ValueError, match="3 components"):
        as_force([1.0, 2.0])


def test_sample_defaults() -> None:
    s = DeviceSample(t=0.5, position=np.ones(3))
    assert s.valid and s.buttons == 0 and s.orientation.tolist() == [1.0, 0.0, 0.0, 0.0]


def test_every_device_implements_the_protocol(tmp_path) -> None:
    task = point_task()
    rec = StreamRecorder("x", OMNI_LIMITS, 1000.0)
    rec.append(0, DeviceSample(0.0, np.zeros(3)))
    devices = [
        EmulatorDevice(),
        ScriptedDevice(ScriptedOperator(OperatorProfile(), task, seed=0), task.start),
        BrowserDevice(),
        ReplayDevice(rec.stream()),
        OpenHapticsDevice(),
    ]
    for dev in devices:
        assert isinstance(dev, Device), type(dev).__name__


def test_registry_names_and_duplicates() -> None:
    assert list(DEVICES) == ["emulator", "scripted", "browser", "laparoscopic", "replay",
                             "openhaptics"]
    with pytest.raises(ValueError, match="already registered"):
        DEVICES.add(DeviceInfo("emulator", "again", lambda: None))  # type: ignore[arg-type]
    rows = dict((info.name, avail) for info, avail in probe_all())
    for name in ("emulator", "scripted", "replay"):
        assert rows[name].available and not rows[name].missing
