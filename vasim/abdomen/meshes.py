"""User organ meshes: loading (OBJ, STL, PLY, OFF via trimesh) and validation.

The spec (§1) lets organs come from user meshes ("generated from real patient data"). A mesh
that the mass-spring model cannot use is refused with a :class:`vasim.core.errors.ConfigError`
naming the file, the scene field and every problem found:

* the file is missing, unreadable or of an unsupported format;
* too few or too many vertices (:data:`MIN_VERTICES`, :data:`MAX_VERTICES`: the step cost
  grows with the node count);
* degenerate (zero-area) faces;
* not closed (boundary edges) or non-manifold (edges shared by more than two faces);
* a scale that looks like millimetres or centimetres (extent > :data:`MAX_EXTENT_M`: the
  error names the likely unit, ``units="mm"`` above 100, else ``"cm"`` or ``"mm"``), or too
  small for an organ;
* self-intersection: non-adjacent triangles that cross (trimesh has no such test; a sweep and
  prune on bounding boxes plus an exact edge–triangle test, ``vasim.abdomen._kernels``).

Faces are re-oriented consistently and outward (``trimesh.repair.fix_normals``) when the mesh
is closed and manifold: winding is fixable, the other problems are not.

Example:
    >>> import tempfile, pathlib, trimesh
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "ball.stl"
    >>> _ = trimesh.creation.icosphere(subdivisions=2, radius=30.0).export(path)
    >>> load_user_mesh(path)
    Traceback (most recent call last):
    ...
    vasim.core.errors.ConfigError: ...extent 60 m looks like millimetres; pass units="mm"...
    >>> mesh = load_user_mesh(path, units="mm")
    >>> len(mesh.vertices), round(float(mesh.extents.max()), 3)
    (162, 0.06)
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import numpy as np
import trimesh

from vasim.abdomen import _kernels
from vasim.core.bounds import COORDINATE_M, MESH_FILE_COORDINATE, ORGAN_EXTENT_M, Bound
from vasim.core.config import expect
from vasim.core.errors import ConfigError

Units = Literal["m", "cm", "mm"]
UNIT_SCALE: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001}
"""Factor from each supported unit to metres."""
SUPPORTED_FORMATS = ("obj", "stl", "ply", "off")
"""File extensions accepted (formats trimesh reads without optional dependencies)."""
MIN_VERTICES = 20
"""Fewer vertices cannot describe an organ's shape."""
MAX_VERTICES = 20_000
"""More vertices than this make one organ's step too slow for the physics rate."""
MAX_EXTENT_M = ORGAN_EXTENT_M.high
"""An organ larger than this [m] is in the wrong units or not an organ (bounds table)."""
MIN_EXTENT_M = ORGAN_EXTENT_M.low
"""An organ smaller than this [m] is almost certainly in the wrong units."""
_MAX_REPORTED_PAIRS = 1000


_NAMES = {"cm": "centimetres", "mm": "millimetres"}


def _units_hint(extent: float) -> str:
    """The likely unit of a mesh ``extent`` [file units] > 1 (the hint always said
    mm). Above 100 only millimetres give an organ-sized object; from 1 to 100 both cm and mm
    can, the first named being the one giving the more typical organ (at most 30 cm)."""
    if extent > 100.0:
        order = ["mm"]
    elif extent * UNIT_SCALE["cm"] <= 0.3:
        order = ["cm", "mm"]
    else:
        order = ["mm", "cm"]
    order = [u for u in order if MIN_EXTENT_M <= extent * UNIT_SCALE[u] <= MAX_EXTENT_M]
    if not order:
        return (f"no organ in any unit (m, cm, mm give {extent:.3g}, {extent / 100:.3g}, "
                f"{extent / 1000:.3g} m; an organ is {MIN_EXTENT_M:g}-{MAX_EXTENT_M:g} m)")
    first = order[0]
    text = (f"{_NAMES[first]}; pass units=\"{first}\" (scale by {UNIT_SCALE[first]:g})")
    if len(order) > 1:
        text += f", or units=\"{order[1]}\" if the file is in {_NAMES[order[1]]}"
    return text


def _bad_vertex(v: np.ndarray, bound: Bound) -> str | None:
    """The first non-finite or out-of-``bound`` vertex as a message (None if all are fine).

    Checked before any arithmetic on the coordinates, so a vertex at 1e200 cannot overflow
    the extent, area or scaling computations.
    """
    finite = np.isfinite(v).all(axis=1)
    if not finite.all():
        i = int(np.flatnonzero(~finite)[0])
        return (f"non-finite vertex: vertex {i} is {v[i].tolist()!r} "
                f"({int((~finite).sum())} such vertices)")
    outside = (np.abs(v) > max(abs(bound.low), abs(bound.high))).any(axis=1)
    if outside.any():
        i = int(np.flatnonzero(outside)[0])
        return (f"vertex {i} at {v[i].tolist()!r} is outside [{bound.low:g}, {bound.high:g}] "
                f"{bound.unit} ({bound.reason})")
    return None


