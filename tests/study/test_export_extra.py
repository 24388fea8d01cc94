"""Parquet export is the ``parquet`` extra (vasim/study/export.py, vasim/core/extras.py;
issue #27 item 1): without pyarrow a Parquet export is one line naming the extra, before
anything is written, and CSV export needs nothing."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from vasim.core.extras import MissingExtraError, require
from vasim.study.export import read_export
from vasim.study.store import TrialStore

BLOCK = "import sys; sys.modules['pyarrow'] = None; "
"""Makes ``import pyarrow`` fail in a fresh interpreter, before pandas looks for it (pandas
picks its string storage at import, so pyarrow cannot be hidden from this process)."""


def _without_pyarrow(code: str, tmp_path: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", BLOCK + code], capture_output=True,
                          text=True, timeout=300, cwd=tmp_path, check=False)


@pytest.fixture
def db(tmp_path: Path) -> Path:
    path = tmp_path / "s.db"
    with TrialStore(path) as st:
        st.add_subject("S01")
    return path


def test_parquet_without_pyarrow_is_one_line_naming_the_extra(db: Path,
                                                              tmp_path: Path) -> None:
    out = tmp_path / "out"
    cli = (f"from vasim.cli import main; sys.exit(main(['study', 'export', '--db', "
           f"{str(db)!r}, '--out', {str(out)!r}, '--format', 'csv,parquet']))")
    r = _without_pyarrow(cli, tmp_path)
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "Parquet export needs the 'parquet' extra" in r.stderr, r.stderr
    assert "pip install 'vasim[parquet]'" in r.stderr
    assert not out.exists()                      # refused before anything was written
    api = ("from vasim.study.export import export_study; from vasim.core.extras import "
           f"MissingExtraError, installed; assert not installed('pyarrow')\n"
           f"try:\n    export_study({str(db)!r}, {str(out)!r}, formats=('parquet',))\n"
           "except MissingExtraError as e:\n    print('missing', e.extra)\n"
           # CSV needs no extra
           f"export_study({str(db)!r}, {str(out)!r}, formats=('csv',), tables=('subjects',))")
    r = _without_pyarrow(api, tmp_path)
    assert r.returncode == 0 and r.stdout.strip() == "missing parquet", r.stderr
    assert read_export(out, "subjects", "csv")["subject"].tolist() == ["S01"]


def test_a_broken_module_inside_an_extra_is_not_called_missing(
        monkeypatch: pytest.MonkeyPatch) -> None:
    import pyarrow  # noqa: F401  (installed with the test dependencies: the parquet extra)
    # pyarrow is installed but one of its modules fails: the real error, not "install it"
    for name in [m for m in sys.modules if m.startswith(("pyarrow.parquet", "pyarrow._parquet"))]:
        monkeypatch.delitem(sys.modules, name)     # pyarrow.parquet and what it imported
    monkeypatch.setitem(sys.modules, "pyarrow._parquet", None)
    with pytest.raises(ImportError) as err:
        require("pyarrow.parquet", "Parquet export")
    assert not isinstance(err.value, MissingExtraError)
