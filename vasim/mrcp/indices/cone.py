"""Tool-orientation cone at a fulcrum (spec/mrcp.md §4, seed eq. 3.28-3.29, section 5.2).

A cone with apex at the fulcrum (trocar) and axis the inward normal of the abdominal wall
bounds the valid tool orientations. Its base, at unit height along the axis, is a convex
curve made of elliptical pieces by azimuth: in a sector the radius at azimuth ``θ`` is the
ellipse's ``r(θ) = a b / sqrt((b cos θ)² + (a sin θ)²)`` (``a`` along the cone's reference
``x`` axis, ``b`` along ``y``), and the maximum polar angle is ``φ(θ) = atan r(θ)``. With the
tool's polar angle ``α`` (from the normal) and azimuth ``θ``, the tool is valid when
``α <= φ(θ)``. The index is the angular margin ``1 - α/φ(θ)`` clamped to [0, 1] and
modulated like RJ, ``(1 - cos(π x^(1/b)))/2``.

The tool axis is the line from the fulcrum to the tool tip: the task point is the tip, so
the index needs no joint values; along the predicted trajectory the per-point values are
averaged with ``w_k = 1/(k+1)`` (an unreachable point scores 0).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from vasim.core.geometry import frame_z_x
from vasim.mrcp.indices._index_kernels import cone_along
from vasim.mrcp.indices.base import INDICES, EvalContext

FloatArray = NDArray[np.float64]



def _wrap(angle: float) -> float:
    """``angle`` in ``[0, 2π)``. ``np.mod(-1e-17, 2π)`` rounds to exactly ``2π``, which no
    half-open sector ``[start, end)`` covers: such an angle is mapped to 0."""
    th = float(np.mod(angle, 2 * np.pi))
    return 0.0 if th >= 2 * np.pi else th

@dataclass(frozen=True)
class ConeSector:
    """An elliptical piece of the cone's base for azimuths in ``[start, end)`` [rad]."""

    start: float
    end: float
    a: float        # semi-axis along the cone's x axis (tan of the polar limit there)
    b: float        # semi-axis along y


