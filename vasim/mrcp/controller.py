"""Robot controllers: the driver seam (spec §8) and an emulator of the real controllers'
safety layer (spec §2).

The kernel talks to every robot through :class:`RobotDriver`: it sends a joint target once
per cycle and reads back the joint state. :class:`EmulatedController` implements it in
simulation; a driver for a real controller (e.g. the seed's Stäubli CS7 over its
communication layer) implements the same four members and the kernel does not change.

The emulator does what the real controllers' safety layer does with a position target:
the target is clamped into the joint limits, and the joint moves toward it with a per-joint
trapezoidal (bang-bang) profile that never exceeds the joint's maximum velocity and
acceleration and always stops before a joint limit. The pure step is
:func:`limited_step`; the cycle is 18 ms (55.6 Hz) by default, as in the seed's hardware.

**Decision** (discrete-time braking): a joint moving at ``v`` this cycle and braking by
``a dt`` per cycle covers ``D(v) = dt sum_{k=0..m} (v - k a dt)``, ``m = floor(v / (a dt))``
(the last cycle, slower than ``a dt``, lands on the spot). ``D`` is increasing and piecewise
linear; its inverse is the largest speed that still stops within ``x``:
``v_stop(x) = (x / dt + a dt m (m + 1) / 2) / (m + 1)`` with
``m = floor(sqrt(1/4 + 2 x / (a dt^2)) - 1/2)``. Commanding at most ``v_stop`` toward the
target and toward each limit keeps the profile exact in discrete time, so the final clamp
into the limits (which would break the acceleration bound) only absorbs round-off.

Example:
    >>> from vasim.mrcp.backend import PybulletArm
    >>> from vasim.mrcp.dh import load_robot
    >>> ctrl = EmulatedController(PybulletArm(load_robot("rx60b")))
    >>> ctrl.cycle_time
    0.018
    >>> ctrl.send_target(ctrl.read_state().q + 0.01)
    >>> state = ctrl.sync()
    >>> round(state.t, 3), bool(np.all(np.abs(state.qd) <= ctrl.limits.max_acceleration * 0.018))
    (0.018, True)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from vasim.core.config import check_array, check_number, expect
from vasim.mrcp.interfaces import ArmKinematics, FloatArray

#: the seed's controller cycle [s] (minimum communication cycle of the Stäubli controllers)
DEFAULT_CYCLE = 0.018


@dataclass(frozen=True, eq=False)
class JointLimits:
    """Per-joint limits the safety layer enforces (rad, rad/s, rad/s^2)."""

    lower: FloatArray
    upper: FloatArray
    max_velocity: FloatArray
    max_acceleration: FloatArray

    def __post_init__(self) -> None:
        arrays = [np.array(getattr(self, n), dtype=float) for n in
                  ("lower", "upper", "max_velocity", "max_acceleration")]
        n = arrays[0].shape
        for name, arr in zip(("lower", "upper", "max_velocity", "max_acceleration"), arrays,
                             strict=True):
            check_array(arr, name, shape=n if len(n) == 1 else (None,),
                        what=f"{n[0] if n else 'n'} finite values")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        expect(np.all(self.lower < self.upper), self.lower,
               f"limits below upper ({self.upper!r})", field="lower")
        for name in ("max_velocity", "max_acceleration"):
            expect(np.all(getattr(self, name) > 0), getattr(self, name), "values > 0",
                   field=name)

    @classmethod
    def of(cls, arm: ArmKinematics) -> JointLimits:
        return cls(arm.joint_lower, arm.joint_upper, arm.max_velocity, arm.max_acceleration)


@dataclass(frozen=True, eq=False)
class JointState:
    """What a controller reports each cycle."""

    t: float              # controller time [s]
    q: FloatArray         # (n,) joint positions [rad]
    qd: FloatArray        # (n,) joint velocities [rad/s]
    target: FloatArray    # (n,) the target in force after the safety layer's clamping
    clamped: FloatArray   # (n,) bool: the commanded target was outside the joint limits


def stopping_speed(distance: FloatArray, accel: FloatArray, dt: float) -> FloatArray:
    """Largest speed [rad/s] from which a joint stops within ``distance`` (>= 0) [rad],
    decelerating by ``accel * dt`` per cycle of ``dt``, without passing the spot in one
    cycle (module docstring)."""
    x = np.maximum(np.asarray(distance, dtype=float), 0.0)
    adt = accel * dt
    m = np.floor(np.sqrt(0.25 + 2.0 * x / (adt * dt)) - 0.5)
    return (x / dt + adt * m * (m + 1.0) / 2.0) / (m + 1.0)


def limited_step(q: FloatArray, qd: FloatArray, target: FloatArray, limits: JointLimits,
                 dt: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """One cycle of the safety layer: a pure function.

    Args:
        q, qd: ``(n,)`` current joint positions [rad] and velocities [rad/s].
        target: ``(n,)`` commanded joint positions [rad] (clamped into the limits).
        limits: the joint limits.
        dt: cycle time [s].

    Returns:
        ``(q_next, qd_next, target_clamped)``. Per joint: ``|qd_next| <= max_velocity``,
        ``|qd_next - qd| <= max_acceleration * dt``, ``q_next`` within the limits, and the
        joint settles on the target without overshoot.
    """
    a, vmax = limits.max_acceleration, limits.max_velocity
    tgt = np.clip(target, limits.lower, limits.upper)
    e = tgt - q
    v_des = np.sign(e) * np.minimum(vmax, stopping_speed(np.abs(e), a, dt))
    lo = np.maximum(-stopping_speed(q - limits.lower, a, dt), qd - a * dt)
    hi = np.minimum(stopping_speed(limits.upper - q, a, dt), qd + a * dt)
    lo = np.maximum(lo, -vmax)
    hi = np.minimum(hi, vmax)
    v = np.clip(v_des, lo, hi)
    infeasible = lo > hi          # only from a state no step of this function produces
    if np.any(infeasible):
        v = np.where(infeasible, qd - np.sign(qd) * a * dt, v)
    q_next = np.clip(q + v * dt, limits.lower, limits.upper)
    return q_next, v, tgt


@runtime_checkable
class RobotDriver(Protocol):
    """The kernel's view of one robot controller (spec §8: one internal format)."""

    name: str

    @property
    def cycle_time(self) -> float:
        """The controller's cycle [s]."""
        ...

    def read_state(self) -> JointState:
        """The latest joint state."""
        ...

    def send_target(self, q_target: FloatArray) -> None:
        """Sets the joint position target ``(n,)`` [rad] for the next cycles."""
        ...

    def sync(self) -> JointState:
        """Waits for the next controller cycle (the emulator: runs it) and returns the
        state after it."""
        ...


