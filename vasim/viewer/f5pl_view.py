"""What the experimenter's f5PL editor draws, in the researcher's terms (issue #26 §5).

Every fixture shapes its output with ``f5PL(x; a, b, c, d, g) = d + (a - d) / (1 + (x /
c)^b)^g`` of a normalised distance ``x = |e| / D`` (spec/fixtures.md §1). Read bare, neither
``x`` nor the value means anything to a reader; this module turns them into the fixture's
input and output (:func:`fixture_axes`):

* **input** (x axis): the distance [mm] the fixture sees, ``|e| = x * D`` with ``D`` the
  fixture's ``scale_m`` or the task's scale: to the path (the nearest point of the current
  segment) in trajectory following, to the target in point targeting; MS and FF apply the
  curve to each axis's component of that distance separately.
* **output** (y axis): what the value becomes, with its unit. **Decision**: only outputs
  that are the f5PL value times a constant are drawn (so ``a`` and ``d`` stay readable on
  the axis): VG's arrow opacity (``opacity * f5PL``), AG's modulated error ``m`` (0-1; the
  pitch and beep period follow it geometrically), MS's factor (master motion per slave
  motion), Mag's zoom, FF's spring stiffness ``k * f5PL / D`` [N/mm] and the cone's
  viscosity ``viscosity * f5PL / D`` [N s/m].

:func:`editor_data` gives the plotted series: the edited curve, the shipped schema's curve
(the reference) and the current operating point; :func:`parameter_lines` gives one line per
parameter with its meaning in those units.
"""

from __future__ import annotations

import html
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vasim.fixtures.logistic import Logistic5

FloatArray = NDArray[np.float64]

F5PL_MEANING: dict[str, str] = {
    "a": "value on the path / at the target (distance 0)",
    "b": "slope: how sharp the transition is (larger: sharper)",
    "c": "midpoint: the distance (in D) where the transition is centred",
    "d": "value far away (distance much larger than c·D)",
    "g": "asymmetry: 1 is the symmetric logistic; > 1 the change comes earlier",
}
"""One line per f5PL parameter (spec/fixtures.md §1)."""

F5PL_LABELS: dict[str, str] = {
    "a": "a (at 0 mm)", "b": "b (slope)", "c": "c (midpoint)", "d": "d (far away)",
    "g": "g (asymmetry)",
}
"""The editor's number fields."""


@dataclass(frozen=True)
class FixtureAxes:
    """A fixture's f5PL as its input and output.

    Attributes:
        kind: the fixture kind (``vg``, ``ag``, ``ms``, ``mag``, ``ff``, ``cone``).
        scale_m: D [m] (x = distance / D).
        x_label: the input with its unit. y_label: the output with its unit.
        factor: output = factor * f5PL. per_axis: the curve applies per axis component.
        note: one more line for the reader (e.g. "fade off: the curve is not used").
    """

    kind: str
    scale_m: float
    x_label: str
    y_label: str
    factor: float = 1.0
    per_axis: bool = False
    note: str = ""

    def output(self, value: float) -> float:
        return self.factor * value


def _where(task: str) -> str:
    return "the target" if task == "point" else "the path"


_OUTPUTS: dict[str, Callable[[Any, float], tuple[str, float, str]]] = {
    "vg": lambda p, D: ("arrow opacity [0-1]", float(p.opacity),
                        "" if p.fade else "fade is off: the arrow is drawn at constant "
                                              "opacity and this curve is not used"),
    "ag": lambda p, D: ("modulated error m [0-1]", 1.0,
                        f"pitch {p.pitch_min_hz:g} -> {p.pitch_max_hz:g} Hz and beep period "
                        f"{p.period_max_s:g} -> {p.period_min_s:g} s as m goes 0 -> 1"),
    "ms": lambda p, D: ("motion scaling MS [master mm per slave mm]", 1.0,
                        "MS > 1 slows the tool (fine work), < 1 speeds it up"),
    "mag": lambda p, D: ("zoom [x]", 1.0, ""),
    "ff": lambda p, D: ("spring stiffness K [N/mm]", float(p.k) / D / 1000.0,
                        f"K = k·f5PL/D with k = {p.k:g} N per D; force saturates at "
                        f"{p.max_force_n:g} N"),
    "cone": lambda p, D: ("viscosity [N s/m]", float(p.viscosity) / D,
                          "inside the cone; the attraction and the wall are not shaped by f5PL"),
}


def fixture_axes(kind: str, params: Any, task: str, task_scale_m: float) -> FixtureAxes:
    """The axes of fixture ``kind`` with ``params`` in a ``task`` (``"trajectory"`` or
    ``"point"``) whose scale is ``task_scale_m`` [m].

    >>> from vasim.fixtures.ff import FFParams
    >>> ax = fixture_axes("ff", FFParams(), "trajectory", 0.03)
    >>> ax.x_label, ax.y_label, round(ax.factor, 6), ax.per_axis
    ('distance to the path, per axis [mm]', 'spring stiffness K [N/mm]', 0.083333, True)
    """
    scale = getattr(params, "scale_m", None)
    D = float(scale) if scale is not None else float(task_scale_m)
    per_axis = kind in ("ms", "ff")
    x_label = f"distance to {_where(task)}{', per axis' if per_axis else ''} [mm]"
    make = _OUTPUTS.get(kind)
    if make is None:
        return FixtureAxes(kind, D, x_label, "f5PL value", 1.0, per_axis)
    y_label, factor, note = make(params, D)
    return FixtureAxes(kind, D, x_label, y_label, factor, per_axis, note)


