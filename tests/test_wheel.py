"""The wheel installs and runs outside the checkout (issue #14 item 5).

Builds the wheel from a copy of the checkout with the venv's own setuptools (no network,
no build isolation), installs it with ``--no-deps --no-index`` into a fresh virtualenv in a
temp folder whose dependencies come from this venv's site-packages through a ``.pth`` file,
and runs the ``vasim`` script from a temp folder: the shipped protocols must come from the
installed ``vasim.protocols`` package data, and a user folder must overlay them.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import venv
import zipfile
from pathlib import Path

import pytest
import setuptools

ROOT = Path(__file__).resolve().parent.parent


def test_package_list_matches_the_packages_on_disk() -> None:
    """``[tool.setuptools] packages`` is explicit (for ``vasim.protocols``): no package may
    be missing from it, else the wheel would lack modules."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    listed = set(config["tool"]["setuptools"]["packages"])
    on_disk = set(setuptools.find_packages(where=str(ROOT), include=["vasim", "vasim.*"]))
    assert listed == on_disk | {"vasim.protocols"}
    assert config["tool"]["setuptools"]["package-dir"] == {"vasim.protocols": "protocols"}


def _run(args: list[str], *, cwd: Path, env: dict[str, str], timeout: float = 120) -> str:
    proc = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout, check=False)
    assert proc.returncode == 0, (
        f"{' '.join(args)} exited {proc.returncode}\nstdout:\n{proc.stdout}\n"
        f"stderr:\n{proc.stderr}")
    return proc.stdout


def _copy_checkout(dest: Path) -> Path:
    """Copies what the build reads (the build writes build/ and egg-info beside the sources,
    so the checkout itself stays untouched)."""
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info", "build")
    for name in ("vasim", "protocols"):
        shutil.copytree(ROOT / name, dest / name, ignore=ignore)
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, dest / name)
    return dest


