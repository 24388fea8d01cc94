"""Organ models: topology from the mesh, volume nodes, masses, anchors, validation."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from vasim.abdomen.anatomy import default_anatomy, intestine_loop, vessel
from vasim.abdomen.integrate import OrganSolver
from vasim.abdomen.model import (
    SPRING_BENDING,
    SPRING_STRUCTURAL,
    SPRING_VOLUME,
    AnchorRule,
    OrganModel,
    OrganParams,
    build_organ,
    select_anchors,
)
from vasim.core.errors import ConfigError


def winding_number(mesh, points: np.ndarray) -> np.ndarray:
    """Generalised winding number (Jacobson et al. 2013): ~1 inside a closed outward surface,
    ~0 outside (an independent inside test: trimesh.contains needs rtree)."""
    tri = mesh.triangles[None, :, :, :] - points[:, None, None, :]
    a, b, c = tri[..., 0, :], tri[..., 1, :], tri[..., 2, :]
    la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
    det = np.einsum("...i,...i", a, np.cross(b, c))
    den = (la * lb * lc + np.einsum("...i,...i", a, b) * lc
           + np.einsum("...i,...i", b, c) * la + np.einsum("...i,...i", c, a) * lb)
    return (2.0 * np.arctan2(det, den)).sum(axis=-1) / (4.0 * np.pi)


TOP = AnchorRule(to="point", point=(0.0, 0.0, 0.03), fraction=0.1)


def test_surface_nodes_are_the_mesh_vertices_in_order_then_interior_nodes() -> None:
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.03)
    model = build_organ(mesh, OrganParams(anchors=(TOP,)), name="ball")
    m = len(mesh.vertices)
    assert model.n_surface == m and model.n_nodes > m
    np.testing.assert_array_equal(model.rest[:m], mesh.vertices)
    np.testing.assert_array_equal(model.faces, mesh.faces)
    # every interior node lies inside the surface
    assert (winding_number(mesh, model.rest[m:]) > 0.5).all()


def test_spring_families_match_the_mesh() -> None:
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.03)
    model = build_organ(mesh, OrganParams(stiffness=120.0, bending_stiffness=12.0,
                                          volume_stiffness=60.0, anchors=(TOP,)), name="ball")
    types = model.spring_type
    edges = {tuple(e) for e in np.sort(mesh.edges_unique, axis=1)}
    structural = {tuple(e) for e in np.sort(model.springs[types == SPRING_STRUCTURAL], axis=1)}
    assert structural == edges  # one per edge
    # one bending spring per edge, across it (a closed triangulation: as many as edges)
    assert (types == SPRING_BENDING).sum() == len(edges)
    np.testing.assert_array_equal(model.stiffness[types == SPRING_STRUCTURAL], 120.0)
    np.testing.assert_array_equal(model.stiffness[types == SPRING_BENDING], 12.0)
    np.testing.assert_array_equal(model.stiffness[types == SPRING_VOLUME], 60.0)
    # every surface vertex has exactly one spoke to an interior node
    volume = model.springs[types == SPRING_VOLUME]
    spokes = volume[volume.min(axis=1) < model.n_surface]
    assert (spokes.max(axis=1) >= model.n_surface).all()  # surface to interior
    np.testing.assert_array_equal(np.sort(spokes.min(axis=1)), np.arange(model.n_surface))
    # no pair twice, rest lengths are the rest distances
    key = np.sort(model.springs, axis=1)
    assert len(np.unique(key, axis=0)) == len(key)
    np.testing.assert_allclose(
        model.rest_length,
        np.linalg.norm(model.rest[model.springs[:, 0]] - model.rest[model.springs[:, 1]], axis=1))


@pytest.mark.parametrize("mesh", [vessel(), intestine_loop((0.0, 0.0, 0.03))],
                         ids=["vessel", "bowel loop"])
def test_thin_tubes_get_interior_nodes_on_their_centre_line(mesh) -> None:
    model = build_organ(mesh, OrganParams(anchors=(TOP,)), name="tube")
    interior = model.rest[model.n_surface:]
    assert len(interior) >= 5
    assert (winding_number(mesh, interior) > 0.5).all()


@pytest.mark.parametrize("distribution", ["area", "uniform"])
def test_masses_sum_to_the_organ_mass(distribution: str) -> None:
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.03)
    model = build_organ(mesh, OrganParams(mass=0.37, mass_distribution=distribution,
                                          anchors=(TOP,)), name="ball")
    assert model.total_mass == pytest.approx(0.37, rel=1e-12)
    assert (model.mass > 0).all()
    if distribution == "uniform":
        np.testing.assert_allclose(model.mass, 0.37 / model.n_nodes)


def test_volume_springs_keep_a_hanging_organ_from_collapsing() -> None:
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.03)
    volumes = {}
    for volume in (False, True):
        params = OrganParams(stiffness=50.0, bending_stiffness=5.0, volume=volume,
                             volume_stiffness=50.0, mass=0.2, damping=0.01, anchors=(TOP,))
        model = build_organ(mesh, params, name="ball")
        solver = OrganSolver(model, 0.004)
        state = solver.initial_state()
        for _ in range(500):
            assert solver.step(state, model.rest[model.anchors]).ok
        volumes[volume] = trimesh.Trimesh(state.x[: model.n_surface], mesh.faces).volume
    assert volumes[True] > 0.9 * mesh.volume
    assert volumes[False] < volumes[True]


def test_anchor_rules_select_what_they_say() -> None:
    rng = np.random.default_rng(0)
    pts = rng.uniform(-0.05, 0.05, size=(200, 3))
    plane = AnchorRule(to="plane", point=(0, 0, -0.03), normal=(0, 0, 2.0), within=0.0)
    np.testing.assert_array_equal(select_anchors(pts, [plane]), np.flatnonzero(pts[:, 2] <= -0.03))
    near = AnchorRule(to="point", point=(0.01, 0.0, 0.0), fraction=0.05)
    got = select_anchors(pts, [near])
    d = np.linalg.norm(pts - [0.01, 0.0, 0.0], axis=1)
    np.testing.assert_array_equal(got, np.sort(np.argsort(d)[:10]))
    both = select_anchors(pts, [plane, near])
    assert set(both) == set(got) | set(np.flatnonzero(pts[:, 2] <= -0.03))
    wall = next(o.mesh for o in default_anatomy() if o.kind == "wall")
    near_wall = select_anchors(pts * 3, [AnchorRule(to="wall", within=0.02)], wall=wall)
    assert len(near_wall) > 0
    with pytest.raises(ConfigError, match="wall mesh"):
        select_anchors(pts, [AnchorRule(to="wall", within=0.02)])


def test_kinematic_body_has_every_node_anchored_and_no_springs() -> None:
    mesh = trimesh.creation.icosphere(subdivisions=1, radius=0.1)
    model = build_organ(mesh, OrganParams(kinematic=True, volume=False), name="wall", kind="wall")
    assert len(model.springs) == 0 and len(model.anchors) == model.n_nodes
    assert not model.free.any()


def test_model_arrays_are_read_only() -> None:
    mesh = trimesh.creation.icosphere(subdivisions=1, radius=0.03)
    model = build_organ(mesh, OrganParams(volume=False, anchors=(TOP,)), name="ball")
    for name in ("rest", "springs", "stiffness", "mass", "anchors", "rest_length"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(model, name)[0] = 0


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("stiffness", -5.0, r"stiffness.*got -5.*in \[0, "),
        ("bending_stiffness", -1.0, r"bending_stiffness.*-1"),
        ("mass", 0.0, r"'mass'.*got 0.0.*in \[0.001, 10\] kg"),
        ("mass", -1.0, r"'mass'.*-1"),
        ("damping", -0.1, r"damping.*-0.1"),
        ("volume_spacing", 0.0, r"volume_spacing"),
        ("mass_distribution", "volume", r"mass_distribution.*'volume'"),
        ("stiffness", float("nan"), r"stiffness.*finite"),
    ],
)
def test_bad_params_are_refused_naming_field_and_value(field: str, value, match: str) -> None:
    with pytest.raises(ConfigError, match=match) as info:
        OrganParams(**{field: value})
    assert info.value.field == field


def test_bad_anchor_rules_are_refused() -> None:
    with pytest.raises(ConfigError, match="exactly one"):
        AnchorRule(to="point", point=(0, 0, 0), within=0.01, fraction=0.1)
    with pytest.raises(ConfigError, match="needs 'normal'"):
        AnchorRule(to="plane", point=(0, 0, 0), fraction=0.1)
    with pytest.raises(ConfigError, match="fraction"):
        AnchorRule(to="point", point=(0, 0, 0), fraction=1.5)
    with pytest.raises(ConfigError, match=r"'to'.*'ligament'"):
        AnchorRule(to="ligament", fraction=0.1)  # type: ignore[arg-type]
    mesh = trimesh.creation.icosphere(subdivisions=1, radius=0.03)
    far = AnchorRule(to="point", point=(0.4, 0.4, 0.4), within=0.01)
    with pytest.raises(ConfigError, match="select no node"):
        build_organ(mesh, OrganParams(anchors=(far,)), name="ball")


def test_bad_model_arrays_are_refused_naming_the_entry() -> None:
    base = dict(name="x", rest=np.array([[0.0, 0, 0], [1, 0, 0]]), faces=np.zeros((0, 3)),
                n_surface=2, springs=np.array([[0, 1]]), rest_length=np.array([1.0]),
                stiffness=np.array([10.0]), mass=np.array([1.0, 1.0]), damping=0.0,
                anchors=np.array([0]), gravity=(0.0, 0.0, -9.81))
    OrganModel(**base)
    cases = [
        ({"stiffness": np.array([-3.0])}, r"stiffness\[0\]"),
        ({"mass": np.array([1.0, 0.0])}, r"mass\[1\]"),
        ({"rest_length": np.array([0.0])}, r"rest_length\[0\]"),
        ({"springs": np.array([[0, 2]])}, "springs"),
        ({"springs": np.array([[1, 1]])}, r"springs\[0\]"),
        ({"anchors": np.array([0, 0])}, "repeated"),
        ({"faces": np.array([[0, 1, 2]])}, "faces"),
        ({"rest": np.array([[0, 0, 0], [np.nan, 0, 0]])}, "non-finite"),
    ]
    for change, match in cases:
        with pytest.raises(ConfigError, match=match):
            OrganModel(**{**base, **change})


def test_open_mesh_is_refused() -> None:
    mesh = trimesh.creation.icosphere(subdivisions=1, radius=0.03)
    mesh = trimesh.Trimesh(mesh.vertices, mesh.faces[1:], process=False)
    with pytest.raises(ConfigError, match="watertight"):
        build_organ(mesh, OrganParams(anchors=(TOP,)), name="ball")


def test_unanchored_organs_and_parts_are_refused() -> None:
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.03)
    with pytest.raises(ConfigError, match="no anchor") as info:
        build_organ(ball, OrganParams(), name="ball")
    assert info.value.field == "anchors"
    two = trimesh.util.concatenate([ball, ball.copy().apply_translation((0.2, 0.0, 0.0))])
    rule = AnchorRule(to="point", point=(0.0, 0.0, 0.0), fraction=0.1)
    with pytest.raises(ConfigError, match=r"'pair'.*part 1 of 2 connected parts"):
        build_organ(two, OrganParams(anchors=(rule,)), name="pair")
    rule2 = AnchorRule(to="point", point=(0.2, 0.0, 0.0), within=0.031)
    model = build_organ(two, OrganParams(anchors=(rule, rule2)), name="pair")
    assert len(model.anchors) > 0
    # a kinematic organ is entirely anchored: accepted
    build_organ(ball, OrganParams(kinematic=True, volume=False), name="rigid")
