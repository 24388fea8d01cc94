"""POIs bound to organ surfaces reproduce their rest positions and ride with the tissue."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from vasim.abdomen.attach import bind_points


def sphere(centre, radius=0.02):
    m = trimesh.creation.icosphere(subdivisions=3, radius=radius)
    return np.asarray(m.vertices) + centre, np.asarray(m.faces, dtype=np.int64)


A = sphere(np.array([0.0, 0.0, 0.0]))
B = sphere(np.array([0.1, 0.0, 0.0]))


def test_rest_positions_are_reproduced_and_bound_to_the_nearest_organ():
    pts = np.array([[0.0, 0.0, 0.035], [0.1, 0.0, -0.03], [0.045, 0.0, 0.0]])
    b = bind_points(pts, [A, B])
    np.testing.assert_allclose(b.positions([A[0], B[0]]), pts, atol=1e-12)
    assert b.organ.tolist() == [0, 1, 0]
    np.testing.assert_allclose(b.weights.sum(axis=1), 1.0)
    assert np.all(b.weights >= 0)
    # the distance to a sphere of radius 2 cm (faceted: slightly larger)
    assert b.distance[0] == pytest.approx(0.015, abs=5e-4)


def test_points_follow_the_translation_of_their_organ_only():
    pts = np.array([[0.0, 0.0, 0.035], [0.1, 0.0, -0.03]])
    b = bind_points(pts, [A, B])
    shift = np.array([0.0, 0.01, 0.0])
    moved = b.positions([A[0] + shift, B[0]])
    np.testing.assert_allclose(moved[0], pts[0] + shift, atol=1e-12)
    np.testing.assert_allclose(moved[1], pts[1], atol=1e-12)


def test_a_surface_point_stays_on_the_deformed_surface_with_its_normal():
    x = A[0]
    foot = x[5] * 0.999  # just under a vertex: bound with a tiny offset
    b = bind_points(foot[None], [A])
    dented = x.copy()
    dented[5] *= 0.9  # push that vertex 10 % inward
    p = b.positions([dented])[0]
    assert np.linalg.norm(p) < np.linalg.norm(foot) - 0.001
    n = b.normals([x])[0]
    assert n @ (x[5] / np.linalg.norm(x[5])) > 0.95  # outward normal


def test_bad_input():
    with pytest.raises(ValueError, match="at least one surface"):
        bind_points(np.zeros((1, 3)), [])
    with pytest.raises(ValueError, match="finite"):
        bind_points(np.array([[np.nan, 0, 0]]), [A])
