"""The scripted operator (``vasim.operator.scripted``) as a device.

The simulated person moves the master by an increment dX_M per servo tick; the device's
position is the integral of these increments, starting at ``start`` (the task's start, in
the world-aligned master frame the operator works in). The person needs to *see* the task
to move, which is the hook of ``ObservingDevice``: before each ``read()`` the servo loop
calls ``observe(obs)`` with the plant's ``OperatorObservation`` (the slave TCP, the goal,
the cues and the force the person feels, as of the last tick). ``read()`` then steps the
operator once with that observation.

Without a plant that provides observations (no ``observe`` call before a read) the device
runs **standalone** (**decision**, for demos, benchmarks and ``vasim devices``): it
observes itself as if master and slave were the same point (no motion scaling), the goal
being the task's POI i, advanced when the position comes within ``task.reach_radius`` of it
(the trial's reach rule), and feels the force last written to it.

Time: t = k dt at the k-th read (k = 0 first), the operator's control step ``dt``.

Example:
    >>> from vasim.operator.scripted import OperatorProfile, ScriptedOperator
    >>> from vasim.tasks import point_task
    >>> task = point_task()
    >>> dev = ScriptedDevice(ScriptedOperator(OperatorProfile.expert(), task, seed=1),
    ...                      task.start)
    >>> dev.start()
    >>> s = [dev.read() for _ in range(3)]
    >>> s[0].t, s[2].t, bool((s[0].position == task.start).all())
    (0.0, 0.002, True)
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from vasim.core.errors import DeviceError
from vasim.haptics.device import (
    UNBOUNDED,
    DeviceLimits,
    DeviceSample,
    FloatArray,
    as_force,
)
from vasim.haptics.observation import OperatorObservation
from vasim.operator.scripted import ScriptedOperator

SCRIPTED_LIMITS = DeviceLimits(workspace_min=UNBOUNDED[0], workspace_max=UNBOUNDED[1],
                               max_force_n=3.3, max_continuous_force_n=0.88)
"""The simulated person holds an Omni-like stylus (3.3 N peak, 0.88 N continuous, as in the
VF study) but is not confined to a workspace box (its task frame is the scene's)."""


class ScriptedDevice:
    """A ``ScriptedOperator`` presented as a device (module docstring).

    Args:
        operator: the simulated person (``reset`` is called by ``start``).
        start: (3,) initial master position [m] (the task's start).
        dt: control step [s] (the servo period).
        limits: device limits.
        name: device name.
    """

    def __init__(self, operator: ScriptedOperator, start: ArrayLike, *, dt: float = 1e-3,
                 limits: DeviceLimits = SCRIPTED_LIMITS, name: str = "scripted"):
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be > 0 s, got {dt!r}")
        self.operator = operator
        self.name = name
        self.dt = float(dt)
        self._limits = limits
        self._start = np.array(start, dtype=np.float64).reshape(3)
        self._started = False
        self._reset()

    def _reset(self) -> None:
        self._x = self._start.copy()
        self._k = 0
        self._obs: OperatorObservation | None = None
        self._force = np.zeros(3)
        self._goal = 0
        self.standalone_steps = 0

    @property
    def limits(self) -> DeviceLimits:
        return self._limits

    @property
    def position(self) -> FloatArray:
        """(3,) current master position [m]."""
        return self._x.copy()

    @property
    def goal_index(self) -> int:
        """Standalone mode's goal index (number of POIs reached)."""
        return self._goal

    def start(self) -> None:
        """Resets the operator and the position to ``start``."""
        self.operator.reset(self._start)
        self._reset()
        self._started = True

    def stop(self) -> None:
        self._started = False

    def observe(self, obs: OperatorObservation) -> None:
        """What the person perceives before the next ``read()`` (the servo loop's hook)."""
        self._obs = obs

    def read(self) -> DeviceSample:
        """Moves the hand by one operator step (none on the first read) and returns it."""
        if not self._started:
            raise DeviceError(f"{self.name}: read() before start()")
        k = self._k
        if k > 0:
            obs = self._obs if self._obs is not None else self._self_observation(k)
            self._obs = None
            dx = np.asarray(self.operator.step(obs), dtype=np.float64)
            self._x = self._x + dx
        self._k = k + 1
        return DeviceSample(t=k * self.dt, position=self._x.copy())

    def write_force(self, force: FloatArray) -> None:
        self._force = as_force(force)

    def _self_observation(self, k: int) -> OperatorObservation:
        """Standalone: master = slave, the reach rule on the task's POIs."""
        task = self.operator.task
        pts = np.asarray(task.points, dtype=np.float64)
        n = len(pts)
        r2 = task.reach_radius ** 2
        while self._goal < n and float(((self._x - pts[self._goal]) ** 2).sum()) <= r2:
            self._goal += 1
        i = min(self._goal, n - 1)
        self.standalone_steps += 1
        return OperatorObservation(t=k * self.dt, dt=self.dt, tcp=self._x.copy(),
                                   goal=pts[i], goal_index=i, force=self._force.copy())


__all__ = ["SCRIPTED_LIMITS", "ScriptedDevice"]
