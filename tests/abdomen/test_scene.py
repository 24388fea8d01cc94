"""Scene files: the shipped default, round trips, user meshes, validation, stepping."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import trimesh

from vasim.abdomen.anatomy import default_anatomy
from vasim.abdomen.motion import point_offsets
from vasim.abdomen.scene import (
    OrganConfig,
    Scene,
    ScenePhysics,
    load_scene,
    parse_scene,
    procedural_names,
    with_organ,
)
from vasim.core.errors import ConfigError

MINIMAL = """
name = "mini"
[organs.liver]
stiffness = 100.0
mass = 1.0
[[organs.liver.anchors]]
to = "plane"
point = [0.0, 0.14, 0.0]
normal = [0.0, -1.0, 0.0]
fraction = 0.1
"""


@pytest.fixture(scope="module")
def default() -> Scene:
    return load_scene("default")


@pytest.fixture(scope="module")
def default_models(default: Scene):
    return default.build()


def test_the_shipped_scene_has_every_procedural_organ(default: Scene, default_models) -> None:
    assert [o.name for o in default.organs] == [o.name for o in default_anatomy()]
    assert set(procedural_names()) == {o.name for o in default.organs}
    assert default.physics.dt == 0.004 and default.physics.rate_hz == 250.0
    by_name = {m.name: m for m in default_models}
    assert by_name["vessel"].delicate and not by_name["liver"].delicate
    deformable = [m for m in default_models if m.kind != "wall"]
    assert sum(m.n_nodes for m in deformable) >= 3000
    for m in deformable:
        assert 0 < len(m.anchors) < m.n_surface, m.name
    wall = by_name["abdominal_wall"]
    assert len(wall.anchors) == wall.n_nodes  # kinematic
    # breathing is mostly cranio-caudal (+y) and largest for the liver
    liver = default.organ("liver").breathing_m
    assert abs(liver[1]) > abs(liver[0]) and abs(liver[1]) > abs(liver[2])
    assert all(abs(o.breathing_m[1]) <= abs(liver[1]) for o in default.organs)


def test_round_trip_through_text_and_file(default: Scene, tmp_path: Path) -> None:
    text = str(default)
    again = parse_scene(text)
    assert again == default
    path = tmp_path / "copy.toml"
    path.write_text(text)
    assert load_scene(path) == default
    assert str(load_scene(path)) == text


def test_user_mesh_relative_to_the_scene_file(tmp_path: Path) -> None:
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=25.0)  # millimetres
    (tmp_path / "meshes").mkdir()
    mesh.export(tmp_path / "meshes" / "kidney.stl")
    text = MINIMAL + """
