"""The operator port of a trial: one protocol every input source implements.

A trial engine (``vasim.trials.vf.TrialRunner``) asks its operator for the master increment
dX_M once per control step, and nothing else. What the operator may use to decide is a
:class:`Percept`: the last frame as the person perceives it (TCP, goal, the fixtures' cues,
the force felt on the hand), kept as floats so that the 1 kHz loop builds no arrays; a
:class:`Percept` also gives the same content as an ``OperatorObservation``
(``percept.observation()``) for operators written against that dataclass.

Operators (each implements :class:`TrialOperator`):

* ``vasim.operator.scripted.ScriptedOperator`` -- the simulated person (reads the floats);
* :class:`MasterIncrement` -- an increment handed in from outside (the real-time trial's
  servo loop reads the device, applies guard and clutch, and sets the increment);
* :class:`ObservingOperator` -- wraps any object with ``step(obs: OperatorObservation)``
  (a device operator, a test double): ``act(p) = step(p.observation())``.

Adding an operator: write a class with ``profile`` (the simulated person's
``OperatorProfile``, or None for a real device), ``reset(start)`` and
``act(percept) -> (dx, dy, dz)``, then plug it in with ``runner.operator = op``. The engine
never asks which class it is (no ``type(op) is`` dispatch).

A teleoperation trial (``vasim.trials.teleop.TeleopTrial``) moves its masters with *hands*,
one per path of goals: a :class:`MasterHand` (``move`` gives the master increment,
``check`` advances the goal) that the trial asks of its :class:`HandFactory` with a
:class:`HandRequest` each time a new path starts. The default factory is the scripted
person's (``vasim.trials.teleop_hands.ScriptedHands``); the viewer passes one whose hands
read the page's device (``vasim.viewer.teleop_live.DeviceHands``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from vasim.fixtures.types import Vec3
    from vasim.haptics.observation import OperatorObservation
    from vasim.operator.profile import OperatorProfile


class Percept(Protocol):
    """What the operator perceives at one control step (read-only for the operator).

    Attributes:
        t: time of this step [s]. dt: control step [s].
        tcp: (3 floats) slave TCP as last shown [m]. goal: (3 floats) current goal [m].
        goal_index: index of the goal.
        guidance: True while the VG arrow is visible (opacity above the noticing threshold).
        audio_volume: AG volume in [0, 1]. zoom: Mag zoom (1: no Mag).
        ms_factors: (3 floats) MS factors of the last step.
        force: (3 floats) force felt on the hand [N]: the fixtures' plus the tissue's.
    """

    @property
    def t(self) -> float: ...

    @property
    def dt(self) -> float: ...

    @property
    def tcp(self) -> Sequence[float]: ...

    @property
    def goal(self) -> Sequence[float]: ...

    @property
    def goal_index(self) -> int: ...

    @property
    def guidance(self) -> bool: ...

    @property
    def audio_volume(self) -> float: ...

    @property
    def zoom(self) -> float: ...

    @property
    def ms_factors(self) -> Sequence[float]: ...

    @property
    def force(self) -> Sequence[float]: ...

    def observation(self) -> OperatorObservation:
        """The same step as an ``OperatorObservation`` (arrays; built on request)."""
        ...


@runtime_checkable
class TrialOperator(Protocol):
    """An input source of a trial: the master increment dX_M per control step."""

    @property
    def profile(self) -> OperatorProfile | None:
        """The simulated person behind the input, or None (a device, a servo loop)."""
        ...

    def reset(self, start: Vec3) -> None:
        """Called once with the tool's start position before the first step."""
        ...

    def act(self, percept: Percept) -> Sequence[float]:
        """The master increment dX_M [m] of this step (3 floats; a non-finite value is
        dropped by the engine and logged)."""
        ...


