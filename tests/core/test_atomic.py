"""Atomic files and folders: a killed writer leaves the old complete set or the new one."""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from vasim.core.atomic import atomic_file, atomic_folder, exchange
from vasim.core.errors import ConfigError


def test_atomic_file_replaces_only_on_success(tmp_path: Path) -> None:
    target = tmp_path / "a.bin"
    target.write_bytes(b"old")
    with pytest.raises(RuntimeError), atomic_file(target) as fh:
        fh.write(b"half")
        raise RuntimeError("killed mid-write")
    assert target.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["a.bin"]  # no temporary left
    with atomic_file(target) as fh:
        fh.write(b"new")
    assert target.read_bytes() == b"new"
    with pytest.raises(ValueError, match="no 'w'"), atomic_file(target, "rb"):
        pass


def _owned(rel: Path) -> bool:
    return rel.name in {"manifest.json", "data.bin"} or rel.parts[0] == "tables"


def test_atomic_folder_swaps_complete_sets(tmp_path: Path) -> None:
    out = tmp_path / "export"
    with atomic_folder(out, owned=_owned) as tmp:
        (tmp / "data.bin").write_bytes(b"v1")
        (tmp / "tables").mkdir()
        (tmp / "tables" / "t.csv").write_text("a\n1\n")
    assert (out / "data.bin").read_bytes() == b"v1"
    with pytest.raises(KeyError), atomic_folder(out, owned=_owned) as tmp:
        (tmp / "data.bin").write_bytes(b"v2-partial")
        raise KeyError("the writer failed")
    assert (out / "data.bin").read_bytes() == b"v1"           # old set intact
    with atomic_folder(out, owned=_owned) as tmp:
        (tmp / "data.bin").write_bytes(b"v2")
    assert (out / "data.bin").read_bytes() == b"v2"
    assert not (out / "tables").exists()                      # the whole set was replaced
    assert sorted(p.name for p in tmp_path.iterdir()) == ["export"]  # nothing left over


def test_atomic_folder_keeps_files_it_did_not_write(tmp_path: Path) -> None:
    out = tmp_path / "mine"
    (out / "sub").mkdir(parents=True)
    (out / "thesis.docx").write_text("precious")
    (out / "sub" / "notes.txt").write_text("mine too")
    (out / "data.bin").write_bytes(b"old")
    with atomic_folder(out, owned=_owned, what="export") as tmp:
        (tmp / "data.bin").write_bytes(b"new")
    assert (out / "thesis.docx").read_text() == "precious"
    assert (out / "sub" / "notes.txt").read_text() == "mine too"
    assert (out / "data.bin").read_bytes() == b"new"
    # A writer that would produce a file of the user's name refuses instead.
    with pytest.raises(ConfigError, match=r"thesis\.docx"), \
            atomic_folder(out, owned=_owned, what="export") as tmp:
        (tmp / "thesis.docx").write_text("clobber")
    assert (out / "thesis.docx").read_text() == "precious"
    (tmp_path / "file").write_text("x")
    not_a_folder = r"\(exists and is not a folder\), expected the output folder"
    with pytest.raises(ConfigError, match=not_a_folder), \
            atomic_folder(tmp_path / "file", owned=_owned):
        pass


def test_exchange_is_atomic_here(tmp_path: Path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    (a / "x").write_text("a")
    (b / "x").write_text("b")
    if sys.platform.startswith("linux"):
        assert exchange(a, b)
        assert (a / "x").read_text() == "b" and (b / "x").read_text() == "a"


_WRITER = r"""
import hashlib, json, os, sys
from pathlib import Path
from vasim.core.atomic import atomic_folder
out = Path(sys.argv[1])
owned = lambda rel: rel.name in {"manifest.json", "a.bin", "b.bin"}
for version in range(1, 10**6):
    with atomic_folder(out, owned=owned) as tmp:
        files = {}
        for name in ("a.bin", "b.bin"):
            data = os.urandom(3 << 20)
            (tmp / name).write_bytes(data)
            files[name] = hashlib.sha256(data).hexdigest()
        (tmp / "manifest.json").write_text(json.dumps({"version": version, "files": files}))
    print(version, flush=True)
"""


def _complete(out: Path) -> int:
    manifest = json.loads((out / "manifest.json").read_text())
    for name, digest in manifest["files"].items():
        assert hashlib.sha256((out / name).read_bytes()).hexdigest() == digest, name
    return int(manifest["version"])


def test_sigkill_during_writes_leaves_a_complete_set(tmp_path: Path) -> None:
    out = tmp_path / "set"
    seen: list[int] = []
    for delay in (0.0, 0.05, 0.1, 0.2, 0.3):
        child = subprocess.Popen([sys.executable, "-c", _WRITER, str(out)],
                                 stdout=subprocess.PIPE, text=True)
        try:
            assert child.stdout is not None
            child.stdout.readline()    # one set is complete; the next one is being written
            time.sleep(delay)
        finally:
            os.kill(child.pid, signal.SIGKILL)
            child.wait(timeout=30)
        seen.append(_complete(out))    # old or new, never mixed
    assert len(seen) == 5