[organs.kidney]
mesh = "meshes/kidney.stl"
units = "mm"
kind = "parenchyma"
color = [0.5, 0.2, 0.2]
mass = 0.15
[[organs.kidney.anchors]]
to = "point"
point = [0.0, 0.0, -0.025]
within = 0.01
"""
    path = tmp_path / "kidney_scene.toml"
    path.write_text(text)
    scene = load_scene(path)
    assert Path(scene.organ("kidney").mesh).is_absolute()
    models = {m.name: m for m in scene.build()}
    kidney = models["kidney"]
    assert kidney.n_surface == len(mesh.vertices)
    assert np.ptp(kidney.rest[: kidney.n_surface], axis=0).max() == pytest.approx(0.05)
    assert parse_scene(str(scene)) == scene


def error_of(text: str, tmp_path: Path) -> ConfigError:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_scene(path)
    assert info.value.file == str(path)
    return info.value


@pytest.mark.parametrize(
    ("old", "new", "field", "value"),
    [
        ("stiffness = 100.0", "stiffness = -5.0", "organs.liver.stiffness", "-5.0"),
        ("mass = 1.0", "mass = 0.0", "organs.liver.mass", "0.0"),
        ("mass = 1.0", "mass = -2", "organs.liver.mass", "-2"),
        ("[organs.liver]", "[organs.lvier]", "organs.lvier.mesh", "'lvier'"),
        ("[organs.liver]", '[organs.liver]\nmesh = "nowhere/kidney.obj"',
         "organs.liver.mesh", "kidney.obj"),
        ("fraction = 0.1", "fraction = 0.1\nwithin = 0.01", "organs.liver.anchors[0].within",
         "0.01"),
        ("fraction = 0.1", "fraction = 2.0", "organs.liver.anchors[0].fraction", "2.0"),
        ('to = "plane"', 'to = "ligament"', "organs.liver.anchors[0].to", "'ligament'"),
        ("stiffness = 100.0", "stifness = 100.0", "organs.liver.stifness", "100.0"),
        ('name = "mini"', 'name = "mini"\n[physics]\ndt = 0.05', "physics.dt", "0.05"),
        ('name = "mini"', 'name = "mini"\n[physics]\nmax_iterations = 0',
         "physics.max_iterations", "0"),
        ('name = "mini"', 'name = "mini"\n[motion]\nbreathing_hz = -0.25',
         "motion.breathing_hz", "-0.25"),
        ("stiffness = 100.0", 'stiffness = 100.0\nbreathing_m = [0.0, "1cm"]',
         "organs.liver.breathing_m", "1cm"),
        ("stiffness = 100.0", 'stiffness = 100.0\nkind = "kidney"', "organs.liver.kind",
         "'kidney'"),
    ],
)
def test_bad_values_are_refused_naming_file_field_and_value(
        tmp_path: Path, old: str, new: str, field: str, value: str) -> None:
    assert old in MINIMAL
    err = error_of(MINIMAL.replace(old, new, 1), tmp_path)
    assert err.field == field
    message = str(err)
    assert "bad.toml" in message and f"field '{field}'" in message
    assert value in message, message


def test_missing_scene_and_bad_toml(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="scene file not found"):
        load_scene(tmp_path / "none.toml")
    err = error_of("name = \n", tmp_path)
    assert "invalid TOML" in str(err)
    err = error_of("[organs.liver]\nmass = 1.0\n", tmp_path)
    assert err.field == "name"
    err = error_of('name = "empty"\n', tmp_path)
    assert err.field == "organs"


def test_a_bad_user_mesh_is_refused_at_build_naming_the_mesh_file(tmp_path: Path) -> None:
    s = trimesh.creation.icosphere(subdivisions=2, radius=0.03)
    trimesh.Trimesh(s.vertices, s.faces[2:], process=False).export(tmp_path / "open.obj")
    path = tmp_path / "scene.toml"
    path.write_text(MINIMAL + '\n[organs.cyst]\nmesh = "open.obj"\nmass = 0.1\n'
                    '[[organs.cyst.anchors]]\nto = "point"\npoint = [0, 0, 0]\nfraction = 0.1\n')
    scene = load_scene(path)
    with pytest.raises(ConfigError, match="boundary edges") as info:
        scene.build()
    assert info.value.file.endswith("open.obj") and info.value.field == "organs.cyst.mesh"


def test_scene_physics_moves_anchors_with_the_motion_and_takes_forces(default: Scene,
                                                                      default_models) -> None:
    still = ScenePhysics(default, default_models)
    pushed = ScenePhysics(default, default_models)
    liver = pushed.models["liver"]
    top = np.argsort(liver.rest[: liver.n_surface, 2])[-20:]
    force = np.zeros((liver.n_nodes, 3))
    force[top, 2] = -1.0 / len(top)  # 1 N down on the liver's top
    for _ in range(50):
        assert all(r.ok for r in still.step().values())
        assert all(r.ok for r in pushed.step({"liver": force}).values())
    t = still.t
    assert t == pytest.approx(0.2)
    for name, model in still.models.items():
        offsets = point_offsets(still.motions[name], model.rest[model.anchors], t)
        np.testing.assert_allclose(still.states[name].x[model.anchors],
                                   model.rest[model.anchors] + offsets, atol=1e-15)
    dz = pushed.states["liver"].x[top, 2] - still.states["liver"].x[top, 2]
    assert dz.mean() < -1e-3  # the push dents the liver by millimetres
    np.testing.assert_array_equal(pushed.states["stomach"].x, still.states["stomach"].x)


def test_with_organ_replaces_or_adds(default: Scene) -> None:
    liver = default.organ("liver")
    stiffer = OrganConfig(**{**liver.__dict__, "breathing_m": (0.0, 0.02, 0.0)})
    scene = with_organ(default, stiffer)
    assert scene.organ("liver").breathing_m == (0.0, 0.02, 0.0)
    assert [o.name for o in scene.organs] == [o.name for o in default.organs]
    extra = OrganConfig(name="liver_copy", mesh="liver")
    assert with_organ(default, extra).organs[-1].name == "liver_copy"
    with pytest.raises(ConfigError, match=re.escape("duplicate organ name 'liver'")):
        Scene("x", organs=(liver, liver))


# -- Plausibility bounds: implausible motion amplitudes, rates and gravity are refused; a
# deformable abdominal wall or an all-kinematic scene too.
LIVER = """
[[organs.liver.anchors]]
to = "plane"
point = [0.0, 0.142, 0.0]
normal = [0.0, -1.0, 0.0]
fraction = 0.1
"""


def scene_text(physics: str = "", motion: str = "", organ: str = "") -> str:
    return (f'name="x"\n[physics]\n{physics}\n[motion]\n{motion}\n[organs.liver]\n{organ}\n'
            + LIVER)


@pytest.mark.parametrize(("kw", "field", "value"), [
    ({"organ": "breathing_m=[0.0,12.0,0.0]"}, "organs.liver.breathing_m", "12.0"),
    ({"organ": "heartbeat_m=[0.0,0.0,0.02]"}, "organs.liver.heartbeat_m", "0.02"),
    ({"motion": "breathing_hz=100.0"}, "motion.breathing_hz", "100.0"),
    ({"motion": "heartbeat_hz=250.0"}, "motion.heartbeat_hz", "250.0"),
    ({"physics": "gravity=[0.0,0.0,-1e6]"}, "physics.gravity", "1000000.0"),
])
def test_implausible_motion_and_gravity_are_refused(kw: dict[str, str], field: str,
                                                    value: str) -> None:
    with pytest.raises(ConfigError) as info:
        parse_scene(scene_text(**kw), source="/x/scene.toml")
    assert info.value.field == field and info.value.file == "/x/scene.toml"
    assert value in str(info.value)


def test_plausible_values_and_still_motion_are_accepted() -> None:
    scene = parse_scene(scene_text(motion="breathing_hz=0.0\nheartbeat_hz=3.0",
                                   organ="breathing_m=[0.0,0.05,0.0]\nheartbeat_m=[0,0,0.01]"))
    assert scene.motion.heartbeat_hz == 3.0


def test_a_deformable_wall_and_an_all_kinematic_scene_are_refused() -> None:
    with pytest.raises(ConfigError, match="must be kinematic") as info:
        parse_scene('name="w"\n[organs.abdominal_wall]\nkinematic=false\n' + LIVER.replace(
            "liver", "abdominal_wall"))
    assert info.value.field == "organs.abdominal_wall.kinematic"
    with pytest.raises(ConfigError, match="deformable organ") as info:
        parse_scene('name="w"\n[organs.liver]\nkinematic=true\nvolume=false\n')
    assert info.value.field == "organs"
