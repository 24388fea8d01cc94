"""User meshes: good files load in metres; each kind of bad mesh is refused with its reason.

The bad meshes are generated here (no fixture files): a hole, a fin (non-manifold edge), a
zero-area face, two interpenetrating spheres, a millimetre-scale sphere.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from vasim.abdomen import _kernels, meshes
from vasim.abdomen.meshes import load_user_mesh, mesh_problems
from vasim.core.errors import ConfigError


def sphere(radius: float = 0.03, subdivisions: int = 2) -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)


def write(mesh: trimesh.Trimesh, path: Path) -> Path:
    mesh.export(path)
    return path


@pytest.mark.parametrize("ext", ["obj", "stl", "ply", "off"])
def test_a_good_mesh_loads_closed_outward_in_metres(tmp_path: Path, ext: str) -> None:
    good = sphere()
    mesh = load_user_mesh(write(good, tmp_path / f"ball.{ext}"))
    assert mesh.is_watertight and mesh.volume > 0
    assert len(mesh.vertices) == len(good.vertices)  # STL's repeated vertices are merged
    np.testing.assert_allclose(mesh.extents, good.extents, rtol=1e-6)


def test_millimetres_are_detected_and_converted(tmp_path: Path) -> None:
    path = write(sphere(radius=30.0), tmp_path / "ball_mm.stl")
    with pytest.raises(ConfigError, match=r'looks like millimetres; pass units="mm"') as info:
        load_user_mesh(path, field="organs.kidney.mesh")
    assert info.value.file == str(path) and info.value.field == "organs.kidney.mesh"
    assert "ball_mm.stl" in str(info.value) and "organs.kidney.mesh" in str(info.value)
    mesh = load_user_mesh(path, units="mm")
    assert mesh.extents.max() == pytest.approx(0.06, rel=1e-6)
    with pytest.raises(ConfigError, match="too small"):
        load_user_mesh(write(sphere(radius=0.001), tmp_path / "tiny.obj"))


def test_inward_faces_are_turned_outward(tmp_path: Path) -> None:
    inside_out = sphere()
    inside_out.invert()
    assert inside_out.volume < 0
    assert load_user_mesh(write(inside_out, tmp_path / "inv.obj")).volume > 0


def test_an_open_mesh_is_refused(tmp_path: Path) -> None:
    s = sphere()
    holed = trimesh.Trimesh(s.vertices, s.faces[3:], process=False)
    with pytest.raises(ConfigError, match=r"not closed \(not watertight\): 9 boundary edges"):
        load_user_mesh(write(holed, tmp_path / "holed.obj"))


def test_a_non_manifold_edge_is_refused() -> None:
    s = sphere()
    a, b = s.faces[0, 0], s.faces[0, 1]
    fin_tip = s.vertices[[a, b]].mean(axis=0) * 1.5
    verts = np.vstack([s.vertices, fin_tip])
    faces = np.vstack([s.faces, [[a, b, len(s.vertices)]]])
    problems = mesh_problems(trimesh.Trimesh(verts, faces, process=False))
    assert any("non-manifold: 1 edges shared by more than two faces" in p for p in problems)


def test_a_degenerate_face_is_refused() -> None:
    s = sphere()
    a, b = s.faces[0, 0], s.faces[0, 1]
    mid = s.vertices[[a, b]].mean(axis=0)  # collinear with a and b: zero area
    verts = np.vstack([s.vertices, mid])
    faces = np.vstack([s.faces, [[a, b, len(s.vertices)]]])
    problems = mesh_problems(trimesh.Trimesh(verts, faces, process=False))
    assert any("1 degenerate (zero-area) faces" in p for p in problems)


def test_self_intersection_is_refused(tmp_path: Path) -> None:
    a = sphere()
    b = sphere()
    b.apply_translation([0.03, 0.0, 0.0])  # half inside the first: two closed shells crossing
    both = trimesh.util.concatenate([a, b])
    assert both.is_watertight  # the only problem is the crossing
    with pytest.raises(ConfigError, match=r"self-intersecting: \d+ pairs of faces cross"):
        load_user_mesh(write(both, tmp_path / "two.ply"))
    apart = trimesh.util.concatenate([a, sphere().apply_translation([0.1, 0.0, 0.0])])
    assert mesh_problems(apart) == []


def test_triangle_pair_test_against_hand_made_cases() -> None:
    v = np.array([
        [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0],       # T0 in z = 0
        [0.2, 0.2, -0.5], [0.2, 0.2, 0.5], [0.9, 0.9, 0.5],      # T1 pierces T0
        [2.0, 2.0, -0.5], [2.0, 2.0, 0.5], [3.0, 3.0, 0.5],      # T2 far away
        [0.2, 0.2, 0.1], [0.3, 0.2, 0.1], [0.2, 0.3, 0.1],       # T3 parallel above T0
    ])
    faces = np.arange(12, dtype=np.int64).reshape(4, 3)
    pairs = _kernels.self_intersections(v, faces, 10)
    assert {tuple(sorted(p)) for p in pairs.tolist()} == {(0, 1), (1, 3)}


def test_vertex_count_limits(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    tetra = trimesh.creation.box(extents=(0.05, 0.05, 0.05))  # 8 vertices
    with pytest.raises(ConfigError, match=r"too few vertices \(8; at least 20\)"):
        load_user_mesh(write(tetra, tmp_path / "box.obj"))
    monkeypatch.setattr(meshes, "MAX_VERTICES", 100)
    with pytest.raises(ConfigError, match=r"too many vertices \(162; at most 100"):
        load_user_mesh(write(sphere(), tmp_path / "ball.obj"))


def test_file_problems_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="mesh file not found") as info:
        load_user_mesh(tmp_path / "missing.obj", field="organs.x.mesh")
    assert info.value.file == str(tmp_path / "missing.obj")
    bad_format = tmp_path / "ball.xyz"
    bad_format.write_text("1 2 3\n")
    with pytest.raises(ConfigError, match=r"got '\.xyz', expected a supported mesh format"):
        load_user_mesh(bad_format)
    garbage = tmp_path / "garbage.stl"
    garbage.write_bytes(b"\x00\x01not a mesh at all" * 3)
    with pytest.raises(ConfigError, match=r"garbage\.stl") as info:
        load_user_mesh(garbage)
    assert "cannot read" in info.value.reason or "no triangle" in info.value.reason
    with pytest.raises(ConfigError, match="units"):
        load_user_mesh(write(sphere(), tmp_path / "ball.obj"), units="inch")  # type: ignore


def test_the_units_hint_names_centimetres_or_millimetres(tmp_path: Path) -> None:
    cm = tmp_path / "cm.obj"
    trimesh.creation.icosphere(subdivisions=2, radius=3.0).export(cm)
    with pytest.raises(ConfigError, match='centimetres; pass units="cm"'):
        load_user_mesh(cm)
    assert load_user_mesh(cm, units="cm").extents.max() == pytest.approx(0.06, rel=1e-6)
    mm = tmp_path / "mm.obj"
    trimesh.creation.icosphere(subdivisions=2, radius=150.0).export(mm)
    with pytest.raises(ConfigError, match='millimetres; pass units="mm"'):
        load_user_mesh(mm)
