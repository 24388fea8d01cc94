"""Q of the MRCP study as the seed measures it: the deformation of the targets.

Seed chapter 5, experiment 2 (seed l. 3881-3884): "Q, determined from the trajectories
described by the leds attached to the target points (leds pose vary due to collisions with
the needle or with the laparoscopic tools), evaluates the execution quality. The target
movements, caused by the interaction with the tools, emulate tissue deformation." The
simulated rings ride on the tissue (``Abdomen.bind_targets``), and the abdomen knows where
each would be with breathing alone (``p_free``; ``AbdomenSnapshot.target_displacement`` is
``|p_j - p_free,j|`` per target). Per trial::

    Q    = sum_steps dt * sum_j |p_j - p_free,j|    [mm s]   (``target_deformation``)
    Qmax = max_steps max_j |p_j - p_free,j|         [mm]     (``target_deformation_peak``)

over the physics steps (dt = the abdomen's step, 4 ms) and the task's rings j.

**Decision**: Q is the displacement integrated over time and summed over the targets, in
millimetre-seconds, because the seed's Q accumulates over the whole trial ("the amount of
target deformation produced by undesired collisions", l. 3837) and over all six targets,
and grows both with how far a target was pushed and for how long: 2 mm for 0.5 s is
1 mm s. Its peak is stored beside it (mm, the deepest push). The seed's own unit (the LED
track on the tracking camera's image) cannot be recovered from the text, so the simulated
and the seed's Q compare as ratios between modes (gains), not as numbers. Breathing moves
the rings without deforming them and is not counted (``p_free``); a tool touching tissue
far from every ring gives Q = 0 (the rings did not move): contact time, force and torque
(the abdomen's quality accumulator) measure those contacts.

Example:
    >>> q = TargetDeformation()
    >>> q.add(0.5, [0.002, 0.0, 0.001])       # 2 mm and 1 mm for 0.5 s
    >>> round(q.total_mm_s, 6), round(q.peak_mm, 6)
    (1.5, 2.0)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass
class TargetDeformation:
    """Accumulates Q over the physics steps of one trial (module docstring).

    Attributes:
        total_mm_s: Q so far [mm s]. peak_mm: the largest displacement so far [mm].
        duration: time accounted [s].
    """

    total_mm_s: float = 0.0
    peak_mm: float = 0.0
    duration: float = 0.0

    def add(self, dt: float, displacement: Sequence[float] | NDArray[np.float64]) -> None:
        """Accounts one physics step.

        Args:
            dt: step length [s], > 0.
            displacement: per target, ``|p_j - p_free,j|`` [m] this step.

        Raises:
            ValueError: ``dt`` not finite and > 0, or a displacement negative or not finite.
        """
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"TargetDeformation.add: dt must be a finite number > 0 s, "
                             f"got {dt!r}")
        d = np.asarray(displacement, dtype=float).ravel()
        if d.size and not (np.isfinite(d).all() and (d >= 0).all()):
            raise ValueError("TargetDeformation.add: displacements must be finite and >= 0 m, "
                             f"got {d.tolist()!r}")
        self.duration += dt
        if d.size:
            self.total_mm_s += 1e3 * dt * float(d.sum())
            self.peak_mm = max(self.peak_mm, 1e3 * float(d.max()))

    def as_metrics(self) -> dict[str, float]:
        """``{"target_deformation": Q [mm s], "target_deformation_peak": Qmax [mm]}``."""
        return {"target_deformation": self.total_mm_s,
                "target_deformation_peak": self.peak_mm}


__all__ = ["TargetDeformation"]
