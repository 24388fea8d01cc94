"""The procedural anatomy: closed meshes, inside the cavity, not interpenetrating, and
consistent with the task geometry that was placed on it."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from vasim.abdomen.anatomy import (
    CAVITY_MAX,
    CAVITY_MIN,
    TROCAR_NAMES,
    abdominal_wall,
    default_anatomy,
    inside_wall,
    liver,
    trocar_points,
)
from vasim.tasks import TRAJECTORY_VARIANTS, trajectory_task
from vasim.tasks.base import WORKSPACE_MAX, WORKSPACE_MIN
from vasim.tasks.point import LIVER_NORMAL, LIVER_POI


def winding_number(mesh, points: np.ndarray) -> np.ndarray:
    """Generalised winding number (Jacobson et al. 2013): ~1 inside a closed outward
    surface, ~0 outside. Independent of trimesh.contains (which needs rtree)."""
    tri = mesh.triangles[None, :, :, :] - points[:, None, None, :]
    a, b, c = tri[..., 0, :], tri[..., 1, :], tri[..., 2, :]
    la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
    det = np.einsum("...i,...i", a, np.cross(b, c))
    den = (la * lb * lc + np.einsum("...i,...i", a, b) * lc
           + np.einsum("...i,...i", b, c) * la + np.einsum("...i,...i", c, a) * lb)
    return (2.0 * np.arctan2(det, den)).sum(axis=-1) / (4.0 * np.pi)


@pytest.fixture(scope="module")
def organs():
    return default_anatomy()


def test_meshes_are_closed_outward_and_modest(organs) -> None:
    names = [o.name for o in organs]
    assert len(set(names)) == len(names)
    for o in organs:
        m = o.mesh
        assert m.is_watertight, o.name
        assert m.is_winding_consistent, o.name
        assert m.volume > 0, f"{o.name}: faces point inward"
        assert 200 <= len(m.vertices) <= 2500, (o.name, len(m.vertices))
        assert all(0.0 <= c <= 1.0 for c in o.color)
        # A point far outside has winding number 0, the centroid of a convex-ish organ 1.
        assert abs(winding_number(m, np.array([[1.0, 1.0, 1.0]]))[0]) < 1e-6


def test_everything_inside_the_cavity_box(organs) -> None:
    for o in organs:
        lo, hi = o.mesh.bounds
        assert np.all(lo >= CAVITY_MIN - 1e-9) and np.all(hi <= CAVITY_MAX + 1e-9), o.name


def test_organs_lie_under_the_wall(organs) -> None:
    for o in organs:
        if o.kind == "wall":
            continue
        assert inside_wall(o.mesh.vertices).all(), o.name


def test_organs_do_not_interpenetrate(organs) -> None:
    inner = [o for o in organs if o.kind != "wall"]
    rng = np.random.default_rng(0)
    for a, b in itertools.combinations(inner, 2):
        lo = np.maximum(a.mesh.bounds[0], b.mesh.bounds[0])
        hi = np.minimum(a.mesh.bounds[1], b.mesh.bounds[1])
        if np.any(lo >= hi):
            continue  # disjoint bounding boxes
        # No vertex of one inside the other ...
        assert (winding_number(b.mesh, a.mesh.vertices) > 0.5).sum() == 0, (a.name, b.name)
        assert (winding_number(a.mesh, b.mesh.vertices) > 0.5).sum() == 0, (a.name, b.name)
        # ... and no common volume in the boxes' overlap.
        pts = rng.uniform(lo, hi, size=(300, 3))
        both = (winding_number(a.mesh, pts) > 0.5) & (winding_number(b.mesh, pts) > 0.5)
        assert both.sum() == 0, (a.name, b.name)


def test_only_the_vessel_is_delicate(organs) -> None:
    delicate = [o.name for o in organs if o.delicate]
    assert delicate == ["vessel"]
    assert {o.kind for o in organs} == {"parenchyma", "hollow", "vessel", "wall"}


def test_trocars_sit_in_the_wall_above_the_workspace() -> None:
    t = trocar_points()
    assert t.shape == (len(TROCAR_NAMES), 3)
    assert np.all(t >= CAVITY_MIN) and np.all(t <= CAVITY_MAX)
    assert not inside_wall(t).any()  # in the wall, not in the cavity below it
    assert np.all(t[:, 2] > WORKSPACE_MAX[2])
    # Just below each trocar is cavity.
    assert inside_wall(t - np.array([0.0, 0.0, 0.01])).all()


def test_task_geometry_fits_the_anatomy(organs) -> None:
    # The point task's POI was taken from the default liver: it must stay on its surface.
    m = liver()
    d = np.linalg.norm(m.vertices - np.array(LIVER_POI), axis=1)
    i = int(d.argmin())
    assert d[i] < 1e-4
    n = np.array(LIVER_NORMAL) / np.linalg.norm(LIVER_NORMAL)
    assert float(m.vertex_normals[i] @ n) > 0.999
    # The trajectory workspace and every trajectory are in free space under the wall.
    corners = np.array(list(itertools.product(*zip(WORKSPACE_MIN, WORKSPACE_MAX, strict=True))))
    pts = np.vstack([corners] + [trajectory_task(v).points for v in range(TRAJECTORY_VARIANTS)])
    assert inside_wall(pts).all()
    for o in organs:
        if o.kind != "wall":
            assert (winding_number(o.mesh, pts) < 0.5).all(), o.name


def test_meshes_are_pure_functions_of_their_parameters() -> None:
    np.testing.assert_array_equal(liver().vertices, liver().vertices)
    assert not np.array_equal(liver(size=(0.1, 0.1, 0.05)).vertices, liver().vertices)
    a, b = default_anatomy(), default_anatomy()
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.mesh.vertices, y.mesh.vertices)


def test_bad_parameters_raise() -> None:
    with pytest.raises(ValueError, match="taper"):
        liver(taper=0.0)
    with pytest.raises(ValueError, match="thickness"):
        abdominal_wall(thickness=0.5)