class EmulatedController:
    """A simulated robot controller (:class:`RobotDriver`) with the safety layer of
    :func:`limited_step`.

    Args:
        arm: limits come from it (``joint_lower`` ... ``max_acceleration``).
        q0: initial joint positions (default: the arm's ``home`` if it has one, else the
            middle of the joint ranges); must lie within the limits.
        cycle: cycle time [s] (default 18 ms).
        name: the driver's name (default: the arm's).
    """

    def __init__(self, arm: ArmKinematics, q0: FloatArray | None = None,
                 cycle: float = DEFAULT_CYCLE, name: str | None = None) -> None:
        check_number(cycle, "cycle", gt=0)
        self.name = name or arm.name
        self.limits = JointLimits.of(arm)
        self._dt = float(cycle)
        if q0 is None:
            home = getattr(arm, "home", None)
            q0 = home if home is not None else (self.limits.lower + self.limits.upper) / 2
        q = np.array(q0, dtype=float)
        expect(q.shape == self.limits.lower.shape and bool(np.all(
            (q >= self.limits.lower) & (q <= self.limits.upper))), q0,
            f"{self.limits.lower.size} joint values within the limits", field="q0")
        self._t = 0.0
        self._q = q
        self._qd = np.zeros_like(q)
        self._target = q.copy()
        self._clamped = np.zeros(q.shape, dtype=bool)

    @property
    def cycle_time(self) -> float:
        return self._dt

    def read_state(self) -> JointState:
        return JointState(self._t, self._q.copy(), self._qd.copy(), self._target.copy(),
                          self._clamped.copy())

    def send_target(self, q_target: FloatArray) -> None:
        target = np.array(q_target, dtype=float)
        if target.shape != self._q.shape or not np.all(np.isfinite(target)):
            raise ValueError(f"{self.name}: the target must be {self._q.size} finite joint "
                             f"values, got {q_target!r}")
        clipped = np.clip(target, self.limits.lower, self.limits.upper)
        self._clamped = clipped != target
        self._target = clipped

    def sync(self) -> JointState:
        self._q, self._qd, _ = limited_step(self._q, self._qd, self._target, self.limits,
                                            self._dt)
        self._t += self._dt
        return self.read_state()

    def stop(self) -> None:
        """Holds the current position as the target (the joints brake within limits)."""
        self._target = self._q.copy()
        self._clamped = np.zeros(self._q.shape, dtype=bool)
