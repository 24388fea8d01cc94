"""Task geometry that rides on the tissue: points bound to organ surfaces.

A point of interest (POI) is bound once, at rest, to the nearest point of the nearest organ
surface: the triangle's three nodes, the barycentric weights of the foot point, and the
offset from the foot point to the POI. Afterwards its position is a pure function of the
organ's node positions:

    p(x) = Σ_i w_i x_i + o

**Decision** (the spec says the path "moves with the organs it is attached to" and leaves
how open): the offset ``o`` is a constant vector, so a POI above an organ follows the
*translation* of its foot point (breathing, heartbeat, the push of the tool), not the
rotation of the triangle under it. A rotating offset would swing a POI 3 cm above the liver
by centimetres whenever the tool dents the tissue near its foot; surgeons' targets do not
jump like that. A POI on the surface (point targeting) has ``o = 0`` and is exactly on the
tissue, and its normal is the current normal of the bound triangle.

Example:
    >>> import numpy as np
    >>> x = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
    >>> faces = np.array([[0, 1, 2]])
    >>> b = bind_points(np.array([[0.25, 0.25, 0.5]]), [(x, faces)])
    >>> b.positions([x]).round(3).tolist()
    [[0.25, 0.25, 0.5]]
    >>> b.positions([x + [0, 0, 0.1]]).round(3).tolist()   # the surface rises by 0.1
    [[0.25, 0.25, 0.6]]
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import trimesh
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(frozen=True, eq=False)
class SurfaceBinding:
    """Points bound to organ surfaces.

    Attributes:
        organ: (p,) index of the organ each point is bound to (into the surfaces list).
        nodes: (p, 3) the bound triangle's node indices in that organ.
        weights: (p, 3) barycentric weights of the foot point (sum 1, each >= 0).
        offset: (p, 3) constant offset foot → point [m].
        distance: (p,) rest distance of the point from the surface [m].
    """

    organ: IntArray
    nodes: IntArray
    weights: FloatArray
    offset: FloatArray
    distance: FloatArray

    @property
    def size(self) -> int:
        return int(self.organ.shape[0])

    def feet(self, positions: Sequence[FloatArray]) -> FloatArray:
        """(p, 3) current foot points on the surfaces, given each organ's (n, 3) nodes."""
        out = np.empty((self.size, 3))
        for k in np.unique(self.organ):
            sel = self.organ == k
            x = positions[int(k)]
            out[sel] = np.einsum("pi,pia->pa", self.weights[sel], x[self.nodes[sel]])
        return out

    def positions(self, positions: Sequence[FloatArray]) -> FloatArray:
        """(p, 3) current positions of the bound points [m]."""
        return self.feet(positions) + self.offset

    def normals(self, positions: Sequence[FloatArray]) -> FloatArray:
        """(p, 3) current unit normals of the bound triangles (outward)."""
        out = np.empty((self.size, 3))
        for k in np.unique(self.organ):
            sel = self.organ == k
            tri = positions[int(k)][self.nodes[sel]]
            n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            out[sel] = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        return out


def bind_points(points: FloatArray,
                surfaces: Sequence[tuple[FloatArray, IntArray]]) -> SurfaceBinding:
    """Binds each point to the nearest point of the nearest surface.

    Args:
        points: (p, 3) points to bind [m].
        surfaces: per organ, (x (n, 3) rest node positions, faces (f, 3)).

    Returns:
        The binding (rest positions are reproduced exactly).

    Raises:
        ValueError: without surfaces or with a non-finite point.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if not surfaces:
        raise ValueError("bind_points needs at least one surface")
    if not np.all(np.isfinite(pts)):
        raise ValueError("bind_points: points must be finite")
    best_d = np.full(len(pts), np.inf)
    organ = np.zeros(len(pts), dtype=np.int64)
    nodes = np.zeros((len(pts), 3), dtype=np.int64)
    weights = np.zeros((len(pts), 3))
    feet = np.zeros((len(pts), 3))
    for k, (x, faces) in enumerate(surfaces):
        mesh = trimesh.Trimesh(vertices=x, faces=faces, process=False)
        foot, dist, tri_id = trimesh.proximity.closest_point(mesh, pts)
        better = dist < best_d
        if not better.any():
            continue
        tri = x[faces[tri_id[better]]]
        w = trimesh.triangles.points_to_barycentric(tri, foot[better])
        w = np.clip(w, 0.0, 1.0)
        w /= w.sum(axis=1, keepdims=True)
        best_d[better] = dist[better]
        organ[better] = k
        nodes[better] = faces[tri_id[better]]
        weights[better] = w
        feet[better] = np.einsum("pi,pia->pa", w, tri)
    return SurfaceBinding(organ, nodes, weights, pts - feet, best_d)


__all__ = ["SurfaceBinding", "bind_points"]
