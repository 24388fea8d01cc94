"""Tests of the trajectory-following and point-targeting tasks (spec/study.md §1)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from vasim.core.errors import ConfigError
from vasim.tasks import (
    DEFAULT_REACH_RADIUS,
    TRAJECTORY_VARIANTS,
    WORKSPACE_MAX,
    WORKSPACE_MIN,
    Task,
    point_task,
    trajectory_task,
)
from vasim.tasks.trajectory import variant_matrix

VARIANTS = range(TRAJECTORY_VARIANTS)


@pytest.fixture(scope="module")
def tasks() -> list[Task]:
    return [trajectory_task(v) for v in VARIANTS]


def test_seven_variants() -> None:
    assert TRAJECTORY_VARIANTS == 7


def test_variants_share_length_and_curvature(tasks: list[Task]) -> None:
    ref = tasks[0]
    for t in tasks[1:]:
        assert t.n_points == ref.n_points
        assert abs(t.length() - ref.length()) < 1e-9
        np.testing.assert_allclose(t.curvature_profile(), ref.curvature_profile(),
                                   rtol=0, atol=1e-9)
        np.testing.assert_allclose(t.segment_lengths(), ref.segment_lengths(),
                                   rtol=0, atol=1e-12)


def test_variants_are_distinct(tasks: list[Task]) -> None:
    for a, b in itertools.combinations(tasks, 2):
        # distinct as point sequences and as sets (not the same path walked backwards)
        assert np.max(np.abs(a.points - b.points)) > 5e-3, (a.name, b.name)
        assert np.max(np.abs(a.points - b.points[::-1])) > 5e-3, (a.name, b.name)


def test_variants_are_isometries_about_the_centroid(tasks: list[Task]) -> None:
    c0 = tasks[0].points.mean(axis=0)
    for v, t in zip(VARIANTS, tasks, strict=True):
        m = variant_matrix(v)
        np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-15)
        np.testing.assert_allclose(t.points.mean(axis=0), c0, atol=1e-12)
        # pairwise distances preserved
        d0 = np.linalg.norm(tasks[0].points[:, None] - tasks[0].points[None], axis=-1)
        d = np.linalg.norm(t.points[:, None] - t.points[None], axis=-1)
        np.testing.assert_allclose(d, d0, atol=1e-12)
    dets = sorted(round(float(np.linalg.det(variant_matrix(v)))) for v in VARIANTS)
    assert dets.count(1) == 4 and dets.count(-1) == 3  # proper and improper isometries


def test_inside_workspace(tasks: list[Task]) -> None:
    for t in tasks:
        pts = np.vstack([t.points, t.start[None]])
        assert np.all(pts >= WORKSPACE_MIN) and np.all(pts <= WORKSPACE_MAX), t.name


def test_path_shape(tasks: list[Task]) -> None:
    t = tasks[0]
    assert 25 <= t.n_points <= 40
    assert 0.25 <= t.length() <= 0.35
    seg = t.segment_lengths()
    # successive POIs are distinct with a 5 mm reach radius: reaching p_i never reaches p_i+1
    assert seg.min() > 2 * t.reach_radius
    assert seg.max() < 0.012
    kappa = t.curvature_profile()
    assert kappa.shape == (t.n_points - 2,)
    assert kappa.max() > 5 * kappa.min()  # varying curvature
    start_gap = float(np.linalg.norm(t.start - t.points[0]))
    assert t.reach_radius < start_gap < 0.03


def test_reach_radius_default_and_advance() -> None:
    t = trajectory_task()
    assert t.reach_radius == DEFAULT_REACH_RADIUS == 0.005
    p0 = t.points[0]
    assert t.advance(0, p0 + np.array([0.0, 0.0, 0.0049])) == 1
    assert t.advance(0, p0 + np.array([0.0, 0.0, 0.0051])) == 0
    assert t.advance(t.n_points, p0) == t.n_points


def test_lookahead_walks_the_polyline() -> None:
    t = trajectory_task()
    la = t.lookahead(3, 0.0)
    np.testing.assert_allclose(la, t.points[3])
    seg = t.segment_lengths()
    la = t.lookahead(3, seg[3] + 0.5 * seg[4])
    np.testing.assert_allclose(la, 0.5 * (t.points[4] + t.points[5]), atol=1e-12)
    np.testing.assert_allclose(t.lookahead(t.n_points - 2, 1.0), t.points[-1])
    np.testing.assert_allclose(t.lookahead(10**6), t.points[-1])
    with pytest.raises(ValueError, match="-1"):
        t.lookahead(0, -1.0)


def test_points_are_read_only() -> None:
    t = trajectory_task(2)
    with pytest.raises(ValueError):
        t.points[0, 0] = 1.0
    with pytest.raises(ValueError):
        t.start[0] = 1.0


@pytest.mark.parametrize("bad", [-1, 7, 100, 1.5, "0", None, True])
def test_bad_variant_rejected(bad: object) -> None:
    with pytest.raises(ConfigError, match="variant") as exc:
        trajectory_task(bad)  # type: ignore[arg-type]
    assert repr(bad) in str(exc.value)
    assert isinstance(exc.value, ValueError)


def test_point_task() -> None:
    t = point_task()
    assert t.kind == "point" and t.n_points == 1
    assert t.normals is not None and t.normals.shape == (1, 3)
    n = t.normals[0]
    assert abs(np.linalg.norm(n) - 1.0) < 1e-12
    assert n[2] > 0.9  # roughly +z (the liver's upper surface)
    d = t.start - t.points[0]
    assert 0.06 <= np.linalg.norm(d) <= 0.08
    np.testing.assert_allclose(d / np.linalg.norm(d), n, atol=1e-12)
    assert t.length() == 0.0 and t.curvature_profile().shape == (0,)
    np.testing.assert_allclose(t.lookahead(0), t.points[0])
    st = t.state(0, t.start)
    assert st.kind == "point" and st.normal is not None and st.scale == t.scale


def test_point_task_custom_normal_is_normalised() -> None:
    t = point_task((0.0, 0.0, 0.05), (0.0, 0.0, 3.0), start_distance=0.06)
    np.testing.assert_allclose(t.normals, [[0.0, 0.0, 1.0]])
    np.testing.assert_allclose(t.start, [0.0, 0.0, 0.11])


@pytest.mark.parametrize("kwargs, field", [
    ({"normal": (0.0, 0.0, 0.0)}, "normal"),
    ({"normal": (0.0, float("nan"), 1.0)}, "normal"),
    ({"poi": (0.0, 0.0)}, "poi"),
    ({"start_distance": -0.01}, "start_distance"),
])
def test_point_task_rejects_bad_input(kwargs: dict, field: str) -> None:
    with pytest.raises(ConfigError, match=field):
        point_task(**kwargs)


@pytest.mark.parametrize("kwargs, field", [
    ({"points": np.zeros((3, 2))}, "points"),
    ({"points": np.full((2, 3), np.nan)}, "points"),
    ({"reach_radius": 0.0}, "reach_radius"),
    ({"scale": -1.0}, "scale"),
    ({"normals": np.ones((2, 3))}, "normals"),
    ({"kind": "ring"}, "kind"),
])
def test_task_validation(kwargs: dict, field: str) -> None:
    base = {"name": "x", "kind": "trajectory", "variant": 0,
            "points": np.array([[0, 0, 0.1], [0.01, 0, 0.1]]), "normals": None}
    base.update(kwargs)
    with pytest.raises(ConfigError, match=field):
        Task(**base)


def test_trajectory_state_fields() -> None:
    t = trajectory_task(4)
    st = t.state(5, t.points[5] + 0.001, t=1.5)
    assert st.kind == "trajectory" and st.normal is None and st.t == 1.5
    np.testing.assert_allclose(st.goal, t.points[5])
    assert st.lookahead is not None
    assert abs(np.linalg.norm(st.lookahead - t.points[5]) - 0.02) < 0.002


def test_poi_spacing_is_a_task_parameter():
    from vasim.tasks.trajectory import POI_SPACING

    default = trajectory_task(0)
    assert default.n_points == 30
    fine = trajectory_task(0, poi_spacing=0.0056, reach_radius=0.0025)
    # the same polyline resampled: ~56 POIs (the seed's ~56 rows per trial), equal chords
    assert 54 <= fine.n_points <= 58
    chords = np.linalg.norm(np.diff(fine.points, axis=0), axis=1)
    assert chords.min() > 2 * 0.0025 and chords.max() < 0.0056 * 1.05
    assert fine.length() == pytest.approx(default.length(), rel=0.02)
    # the same path: the start agrees up to the re-centring on the POIs' centroid (< 1 mm)
    np.testing.assert_allclose(fine.points[0], default.points[0], atol=1e-3)
    # a reach sphere may not overlap the next POI's
    with pytest.raises(ConfigError, match="twice the reach radius"):
        trajectory_task(0, poi_spacing=0.008)     # default reach radius 5 mm
    with pytest.raises(ConfigError, match="poi_spacing"):
        trajectory_task(0, poi_spacing=0.5)
    assert trajectory_task(3, poi_spacing=POI_SPACING).n_points == 30
