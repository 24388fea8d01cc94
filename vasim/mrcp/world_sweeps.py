"""The bodies as the compiled distance model sees them (``vasim.mrcp._distance_kernels``):
per robot model, its links' key points swept by a unit polytope (``_robot_sweep``) and
bounding spheres (``_link_spheres``); a sphere obstacle as a ball (``_sphere_sweep``).
Cached per model content; used by :class:`vasim.mrcp.world.PybulletWorld`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import trimesh
from numpy.typing import NDArray

from vasim.mrcp.dh import RobotModel
from vasim.mrcp.interfaces import FloatArray
from vasim.mrcp.urdf import link_hulls, link_sweep, model_key

#: pybullet grows every convex-hull collision shape by this margin [m] (a Minkowski sum with
#: a ball): distances to robot links are the bare hulls' minus this (measured 0.97-1.0 mm;
#: ``changeDynamics(collisionMargin=...)`` does not change it). Conservative for safety.
HULL_MARGIN = 0.001

_SPHERES: dict[str, tuple[FloatArray, FloatArray]] = {}


def _link_spheres(model: RobotModel) -> tuple[FloatArray, FloatArray]:
    """Per link (0..n), a sphere bounding its hull grown by the margin: centres ``(L, 3)``
    in the link frames (the hull's bounding-box centre) and radii ``(L,)``."""
    key = model_key(model)
    if key not in _SPHERES:
        centres, radii = [], []
        for hull in link_hulls(model):
            v = np.asarray(hull.vertices)
            c = (v.min(axis=0) + v.max(axis=0)) / 2
            centres.append(c)
            radii.append(float(np.max(np.linalg.norm(v - c, axis=1))) + HULL_MARGIN + 1e-6)
        _SPHERES[key] = (np.array(centres), np.array(radii))
    return _SPHERES[key]


@dataclass(frozen=True)
class _Sweep:
    """A body as the compiled distance model sees it (``vasim.mrcp._distance_kernels``):
    per link, key points ``(L, 3, 3)`` (link frame) and their count, the scale of the unit
    polytope swept over them, a ball radius instead (> 0) and a bounding sphere."""

    pts: FloatArray
    count: NDArray[np.int64]
    scale: FloatArray
    ball: FloatArray
    centre: FloatArray
    radius: FloatArray


_SWEEPS: dict[str, _Sweep] = {}
_UNIT: list[NDArray[Any]] = []     # the unit polytope of the link hulls and its graph


def _reduce_points(pts: FloatArray) -> FloatArray:
    """Key points without duplicates; three collinear points -> the two extremes."""
    out: list[FloatArray] = []
    for p in pts:
        if all(np.linalg.norm(p - o) > 1e-9 for o in out):
            out.append(p)
    if len(out) == 3:
        area = np.linalg.norm(np.cross(out[1] - out[0], out[2] - out[0]))
        if area <= 1e-9 * max(1.0, max(float(np.linalg.norm(o - out[0])) for o in out)):
            dist = {(i, j): float(np.linalg.norm(out[i] - out[j]))
                    for i in range(3) for j in range(i + 1, 3)}
            i, j = max(dist, key=lambda ij: dist[ij])
            out = [out[i], out[j]]
    if len(out) > 3:
        raise ValueError(f"the compiled distance model takes at most 3 key points per link, "
                         f"got {len(out)}")
    return np.array(out)


def _neighbours(vertices: FloatArray) -> NDArray[np.int64]:
    """``(V, k)`` neighbours of each vertex of a convex polytope (-1 padded), from the
    faces of its hull (trimesh)."""
    hull = trimesh.convex.convex_hull(np.asarray(vertices, dtype=float))
    if len(hull.vertices) != len(vertices):
        raise ValueError("every vertex of the sweeping polytope must lie on its hull")
    # map the hull's vertex order back to ours
    idx = [int(np.argmin(np.linalg.norm(vertices - v, axis=1))) for v in hull.vertices]
    nb = hull.vertex_neighbors
    width = max(len(n) for n in nb)
    out = np.full((len(vertices), width), -1, dtype=np.int64)
    for h, ns in enumerate(nb):
        out[idx[h], :len(ns)] = [idx[k] for k in ns]
    return out


def _robot_sweep(model: RobotModel) -> _Sweep:
    key = model_key(model)
    if key not in _SWEEPS:
        n_links = model.n_joints + 1
        pts = np.zeros((n_links, 3, 3))
        count = np.zeros(n_links, dtype=np.int64)
        scale = np.zeros(n_links)
        centre = np.zeros((n_links, 3))
        radius = np.zeros(n_links)
        for k in range(n_links):
            raw, unit, sc = link_sweep(model, k)
            p = _reduce_points(raw)
            pts[k, :len(p)], count[k], scale[k] = p, len(p), sc
            c = (p.min(axis=0) + p.max(axis=0)) / 2
            centre[k] = c
            radius[k] = float(np.max(np.linalg.norm(p - c, axis=1))) + sc + 1e-9
            if not _UNIT:
                _UNIT.append(np.ascontiguousarray(unit, dtype=float))
                _UNIT.append(_neighbours(unit))
        _SWEEPS[key] = _Sweep(pts, count, scale, np.zeros(n_links), centre, radius)
    return _SWEEPS[key]


def _sphere_sweep(radius: float) -> _Sweep:
    return _Sweep(np.zeros((1, 3, 3)), np.ones(1, dtype=np.int64), np.zeros(1),
                  np.array([float(radius)]), np.zeros((1, 3)), np.array([float(radius)]))


__all__ = ["HULL_MARGIN"]
