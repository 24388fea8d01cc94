"""The endoscope camera a trial's ``in_view`` column is measured against: a fixed scope
(the default: lens at the camera trocar, aimed at the workspace centre, 100 deg field of
view; the decision and its reasons: ``vasim.trials.vf``) and the circular view cone test.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vasim.core.config import check_number, expect
from vasim.tasks import WORKSPACE_CENTRE


@dataclass(frozen=True)
class EndoscopeView:
    """A fixed endoscope camera: lens position, aim point, full field of view.

    Attributes:
        position: (3,) lens position [m], world frame. look_at: (3,) aim point [m].
        fov_deg: full (cone) field of view [deg], in (0, 180).
    """

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    fov_deg: float

    def __post_init__(self) -> None:
        d = np.subtract(self.look_at, self.position)
        expect(bool(np.all(np.isfinite(d))) and float(np.linalg.norm(d)) > 0, self.look_at,
               "a finite point other than position", field="look_at")
        check_number(self.fov_deg, "fov_deg", gt=0, lt=180)

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Whether each of the (n, 3) points [m] is inside the view cone; (n,) bool."""
        return in_view_cone(points, self.position, self.look_at, math.radians(self.fov_deg))


def in_view_cone(points: np.ndarray, position: object, look_at: object,
                 fov: float) -> np.ndarray:
    """Whether points lie inside a camera's circular field of view (a cone).

    Args:
        points: (n, 3) positions [m], world frame. position: (3,) lens [m].
        look_at: (3,) aim point [m]. fov: full field of view [rad].

    Returns:
        (n,) bool: angle between the optical axis and the lens->point direction <= fov/2
        (a point at the lens counts as inside).

    Example:
        >>> in_view_cone(np.array([[0, 0, 1.0], [1.0, 0, 1.0], [0, 0, -1.0]]),
        ...              (0, 0, 0), (0, 0, 1), math.radians(100)).tolist()
        [True, True, False]
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    c = np.asarray(position, dtype=np.float64)
    f = np.asarray(look_at, dtype=np.float64) - c
    f = f / np.linalg.norm(f)
    d = p - c
    dist = np.sqrt((d * d).sum(axis=1))
    return (d @ f) >= math.cos(0.5 * fov) * dist - 1e-15


def _default_endoscope() -> EndoscopeView:
    from vasim.abdomen.anatomy import trocar_points

    port = trocar_points()[0]
    return EndoscopeView(position=(float(port[0]), float(port[1]), float(port[2])),
                         look_at=(float(WORKSPACE_CENTRE[0]), float(WORKSPACE_CENTRE[1]),
                                  float(WORKSPACE_CENTRE[2])),
                         fov_deg=DEFAULT_ENDOSCOPE_FOV_DEG)


DEFAULT_ENDOSCOPE_FOV_DEG = 100.0
"""Full field of view of the fixed default endoscope [deg] (module docstring, decision)."""

DEFAULT_ENDOSCOPE = _default_endoscope()
"""The fixed camera of trials without Mag: lens at the camera trocar, aimed at the workspace
centre, 100 deg field of view (module docstring)."""


__all__ = ["DEFAULT_ENDOSCOPE", "DEFAULT_ENDOSCOPE_FOV_DEG", "EndoscopeView", "in_view_cone"]
