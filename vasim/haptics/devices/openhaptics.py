"""The Phantom Omni / Geomagic Touch through OpenHaptics (optional: ``vasim[openhaptics]``).

The PyPI package ``pyopenhaptics`` (import name ``pyOpenHaptics``, 1.0.1) is a small ctypes
wrapper over the vendor's HD library. It loads ``libHD.so`` (``HD.dll`` on Windows) **when
it is imported**, so importing it without the OpenHaptics runtime raises ``OSError``. This
module therefore imports it lazily, only in :func:`load_sdk` (called by
``OpenHapticsDevice.start`` and by the ``vasim devices`` probe), and turns each failure into
a ``DeviceError`` that says what to install:

* package missing (``ImportError``) -> "pip install 'vasim[openhaptics]'";
* runtime missing (``OSError`` at import) -> "OpenHaptics runtime (libHD.so) not found";
* no device attached (``hdInitDevice`` fails: ``init_device`` returns None or the HD error
  flag is set) -> "no OpenHaptics device found".

Nothing else in vasim imports ``pyOpenHaptics``.

The pyopenhaptics API used (checked against the 1.0.1 wheel): ``hd.init_device(name)``,
``hd.enable_force()``, ``hd.start_scheduler()``, ``hd.stop_scheduler()``,
``hd.close_device(id)``, ``hd.get_error() -> bool``, ``hd.get_transform()`` (the 4x4
column-major ``HD_CURRENT_TRANSFORM``, translation in mm in ``m[3][0:3]``),
``hd.get_buttons() -> int``, ``hd.set_force([fx, fy, fz])`` [N], ``hd.get_model()``,
``hd.get_vendor()``, ``hd._get_doublev(code, ctype)`` (for the workspace and force
limits; private, so used best-effort with the Touch's data-sheet values as fallback),
``hd_callback.hd_callback`` (wraps a Python function into the scheduler's C callback,
between ``hdBeginFrame`` and ``hdEndFrame``) and ``hd_callback.hdAsyncSheduler(cb)``.

How the servo loop and the vendor scheduler meet: the device registers one asynchronous
scheduler callback, which runs in the vendor's 1 kHz servo thread. Each call it reads the
transform and buttons into a snapshot, calls the servo hook if one is set
(``ServoLoop.start(driver="device")``: the whole servo tick runs inside the callback), and
sends the latest force. With ``driver="thread"`` the loop runs on its own timer and meets
the callback through the snapshot and the latest force (a mailbox; up to one period of
extra latency). Units: the device reports millimetres; readings are converted to metres
(device frame: x right, y up, z toward the user).
"""

from __future__ import annotations

import contextlib
import ctypes
import importlib
import io
import logging
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from types import ModuleType

import numpy as np

from vasim.core.errors import DeviceError
from vasim.core.geometry import quat_from_matrix
from vasim.haptics.device import (
    OMNI_LIMITS,
    DeviceLimits,
    DeviceSample,
    FloatArray,
    as_force,
)

log = logging.getLogger(__name__)

PACKAGE = "pyOpenHaptics"
"""Import name of the PyPI distribution ``pyopenhaptics``."""
INSTALL_HINT = "pip install 'vasim[openhaptics]'"
RUNTIME_LIBRARY = "libHD.so"

# OpenHaptics enums (hd_define.py of pyopenhaptics 1.0.1 = hdDefines.h)
HD_USABLE_WORKSPACE_DIMENSIONS = 0x2551
HD_NOMINAL_MAX_FORCE = 0x2603
HD_NOMINAL_MAX_CONTINUOUS_FORCE = 0x2604

MSG_PACKAGE = (f"the OpenHaptics device needs the Python package 'pyopenhaptics': "
               f"{INSTALL_HINT}")
RUNTIME_HINT = ("install 'OpenHaptics for Linux' and the Touch device driver from 3D Systems, "
                f"and make sure {RUNTIME_LIBRARY} is on the library path (e.g. "
                "LD_LIBRARY_PATH)")
MSG_RUNTIME = f"OpenHaptics runtime ({RUNTIME_LIBRARY}) not found: {RUNTIME_HINT}"
MSG_DEVICE = ("no OpenHaptics device found (hdInitDevice failed for {name!r}): connect and "
              "power the Phantom Omni / Touch, check it with the vendor's Touch_Setup / "
              "Touch_Diagnostic, and check the device name")


@dataclass(frozen=True)
class SDK:
    """The lazily imported pyopenhaptics modules."""

    hd: ModuleType
    callback: ModuleType


