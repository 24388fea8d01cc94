"""Read-only stores (issue #16 item 4): listing, export and report open a database
``mode=ro`` and work on a read-only file in a read-only folder; writing commands on a
read-only file are one-line ``StoreError`` s; ``vasim serve --db`` checks the file first.

The suite runs as root, for whom ``chmod`` forbids nothing, and the interpreter lives where
user ``nobody`` cannot run it (``setpriv --reuid nobody`` fails with "Permission denied"),
so the checks are: the files are made read-only with ``chmod`` (444 file, 555 folder),
every SQLite connection the command opens is recorded and must be a ``mode=ro`` URI, and
the database's bytes must be unchanged afterwards. Where root's permissions would let a
write through, the permission check itself is simulated (``os.access`` answering "not
writable" for that file), and a genuinely read-only SQLite connection is used for the
error path of a write.
"""

from __future__ import annotations

import hashlib
import os
import sqlite3
import stat
import subprocess
import sys
from pathlib import Path

import pytest

import vasim.study.store.connection as connection_mod
from vasim.cli import main
from vasim.core.errors import StoreError
from vasim.records.trial_meta import TrialMeta
from vasim.study.protocol import parse_protocol
from vasim.study.session import run_session, start_session
from vasim.study.store import TrialStore

PROTOCOL = """
name = "ro"
description = "one short trial"
task = "trajectory"
max_trial_time_s = 0.05
[[blocks]]
name = "b"
condition = "none"
probe = true
counterbalance = false
"""


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


@pytest.fixture
def ro_db(tmp_path: Path):
    """A study database with one completed session and one stale 'running' trial (its
    writer is dead), then made read-only: file 444 in a folder 555."""
    folder = tmp_path / "ro"
    folder.mkdir()
    db = folder / "study.sqlite"
    with TrialStore(db) as st:
        sid = start_session(st, parse_protocol(PROTOCOL), "S01", seed=1)
        run_session(st, sid, progress=False)
        stale = st.begin_trial(TrialMeta(subject="S01", task="trajectory", pid=dead_pid()))
    for extra in folder.glob("study.sqlite-*"):  # a clean close leaves none; be sure
        extra.unlink()
    db.chmod(0o444)
    folder.chmod(0o555)
    yield db, stale
    folder.chmod(0o755)
    db.chmod(0o644)


@pytest.fixture
def connects(monkeypatch):
    """Every ``sqlite3.connect`` target (path or URI) opened while the test runs."""
    seen: list[str] = []
    real = sqlite3.connect

    def spy(database, *args, **kwargs):
        seen.append(str(database))
        return real(database, *args, **kwargs)

    monkeypatch.setattr(connection_mod.sqlite3, "connect", spy)
    return seen


def _assert_read_only_opens(seen: list[str], db: Path) -> None:
    mine = [s for s in seen if db.name in s]
    assert mine, "the command opened no connection to the database"
    assert all(s.startswith("file:") and "mode=ro" in s for s in mine), mine


def test_the_files_are_read_only(ro_db):
    db, _ = ro_db
    assert stat.S_IMODE(db.stat().st_mode) == 0o444
    assert stat.S_IMODE(db.parent.stat().st_mode) == 0o555


def test_study_list_reads_a_read_only_store_and_says_it_cannot_recover(ro_db, connects,
                                                                       capsys):
    db, stale = ro_db
    before = _sha(db)
    assert main(["study", "list", "--db", str(db)]) == 0
    out, err = capsys.readouterr()
    assert "S01" in out and "completed" in out
    lines = [ln for ln in err.splitlines() if "stale" in ln]
    assert len(lines) == 1
    assert f"({stale})" in lines[0] and "not marked interrupted" in lines[0]
    assert str(db) in lines[0]
    _assert_read_only_opens(connects, db)
    assert _sha(db) == before
    with TrialStore(db, readonly=True) as st:  # still 'running': nothing was written
        assert st.trial(stale)["status"] == "running" and st.stale == [stale]


def test_study_export_reads_a_read_only_store(ro_db, connects, tmp_path: Path, capsys):
    db, _ = ro_db
    before = _sha(db)
    assert main(["study", "export", "--db", str(db), "--out", str(tmp_path / "out"),
                 "--no-progress"]) == 0
    assert "written to" in capsys.readouterr().out
    assert (tmp_path / "out" / "trials.csv").read_text().count("\n") == 1 + 2
    _assert_read_only_opens(connects, db)
    assert _sha(db) == before


