"""Procedural abdominal anatomy: one watertight triangle mesh per organ, no download.

Every mesh is a pure function of its parameters (centre, size, resolution), built from a
trimesh primitive (icosphere, capsule, torus) or a surface of revolution and deformed with
numpy. The abdomen model will later turn these surfaces into deformable mass-spring organs,
so nothing here holds state.

World frame (the scene convention), metres: ``z`` up (anterior, toward the abdominal wall),
``y`` cranial, ``x`` toward the patient's left. The abdominal cavity is roughly
``x in [-0.15, 0.15]``, ``y in [-0.12, 0.18]``, ``z in [0.0, 0.16]``; the organs lie in its
lower half, the abdominal wall is a dome over them.

Example:
    >>> organs = default_anatomy()
    >>> [o.name for o in organs][:3], len(organs)
    (['liver', 'stomach', 'intestine_0'], 10)
    >>> all(o.mesh.is_watertight for o in organs)
    True
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import trimesh
from numpy.typing import NDArray

from vasim.core import geometry

FloatArray = NDArray[np.float64]

OrganKind = Literal["parenchyma", "hollow", "vessel", "wall"]
"""``parenchyma`` (solid organ: liver), ``hollow`` (stomach, bowel), ``vessel``, ``wall``."""

CAVITY_MIN = np.array([-0.15, -0.12, 0.0])
"""(3,) lower corner of the abdominal cavity box [m], world frame."""
CAVITY_MAX = np.array([0.15, 0.18, 0.16])
"""(3,) upper corner of the abdominal cavity box [m], world frame."""

WALL_CENTRE_XY = (0.0, 0.03)
"""Centre of the wall's footprint in the ``z = 0`` plane [m]."""
WALL_HALF_EXTENT = (0.15, 0.15, 0.16)
"""Outer half-extents of the abdominal-wall dome along x, y and its height along z [m]."""
WALL_THICKNESS = 0.008
"""Thickness of the abdominal wall [m] (thin: it is drawn, not simulated yet)."""
WALL_FOOTPRINT_EXPONENT = 4.0
"""Superellipse exponent of the footprint (2 = ellipse, larger = rounder rectangle)."""
WALL_PROFILE_EXPONENT = 3.0
"""Exponent of the dome profile ``z = h (1 - r^p)^(1/p)`` (2 = ellipsoid; larger = flatter)."""

TROCAR_NAMES = ("camera", "working_right", "working_left", "assistant")
"""Names of the rows of :func:`trocar_points`, in order (right/left: the patient's)."""
_TROCAR_XY = ((0.0, -0.05), (-0.075, -0.02), (0.075, -0.02), (0.0, 0.13))


@dataclass(frozen=True, eq=False)
class Organ:
    """One organ of the scene.

    Attributes:
        name: unique name, also used as the scene-node name in the viewer.
        mesh: watertight triangle surface, vertices in metres, world frame.
        color: RGB in [0, 1].
        delicate: True for structures that must not be touched (a forbidden region).
        kind: tissue class, see :data:`OrganKind`.
    """

    name: str
    mesh: trimesh.Trimesh
    color: tuple[float, float, float]
    delicate: bool
    kind: OrganKind


# ---------------------------------------------------------------------------------------
# Geometry helpers


