"""A killed re-export leaves the previous complete export or the new one (issue #16 §3).

Before: files were written in place, so a SIGKILL during a re-export left the old
``manifest.json`` beside a truncated ``samples.csv`` and an unreadable
``samples.parquet``.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from vasim.core.errors import ConfigError
from vasim.study.export import export_study, read_export
from vasim.study.store import TrialStore
from vasim.trials.registry import run_trial
from vasim.trials.vf import TrialConfig


@pytest.fixture(scope="module")
def db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("export") / "study.sqlite"
    with TrialStore(path) as st:
        for seed in range(3):
            run_trial(TrialConfig(schema="ff", seed=seed, scene="none", max_time=4.0), st)
    return path


def _check_complete(out: Path) -> str:
    """Every table the manifest lists reads back with the row count it states."""
    manifest = json.loads((out / "manifest.json").read_text())
    for table, info in manifest["tables"].items():
        for fmt in info["files"]:
            assert len(read_export(out, table, fmt)) == info["rows"], (table, fmt)
    return str(manifest["exported_at"])


def test_a_sigkilled_re_export_leaves_a_complete_set(db: Path, tmp_path: Path) -> None:
    out = tmp_path / "export"
    export_study(db, out, formats=("csv", "parquet"))
    stamps = {_check_complete(out)}
    code = ("import sys; from vasim.study.export import export_study\n"
            "while True: export_study(sys.argv[1], sys.argv[2], formats=('csv', 'parquet'))")
    for delay in (0.8, 1.2, 1.6, 2.0, 2.6):
        child = subprocess.Popen([sys.executable, "-c", code, str(db), str(out)])
        try:
            time.sleep(delay)
        finally:
            os.kill(child.pid, signal.SIGKILL)
            child.wait(timeout=30)
        stamps.add(_check_complete(out))     # old or new: never a mixture
    leftovers = [p.name for p in tmp_path.iterdir() if p.name != "export"]
    assert len(leftovers) <= 1  # at most the temporary folder of the last killed run
    export_study(db, out, formats=("csv",))  # the next export cleans up after it
    assert [p.name for p in tmp_path.iterdir()] == ["export"]
    assert sorted(p.suffix for p in out.iterdir()) == [".csv"] * 8 + [".json"]


def test_an_export_never_deletes_files_it_did_not_write(db: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    (out / "trials.csv").write_text("an old export's table")
    export_study(db, out)
    assert (out / "notes.txt").read_text() == "mine"                   # kept
    assert (out / "trials.csv").read_text() != "an old export's table"  # replaced
    with pytest.raises(ConfigError, match="is not a folder"):
        export_study(db, out / "notes.txt")
