"""The cases of issue #16 item 1: implausible numbers are refused on load, naming the file,
the field, the value and the allowed range (bounds in vasim.core.bounds)."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from vasim.abdomen.meshes import load_user_mesh, mesh_problems
from vasim.abdomen.scene import parse_scene
from vasim.core.errors import ConfigError
from vasim.core.resources import protocols_dir
from vasim.fixtures.schema import parse_schema
from vasim.mrcp.dh import parse_robot
from vasim.study.protocol import parse_protocol

HEAD = 'name = "x"\ndescription = "d"\n'
SRC = "protocols/schemas/ff.toml"


@pytest.mark.parametrize(("body", "field", "shown"), [
    ("max_force_n = 1000", "max_force_n", "got 1000, expected a finite number in (0, 3.3] N"),
    ("[fixtures.ff]\nmax_force_n = 1000", "fixtures.ff.max_force_n", "got 1000"),
    ("[fixtures.ff]\nk = 1e6", "fixtures.ff.k", "got 1000000.0, expected a finite number in "
                                               "[0, 100] N per unit d_norm"),
    ("max_force_n = 1e300", "max_force_n", "got 1e+300"),
    ("[fixtures.ff.f5pl]\na = 0\nb = 1e308\nc = 1\nd = 1", "fixtures.ff.f5pl.b", "(0, 50]"),
    ("scale_m = 1e-300", "scale_m", "[0.001, 0.5] m"),
])
def test_schema_numbers_beyond_the_omni_are_refused(body: str, field: str, shown: str) -> None:
    with pytest.raises(ConfigError) as info:
        parse_schema(HEAD + body, source=SRC)
    assert info.value.file == SRC and info.value.field == field
    assert shown in str(info.value)


PROTO = ('name = "p"\ndescription = "d"\ntask = "trajectory"\n{extra}\n'
         '[[blocks]]\nname = "b"\ncondition = "none"\n{block}\n')


@pytest.mark.parametrize(("extra", "block", "field", "shown"), [
    ("reach_radius_m = 0.5", "", "reach_radius_m", "got 0.5, expected a finite number in "
                                                   "[0.0001, 0.02] m"),
    ("reach_radius_m = 1e300", "", "reach_radius_m", "got 1e+300"),
    ("excessive_force_n = 5.0", "", "excessive_force_n", "(0, 3.3] N"),
    ("max_trial_time_s = inf", "", "max_trial_time_s", "got inf"),
    ("", "repetitions = 100000", "blocks[0].repetitions", "[1, 1000]"),
    ("", "repetitions = 1000\nprobes_after = 1000\nvariants = [0, 1, 2, 3, 4, 5, 6]", "blocks",
     "got 16000, expected at most 10,000 trials per session"),
])
def test_protocol_numbers_are_bounded(extra: str, block: str, field: str, shown: str) -> None:
    text = PROTO.format(extra=extra, block=block)
    if field == "blocks":  # 7 x 1000 + 1000 = 8000 trials pass; two such blocks do not
        text += '[[blocks]]\nname = "c"\ncondition = "none"\n' + block + "\n"
    with pytest.raises(ConfigError) as info:
        parse_protocol(text, source="p.toml")
    assert info.value.file == "p.toml" and info.value.field == field
    assert shown in str(info.value)


def test_scene_mass_of_1e_minus_300_is_refused() -> None:
    with pytest.raises(ConfigError) as info:
        parse_scene('name = "s"\n[organs.liver]\nmass = 1e-300\n', source="s.toml")
    assert info.value.field == "organs.liver.mass"
    assert "got 1e-300, expected a finite number in [0.001, 10] kg" in str(info.value)


def test_a_bom_is_accepted_by_every_loader() -> None:
    root = protocols_dir()
    for folder, load in (("schemas", lambda t, s: parse_schema(t, source=s)),
                         ("studies", lambda t, s: parse_protocol(t, source=s)),
                         ("scenes", lambda t, s: parse_scene(t, source=s)),
                         ("robots", lambda t, s: parse_robot(t, file=s))):
        for p in sorted((root / folder).glob("*.toml")):
            text = p.read_text(encoding="utf-8")
            assert load("\ufeff" + text, str(p)) == load(text, str(p)), p


# -- user meshes -----------------------------------------------------------------------
def _write(tmp_path: Path, vertices: np.ndarray, faces: np.ndarray, name: str) -> Path:
    p = tmp_path / name
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in vertices.tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces.tolist()]
    p.write_text("\n".join(lines) + "\n")
    return p


BALL = trimesh.creation.icosphere(subdivisions=2, radius=0.03)


def test_a_nan_vertex_is_reported_as_non_finite_not_as_a_hole(tmp_path: Path) -> None:
    v = BALL.vertices.copy()
    v[5, 1] = math.nan
    with pytest.raises(ConfigError) as info:
        load_user_mesh(_write(tmp_path, v, BALL.faces, "nan.obj"), field="organs.x.mesh")
    assert "non-finite vertex: vertex 5" in str(info.value)
    assert "not closed" not in str(info.value) and info.value.field == "organs.x.mesh"


def test_a_vertex_at_1e200_is_refused_without_overflow(tmp_path: Path) -> None:
    v = BALL.vertices.copy()
    v[0, 0] = 1e200
    with np.errstate(all="raise"), pytest.raises(ConfigError, match=r"vertex 0 at .*1e\+200"):
        load_user_mesh(_write(tmp_path, v, BALL.faces, "huge.obj"))


def test_a_1e20_mesh_suggests_no_unit(tmp_path: Path) -> None:
    mesh = BALL.copy()
    mesh.apply_scale(1e20 / 0.06)  # a 1e20 m "organ": mm would still be 1e17 m
    problems = mesh_problems(mesh, check_self_intersection=False)
    assert len(problems) == 1 and "no organ in any unit" in problems[0]
    assert 'units="mm"' not in problems[0]
    # 60 (mm) still suggests millimetres
    mesh = BALL.copy()
    mesh.apply_scale(1000.0)
    assert 'pass units="mm"' in mesh_problems(mesh, check_self_intersection=False)[0]


def test_a_09_m_organ_is_refused(tmp_path: Path) -> None:
    big = BALL.vertices * 15.0  # 0.9 m across: larger than the abdominal cavity
    with pytest.raises(ConfigError, match=r"extent 0\.9 m is larger than any organ"):
        load_user_mesh(_write(tmp_path, big, BALL.faces, "big.obj"))
    off = BALL.vertices + np.array([0.6, 0.0, 0.0])  # organ-sized, outside the abdomen
    with pytest.raises(ConfigError, match=r"outside \[-0\.5, 0\.5\] m"):
        load_user_mesh(_write(tmp_path, off, BALL.faces, "off.obj"))
    assert len(load_user_mesh(_write(tmp_path, BALL.vertices, BALL.faces, "ok.obj")).vertices
               ) == len(BALL.vertices)


# -- command line ---------------------------------------------------------------------
def test_serve_refuses_a_bad_host_before_the_exposure_warning() -> None:
    p = subprocess.run([sys.executable, "-m", "vasim", "serve", "--host", "999.1.1.1",
                        "--duration", "1"], capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and "warning" not in p.stderr
    assert p.stderr.count("\n") == 1 and "got '999.1.1.1', expected an IP address" in p.stderr


@pytest.mark.parametrize(("argv", "needle"), [
    (["study", "simulate", "--protocol", "p", "--db", "x", "--subjects", "1000000000"],
     "got 1000000000, expected an integer in [1, 10000]"),
    (["study", "simulate", "--protocol", "p", "--db", "x", "--workers", "1000"],
     "got 1000, expected an integer in [0, "),
    (["trial", "--variant", "7"], "got 7, expected an integer in [0, 6]"),
    (["serve", "--port", "70000"], "got 70000, expected an integer in [0, 65535]"),
])
def test_cli_numbers_are_refused_at_parse_time(argv: list[str], needle: str, capsys) -> None:
    from vasim.cli import main

    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err
