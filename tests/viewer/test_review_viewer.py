"""Review fixes in the viewer: the schema menu accepts only its own entries (no file path
from a client is ever read), the audio stream survives clients connecting while it sends,
and ``vasim serve --db DIR`` is refused at start-up."""

from __future__ import annotations

import shutil
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

import vasim.viewer.audio as audio
import vasim.viewer.controller as controller_mod
from vasim.cli import main
from vasim.core.errors import ConfigError
from vasim.fixtures.schema import schema_path
from vasim.fixtures.types import AudioCue
from vasim.viewer.audio import AudioStream
from vasim.viewer.controller import Command, TrainingController, schema_choices


def test_a_schema_outside_the_menu_is_refused_without_reading_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    secret = tmp_path / "notaschema.toml"
    secret.write_text('secret_token = "hunter2"\n')
    c = TrainingController(scene="none", db=tmp_path / "s.sqlite", speed=25.0, max_time=20.0)
    try:
        c.handle(Command("mode", "free"))
        read: list[str] = []
        real = controller_mod.load_schema

        def spy(name: Any, *a: Any, **k: Any) -> Any:
            read.append(str(name))
            return real(name, *a, **k)

        monkeypatch.setattr(controller_mod, "load_schema", spy)
        before = c.panel.schema
        for value in (str(secret), "/etc/passwd", "/nonexistent/x.toml", "x" * 500):
            with pytest.raises(ConfigError) as exc:
                c.handle(Command("schema", value))
            msg = str(exc.value)
            assert "hunter2" not in msg and "unknown schema" in msg
            assert value[:40] in msg and len(msg) < 200
        assert read == [] and c.panel.schema == before
        # Menu entries still work.
        assert "vg" in schema_choices(before)
        c.handle(Command("schema", "vg"))
        assert c.panel.schema == "vg"
    finally:
        c.close()


def test_a_schema_file_given_at_start_up_stays_selectable(tmp_path: Path) -> None:
    own = tmp_path / "own.toml"
    shutil.copy(schema_path("trajectory_following"), own)
    c = TrainingController(scene="none", db=tmp_path / "s.sqlite", schema=str(own),
                           speed=25.0, max_time=20.0)
    try:
        assert str(own) in schema_choices(str(own))
        c.handle(Command("mode", "free"))
        c.handle(Command("schema", "vg"))
        c.handle(Command("schema", str(own)))  # the menu offers it: accepted
        assert c.panel.schema == str(own)
    finally:
        c.close()


def test_audio_install_during_an_update_does_not_break_the_stream(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A client connecting (viser callback thread) while update() sends (view thread): the
    send to the first client installs another, deterministically, in the middle of the
    iteration (this raised "Set changed size during iteration")."""
    clients: dict[int, Any] = {i: SimpleNamespace(client_id=i) for i in range(3)}
    sets: list[int] = []
    armed = [False]

    def run_js(client: Any, src: str) -> None:
        if src.startswith("window.__vasimAudioSet"):
            sets.append(client.client_id)
            if armed[0]:  # a client connects while update() is sending
                armed[0] = False
                clients[99] = SimpleNamespace(client_id=99)
                stream.install(clients[99])

    monkeypatch.setattr(audio, "run_js", run_js)
    stream = AudioStream(SimpleNamespace(get_clients=lambda: dict(clients)),  # type: ignore[arg-type]
                         rate_hz=1e9)
    for c in list(clients.values()):
        stream.install(c)
    cue = AudioCue(600.0, 0.2, 0.5)
    armed[0] = True
    stream.update(cue, now=1.0)  # raised "Set changed size during iteration"
    assert sorted(sets) == [0, 1, 2, 99]  # 99 got the cue from install()
    assert stream._installed == {0, 1, 2, 99}
    sets.clear()
    stream.update(cue, now=2.0)
    assert sorted(sets) == [0, 1, 2, 99]


def test_a_db_directory_is_refused_at_start_up(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ConfigError, match="is a directory"):
        TrainingController(scene="none", db=tmp_path)
    code = main(["serve", "--db", str(tmp_path), "--scene", "none", "--port", "0",
                 "--duration", "0"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("vasim serve: error:")
    assert "is a directory" in err and str(tmp_path) in err