@dataclass(frozen=True)
class ToolCone:
    """The orientation cone of one fulcrum.

    Attributes:
        fulcrum: ``(3,)`` apex [m], world frame.
        normal: ``(3,)`` axis: the wall's normal pointing *into* the body.
        x_axis: ``(3,)`` azimuth reference (made orthogonal to ``normal``).
        sectors: elliptical pieces covering ``[0, 2π)``; the seed's example uses
            ``a = 0.8`` or ``0.6`` with ``b = 1.0`` in different sectors.
    """

    fulcrum: FloatArray
    normal: FloatArray
    x_axis: FloatArray
    sectors: Sequence[ConeSector] = (ConeSector(0.0, 2 * np.pi, 0.8, 1.0),)

    def frame(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The cone's orthonormal frame ``(x, y, z)``, ``z`` the normal."""
        return self._frame

    @cached_property
    def sector_table(self) -> FloatArray:
        """``(S, 4)`` rows ``(start, end, a, b)`` of the sectors."""
        return np.array([[s.start, s.end, s.a, s.b] for s in self.sectors], dtype=np.float64)

    @cached_property
    def _frame(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        z = np.asarray(self.normal, dtype=np.float64)
        f = frame_z_x(z / np.linalg.norm(z), self.x_axis, what="ToolCone: x_axis")
        # contiguous copies of the columns, as the axes were before core.geometry built them
        return (np.ascontiguousarray(f[:, 0]), np.ascontiguousarray(f[:, 1]),
                np.ascontiguousarray(f[:, 2]))

    def max_polar(self, azimuth: float) -> float:
        """``φ(θ)`` [rad]: the cone's half-angle at azimuth ``θ``."""
        th = _wrap(float(azimuth))
        for s in self.sectors:
            if s.start <= th < s.end or (th == 0.0 and s.end >= 2 * np.pi and s.start == 0.0):
                r = s.a * s.b / np.hypot(s.b * np.cos(th), s.a * np.sin(th))
                return float(np.arctan(r))
        raise ValueError(f"ToolCone: azimuth {th!r} not covered by the sectors {self.sectors!r}")

    def polar_azimuth(self, tip: FloatArray) -> tuple[float, float]:
        """Tool polar angle ``α`` and azimuth ``θ`` [rad] for a tool tip position."""
        x, y, z = self.frame()
        d = np.asarray(tip, dtype=np.float64) - np.asarray(self.fulcrum, dtype=np.float64)
        n = float(np.linalg.norm(d))
        if n < 1e-12:
            return 0.0, 0.0
        d = d / n
        alpha = float(np.arccos(np.clip(d @ z, -1.0, 1.0)))
        theta = _wrap(float(np.arctan2(d @ y, d @ x)))
        return alpha, theta

    def margin(self, tip: FloatArray) -> float:
        """``1 - α/φ(θ)`` clamped to [0, 1] (1 = along the normal, 0 = on/outside the cone)."""
        alpha, theta = self.polar_azimuth(tip)
        return float(np.clip(1.0 - alpha / self.max_polar(theta), 0.0, 1.0))

    def margins(self, tips: FloatArray) -> FloatArray:
        """:meth:`margin` for ``(k, 3)`` tool tips at once."""
        x, y, z = self.frame()
        d = np.asarray(tips, dtype=np.float64) - np.asarray(self.fulcrum, dtype=np.float64)
        n = np.linalg.norm(d, axis=1)
        safe = np.where(n > 1e-12, n, 1.0)
        dz, dx, dy = d @ z / safe, d @ x / safe, d @ y / safe
        alpha = np.where(n > 1e-12, np.arccos(np.clip(dz, -1.0, 1.0)), 0.0)
        theta = np.where(n > 1e-12, np.mod(np.arctan2(dy, dx), 2 * np.pi), 0.0)
        theta = np.where(theta >= 2 * np.pi, 0.0, theta)  # see _wrap
        phi = np.full(theta.shape, np.nan)
        for sec in self.sectors:
            inside = (theta >= sec.start) & (theta < sec.end)
            r = sec.a * sec.b / np.hypot(sec.b * np.cos(theta), sec.a * np.sin(theta))
            phi = np.where(inside & np.isnan(phi), np.arctan(r), phi)
        if np.any(np.isnan(phi)):
            raise ValueError(f"ToolCone: azimuths {theta[np.isnan(phi)]!r} not covered by the "
                             f"sectors {self.sectors!r}")
        return np.clip(1.0 - alpha / phi, 0.0, 1.0)


@INDICES.add("cone")
class ToolConeIndex:
    """Tool-orientation cone index per robot (robots without a fulcrum score 1).

    Args:
        cones: robot name -> its :class:`ToolCone`.
        b: RJ-like modulation of the margin (>= 1).
    """

    name = "cone"

    def __init__(self, cones: Mapping[str, ToolCone] | None = None, b: float = 1.0) -> None:
        if b < 1.0:
            raise ValueError(f"cone: modulation b must be >= 1, got {b!r}")
        self.cones = dict(cones or {})
        self.b = float(b)

    def evaluate(self, ctx: EvalContext) -> float:
        cone = self.cones.get(ctx.robot)
        if cone is None:
            return 1.0 if ctx.reachable[0] else 0.0
        x, y, z = cone.frame()
        value = cone_along(np.ascontiguousarray(ctx.positions, dtype=np.float64),
                           np.ascontiguousarray(ctx.reachable), _f64(cone.fulcrum), x, y, z,
                           cone.sector_table, self.b)
        if value < 0.0:   # an azimuth outside the sectors: the numpy path names it
            cone.margins(ctx.positions)
        return float(value)


def _f64(a: FloatArray) -> FloatArray:
    return np.ascontiguousarray(a, dtype=np.float64)