def test_report_reads_a_read_only_store(ro_db, connects, tmp_path: Path, capsys):
    db, _ = ro_db
    before = _sha(db)
    assert main(["report", "--db", str(db), "--out", str(tmp_path / "rep"),
                 "--no-progress"]) == 0
    assert (tmp_path / "rep" / "index.html").is_file()
    _assert_read_only_opens(connects, db)
    assert _sha(db) == before


def test_a_read_only_folder_without_wal_files_is_read_as_immutable(tmp_path: Path,
                                                                    monkeypatch):
    # What a non-root reader meets: SQLite cannot create the -shm file beside the database.
    db = tmp_path / "s.sqlite"
    with TrialStore(db) as st:
        st.add_subject("S01")
    real = sqlite3.connect
    opened: list[str] = []

    def no_shm(database, *args, **kwargs):
        opened.append(str(database))
        if "immutable=1" not in str(database):
            raise sqlite3.OperationalError("unable to open database file")
        return real(database, *args, **kwargs)

    monkeypatch.setattr(connection_mod.sqlite3, "connect", no_shm)
    monkeypatch.setattr(connection_mod.os, "access", lambda p, mode: False)
    with TrialStore(db, readonly=True) as st:
        assert st.subjects()["code"].tolist() == ["S01"]
    assert opened[-1].endswith("?mode=ro&immutable=1")


# ------------------------------------------------------------------------- writers
@pytest.fixture
def not_writable(monkeypatch):
    """``os.access`` in the store answers "not writable" for files named ``*.sqlite``
    (root may write anything; a real user would get this answer for a 444 file)."""
    real = os.access

    def access(path, mode):
        if str(path).endswith(".sqlite") and mode & os.W_OK:
            return False
        return real(path, mode)

    monkeypatch.setattr(connection_mod.os, "access", access)


@pytest.mark.parametrize("argv", [
    ["trial", "--schema", "ff", "--max-time", "0.05", "--scene", "none"],
    ["study", "run", "--protocol", "vf_learning_curve", "--subject", "S02", "--seed", "1",
     "--no-progress"],
])
def test_writing_commands_on_a_read_only_file_are_one_line_errors(ro_db, not_writable,
                                                                  argv, capsys):
    db, _ = ro_db
    before = _sha(db)
    assert main([*argv, "--db", str(db)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert str(db) in err and "read-only" in err
    assert "OperationalError" not in err and "Traceback" not in err
    assert _sha(db) == before


def test_a_write_through_a_read_only_connection_is_a_store_error(tmp_path: Path,
                                                                 monkeypatch):
    db = tmp_path / "s.sqlite"
    TrialStore(db).close()
    st = TrialStore(db)
    st.close()
    # the connection SQLite gives when it could only open the file read-only
    st._con = sqlite3.connect(connection_mod.readonly_uri(db), uri=True, isolation_level=None)
    for write in (lambda: st.begin_trial(TrialMeta(subject="S01", task="trajectory")),
                  lambda: st.add_subject("S01")):
        with pytest.raises(StoreError, match="cannot be written") as e:
            write()
        assert str(db) in str(e.value)
        assert isinstance(e.value.__cause__, sqlite3.OperationalError)
    st.close()


def test_a_read_only_store_refuses_recovery_writes(ro_db):
    db, stale = ro_db
    with TrialStore(db, readonly=True) as st:
        with pytest.raises(StoreError, match="read-only"):
            st.recover_interrupted()
        with pytest.raises(StoreError, match="read-only"):
            st.mark_interrupted(stale)


# --------------------------------------------------------------------------- serve
def test_serve_refuses_a_garbage_database_before_the_server_starts(tmp_path: Path,
                                                                   monkeypatch, capsys):
    import vasim.viewer.app as app_mod

    def never(*a, **k):
        raise AssertionError("the viewer was started")

    monkeypatch.setattr(app_mod, "ViewerApp", never)
    garbage = tmp_path / "garbage.sqlite"
    garbage.write_bytes(b"this is not a database" * 100)
    assert main(["serve", "--db", str(garbage), "--port", "0", "--duration", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert str(garbage) in err and len(err.splitlines()) == 1