def _import_sdk() -> SDK:
    """Imports pyopenhaptics; raises the raw ImportError / OSError."""
    hd = importlib.import_module(f"{PACKAGE}.hd")
    cb = importlib.import_module(f"{PACKAGE}.hd_callback")
    return SDK(hd, cb)


def load_sdk() -> SDK:
    """Imports pyopenhaptics (lazily, here only).

    Raises:
        DeviceError: the package is not installed (message: ``pip install
            'vasim[openhaptics]'``), or the OpenHaptics runtime library cannot be loaded
            (message: "OpenHaptics runtime (libHD.so) not found").
    """
    try:
        return _import_sdk()
    except ImportError as exc:
        raise DeviceError(f"{MSG_PACKAGE} ({exc})") from exc
    except OSError as exc:
        raise DeviceError(f"{MSG_RUNTIME} ({exc})") from exc


def runtime_loadable() -> bool:
    """Whether the dynamic loader finds the OpenHaptics runtime (``libHD.so``)."""
    try:
        ctypes.CDLL(RUNTIME_LIBRARY)
    except OSError:
        return False
    return True


@contextlib.contextmanager
def _quiet() -> Iterator[io.StringIO]:
    """pyopenhaptics prints to stdout (device init, errors): capture it into the log."""
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        yield buf
    text = buf.getvalue().strip()
    if text:
        log.debug("pyopenhaptics: %s", text)


def open_device(sdk: SDK, name: str) -> int:
    """``hdInitDevice(name)``; returns the handle.

    Raises:
        DeviceError: no device (message ``MSG_DEVICE``).
    """
    hd = sdk.hd
    with _quiet():
        try:
            handle = hd.init_device(name)
        except Exception as exc:  # the wrapper's own exceptions (DeviceInitException, ...)
            raise DeviceError(f"{MSG_DEVICE.format(name=name)} ({type(exc).__name__})") from exc
        failed = handle is None or bool(hd.get_error())
    if failed:
        raise DeviceError(MSG_DEVICE.format(name=name))
    return int(handle)


def _doubles(sdk: SDK, code: int, n: int) -> list[float] | None:
    getter = getattr(sdk.hd, "_get_doublev", None)
    if getter is None:
        return None
    try:
        with _quiet():
            vals = getter(code, ctypes.c_double * n)
        return [float(vals[i]) for i in range(n)]
    except Exception as exc:  # best effort: fall back to the data sheet
        log.debug("hdGetDoublev(0x%x) failed: %s", code, exc)
        return None


def query_limits(sdk: SDK) -> DeviceLimits:
    """The attached device's limits from HD (usable workspace [mm -> m], nominal peak and
    continuous force [N]); the Omni's data-sheet values for anything HD does not give."""
    ws = _doubles(sdk, HD_USABLE_WORKSPACE_DIMENSIONS, 6)
    fmax = _doubles(sdk, HD_NOMINAL_MAX_FORCE, 1)
    fcont = _doubles(sdk, HD_NOMINAL_MAX_CONTINUOUS_FORCE, 1)
    lo, hi = OMNI_LIMITS.workspace_min, OMNI_LIMITS.workspace_max
    if ws is not None and all(a < b for a, b in zip(ws[:3], ws[3:], strict=True)):
        lo = (ws[0] * 1e-3, ws[1] * 1e-3, ws[2] * 1e-3)
        hi = (ws[3] * 1e-3, ws[4] * 1e-3, ws[5] * 1e-3)
    peak = fmax[0] if fmax is not None and fmax[0] > 0 else OMNI_LIMITS.max_force_n
    cont = fcont[0] if fcont is not None and 0 < fcont[0] <= peak else min(
        OMNI_LIMITS.max_continuous_force_n, peak)
    return DeviceLimits(workspace_min=lo, workspace_max=hi, max_force_n=peak,
                        max_continuous_force_n=cont,
                        continuous_window_s=OMNI_LIMITS.continuous_window_s,
                        position_resolution_m=OMNI_LIMITS.position_resolution_m)


def sample_from_transform(t: float, m: object, buttons: int) -> DeviceSample:
    """A ``DeviceSample`` from HD's 4x4 column-major transform (translation in mm).

    >>> import numpy as np
    >>> m = np.eye(4); m[3, :3] = [10.0, -20.0, 5.0]          # column-major: row 3
    >>> s = sample_from_transform(0.0, m.tolist(), 1)
    >>> s.position.tolist(), s.orientation.tolist(), s.buttons
    ([0.01, -0.02, 0.005], [1.0, 0.0, 0.0, 0.0], 1)
    """
    a = np.array([[float(m[i][j]) for j in range(4)] for i in range(4)])  # type: ignore[index]  # m: the driver's 4x4 nested list
    rot = a[:3, :3].T  # m[col][row] -> R[row][col]
    pos = a[3, :3] * 1e-3
    finite = bool(np.all(np.isfinite(a)))
    quat = quat_from_matrix(rot) if finite else np.full(4, np.nan)
    return DeviceSample(t=t, position=pos, orientation=quat, buttons=int(buttons))


