"""A laparoscopic instrument driven from the browser: mouse, keyboard or gamepad.

Without a haptic device the trainee still handles an instrument that pivots about its
trocar (:mod:`vasim.haptics.laparoscopic`): the page sends batches of raw input
(:class:`~vasim.haptics.laparoscopic.Increment`: pointer-lock movement, wheel, held keys,
gamepad sticks) at its frame rate; :meth:`LaparoscopicDevice.push` turns each batch into a
new *target* pose of the instrument (angles about the port, insertion, roll), clamped to the
port's limits. The servo loop reads the device at 1 kHz like any other: :meth:`read` moves
the rendered pose toward the target with a first-order filter (``tau_s``, **decision**:
15 ms: a 60 Hz page's steps of 16.7 ms become smooth motion without a noticeable lag) and
returns the tip position and the instrument's orientation.

The device is an ordinary :class:`vasim.haptics.device.Device`: the servo loop guards its
readings, records them (``ServoLoop(record=True)``) and a replay reproduces the trial; it
renders no force (``max_force_n = 0``), the page draws the FF arrow instead. Non-finite
batches are dropped and counted (``dropped``); a batch never moves the shaft by more than
45 deg or the insertion by more than 10 cm.

Example:
    >>> import numpy as np
    >>> from vasim.haptics.laparoscopic import Increment, Port
    >>> now = [0.0]
    >>> dev = LaparoscopicDevice(Port(fulcrum=(0, 0, 0.1), axis=(0, 0, -1)),
    ...                          clock=lambda: now[0])
    >>> dev.start()
    >>> dev.push(Increment(wheel=5.0))            # 5 wheel lines: 2 cm deeper
    True
    >>> now[0] = 1.0                              # long after the 15 ms filter
    >>> round(float(dev.read().position[2]), 4)   # 0.1 - (0.08 + 0.02)
    0.0
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike

from vasim.core.config import check_number
from vasim.core.errors import DeviceError
from vasim.haptics.device import DeviceLimits, DeviceSample, FloatArray
from vasim.haptics.laparoscopic import (
    Increment,
    InputMapping,
    InstrumentPose,
    Port,
    clamp,
    orientation,
    tip_position,
)


def _toward(a: float, b: float, alpha: float, *, wrap: bool = False) -> float:
    d = math.remainder(b - a, 2 * math.pi) if wrap else b - a
    return a + alpha * d


class LaparoscopicDevice:
    """The instrument as a servo-loop device (no force output).

    Args:
        port: the trocar the instrument passes through.
        mapping: how raw input becomes motion (fulcrum effect, sensitivity).
        start: the pose at start (clamped to the port).
        tau_s: time constant of the smoothing toward the target [s], > 0.
        clock: monotonic time source [s] (tests pass a fake one).
    """

    name = "laparoscopic"

    def __init__(self, port: Port, mapping: InputMapping | None = None, *,
                 start: InstrumentPose | None = None, tau_s: float = 0.015,
                 clock: Callable[[], float] = time.monotonic):
        check_number(tau_s, "tau_s", gt=0)
        self.port = port
        self.mapping = mapping or InputMapping()
        self.tau_s = float(tau_s)
        self._clock = clock
        pose = clamp(port, start or InstrumentPose())
        self._target = pose
        self._pose = pose
        self._screen: tuple[FloatArray, FloatArray] | None = None
        self._buttons = 0
        self._lock = threading.Lock()
        self._t_start: float | None = None
        self._t_last: float | None = None
        self.dropped = 0
        """Batches refused because a value was not finite."""
        self.pushed = 0
        reach = port.max_insertion_m
        fx, fy, fz = (float(v) for v in port.fulcrum)
        self._limits = DeviceLimits(
            workspace_min=(fx - reach, fy - reach, fz - reach),
            workspace_max=(fx + reach, fy + reach, fz + reach),
            max_force_n=0.0, max_continuous_force_n=0.0)

    @property
    def limits(self) -> DeviceLimits:
        """The sphere of reach around the port as a box; no force output."""
        return self._limits

    @property
    def target(self) -> InstrumentPose:
        with self._lock:
            return self._target

    @property
    def pose(self) -> InstrumentPose:
        """The pose last rendered by :meth:`read`."""
        with self._lock:
            return self._pose

    def set_screen(self, right: ArrayLike, up: ArrayLike) -> None:
        """The view's right and up axes in the world frame (the endoscope's), which pointer
        and stick motion follow."""
        r = np.asarray(right, dtype=float).reshape(3)
        u = np.asarray(up, dtype=float).reshape(3)
        if not (np.isfinite(r).all() and np.isfinite(u).all()) or min(
                float(np.linalg.norm(r)), float(np.linalg.norm(u))) < 1e-9:
            raise ValueError("screen axes must be finite non-zero 3-vectors")
        with self._lock:
            self._screen = (r / np.linalg.norm(r), u / np.linalg.norm(u))

    def set_mapping(self, mapping: InputMapping) -> None:
        """Changes the fulcrum effect or sensitivity (takes effect with the next batch)."""
        with self._lock:
            self.mapping = mapping

    def push(self, inc: Increment, buttons: int | None = None) -> bool:
        """Applies one batch of page input to the target pose; False if it was refused."""
        if not isinstance(inc, Increment) or not inc.finite():
            self.dropped += 1
            return False
        with self._lock:
            self._target = self.mapping.apply(self.port, self._target, inc, self._screen)
            if buttons is not None:
                self._buttons = int(buttons) & 0xFF
            self.pushed += 1
        return True

    def start(self) -> None:
        self._t_start = self._t_last = self._clock()

    def stop(self) -> None:
        self._t_start = None

    def read(self) -> DeviceSample:
        if self._t_start is None or self._t_last is None:
            raise DeviceError("LaparoscopicDevice.read() before start()")
        now = self._clock()
        dt = max(0.0, now - self._t_last)
        self._t_last = now
        alpha = 1.0 - math.exp(-dt / self.tau_s)
        with self._lock:
            p, g = self._pose, self._target
            self._pose = replace(
                p, yaw=_toward(p.yaw, g.yaw, alpha), pitch=_toward(p.pitch, g.pitch, alpha),
                insertion=_toward(p.insertion, g.insertion, alpha),
                roll=math.remainder(_toward(p.roll, g.roll, alpha, wrap=True), 2 * math.pi))
            pose, buttons = self._pose, self._buttons
        return DeviceSample(t=now - self._t_start, position=tip_position(self.port, pose),
                            orientation=orientation(self.port, pose), buttons=buttons)

    def write_force(self, force: FloatArray) -> None:
        """No force output (a browser); the servo loop passes zeros anyway."""


__all__ = ["LaparoscopicDevice"]