def mesh_problems(mesh: trimesh.Trimesh, *, check_self_intersection: bool = True) -> list[str]:
    """Every reason why ``mesh`` cannot be an organ surface (empty if it can).

    Args:
        mesh: triangle mesh, vertices in metres.
        check_self_intersection: run the (O(f log f) + candidate pairs) intersection test.

    Returns:
        Human-readable problems, most basic first.
    """
    problems: list[str] = []
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces, dtype=np.int64)
    if len(f) == 0:
        return ["the mesh has no triangles"]
    if not np.isfinite(v).all():
        return [str(_bad_vertex(v, MESH_FILE_COORDINATE))]
    n = len(v)
    if n < MIN_VERTICES:
        problems.append(f"too few vertices ({n}; at least {MIN_VERTICES})")
    if n > MAX_VERTICES:
        problems.append(f"too many vertices ({n}; at most {MAX_VERTICES}: simplify the mesh)")
    extent = float(np.ptp(v, axis=0).max())
    if extent > MAX_EXTENT_M:
        problems.append(f"extent {extent:.3g} m looks like {_units_hint(extent)}"
                        if extent > 1.0 else
                        f"extent {extent:.3g} m is larger than any organ ({ORGAN_EXTENT_M.reason}"
                        f"; allowed {MIN_EXTENT_M:g}-{MAX_EXTENT_M:g} m)")
    elif extent < MIN_EXTENT_M:
        problems.append(f"extent {extent:.3g} m is too small for an organ; check the units")
    if extent > MAX_EXTENT_M:
        return problems  # wrong units: the area and intersection tests would mislead
    bad = _bad_vertex(v, COORDINATE_M)
    if bad:
        problems.append(bad)
        return problems
    area = np.asarray(mesh.area_faces)
    degenerate = np.flatnonzero(area <= 1e-12 * max(extent, 1e-12) ** 2)
    if degenerate.size:
        problems.append(f"{degenerate.size} degenerate (zero-area) faces, e.g. face "
                        f"{int(degenerate[0])}")
    edges = np.sort(f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    boundary = int(np.sum(counts == 1))
    nonmanifold = int(np.sum(counts > 2))
    if boundary:
        problems.append(f"not closed (not watertight): {boundary} boundary edges")
    if nonmanifold:
        problems.append(f"non-manifold: {nonmanifold} edges shared by more than two faces")
    if check_self_intersection and not degenerate.size:
        pairs = _kernels.self_intersections(np.ascontiguousarray(v), np.ascontiguousarray(f),
                                            _MAX_REPORTED_PAIRS)
        if len(pairs):
            more = "+" if len(pairs) >= _MAX_REPORTED_PAIRS else ""
            problems.append(f"self-intersecting: {len(pairs)}{more} pairs of faces cross, e.g. "
                            f"faces {int(pairs[0, 0])} and {int(pairs[0, 1])}")
    return problems


def load_user_mesh(
    path: str | Path,
    *,
    units: Units = "m",
    field: str | None = None,
    check_self_intersection: bool = True,
) -> trimesh.Trimesh:
    """Loads and validates an organ surface from a mesh file.

    Args:
        path: an OBJ, STL, PLY or OFF file.
        units: the file's length unit (``"m"``, ``"cm"``, ``"mm"``); vertices are returned in m.
        field: the scene field the path came from, for error messages (e.g.
            ``organs.liver.mesh``).
        check_self_intersection: also test for crossing triangles.

    Returns:
        The mesh in metres, duplicate vertices merged, faces oriented outward.

    Raises:
        ConfigError: naming the file, the field and every problem (module docstring).
    """
    p = Path(path)
    expect(units in UNIT_SCALE, units, f"units, one of {', '.join(UNIT_SCALE)}", file=p,
            field=field)
    expect(p.is_file(), str(p), "an existing mesh file (mesh file not found)", file=p,
            field=field)
    ext = p.suffix.lower().lstrip(".")
    expect(ext in SUPPORTED_FORMATS, p.suffix, f"a supported mesh format (one of "
           f"{', '.join(SUPPORTED_FORMATS)})", file=p, field=field)
    try:
        # process=False first: merging vertices would drop a NaN vertex and report the hole
        # it leaves ("not closed") instead of the bad vertex.
        loaded = trimesh.load(p, file_type=ext, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many kinds of errors on bad files
        raise ConfigError(f"cannot read the mesh: {type(exc).__name__}: {exc}", file=p,
                          field=field) from exc
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise ConfigError("the file holds no triangle mesh", file=p, field=field)
    bad = _bad_vertex(np.asarray(loaded.vertices, dtype=np.float64), MESH_FILE_COORDINATE)
    if bad:
        raise ConfigError(bad, file=p, field=field)
    loaded.process()
    mesh = loaded
    if UNIT_SCALE[units] != 1.0:
        mesh.apply_scale(UNIT_SCALE[units])
    problems = mesh_problems(mesh, check_self_intersection=check_self_intersection)
    if problems:
        raise ConfigError("; ".join(problems), file=p, field=field)
    if not mesh.is_winding_consistent:
        trimesh.repair.fix_normals(mesh)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


__all__ = [
    "MAX_EXTENT_M",
    "MAX_VERTICES",
    "MIN_EXTENT_M",
    "MIN_VERTICES",
    "SUPPORTED_FORMATS",
    "UNIT_SCALE",
    "Units",
    "load_user_mesh",
    "mesh_problems",
]
