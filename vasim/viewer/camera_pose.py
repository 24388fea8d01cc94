"""A camera placement for the browser (:class:`CameraPose`), shared by the views
(:mod:`vasim.viewer.views`, which re-exports it) and the endoscope
(:mod:`vasim.viewer.endoscope`).

**Decision** (issue #29 item 4): its own module, below both, so that the endoscope does not
import the views (which use the endoscope's tissue look): the former ``views`` <->
``endoscope`` module cycle, hidden by a function-level import, is gone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from vasim.fixtures.types import CameraView

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class CameraPose:
    """A camera placement for the browser (world frame).

    Attributes:
        position: (3,) [m]. look_at: (3,) [m]. up: (3,) direction. fov: vertical [rad].
    """

    position: FloatArray
    look_at: FloatArray
    up: FloatArray
    fov: float

    @staticmethod
    def from_view(view: CameraView) -> CameraPose:
        return CameraPose(np.asarray(view.position, dtype=np.float64),
                          np.asarray(view.look_at, dtype=np.float64),
                          np.asarray(view.up, dtype=np.float64), float(view.fov))

    def close_to(self, other: CameraPose, *, tol_m: float = 2e-4, tol_rad: float = 2e-3) -> bool:
        return (
            float(np.max(np.abs(self.position - other.position))) < tol_m
            and float(np.max(np.abs(self.look_at - other.look_at))) < tol_m
            and float(np.max(np.abs(self.up - other.up))) < tol_rad
            and abs(self.fov - other.fov) < tol_rad
        )
