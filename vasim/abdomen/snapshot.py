"""What one physics step of the abdomen publishes: immutable snapshots for every reader.

:class:`AbdomenSnapshot` is the hand-off between the physics (:class:`vasim.abdomen.world.
Abdomen`) and everything downstream (the haptic coupling, the trial recorder, the viewer):
arrays are read-only copies, a sleeping organ's surface is computed only when read.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from vasim.abdomen.contact import ContactPatch

FloatArray = NDArray[np.float64]


class _SurfaceModel(Protocol):
    @property
    def n_surface(self) -> int: ...


class SleepingBody(Protocol):
    """What a snapshot reads of a sleeping organ (the world's per-organ body): its model's
    surface size and its positions at a time. Declared here, below the world, so that the
    snapshot does not import :mod:`vasim.abdomen.world` (issue #29: no module cycle)."""

    @property
    def model(self) -> _SurfaceModel: ...

    def sleeping_x(self, t: float) -> FloatArray: ...


def readonly(a: FloatArray) -> FloatArray:
    """A read-only float64 copy of ``a``."""
    a = np.array(a, dtype=np.float64)
    a.setflags(write=False)
    return a


# ---------------------------------------------------------------------------------------
# Snapshots


@dataclass(frozen=True, eq=False)
class OrganView:
    """One organ's surface in a snapshot (computed on first read when the organ sleeps)."""

    name: str
    awake: bool
    _x: FloatArray | None = field(repr=False, default=None)
    _body: SleepingBody | None = field(repr=False, default=None)
    _t: float = 0.0

    @cached_property
    def surface(self) -> FloatArray:
        """(n_surface, 3) surface node positions [m], read-only."""
        if self._x is not None:
            return self._x
        assert self._body is not None
        return readonly(self._body.sleeping_x(self._t)[: self._body.model.n_surface])


@dataclass(frozen=True, eq=False)
class ToolContact:
    """One instrument's contact result in a snapshot (arrays read-only).

    Attributes:
        name: the instrument's name (the mapping key given to :meth:`Abdomen.step`, else its
            position in the sequence, ``"0"``, ``"1"``, ...).
        force: (3,) total contact force on this instrument [N].
        force_tip: (3,) contact force felt at its tip [N].
        torque: (3,) contact torque about its fulcrum [N·m].
        stiffness_tip: (3, 3) dF_tip/dx [N/m].
        patch: its contact planes for a 1 kHz force model.
        touching: names of the organs it touches (scene order).
        delicate_contact: it touches a delicate organ.
    """

    name: str
    force: FloatArray
    force_tip: FloatArray
    torque: FloatArray
    stiffness_tip: FloatArray
    patch: ContactPatch = field(repr=False)
    touching: tuple[str, ...]
    delicate_contact: bool

    @property
    def in_contact(self) -> bool:
        return bool(self.touching)


@dataclass(frozen=True, eq=False)
class AbdomenSnapshot:
    """The abdomen after one physics step (immutable: arrays are read-only copies).

    Attributes:
        t: simulated time [s].
        seq: step counter (1 for the first step).
        organs: (property) per organ, its surface (see :class:`OrganView`), scene order.
        targets: (p, 3) bound target positions [m] (empty without bound targets).
        target_normals: (p, 3) unit normals of the tissue under the targets.
        target_displacement: (p,) distance of each target from where the physiological
            motion alone would put it [m] (what the tool did to it).
        force: (3,) total contact force on the (first) tool [N].
        force_tip: (3,) contact force felt at the (first) tool's tip [N].
        torque: (3,) contact torque about the (first) tool's fulcrum [N·m].
        stiffness_tip: (3, 3) dF_tip/dx of the first tool [N/m].
        patch: the first tool's contact planes for the 1 kHz force model.
        touching: names of the organs the first tool touches.
        delicate_contact: the first tool touches a delicate organ.
        events: (kind, detail) of what happened in this step (e.g. an organ reset).
        tools: every instrument's result, in the order given to :meth:`Abdomen.step`
            (empty without a tool); ``tools[0]`` carries the top-level fields' values.
    """

    t: float
    seq: int
    organ_sources: tuple[tuple[str, FloatArray | None, SleepingBody], ...] = field(repr=False)
    targets: FloatArray
    target_normals: FloatArray
    target_displacement: FloatArray
    force: FloatArray
    force_tip: FloatArray
    torque: FloatArray
    stiffness_tip: FloatArray
    patch: ContactPatch
    touching: tuple[str, ...]
    delicate_contact: bool
    events: tuple[tuple[str, str], ...] = ()
    tools: tuple[ToolContact, ...] = ()

    @property
    def in_contact(self) -> bool:
        """The first tool touches tissue (see :attr:`any_contact` for every instrument)."""
        return bool(self.touching)

    @property
    def any_contact(self) -> bool:
        """Any instrument touches tissue."""
        return self.in_contact or any(tc.in_contact for tc in self.tools)

    @property
    def touching_any(self) -> tuple[str, ...]:
        """Names of the organs touched by any instrument (first-seen order)."""
        names = dict.fromkeys(self.touching)
        for tc in self.tools:
            names.update(dict.fromkeys(tc.touching))
        return tuple(names)

    @property
    def delicate_any(self) -> bool:
        """Any instrument touches a delicate organ."""
        return self.delicate_contact or any(tc.delicate_contact for tc in self.tools)

    def tool(self, name: str) -> ToolContact:
        """The result of the instrument named ``name``."""
        for tc in self.tools:
            if tc.name == name:
                return tc
        raise KeyError(f"no instrument {name!r} in the snapshot "
                       f"(instruments: {[tc.name for tc in self.tools]!r})")

    @cached_property
    def organs(self) -> tuple[OrganView, ...]:
        return tuple(OrganView(name, True, _x=x) if x is not None
                     else OrganView(name, False, _body=body, _t=self.t)
                     for name, x, body in self.organ_sources)

    def organ(self, name: str) -> OrganView:
        for o in self.organs:
            if o.name == name:
                return o
        raise KeyError(f"no organ {name!r} in the snapshot")


__all__ = ["AbdomenSnapshot", "OrganView", "ToolContact", "readonly"]
