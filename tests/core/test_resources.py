"""Data-file lookup: shipped protocols overlaid by $VASIM_PROTOCOLS and the user folder."""

from __future__ import annotations

from pathlib import Path

import pytest

from vasim.core.errors import ConfigError
from vasim.core.resources import (
    available_files,
    data_file,
    protocols_dir,
    schemas_dir,
    studies_dir,
    user_protocols_dir,
)
from vasim.study.protocol import load_protocol

ROOT = Path(__file__).resolve().parent.parent.parent


@pytest.fixture(autouse=True)
def _no_user_overrides(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.delenv("VASIM_PROTOCOLS", raising=False)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))


def _write(folder: Path, name: str, text: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_shipped_folder_is_the_checkout_protocols() -> None:
    assert protocols_dir() == ROOT / "protocols"
    shipped = tuple(sorted(p.stem for p in (ROOT / "protocols" / "studies").glob("*.toml")))
    assert available_files(studies_dir()) == shipped


def test_user_folder_follows_xdg(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    assert user_protocols_dir() == tmp_path / "config" / "vasim" / "protocols"
    monkeypatch.delenv("XDG_CONFIG_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert user_protocols_dir() == tmp_path / "home" / ".config" / "vasim" / "protocols"


def test_env_then_user_then_shipped(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    shipped = available_files(schemas_dir())
    user = _write(user_protocols_dir() / "schemas", "mine", "# user\n")
    user_ms = _write(user_protocols_dir() / "schemas", "ms", "# user ms\n")
    env_ms = _write(tmp_path / "env" / "schemas", "ms", "# env ms\n")
    # the user folder alone: its own file and its replacement of a shipped one
    assert data_file("mine", schemas_dir(), "schema") == user
    assert data_file("ms", schemas_dir(), "schema") == user_ms
    assert available_files(schemas_dir()) == tuple(sorted({*shipped, "mine"}))
    # $VASIM_PROTOCOLS comes first; names it lacks fall through to the user, then shipped
    monkeypatch.setenv("VASIM_PROTOCOLS", str(tmp_path / "env"))
    assert data_file("ms", schemas_dir(), "schema") == env_ms
    assert data_file("mine", schemas_dir(), "schema") == user
    assert data_file("ff", schemas_dir(), "schema") == ROOT / "protocols" / "schemas" / "ff.toml"
    # a folder that is not a shipped sub-folder is searched alone
    assert available_files(tmp_path / "env" / "schemas") == ("ms",)


def test_user_protocol_is_loaded_by_name(tmp_path: Path) -> None:
    text = (ROOT / "protocols" / "studies" / "vf_learning_curve.toml").read_text()
    _write(user_protocols_dir() / "studies", "my_study",
           text.replace('name = "vf_learning_curve"', 'name = "my_study"'))
    assert load_protocol("my_study").name == "my_study"


def test_bad_env_folder_and_unknown_name(monkeypatch: pytest.MonkeyPatch,
                                         tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"unknown schema 'nope'.*ms") as info:
        data_file("nope", schemas_dir(), "schema")
    assert info.value.field == "schema"
    monkeypatch.setenv("VASIM_PROTOCOLS", str(tmp_path / "missing"))
    with pytest.raises(ConfigError, match="protocols folder not found") as info:
        available_files(schemas_dir())
    assert info.value.field == "VASIM_PROTOCOLS"
    assert str(tmp_path / "missing") in str(info.value)
