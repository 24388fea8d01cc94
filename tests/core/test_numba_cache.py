"""A read-only install still runs: numba's kernel cache goes to a writable folder."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from vasim.core import numba_cache


def _unwritable(tmp_path: Path, name: str) -> Path:
    """A folder that cannot be created even by root: its parent is a regular file."""
    blocker = tmp_path / f"{name}.file"
    blocker.write_text("not a folder")
    return blocker / name


def test_writable_dir_tells_a_folder_from_one_under_a_file(tmp_path: Path) -> None:
    assert numba_cache.writable_dir(tmp_path / "a" / "b")
    assert (tmp_path / "a" / "b").is_dir()
    assert not numba_cache.writable_dir(_unwritable(tmp_path, "x"))


def test_nothing_changes_when_the_package_folder_is_writable(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("NUMBA_CACHE_DIR", "")   # registers the undo: the code sets it
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    monkeypatch.setattr(numba_cache, "_PACKAGE", tmp_path / "vasim")
    assert numba_cache.configure_numba_cache() is None
    assert "NUMBA_CACHE_DIR" not in os.environ


def test_a_user_set_cache_dir_is_respected(tmp_path: Path,
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "mine"))
    monkeypatch.setattr(numba_cache, "_PACKAGE", _unwritable(tmp_path, "vasim"))
    assert numba_cache.configure_numba_cache() is None
    assert os.environ["NUMBA_CACHE_DIR"] == str(tmp_path / "mine")


def test_read_only_install_and_home_fall_back_to_the_user_folder_then_temp(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("NUMBA_CACHE_DIR", "")   # registers the undo: the code sets it
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    monkeypatch.setattr(numba_cache, "_PACKAGE", _unwritable(tmp_path, "vasim"))
    # numba's own user-wide folder is unwritable, vasim's user folder too: temp is used.
    monkeypatch.setenv("XDG_CACHE_HOME", str(_unwritable(tmp_path, "cache")))
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    chosen = numba_cache.configure_numba_cache()
    assert chosen == tmp_path / "tmp" / f"vasim-numba-{os.getuid()}"
    assert os.environ["NUMBA_CACHE_DIR"] == str(chosen)
    assert "read-only" in capsys.readouterr().err
    # With a writable XDG cache, numba's own user-wide cache works: nothing to change.
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert numba_cache.configure_numba_cache() is None


def test_an_unwritable_user_set_cache_dir_is_replaced_when_nothing_else_is_writable(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Issue #30 item 5: NUMBA_CACHE_DIR=<read-only folder> on a read-only install made the
    import fail ("cannot cache function"); now a writable folder is used and named."""
    mine = _unwritable(tmp_path, "mine")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(mine))
    monkeypatch.setattr(numba_cache, "_PACKAGE", _unwritable(tmp_path, "vasim"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(_unwritable(tmp_path, "cache")))
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    chosen = numba_cache.configure_numba_cache()
    assert chosen == tmp_path / "tmp" / f"vasim-numba-{os.getuid()}"
    assert os.environ["NUMBA_CACHE_DIR"] == str(chosen)
    err = capsys.readouterr().err
    assert f"NUMBA_CACHE_DIR={mine} is not a writable folder" in err and str(chosen) in err
    # the same unwritable setting beside a writable install: numba's in-tree cache takes
    # over by itself, so the user's setting is left alone
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(mine))
    monkeypatch.setattr(numba_cache, "_PACKAGE", tmp_path / "vasim")
    assert numba_cache.configure_numba_cache() is None
    assert os.environ["NUMBA_CACHE_DIR"] == str(mine)


_RO_SCRIPT = """
set -e
mount --bind "$PKG" "$PKG" && mount -o remount,bind,ro "$PKG"
mount --bind "$HOMEDIR" "$HOMEDIR" && mount -o remount,bind,ro "$HOMEDIR"
export HOME="$HOMEDIR"; unset NUMBA_CACHE_DIR XDG_CACHE_HOME
"$PY" -m vasim --version
"$PY" -c "import vasim.abdomen.integrate; print('kernels imported')"
mkdir -p "$ROCACHE" && mount --bind "$ROCACHE" "$ROCACHE" && mount -o remount,bind,ro "$ROCACHE"
NUMBA_CACHE_DIR="$ROCACHE" "$PY" -c "import vasim.abdomen.integrate; \
print('read-only NUMBA_CACHE_DIR: kernels imported')"
"""


def test_vasim_runs_from_a_read_only_install(tmp_path: Path) -> None:
    """The real case: package folder and home mounted read-only (a private mount namespace,
    so nothing outside the test changes). Before the fix: "cannot cache function
    'spring_forces': no locator available"."""
    if shutil.which("unshare") is None or subprocess.run(
            ["unshare", "-rm", "true"], capture_output=True, check=False).returncode != 0:
        pytest.skip("needs unshare -rm (user + mount namespaces) to mount the install "
                    "read-only")
    import vasim

    home = tmp_path / "home"
    home.mkdir()
    env = dict(os.environ, PKG=str(Path(vasim.__file__).parent), HOMEDIR=str(home),
               PY=sys.executable, TMPDIR=str(tmp_path), ROCACHE=str(tmp_path / "rocache"))
    proc = subprocess.run(["unshare", "-rm", "sh", "-c", _RO_SCRIPT], env=env,
                          capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "vasim 0.1.0" in proc.stdout
    assert "kernels imported" in proc.stdout
    assert "compiled kernels are cached in" in proc.stderr
    assert "read-only NUMBA_CACHE_DIR: kernels imported" in proc.stdout  # issue #30 item 5
    assert f"NUMBA_CACHE_DIR={tmp_path / 'rocache'} is not a writable folder" in proc.stderr