class OpenHapticsDevice:
    """A Phantom Omni / Geomagic Touch driven through pyopenhaptics (module docstring).

    Args:
        device_name: OpenHaptics device name (``"Default Device"`` or as configured with
            Touch_Setup).
        name: vasim device name.

    ``start()`` raises ``DeviceError`` with an actionable message when the package, the
    runtime or the device is missing.
    """

    def __init__(self, device_name: str = "Default Device", *, name: str = "openhaptics"):
        self.device_name = device_name
        self.name = name
        self._limits = OMNI_LIMITS
        self._sdk: SDK | None = None
        self._handle: int | None = None
        self._callback: object | None = None
        self._hook: Callable[[], None] | None = None
        self._force: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._sample = DeviceSample(t=0.0, position=np.zeros(3), valid=False)
        self._lock = threading.Lock()
        self.callbacks = 0
        self.model = ""
        self.vendor = ""

    @property
    def limits(self) -> DeviceLimits:
        return self._limits

    def set_servo_hook(self, hook: Callable[[], None] | None) -> None:
        """Runs ``hook()`` inside the scheduler callback (``ScheduledDevice``)."""
        self._hook = hook

    def start(self) -> None:
        """Loads the SDK, opens the device, enables force and starts the scheduler."""
        if self._handle is not None:
            return
        sdk = load_sdk()
        handle = open_device(sdk, self.device_name)
        self._sdk = sdk
        self._handle = handle
        try:
            with _quiet():
                self.model = str(sdk.hd.get_model())
                self.vendor = str(sdk.hd.get_vendor())
            self._limits = query_limits(sdk)
            device = self

            def _servo() -> None:
                device._servo()

            self._callback = sdk.callback.hd_callback(_servo)  # keep a reference (ctypes)
            with _quiet():
                sdk.hd.enable_force()
                sdk.hd.start_scheduler()
                sdk.callback.hdAsyncSheduler(self._callback)
                if sdk.hd.get_error():
                    raise DeviceError(f"{self.name}: the OpenHaptics scheduler failed to start")
        except BaseException:
            self.stop()
            raise
        log.info("OpenHaptics device %r opened: %s %s", self.device_name, self.vendor,
                 self.model)

    def stop(self) -> None:
        """Stops the scheduler and closes the device (safe to call twice)."""
        sdk, handle = self._sdk, self._handle
        self._handle = None
        self._hook = None
        self._force = (0.0, 0.0, 0.0)
        if sdk is None or handle is None:
            return
        with _quiet():
            try:
                sdk.hd.stop_scheduler()
            finally:
                sdk.hd.close_device(handle)

    def read(self) -> DeviceSample:
        """The latest snapshot the scheduler callback took (``valid=False`` before one)."""
        if self._handle is None:
            raise DeviceError(f"{self.name}: read() before start()")
        with self._lock:
            return self._sample

    def write_force(self, force: FloatArray) -> None:
        """Sets the force the scheduler callback sends next [N], device frame."""
        f = as_force(force)
        self._force = (float(f[0]), float(f[1]), float(f[2]))

    def _servo(self) -> None:
        """The scheduler callback body (vendor thread, inside begin/end frame)."""
        sdk = self._sdk
        if sdk is None:
            return
        hd = sdk.hd
        try:
            s = sample_from_transform(time.perf_counter(), hd.get_transform(),
                                      hd.get_buttons())
            with self._lock:
                self._sample = s
            self.callbacks += 1
            hook = self._hook
            if hook is not None:
                hook()
        except Exception:  # nothing may escape into the vendor's C thread: render nothing
            log.exception("%s: scheduler callback failed; force zeroed", self.name)
            self._force = (0.0, 0.0, 0.0)
            with self._lock:
                self._sample = DeviceSample(t=time.perf_counter(), position=np.zeros(3),
                                            valid=False)
        hd.set_force(list(self._force))


__all__ = [
    "INSTALL_HINT",
    "MSG_DEVICE",
    "MSG_PACKAGE",
    "MSG_RUNTIME",
    "PACKAGE",
    "RUNTIME_HINT",
    "SDK",
    "OpenHapticsDevice",
    "load_sdk",
    "open_device",
    "query_limits",
    "runtime_loadable",
    "sample_from_transform",
]
