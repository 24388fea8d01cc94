"""Per-trial tissue-quality metrics of spec/study.md §4, accumulated at the physics rate.

What the MRCP experiments measured as "quality" (Q) and commercial trainers record as
tissue handling: the accumulated contact time and the number of contacts, the accumulated
force and torque on tissue, the displacement of targets caused by the tool, and contacts
with a delicate structure (damage).

Definitions (each integral is a left Riemann sum over the physics steps, dt each):
    contact_time      = Σ dt over steps with any tool–tissue contact            [s]
    contact_count     = number of rising edges of "in contact"
    force_integral    = Σ |F| dt, F the total contact force on the tool          [N·s]
    torque_integral   = Σ |τ| dt, τ the contact torque about the fulcrum          [N·m·s]
    max_force         = max |F|                                                    [N]
    delicate_time     = Σ dt with a contact on a delicate organ                    [s]
    delicate_count    = rising edges of delicate contact
    target_displacement_max  = max over steps and targets of |p - p_free|          [m]
    target_displacement_mean = time mean of the largest target displacement        [m]
where ``p_free`` is where the target would be with the physiological motion alone (no tool):
the displacement the operator caused, not breathing.

Several instruments (**decision**, issue #7 §4, :meth:`TissueQuality.add_instruments`): a
step is "in contact" when any instrument touches tissue (delicate: any instrument on a
delicate organ); the force and torque of a step are the sums of the instruments'
magnitudes, ``|F| = Σ_i |F_i|`` and ``|τ| = Σ_i |τ_i|`` (each instrument loads the tissue on
its own: opposite pushes do not cancel, and each torque is about its own trocar);
``max_force`` is the largest such sum. With one instrument this is :meth:`TissueQuality.add`,
bit for bit.

Example:
    >>> q = TissueQuality()
    >>> for f in (0.0, 1.0, 1.0, 0.0, 2.0):
    ...     q.add(0.004, force=(0.0, 0.0, f), torque=(0.0, 0.0, 0.0), in_contact=f > 0)
    >>> q.contact_count, round(q.contact_time, 3), round(q.force_integral, 3)
    (2, 0.012, 0.016)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import NDArray

#: A (3,) vector [N] or [N·m]: a tuple from callers, an array from the physics snapshot.
Vector3 = Sequence[float] | NDArray[np.float64]


def _norm(v: Vector3) -> float:
    return math.sqrt(sum(float(c) * float(c) for c in v))


@dataclass
class TissueQuality:
    """Accumulator of the tissue metrics of one trial (see the module docstring)."""

    contact_time: float = 0.0
    contact_count: int = 0
    force_integral: float = 0.0
    torque_integral: float = 0.0
    max_force: float = 0.0
    delicate_time: float = 0.0
    delicate_count: int = 0
    target_displacement_max: float = 0.0
    target_displacement_mean: float = 0.0
    duration: float = 0.0
    _was_contact: bool = False
    _was_delicate: bool = False
    _disp_integral: float = 0.0

    def add(self, dt: float, *, force: Vector3, torque: Vector3,
            in_contact: bool, delicate_contact: bool = False,
            target_displacement: float = 0.0) -> None:
        """Accounts one physics step of length ``dt`` [s]."""
        self._accumulate(dt, _norm(force), _norm(torque), in_contact, delicate_contact,
                         target_displacement)

    def add_instruments(self, dt: float, *, forces: Sequence[Vector3],
                        torques: Sequence[Vector3], in_contact: bool,
                        delicate_contact: bool = False,
                        target_displacement: float = 0.0) -> None:
        """Accounts one physics step with several instruments (module docstring).

        Args:
            dt: step length [s].
            forces: per instrument, (3,) contact force on it [N].
            torques: per instrument, (3,) contact torque about its fulcrum [N·m].
            in_contact: any instrument touches tissue.
            delicate_contact: any instrument touches a delicate organ.
            target_displacement: largest target displacement this step [m].

        Raises:
            ValueError: ``forces`` and ``torques`` differ in length.

        Example:
            >>> q = TissueQuality()
            >>> q.add_instruments(0.5, forces=[(3.0, 0, 0), (-4.0, 0, 0)],
            ...                   torques=[(0, 0, 0.1), (0, 0, -0.1)], in_contact=True)
            >>> q.force_integral, q.torque_integral, q.max_force
            (3.5, 0.1, 7.0)
        """
        if len(forces) != len(torques):
            raise ValueError(f"one torque per instrument force: got {len(forces)} forces and "
                             f"{len(torques)} torques")
        f = sum((_norm(v) for v in forces), 0.0)   # 0.0 + |F_0| == |F_0|, bit for bit
        tau = sum((_norm(v) for v in torques), 0.0)
        self._accumulate(dt, f, tau, in_contact, delicate_contact, target_displacement)

    def _accumulate(self, dt: float, f: float, tau: float, in_contact: bool,
                    delicate_contact: bool, target_displacement: float) -> None:
        if not (math.isfinite(f) and math.isfinite(tau) and math.isfinite(target_displacement)):
            return  # a non-finite step is reported by the solver; it never enters the metrics
        self.duration += dt
        if in_contact:
            self.contact_time += dt
            if not self._was_contact:
                self.contact_count += 1
        if delicate_contact:
            self.delicate_time += dt
            if not self._was_delicate:
                self.delicate_count += 1
        self._was_contact = bool(in_contact)
        self._was_delicate = bool(delicate_contact)
        self.force_integral += f * dt
        self.torque_integral += tau * dt
        self.max_force = max(self.max_force, f)
        self.target_displacement_max = max(self.target_displacement_max, target_displacement)
        self._disp_integral += target_displacement * dt
        self.target_displacement_mean = (self._disp_integral / self.duration
                                         if self.duration > 0 else 0.0)

    def as_dict(self) -> dict[str, float]:
        """The public metrics as a flat dict (stored with the trial summary)."""
        return {k: v for k, v in asdict(self).items() if not k.startswith("_")}


__all__ = ["TissueQuality"]
