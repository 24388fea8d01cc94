"""Tests of the OpenHaptics adapter (vasim/haptics/devices/openhaptics.py) against a fake
``pyOpenHaptics`` injected into ``sys.modules`` that mimics the 1.0.1 API (hd.py,
hd_callback.py: same function names, same return conventions, the same prints), the
failure messages (package missing, runtime missing, no device), and ``vasim devices``."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import types
from collections.abc import Callable

import numpy as np
import pytest

from vasim.cli import main
from vasim.core.errors import DeviceError
from vasim.haptics.devices import openhaptics as oh
from vasim.haptics.servo import ServoLoop


class FakeHD:
    """State of the fake device (what libHD would hold)."""

    def __init__(self, attached: bool = True):
        self.attached = attached
        self.error = False
        self.position_mm = [10.0, -20.0, 5.0]
        self.buttons = 0
        self.forces: list[list[float]] = []
        self.scheduler_running = False
        self.callback: Callable[[], int] | None = None
        self.closed: list[int] = []


def make_fake(state: FakeHD) -> dict[str, types.ModuleType]:
    """The three modules of pyopenhaptics 1.0.1, backed by ``state``."""
    pkg = types.ModuleType("pyOpenHaptics")
    pkg.__path__ = []  # a package
    hd = types.ModuleType("pyOpenHaptics.hd")
    cb = types.ModuleType("pyOpenHaptics.hd_callback")

    def init_device(name: str = "Default Device") -> int | None:
        if not state.attached:
            state.error = True
            print("Unable to initialize the device. Check the connection!")
            return None  # what hd.init_device returns after DeviceInitException
        return 3

    def get_error() -> bool:
        if state.error:
            print("DeviceInitException: Error during the main scheduler.")
        return state.error

    def get_transform() -> list[list[float]]:
        m = np.eye(4)
        m[3, :3] = state.position_mm  # column-major: translation in the 4th column
        return m.tolist()

    def _get_doublev(code: int, dtype: type) -> list[float]:
        if code == 0x2551:
            return [-80.0, -60.0, -35.0, 80.0, 60.0, 35.0]
        if code == 0x2603:
            return [3.3]
        if code == 0x2604:
            return [0.88]
        raise ValueError(code)

    def enable_force() -> None:
        print("Force feedback enabled!")

    hd.init_device = init_device
    hd.get_error = get_error
    hd.get_transform = get_transform
    hd.get_buttons = lambda: state.buttons
    hd.set_force = lambda f: state.forces.append(list(f))
    hd.enable_force = enable_force
    hd.start_scheduler = lambda: setattr(state, "scheduler_running", True)
    hd.stop_scheduler = lambda: setattr(state, "scheduler_running", False)
    hd.close_device = lambda handle: state.closed.append(handle)
    hd.get_model = lambda: "Touch"
    hd.get_vendor = lambda: "3D Systems"
    hd._get_doublev = _get_doublev

    def hd_callback(fn: Callable[[], None]) -> Callable[[], int]:
        def _callback() -> int:  # begin_frame; fn(); end_frame
            fn()
            return 0 if get_error() else 1  # HD_CALLBACK_DONE / HD_CALLBACK_CONTINUE
        return _callback

    def hdAsyncSheduler(callback: Callable[[], int]) -> None:  # pyopenhaptics spelling
        state.callback = callback

    cb.hd_callback = hd_callback
    cb.hdAsyncSheduler = hdAsyncSheduler
    cb.hdSyncSheduler = hdAsyncSheduler
    pkg.hd = hd
    pkg.hd_callback = cb
    return {"pyOpenHaptics": pkg, "pyOpenHaptics.hd": hd, "pyOpenHaptics.hd_callback": cb}


@pytest.fixture
def fake(monkeypatch: pytest.MonkeyPatch) -> FakeHD:
    state = FakeHD()
    for name, mod in make_fake(state).items():
        monkeypatch.setitem(sys.modules, name, mod)
    return state


@pytest.fixture
def no_package(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "pyOpenHaptics", None)  # import raises ImportError


@pytest.fixture
def no_runtime(monkeypatch: pytest.MonkeyPatch, tmp_path) -> None:
    """A pyOpenHaptics whose import fails as the real one does without libHD.so."""
    pkg = tmp_path / "pyOpenHaptics"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("from .hd import *\n")
    (pkg / "hd.py").write_text(
        "from ctypes import CDLL\n_lib_hd = CDLL('libHD_vasim_test_missing.so')\n")
    (pkg / "hd_callback.py").write_text("")
    for name in ("pyOpenHaptics", "pyOpenHaptics.hd", "pyOpenHaptics.hd_callback"):
        monkeypatch.delitem(sys.modules, name, raising=False)
    monkeypatch.syspath_prepend(str(tmp_path))


# -- the device ----------------------------------------------------------------------------

def test_device_reads_and_writes_through_the_scheduler_callback(fake: FakeHD, capsys) -> None:
    dev = oh.OpenHapticsDevice()
    dev.start()
    assert capsys.readouterr().out == ""  # the wrapper's prints go to the log
    assert fake.scheduler_running and fake.callback is not None
    assert dev.model == "Touch" and dev.vendor == "3D Systems"
    assert dev.limits.max_force_n == 3.3 and dev.limits.workspace_max == (0.08, 0.06, 0.035)
    assert not dev.read().valid  # no callback yet
    fake.buttons = 2
    assert fake.callback() == 1
    s = dev.read()
    assert s.valid and s.position.tolist() == pytest.approx([0.01, -0.02, 0.005])
    assert s.buttons == 2 and s.orientation.tolist() == [1.0, 0.0, 0.0, 0.0]
    dev.write_force(np.array([0.1, -0.2, 0.3]))
    fake.callback()
    assert fake.forces[-1] == [0.1, -0.2, 0.3]
    dev.stop()
    assert not fake.scheduler_running and fake.closed == [3]
    with pytest.raises(DeviceError, match="before start"):
        dev.read()


def test_servo_loop_inside_the_device_scheduler(fake: FakeHD) -> None:
    class Spring:
        def on_start(self, t: float) -> None:
            pass

        def tick(self, t: float, master: np.ndarray, buttons: int) -> np.ndarray:
            return -100.0 * master

        def on_stop(self) -> None:
            pass

    dev = oh.OpenHapticsDevice()
    loop = ServoLoop(dev, Spring())
    loop.start(driver="device")
    for _ in range(10):
        fake.callback()
    assert loop.ticks == 10 and dev.callbacks == 10
    # each callback: read, then the whole tick, then the force just computed is sent
    np.testing.assert_allclose(fake.forces[-1], [-1.0, 2.0, -0.5])
    loop.stop()
    assert not fake.scheduler_running and fake.closed == [3]


def test_a_failing_hook_zeroes_the_force_inside_the_callback(fake: FakeHD) -> None:
    dev = oh.OpenHapticsDevice()
    dev.start()
    dev.write_force(np.array([1.0, 0.0, 0.0]))

    def boom() -> None:
        raise RuntimeError("bad plant")

    dev.set_servo_hook(boom)
    fake.callback()  # must not raise into the vendor thread
    assert fake.forces[-1] == [0.0, 0.0, 0.0] and not dev.read().valid
    dev.stop()


def test_no_device_attached(fake: FakeHD) -> None:
    fake.attached = False
    with pytest.raises(DeviceError, match="no OpenHaptics device found"):
        oh.OpenHapticsDevice().start()
    assert not fake.scheduler_running


def test_missing_package_message(no_package: None) -> None:
    with pytest.raises(DeviceError) as info:
        oh.OpenHapticsDevice().start()
    assert "pip install 'vasim[openhaptics]'" in str(info.value)


def test_missing_runtime_message(no_runtime: None) -> None:
    with pytest.raises(DeviceError) as info:
        oh.load_sdk()
    assert "OpenHaptics runtime (libHD.so) not found" in str(info.value)
    assert isinstance(info.value.__cause__, OSError)


def test_nothing_imports_the_sdk_at_module_level() -> None:
    code = ("import sys, vasim.cli, vasim.haptics.servo, vasim.haptics.devices, "
            "vasim.haptics.devices.openhaptics, vasim.cli.haptics; "
            "vasim.cli.build_parser(); print('pyOpenHaptics' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"


# -- vasim devices ------------------------------------------------------------------------

def _devices_json(capsys) -> dict[str, dict]:
    assert main(["devices", "--json"]) == 0
    return {row["name"]: row for row in json.loads(capsys.readouterr().out)}


def test_devices_with_the_fake(fake: FakeHD, capsys) -> None:
    rows = _devices_json(capsys)  # the fake's prints must not break the JSON
    assert rows["openhaptics"]["available"] is True
    assert rows["openhaptics"]["detail"] == "3D Systems Touch"
    assert fake.closed == [3]  # the probe closed what it opened
    assert all(rows[n]["available"] for n in ("emulator", "scripted", "replay"))


def test_devices_with_the_fake_but_no_hardware(fake: FakeHD, capsys) -> None:
    fake.attached = False
    rows = _devices_json(capsys)
    assert rows["openhaptics"]["available"] is False
    assert [m["kind"] for m in rows["openhaptics"]["missing"]] == ["hardware"]


@pytest.mark.parametrize("runtime, kinds", [(False, ["package", "runtime library"]),
                                            (True, ["package"])])
def test_devices_without_the_package(no_package: None, monkeypatch: pytest.MonkeyPatch,
                                     capsys, runtime: bool, kinds: list[str]) -> None:
    monkeypatch.setattr(oh, "runtime_loadable", lambda: runtime)
    rows = _devices_json(capsys)
    missing = rows["openhaptics"]["missing"]
    assert [m["kind"] for m in missing] == kinds
    assert missing[0]["what"] == "pyopenhaptics"
    assert missing[0]["hint"] == "pip install 'vasim[openhaptics]'"
    assert main(["devices"]) == 0
    text = capsys.readouterr().out
    assert re.search(r"^openhaptics +unavailable", text, re.M)
    assert "missing package: pyopenhaptics -- pip install 'vasim[openhaptics]'" in text


def test_devices_without_the_runtime(no_runtime: None, capsys) -> None:
    rows = _devices_json(capsys)
    missing = rows["openhaptics"]["missing"]
    assert [m["kind"] for m in missing] == ["runtime library"]
    assert missing[0]["what"] == "libHD.so"