def _revolve(profile_rz: FloatArray, n_phi: int, radius_of_phi) -> trimesh.Trimesh:
    """Revolves a closed (r, z) profile about the z axis into a watertight surface.

    Args:
        profile_rz: (m, 2) profile from one pole to the other; the first and last points
            must have r = 0 (they become single pole vertices). Walking the profile with
            increasing index must go *counter-clockwise* in the (r, z) half-plane so that
            face normals point outward.
        n_phi: number of segments around the axis.
        radius_of_phi: maps (n_phi,) angles to (n_phi,) radial scale factors (the
            footprint); the profile radius r is multiplied by it.
    """
    prof = np.asarray(profile_rz, dtype=np.float64)
    if prof[0, 0] != 0.0 or prof[-1, 0] != 0.0:
        raise ValueError(f"profile must start and end on the axis, got {prof[[0, -1]]!r}")
    ring = prof[1:-1]
    m = len(ring)
    phi = np.linspace(0.0, 2.0 * np.pi, n_phi, endpoint=False)
    scale = np.asarray(radius_of_phi(phi), dtype=np.float64)
    c, s = np.cos(phi) * scale, np.sin(phi) * scale
    rings = np.empty((m, n_phi, 3))
    rings[:, :, 0] = ring[:, :1] * c[None, :]
    rings[:, :, 1] = ring[:, :1] * s[None, :]
    rings[:, :, 2] = ring[:, 1:2]
    verts = np.vstack([[[0.0, 0.0, prof[0, 1]]], rings.reshape(-1, 3), [[0.0, 0.0, prof[-1, 1]]]])
    first, last = 0, len(verts) - 1

    def idx(i: int, j: NDArray[np.int64]) -> NDArray[np.int64]:
        return 1 + i * n_phi + (j % n_phi)

    j = np.arange(n_phi)
    faces = [np.column_stack([np.full(n_phi, first), idx(0, j + 1), idx(0, j)])]
    for i in range(m - 1):
        a, b = idx(i, j), idx(i, j + 1)
        c2, d = idx(i + 1, j), idx(i + 1, j + 1)
        faces.append(np.column_stack([a, b, d]))
        faces.append(np.column_stack([a, d, c2]))
    faces.append(np.column_stack([np.full(n_phi, last), idx(m - 1, j), idx(m - 1, j + 1)]))
    mesh = trimesh.Trimesh(verts, np.vstack(faces), process=False)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def _superellipse_radius(a: float, b: float, n: float):
    """Returns phi -> radius of the superellipse |x/a|^n + |y/b|^n = 1 in direction phi."""

    def radius(phi: FloatArray) -> FloatArray:
        c, s = np.abs(np.cos(phi)), np.abs(np.sin(phi))
        return (c**n / a**n + s**n / b**n) ** (-1.0 / n)

    return radius


def _dome_profile(height: float, n: int, p: float, *, outward_from_top: bool) -> FloatArray:
    """(n, 2) points (r, z) on z = height (1 - r^p)^(1/p), r in [0, 1], from top to rim."""
    t = np.linspace(0.0, 1.0, n)
    # Angle-like parametrisation: even spacing along the curve, dense near the rim.
    theta = t * np.pi / 2.0
    r = np.sin(theta) ** (2.0 / p)
    z = height * np.cos(theta) ** (2.0 / p)
    pts = np.column_stack([r, z])
    return pts if outward_from_top else pts[::-1]


