"""Two tiny protocols for tests that run whole sessions in seconds (``TINY``, ``RETENTION``:
the #30 round's, ``bench/bad_inputs.py``), :func:`install` to offer them as shipped
protocols for one test (the viewer offers only shipped protocols) and :func:`session_rows`
to read a store's sessions back."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

from bench.bad_inputs import RETENTION, TINY, protocols_folder


def install(monkeypatch: pytest.MonkeyPatch, folder: Path, **texts: str) -> Path:
    """Makes ``folder`` the shipped protocols' folder for the test, holding the shipped
    protocols and ``texts`` (file stem -> TOML text); returns the folder."""
    import vasim.study.protocol.loader as loader

    protocols_folder(folder, **texts)
    monkeypatch.setattr(loader, "studies_dir", lambda: folder)
    return folder


def session_rows(db: Path) -> list[tuple[int, str, str, str | None]]:
    """``(id, subject, status, notes)`` of every session in the store ``db``, by id."""
    con = sqlite3.connect(db)
    try:
        return con.execute("SELECT id, subject, status, notes FROM sessions ORDER BY id"
                           ).fetchall()
    finally:
        con.close()


__all__ = ["RETENTION", "TINY", "install", "session_rows"]