def _fresh_venv(home: Path) -> tuple[Path, dict[str, str]]:
    """A virtualenv without pip whose dependencies (and pip) come from the venv running the
    tests, appended to sys.path after its own site-packages (so what is installed into it
    wins); returns its ``bin`` folder and an environment without this checkout on the path
    and with an empty user config folder."""
    venv.EnvBuilder(with_pip=False).create(home)
    purelib = Path(sysconfig.get_paths(vars={"base": str(home), "platbase": str(home)})
                   ["purelib"])
    (purelib / "_shared_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "VASIM_PROTOCOLS", "VIRTUAL_ENV")}
    env["XDG_CONFIG_HOME"] = str(home / "xdg")
    return home / "bin", env


def _pip_install(bindir: Path, env: dict[str, str], *target: str) -> None:
    _run([str(bindir / "python"), "-m", "pip", "install", "--no-deps", "--no-index",
          "--no-build-isolation", "--ignore-installed", "--quiet", *target],
         cwd=bindir.parent, env=env, timeout=300)


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The wheel built from a copy of the checkout."""
    src = _copy_checkout(tmp_path_factory.mktemp("src"))
    out = tmp_path_factory.mktemp("wheelhouse")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
          "--no-index", "--quiet", "-w", str(out), str(src)], cwd=out, env=env, timeout=300)
    wheels = sorted(out.glob("vasim-*.whl"))
    assert len(wheels) == 1, wheels
    return wheels[0]


def test_wheel_ships_the_protocols(wheel: Path) -> None:
    names = set(zipfile.ZipFile(wheel).namelist())
    shipped = {f"vasim/protocols/{p.relative_to(ROOT / 'protocols').as_posix()}"
               for p in (ROOT / "protocols").rglob("*.toml")}
    assert shipped and shipped <= names, sorted(shipped - names)
    assert "vasim/protocols/studies/vf_learning_curve.toml" in names
    assert "vasim/py.typed" in names
    assert not any(n.startswith("protocols/") for n in names)


@pytest.fixture(scope="module")
def installed(wheel: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, str]]:
    """A fresh virtualenv outside the checkout with the wheel installed: returns its ``bin``
    folder and the environment to run it in."""
    bindir, env = _fresh_venv(tmp_path_factory.mktemp("venv"))
    _pip_install(bindir, env, str(wheel))
    return bindir, env


def test_editable_install_serves_the_checkout_protocols(tmp_path: Path) -> None:
    """``make install`` (``pip install -e``): both the resolver and importlib.resources find
    the checkout's top-level protocols/ from another folder."""
    src = _copy_checkout(tmp_path / "src")
    bindir, env = _fresh_venv(tmp_path / "venv")
    _pip_install(bindir, env, "-e", str(src))
    run_dir = tmp_path / "elsewhere"
    run_dir.mkdir()
    out = _run([str(bindir / "python"), "-c",
                "import vasim, vasim.core.resources as r, importlib.resources as ir; "
                "print(vasim.__file__); print(r.protocols_dir()); "
                "print(ir.files('vasim.protocols'))"], cwd=run_dir, env=env)
    module, protocols, package = (Path(line) for line in out.split())
    assert module == src / "vasim" / "__init__.py"
    assert protocols == src / "protocols"
    assert package == src / "protocols"


def test_installed_vasim_is_the_wheel(installed: tuple[Path, dict[str, str]],
                                      tmp_path: Path) -> None:
    bindir, env = installed
    out = _run([str(bindir / "python"), "-c",
                "import vasim, vasim.core.resources as r; "
                "print(vasim.__file__); print(r.protocols_dir())"], cwd=tmp_path, env=env)
    module, protocols = (Path(line) for line in out.split())
    venv_root = bindir.parent.resolve()
    assert module.resolve().is_relative_to(venv_root), module
    assert protocols.resolve().is_relative_to(venv_root), protocols
    assert protocols.name == "protocols" and protocols.parent.name == "vasim"
    assert not module.resolve().is_relative_to(ROOT)


def test_schemas_list_includes_a_user_schema(installed: tuple[Path, dict[str, str]],
                                             tmp_path: Path) -> None:
    bindir, env = installed
    out = _run([str(bindir / "vasim"), "schemas", "list"], cwd=tmp_path, env=env)
    names = [line.split()[0] for line in out.splitlines() if line.strip()]
    shipped = sorted(p.stem for p in (ROOT / "protocols" / "schemas").glob("*.toml"))
    assert names == shipped
    # A schema in the user folder ($XDG_CONFIG_HOME/vasim/protocols/schemas) is listed too.
    user = Path(env["XDG_CONFIG_HOME"]) / "vasim" / "protocols" / "schemas"
    user.mkdir(parents=True)
    try:
        text = (ROOT / "protocols" / "schemas" / "ms.toml").read_text(encoding="utf-8")
        (user / "my_ms.toml").write_text(text.replace('name = "ms"', 'name = "my_ms"'),
                                         encoding="utf-8")
        out = _run([str(bindir / "vasim"), "schemas", "list"], cwd=tmp_path, env=env)
        names = [line.split()[0] for line in out.splitlines() if line.strip()]
        assert names == sorted([*shipped, "my_ms"])
    finally:
        shutil.rmtree(user.parent)


def test_study_schedule_runs(installed: tuple[Path, dict[str, str]], tmp_path: Path) -> None:
    bindir, env = installed
    out = _run([str(bindir / "vasim"), "study", "schedule", "--protocol", "vf_learning_curve",
                "--seed", "1"], cwd=tmp_path, env=env)
    lines = out.splitlines()
    assert lines[0] == "vf_learning_curve: 38 trials, seed 1"
    rows = [line.split() for line in lines[2:40]]
    assert [int(r[0]) for r in rows] == list(range(38))
    assert lines[41].startswith("block order: Williams sequence 2 of 10")
    assert rows[0][1:3] == ["baseline", "none"]


def test_short_trial_runs(installed: tuple[Path, dict[str, str]], tmp_path: Path) -> None:
    bindir, env = installed
    out = _run([str(bindir / "vasim"), "trial", "--scene", "none", "--max-time", "2",
                "--schema", "none", "--seed", "1"], cwd=tmp_path, env=env)
    fields = {line[:18].strip(): line[18:].strip() for line in out.splitlines()}
    assert fields["duration"] == "2.00 s"                 # not a completion time: ...
    assert fields["outcome"].startswith("timed out after 2.0 s with")  # ... it timed out
    assert fields["samples"] == "2000 at 1000 Hz"
    assert fields["schema"] == "none [no fixtures]"