def _tube(length: float, radius: float, n_around: int, n_along: int) -> trimesh.Trimesh:
    """A capsule along z, centred, with ``n_along`` rings on its cylinder so it can bend.

    (``trimesh.creation.capsule`` has no rings between the caps, so it cannot be bent.)
    """
    cap = np.linspace(-np.pi / 2.0, 0.0, max(3, n_around // 4) + 1)
    bottom = np.column_stack([radius * np.cos(cap), -length / 2.0 + radius * np.sin(cap)])
    z_mid = np.linspace(-length / 2.0, length / 2.0, n_along + 2)[1:-1]
    middle = np.column_stack([np.full_like(z_mid, radius), z_mid])
    top = np.column_stack([radius * np.cos(cap[::-1]), length / 2.0 - radius * np.sin(cap[::-1])])
    profile = np.vstack([bottom, middle, top])
    profile[[0, -1], 0] = 0.0
    return _revolve(profile, n_around, lambda phi: np.ones_like(phi))


def _finish(vertices: FloatArray, faces: NDArray[np.int64]) -> trimesh.Trimesh:
    mesh = trimesh.Trimesh(np.asarray(vertices, dtype=np.float64), faces, process=False)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


# ---------------------------------------------------------------------------------------
# Organs


def liver(
    centre: tuple[float, float, float] = (-0.058, 0.092, 0.04),
    size: tuple[float, float, float] = (0.15, 0.10, 0.066),
    *,
    taper: float = 0.55,
    subdivisions: int = 3,
) -> trimesh.Trimesh:
    """The liver: a wedge-shaped ellipsoid, thick on the patient's right, thin medially.

    Args:
        centre: (3,) centre of the bounding box [m], world frame.
        size: (3,) full extents along x, y, z [m].
        taper: thickness of the medial (x-max) edge relative to the lateral edge, in (0, 1].
        subdivisions: icosphere subdivisions (3 -> 642 vertices).
    """
    if not 0.0 < taper <= 1.0:
        raise ValueError(f"taper must be in (0, 1], got {taper!r}")
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    v = sphere.vertices.copy()
    # u in [0, 1] from lateral (x = -1) to medial (x = +1); thickness tapers with u.
    u = (v[:, 0] + 1.0) / 2.0
    thick = 1.0 - (1.0 - taper) * u
    v[:, 2] *= thick
    # Flatten the visceral (lower) face a little; domed diaphragmatic (upper) face.
    v[:, 2] = np.where(v[:, 2] < 0, 0.7 * v[:, 2], v[:, 2])
    # Pull the medial tip down slightly (the left lobe drapes over the stomach).
    v[:, 2] -= 0.15 * u**2
    v = _fit_box(v, centre, size)
    return _finish(v, sphere.faces)


def stomach(
    centre: tuple[float, float, float] = (0.076, 0.085, 0.036),
    length: float = 0.11,
    radius: float = 0.024,
    *,
    bend: float = 1.5,
    count: int = 20,
) -> trimesh.Trimesh:
    """The stomach: a capsule bent into a bean (J shape), curving around +y.

    Args:
        centre: (3,) centre of the bounding box [m].
        length: length of the straight capsule before bending [m].
        radius: tube radius [m] (sets the thickness along z).
        bend: total bend angle [rad] of the capsule's axis.
        count: tube resolution (segments around and rings along).
    """
    cap = _tube(length - 2 * radius, radius, count, count)
    v = np.array(cap.vertices, dtype=np.float64)  # a plain copy; axis along z, centred
    # Lay along x: (x, y, z) <- (z, y, x); handedness fixed by _finish.
    v = v[:, [2, 1, 0]]
    # Bend the x axis into an arc of radius R in the x-y plane (concave toward -y,
    # the lesser curvature facing the liver side).
    R = length / bend
    ang = v[:, 0] / R
    rr = R + v[:, 1]
    x = rr * np.sin(ang)
    y = R - rr * np.cos(ang)
    v = np.column_stack([x, -y, v[:, 2]])
    # Wider fundus (x-max end), narrower antrum.
    u = (v[:, 0] - v[:, 0].min()) / np.ptp(v[:, 0])
    sect = 0.8 + 0.35 * u
    mid = v.mean(axis=0)
    v[:, 1:] = mid[1:] + (v[:, 1:] - mid[1:]) * sect[:, None]
    v = v - (v.min(axis=0) + v.max(axis=0)) / 2.0 + np.asarray(centre)
    return _finish(v, cap.faces)


def intestine_loop(
    centre: tuple[float, float, float],
    major_radius: float = 0.021,
    minor_radius: float = 0.0085,
    *,
    tilt: float = 0.0,
    wobble: float = 0.15,
    sections: tuple[int, int] = (32, 12),
) -> trimesh.Trimesh:
    """One bowel loop: a torus lying roughly flat, slightly tilted and wobbly.

    Args:
        centre: (3,) centre [m].
        major_radius: loop radius [m]. minor_radius: tube radius [m].
        tilt: rotation about the x axis [rad].
        wobble: relative amplitude of the tube-radius modulation around the loop.
        sections: (major, minor) torus resolution.
    """
    tor = trimesh.creation.torus(
        major_radius=major_radius,
        minor_radius=minor_radius,
        major_sections=sections[0],
        minor_sections=sections[1],
    )
    v = tor.vertices.copy()
    ang = np.arctan2(v[:, 1], v[:, 0])
    ring = np.column_stack([np.cos(ang), np.sin(ang), np.zeros_like(ang)]) * major_radius
    off = v - ring
    v = ring + off * (1.0 + wobble * np.sin(3.0 * ang))[:, None]
    v = v @ geometry.rot_x(tilt).T + np.asarray(centre)
    return _finish(v, tor.faces)


def vessel(
    start: tuple[float, float, float] = (0.018, 0.015, 0.05),
    end: tuple[float, float, float] = (0.016, 0.165, 0.045),
    radius: float = 0.003,
    *,
    sway: float = -0.006,
    count: tuple[int, int] = (12, 40),
) -> trimesh.Trimesh:
    """A delicate vessel: a thin tube from ``start`` to ``end`` that sways sideways.

    Args:
        start, end: (3,) end points of the centre line [m].
        radius: tube radius [m].
        sway: amplitude of the lateral (x) S-curve [m].
        count: tube resolution (segments around, rings along).
    """
    a, b = np.asarray(start, dtype=np.float64), np.asarray(end, dtype=np.float64)
    length = float(np.linalg.norm(b - a))
    cap = _tube(length, radius, count[0], count[1])
    v: FloatArray = cap.vertices.copy()  # along z in [-length/2 - r, length/2 + r]
    s = np.clip(v[:, 2] / length + 0.5, 0.0, 1.0)
    # Rotate +z onto the start->end direction, move to the midpoint, then sway along x.
    d = (b - a) / length
    R = geometry.align_vectors(np.array([0.0, 0.0, 1.0]), d)   # trimesh's roll (geometry)
    v = v @ R.T + (a + b) / 2.0
    v[:, 0] += sway * np.sin(2.0 * np.pi * s)
    return _finish(v, cap.faces)


def abdominal_wall(
    centre_xy: tuple[float, float] = WALL_CENTRE_XY,
    half_extent: tuple[float, float, float] = WALL_HALF_EXTENT,
    thickness: float = WALL_THICKNESS,
    *,
    n_phi: int = 64,
    n_profile: int = 14,
) -> trimesh.Trimesh:
    """The abdominal wall: a closed dome shell of constant-ish thickness over ``z = 0``.

    The footprint is a superellipse (:data:`WALL_FOOTPRINT_EXPONENT`), the profile
    ``z = h (1 - r^p)^(1/p)`` (:data:`WALL_PROFILE_EXPONENT`). The shell is closed at the
    rim by a flat ring, so the mesh is watertight.

    Args:
        centre_xy: centre of the footprint [m].
        half_extent: outer half-extents (a, b, h) along x, y, z [m].
        thickness: wall thickness [m].
        n_phi: segments around; n_profile: points along each of the two profiles.
    """
    a, b, h = half_extent
    if not 0.0 < thickness < min(a, b, h):
        raise ValueError(f"thickness must be in (0, {min(a, b, h)}), got {thickness!r}")
    p = WALL_PROFILE_EXPONENT
    outer = _dome_profile(1.0, n_profile, p, outward_from_top=True)  # top -> rim
    inner = _dome_profile(1.0, n_profile, p, outward_from_top=False)  # rim -> top
    # Profiles in normalised r; z in metres. Inner surface is the outer one shrunk by the
    # thickness (exact on top, approximate on the flanks).
    ka = (min(a, b) - thickness) / min(a, b)
    outer_rz = np.column_stack([outer[:, 0], outer[:, 1] * h])
    inner_rz = np.column_stack([inner[:, 0] * ka, inner[:, 1] * (h - thickness)])
    profile = np.vstack([outer_rz, inner_rz])
    # Going top(outer) -> rim(outer) -> rim(inner) -> top(inner) is clockwise in (r, z):
    # _revolve/_finish fix the orientation by the sign of the volume.
    mesh = _revolve(profile, n_phi, _superellipse_radius(a, b, WALL_FOOTPRINT_EXPONENT))
    mesh.apply_translation([centre_xy[0], centre_xy[1], 0.0])
    return mesh


def _fit_box(v: FloatArray, centre, size) -> FloatArray:
    lo, hi = v.min(axis=0), v.max(axis=0)
    return (v - (lo + hi) / 2.0) / (hi - lo) * np.asarray(size) + np.asarray(centre)


# ---------------------------------------------------------------------------------------
# Scene


def inside_wall(points: FloatArray, *, margin: float = 0.0) -> NDArray[np.bool_]:
    """Whether points lie inside the cavity bounded by the wall's inner surface and z >= 0.

    Args:
        points: (n, 3) positions [m], world frame.
        margin: extra clearance from the inner surface, as a fraction of the cavity size.

    Returns:
        (n,) boolean mask.
    """
    pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
    a, b, h = WALL_HALF_EXTENT
    t = WALL_THICKNESS
    ka = (min(a, b) - t) / min(a, b)
    dx, dy = pts[:, 0] - WALL_CENTRE_XY[0], pts[:, 1] - WALL_CENTRE_XY[1]
    phi = np.arctan2(dy, dx)
    rmax = _superellipse_radius(a, b, WALL_FOOTPRINT_EXPONENT)(phi) * ka
    r = np.hypot(dx, dy) / rmax
    z = np.clip(pts[:, 2] / (h - t), 0.0, None)
    p = WALL_PROFILE_EXPONENT
    # Inside the inner dome: r^p + z^p < 1 (the profile's implicit form).
    return (pts[:, 2] >= 0.0) & (r**p + z**p < (1.0 - margin) ** p)


def trocar_points() -> FloatArray:
    """(4, 3) trocar (port) positions on the abdominal wall [m], world frame.

    Rows follow :data:`TROCAR_NAMES`: the camera port near the umbilicus, the two working
    ports on the patient's right (x < 0) and left (x > 0), and a cranial assistant port.
    Each point lies on the wall's mid-surface.
    """
    a, b, h = WALL_HALF_EXTENT
    t = WALL_THICKNESS
    p = WALL_PROFILE_EXPONENT
    radius = _superellipse_radius(a, b, WALL_FOOTPRINT_EXPONENT)
    out = []
    for x, y in _TROCAR_XY:
        dx, dy = x - WALL_CENTRE_XY[0], y - WALL_CENTRE_XY[1]
        r = np.hypot(dx, dy) / radius(np.arctan2(dy, dx))
        z_outer = h * (1.0 - r**p) ** (1.0 / p)
        out.append((x, y, z_outer - t / 2.0))
    return np.array(out, dtype=np.float64)


def default_anatomy() -> list[Organ]:
    """The demo abdomen: liver, stomach, six bowel loops, one delicate vessel, the wall.

    Returns:
        Organs in drawing order (the semi-transparent wall last).
    """
    loops_xy = [(-0.066, -0.075), (0.0, -0.07), (0.066, -0.075),
                (-0.062, -0.012), (0.0, -0.01), (0.062, -0.014)]  # fmt: skip
    loops = [
        Organ(
            name=f"intestine_{i}",
            mesh=intestine_loop(
                (x, y, 0.024 + 0.008 * (i % 2)),
                tilt=0.12 * (-1) ** i,
                wobble=0.12 + 0.03 * (i % 3),
            ),
            color=(0.86, 0.62, 0.55),
            delicate=False,
            kind="hollow",
        )
        for i, (x, y) in enumerate(loops_xy)
    ]
    return [
        Organ("liver", liver(), (0.48, 0.13, 0.10), delicate=False, kind="parenchyma"),
        Organ("stomach", stomach(), (0.85, 0.55, 0.52), delicate=False, kind="hollow"),
        *loops,
        Organ("vessel", vessel(), (0.70, 0.05, 0.08), delicate=True, kind="vessel"),
        Organ("abdominal_wall", abdominal_wall(), (0.95, 0.80, 0.72), delicate=False, kind="wall"),
    ]


__all__ = [
    "CAVITY_MAX",
    "CAVITY_MIN",
    "TROCAR_NAMES",
    "Organ",
    "OrganKind",
    "abdominal_wall",
    "default_anatomy",
    "inside_wall",
    "intestine_loop",
    "liver",
    "stomach",
    "trocar_points",
    "vessel",
]