class MasterIncrement:
    """An operator whose master increment dX_M is set from outside before each step.

    The real-time trial's servo loop reads the device, applies guard and clutch, and hands
    the increment of the master position to the runner through this object
    (``set(dx)`` then ``TrialRunner.step()``); each increment is used once (``take``
    returns zero motion when none was set). ``profile`` is None: no simulated person.
    """

    profile = None

    def __init__(self) -> None:
        self._dx: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def reset(self, start: object) -> None:
        del start
        self._dx = (0.0, 0.0, 0.0)

    def set(self, dx: tuple[float, float, float]) -> None:
        """The increment [m] the next step uses."""
        self._dx = dx

    def take(self) -> tuple[float, float, float]:
        """The pending increment (then zero)."""
        dx, self._dx = self._dx, (0.0, 0.0, 0.0)
        return dx

    def act(self, percept: Percept) -> tuple[float, float, float]:
        """The operator protocol (the percept is not used): ``take()``."""
        del percept
        return self.take()

    def step(self, obs: OperatorObservation) -> tuple[float, float, float]:
        """``take()`` for callers holding an ``OperatorObservation`` (not used)."""
        del obs
        return self.take()


class StepsOnObservations(Protocol):
    """An object answering ``step(obs: OperatorObservation)`` with dX_M."""

    def reset(self, start: Vec3) -> None: ...

    def step(self, obs: OperatorObservation) -> Sequence[float]: ...


class ObservingOperator:
    """:class:`TrialOperator` over an object with ``step(obs)``: each step builds the
    ``OperatorObservation`` of the percept (arrays; fine outside the headless fast path).

    Args:
        inner: the wrapped operator (``reset`` and ``step`` are forwarded).
        profile: the person behind it (default: ``inner.profile`` if it has one, else None).
    """

    def __init__(self, inner: StepsOnObservations, profile: OperatorProfile | None = None):
        self.inner = inner
        self._profile = profile if profile is not None else getattr(inner, "profile", None)

    @property
    def profile(self) -> OperatorProfile | None:
        return self._profile

    def reset(self, start: Vec3) -> None:
        self.inner.reset(start)

    def act(self, percept: Percept) -> list[float]:
        return np.asarray(self.inner.step(percept.observation()), dtype=np.float64).tolist()


@dataclass(frozen=True, eq=False)
class HandRequest:
    """A new path of a teleoperation trial's hand (what ``HandFactory`` is asked).

    Attributes:
        points: ``(n, 3)`` goals of the path, in order [m].
        start: where the moved point (the needle, or the free tool tip) is now [m].
        reach: the reach of each goal (one for all, or one per goal) [m].
        seed: this path's seed (a scripted hand draws its noise from it).
        carry: the needle is carried to a ring (the threading movement; a scripted hand
            then moves with its ``carry`` profile, else its ``handover`` one).
    """

    points: NDArray[np.float64]
    start: NDArray[np.float64]
    reach: float | tuple[float, ...]
    seed: int
    carry: bool = False


class MasterHand(Protocol):
    """A hand on one master following a path of goals (``j``: the current goal's index)."""

    j: int

    @property
    def done(self) -> bool:
        """Every goal of the path reached."""
        ...

    def move(self, dt: float, seen: NDArray[np.float64], goal: NDArray[np.float64],
             zoom: float) -> NDArray[np.float64]:
        """One hand step of ``dt`` [s] toward ``goal`` from ``seen`` (what the hand moves,
        as seen at magnification ``zoom``): the master increment [m], finite."""
        ...

    def check(self, position: NDArray[np.float64], goal: NDArray[np.float64]) -> bool:
        """Advances ``j`` when ``position`` is within the goal's reach; True if it did."""
        ...


class HandFactory(Protocol):
    """Makes the hand of each new path of a teleoperation trial (module docstring)."""

    def __call__(self, request: HandRequest) -> MasterHand: ...


__all__ = ["HandFactory", "HandRequest", "MasterHand", "MasterIncrement", "ObservingOperator",
           "Percept", "StepsOnObservations", "TrialOperator"]
