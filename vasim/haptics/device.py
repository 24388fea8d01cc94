"""The device protocol of the haptic layer and the values that cross it.

Every input device (the Phantom Omni / Touch through OpenHaptics, the emulator, the scripted
operator, the browser, a replayed recording) is a :class:`Device`: the 1 kHz servo loop
(``vasim.haptics.servo``) calls ``read()`` once per tick, then ``write_force(f)`` once, and
``start()`` / ``stop()`` around a run. Nothing else talks to a device SDK (one owner per
external thing: the SDKs live in ``vasim.haptics.devices``).

Frames and units: positions [m] and forces [N] are in the *device frame* (for the Omni:
x right, y up, z toward the user, origin at the centre of the usable workspace); the plant
(the trial, the physics) maps that frame to the scene. Orientations are unit quaternions
``(w, x, y, z)`` (the project order, ``vasim.core.geometry``) of the stylus in the device
frame (R_device<-stylus). Times are seconds on
the device's own clock, monotonic.

Example:
    >>> import numpy as np
    >>> s = DeviceSample(t=0.0, position=np.zeros(3))
    >>> s.valid, s.buttons, s.orientation.tolist()
    (True, 0, [1.0, 0.0, 0.0, 0.0])
    >>> OMNI_LIMITS.contains(np.array([0.0, 0.05, 0.0])), OMNI_LIMITS.contains([0, 0.07, 0])
    (True, False)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vasim.core.config import check_number, expect
from vasim.haptics.observation import OperatorObservation

FloatArray = NDArray[np.float64]

IDENTITY_QUAT: FloatArray = np.array([1.0, 0.0, 0.0, 0.0])
IDENTITY_QUAT.setflags(write=False)

BUTTON_1 = 1
"""Bit of the first stylus button (OpenHaptics ``HD_DEVICE_BUTTON_1``, the grey/front one)."""
BUTTON_2 = 2
"""Bit of the second stylus button (``HD_DEVICE_BUTTON_2``, the white/rear one): the clutch
by default (``ServoLoop(clutch_button=BUTTON_2)``)."""


@dataclass(frozen=True)
class DeviceLimits:
    """What a device can sense and render.

    Attributes:
        workspace_min: (3,) lower corner of the usable workspace box [m], device frame
            (``-inf`` allowed for unbounded devices).
        workspace_max: (3,) upper corner [m]; every component > ``workspace_min``.
        max_force_n: peak force the device renders [N] (>= 0; 0 = no force output). The
            servo loop saturates every force to it, keeping the direction.
        max_continuous_force_n: force the device sustains indefinitely [N], <= the peak.
        continuous_window_s: the averaging window that defines "continuous" [s]: the
            time constant of the exponentially weighted mean of |F|^2 that must stay below
            ``max_continuous_force_n ** 2`` (see ``vasim.haptics.devices.emulator``).
        position_resolution_m: smallest position step the device reports [m] (>= 0).

    Raises:
        ConfigError: for a non-finite force, an empty box, a continuous force above the peak
            or a non-positive window; the message names the field and the value.
    """

    workspace_min: tuple[float, float, float]
    workspace_max: tuple[float, float, float]
    max_force_n: float
    max_continuous_force_n: float
    continuous_window_s: float = 10.0
    position_resolution_m: float = 0.0

    def __post_init__(self) -> None:
        lo = tuple(float(v) for v in self.workspace_min)
        hi = tuple(float(v) for v in self.workspace_max)
        expect(len(lo) == 3 and len(hi) == 3, (lo, hi), "workspace corners of 3 components",
               field="workspace")
        expect(not any(math.isnan(v) for v in lo + hi)
               and all(a < b for a, b in zip(lo, hi, strict=True)), (lo, hi),
               "workspace_min < workspace_max per axis", field="workspace")
        object.__setattr__(self, "workspace_min", lo)
        object.__setattr__(self, "workspace_max", hi)
        for name in ("max_force_n", "max_continuous_force_n", "position_resolution_m"):
            check_number(getattr(self, name), name, ge=0)
        check_number(self.max_continuous_force_n, "max_continuous_force_n",
                     le=self.max_force_n)
        check_number(self.continuous_window_s, "continuous_window_s", gt=0)

    def contains(self, position: ArrayLike) -> bool:
        """True when ``position`` (3,) [m] lies in the closed workspace box."""
        p0, p1, p2 = (float(v) for v in np.asarray(position, dtype=np.float64).reshape(3))
        lo, hi = self.workspace_min, self.workspace_max
        return (lo[0] <= p0 <= hi[0]) and (lo[1] <= p1 <= hi[1]) and (lo[2] <= p2 <= hi[2])

    @property
    def size(self) -> FloatArray:
        """(3,) edge lengths of the workspace box [m]."""
        return np.asarray(self.workspace_max) - np.asarray(self.workspace_min)

    def to_dict(self) -> dict[str, object]:
        """Plain JSON-able data (stored with recordings); ``from_dict`` inverts it."""
        return {"workspace_min": list(self.workspace_min),
                "workspace_max": list(self.workspace_max),
                "max_force_n": self.max_force_n,
                "max_continuous_force_n": self.max_continuous_force_n,
                "continuous_window_s": self.continuous_window_s,
                "position_resolution_m": self.position_resolution_m}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> DeviceLimits:
        """The limits ``to_dict`` wrote."""
        return cls(workspace_min=tuple(d["workspace_min"]),
                   workspace_max=tuple(d["workspace_max"]),
                   max_force_n=float(d["max_force_n"]),
                   max_continuous_force_n=float(d["max_continuous_force_n"]),
                   continuous_window_s=float(d["continuous_window_s"]),
                   position_resolution_m=float(d["position_resolution_m"]))


OMNI_LIMITS = DeviceLimits(
    workspace_min=(-0.080, -0.060, -0.035),
    workspace_max=(0.080, 0.060, 0.035),
    max_force_n=3.3,
    max_continuous_force_n=0.88,
    continuous_window_s=10.0,
    position_resolution_m=0.055e-3,
)
"""Phantom Omni / Geomagic Touch (SensAble/3D Systems data sheet): usable workspace
160 W x 120 H x 70 D mm (centred box), peak force 3.3 N, continuous force 0.88 N, nominal
position resolution > 450 dpi (~0.055 mm). The data sheet quotes the continuous force for
24 h of exertion; the 10 s window is a **decision** of the emulator's thermal model (the
winding time constant of small DC motors is seconds to tens of seconds)."""

UNBOUNDED = (-math.inf, -math.inf, -math.inf), (math.inf, math.inf, math.inf)
"""Workspace corners of a device without a mechanical range (scripted, browser)."""


@dataclass(frozen=True, eq=False)
class DeviceSample:
    """One reading of a device.

    Attributes:
        t: time of the reading [s], the device's clock.
        position: (3,) stylus tip position [m], device frame.
        orientation: (4,) unit quaternion (w, x, y, z), stylus to device frame.
        buttons: bitmask of the pressed buttons (``BUTTON_1``, ``BUTTON_2``, ...).
        valid: False when the device has no fresh, trustworthy reading (no browser sample
            yet, a driver error): the servo loop then holds its last good state.
    """

    t: float
    position: FloatArray
    orientation: FloatArray = field(default_factory=lambda: IDENTITY_QUAT)
    buttons: int = 0
    valid: bool = True


@runtime_checkable
class Device(Protocol):
    """What the servo loop needs from an input/force device.

    ``read()`` and ``write_force()`` are called from the servo thread once per tick each;
    they must not block for long (no I/O waits) and must be cheap (tens of microseconds).
    ``write_force`` receives a finite (3,) force [N] already saturated to
    ``limits.max_force_n``; a device may limit it further (thermal limits), as hardware does.
    """

    name: str

    @property
    def limits(self) -> DeviceLimits: ...

    def start(self) -> None: ...

    def stop(self) -> None: ...

    def read(self) -> DeviceSample: ...

    def write_force(self, force: FloatArray) -> None: ...


@runtime_checkable
class ObservingDevice(Protocol):
    """A device that needs to see the task to move (the scripted operator).

    The servo loop calls ``observe(obs)`` before each ``read()`` when its plant provides an
    observation (:class:`ObservationSource`): what the simulated person perceives now.
    """

    def observe(self, obs: OperatorObservation) -> None: ...


@runtime_checkable
class ObservationSource(Protocol):
    """A plant that can tell an observing device what the operator perceives."""

    def observation(self) -> OperatorObservation | None: ...


@runtime_checkable
class ScheduledDevice(Protocol):
    """A device whose driver has its own servo scheduler (OpenHaptics' ``hdScheduler``).

    ``set_servo_hook(fn)`` asks the device to call ``fn()`` from its scheduler callback,
    between reading the device state and sending the force: the servo loop then runs inside
    the vendor's 1 kHz callback instead of on its own timer (``ServoLoop.start(driver=
    "device")``). ``None`` removes the hook.
    """

    def set_servo_hook(self, hook: Callable[[], None] | None) -> None: ...


def as_force(force: ArrayLike) -> FloatArray:
    """``force`` as a new float64 (3,) array [N]; raises ``ValueError`` for another shape."""
    f = np.array(force, dtype=np.float64).reshape(-1)
    if f.shape != (3,):
        raise ValueError(f"a force must have 3 components, got shape {f.shape}: {force!r}")
    return f


__all__ = [
    "BUTTON_1",
    "BUTTON_2",
    "IDENTITY_QUAT",
    "OMNI_LIMITS",
    "UNBOUNDED",
    "Device",
    "DeviceLimits",
    "DeviceSample",
    "ObservationSource",
    "ObservingDevice",
    "ScheduledDevice",
    "as_force",
]