def operating_distance(tcp: Any, goal: Any, per_axis: bool) -> float:
    """The fixture's input now [m]: the distance from the tool tip to the fixture's goal
    point (the nearest point of the path segment, or the target); for a per-axis fixture
    the largest axis component (the axis the curve acts on most).

    >>> operating_distance([0.003, -0.004, 0.0], [0, 0, 0], False), \\
    ...     operating_distance([0.003, -0.004, 0.0], [0, 0, 0], True)
    (0.005, 0.004)
    """
    e = np.asarray(tcp, dtype=np.float64).reshape(3) - np.asarray(goal, dtype=np.float64)
    return float(np.abs(e).max()) if per_axis else float(np.linalg.norm(e))


def editor_data(edited: Logistic5, reference: Logistic5 | None, axes: FixtureAxes,
                operating_m: float | None = None, n: int = 80
                ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The plotted series: distance [mm] ``(m,)``, the edited output, the reference
    (shipped) output (NaN without one) and the operating point (NaN except at its
    distance, which is inserted into the grid).

    The range is 0 to 3 c·D of the larger of the two curves' ``c`` (the transition is
    centred on c), extended to the operating point when it lies beyond.

    >>> from vasim.fixtures.ms import MS_TRAJECTORY_F5PL
    >>> ax = FixtureAxes("ms", 0.03, "x", "y")
    >>> x, y, ref, op = editor_data(MS_TRAJECTORY_F5PL, MS_TRAJECTORY_F5PL, ax, 0.015)
    >>> float(x[0]), float(y[0]) == MS_TRAJECTORY_F5PL.a, bool(np.array_equal(y, ref))
    (0.0, True, True)
    >>> i = int(np.nanargmax(op)); float(x[i]), round(float(op[i]), 6) == round(float(y[i]), 6)
    (15.0, True)
    """
    c = max(edited.c, reference.c if reference is not None else 0.0)
    top = 3.0 * c
    xn = np.linspace(0.0, top, n)
    op_n = None
    if operating_m is not None and math.isfinite(operating_m):
        op_n = max(0.0, operating_m / axes.scale_m)
        xn = np.unique(np.append(xn, op_n))     # sorted, with the operating point on it
        if op_n > top:
            xn = np.unique(np.concatenate([xn, np.linspace(top, op_n, 10)]))
    y = axes.factor * np.asarray(edited(xn), dtype=np.float64)
    ref = (axes.factor * np.asarray(reference(xn), dtype=np.float64) if reference is not None
           else np.full(xn.shape, np.nan))
    op = np.full(xn.shape, np.nan)
    if op_n is not None:
        k = int(np.searchsorted(xn, op_n))
        op[k] = y[k]
    return xn * axes.scale_m * 1000.0, y, ref, op


def _fmt(v: float) -> str:
    return f"{v:.3g}"


def parameter_lines(edited: Logistic5, reference: Logistic5 | None, axes: FixtureAxes,
                    operating_m: float | None = None) -> str:
    """Markdown: the input and output, one line per parameter (its meaning, its value in
    the axes' units and the shipped value) and the operating point (escaped)."""
    esc = html.escape
    mm = axes.scale_m * 1000.0
    unit = axes.y_label

    def shipped(k: str) -> str:
        if reference is None:
            return ""
        r = float(getattr(reference, k))
        same = r == float(getattr(edited, k))
        return " (as shipped)" if same else f" (shipped: {_fmt(r)})"

    lines = [f"**input** {esc(axes.x_label)}, D = {_fmt(mm)} mm · **output** {esc(unit)}"]
    if axes.note:
        lines.append(f"*{esc(axes.note)}*")
    lines += [
        f"- **a** = {_fmt(edited.a)}{shipped('a')}: {esc(F5PL_MEANING['a'])} → "
        f"{_fmt(axes.output(edited.a))}",
        f"- **b** = {_fmt(edited.b)}{shipped('b')}: {esc(F5PL_MEANING['b'])}",
        f"- **c** = {_fmt(edited.c)}{shipped('c')}: {esc(F5PL_MEANING['c'])} → "
        f"{_fmt(edited.c * mm)} mm",
        f"- **d** = {_fmt(edited.d)}{shipped('d')}: {esc(F5PL_MEANING['d'])} → "
        f"{_fmt(axes.output(edited.d))}",
        f"- **g** = {_fmt(edited.g)}{shipped('g')}: {esc(F5PL_MEANING['g'])}",
    ]
    if operating_m is not None and math.isfinite(operating_m):
        y = axes.output(float(edited(operating_m / axes.scale_m)))
        lines.append(f"- **now**: {_fmt(operating_m * 1000.0)} mm → {_fmt(y)}")
    return "  \n".join(lines[:2]) + "\n\n" + "\n".join(lines[2:]) if axes.note else \
        lines[0] + "\n\n" + "\n".join(lines[1:])


__all__ = ["F5PL_LABELS", "F5PL_MEANING", "FixtureAxes", "editor_data", "fixture_axes",
           "operating_distance", "parameter_lines"]
