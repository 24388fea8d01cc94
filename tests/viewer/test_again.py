"""Issue #30 item 3 on the experimenter's page: a subject who completed a protocol gets no
second session silently. The rule (``history.session_rule``) against a real store, and the
controller end to end: it completes a tiny protocol, refuses the next Start on the status
line, and starts a new session only with the reason, stored as ``vasim study run --again``
stores it; a reason while the subject's session is open is refused."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import closing
from pathlib import Path

import pytest

from tests.study.tiny_protocols import TINY, install
from tests.study.tiny_protocols import session_rows as sessions
from tests.viewer.driving import drive
from vasim.cli import main
from vasim.core.errors import ConfigError
from vasim.study.protocol import parse_protocol
from vasim.study.session import MAX_REASON_CHARS, start_session
from vasim.study.store import TrialStore
from vasim.viewer.app_options import TrialOptions
from vasim.viewer.controller import Command, TrainingController, TrainingSettings
from vasim.viewer.history import (
    AGAIN_FIELD,
    check_again_reason,
    completed_note,
    open_session,
    session_rule,
)


@pytest.fixture
def done_db(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> Path:
    """A store where D9 completed the tiny protocol (``vasim study run``, session 1)."""
    proto = tmp_path / "tiny.toml"
    proto.write_text(TINY, encoding="utf-8")
    db = tmp_path / "s.sqlite"
    assert main(["study", "run", "--protocol", str(proto), "--db", str(db), "--subject", "D9",
                 "--no-progress"]) == 0
    capsys.readouterr()
    assert sessions(db) == [(1, "D9", "completed", None)]
    return db


# -- the rule -----------------------------------------------------------------------------
def test_the_rule_refuses_a_completed_subject_without_a_reason(done_db: Path) -> None:
    with closing(TrialStore(done_db)) as st:
        with pytest.raises(ConfigError) as info:
            session_rule(st, "D9", "tiny", None)
        msg = str(info.value)
        assert "field 'Again, because'" in msg and "'D9' already completed protocol 'tiny'" in msg
        assert "session 1" in msg and f"'{AGAIN_FIELD}'" in msg and "\n" not in msg
        # with a reason: a new session, with the note --again stores
        assert session_rule(st, "D9", "tiny", "device failed") == (
            None, "again after completed session 1: device failed")
        # another subject: a first session, no note; a reason for them is refused
        assert session_rule(st, "D8", "tiny", None) == (None, None)
        with pytest.raises(ConfigError, match="no completed session"):
            session_rule(st, "D8", "tiny", "device failed")
        # another protocol is another study
        assert session_rule(st, "D9", "other", None) == (None, None)
        # the panel says so when the subject and protocol are picked
        note = completed_note(st, "D9", "tiny")
        assert note is not None and "Start is refused" in note and AGAIN_FIELD in note
        assert completed_note(st, "D8", "tiny") is None


def test_an_open_session_is_resumed_and_a_reason_for_it_refused(done_db: Path) -> None:
    proto = parse_protocol(TINY, source="tiny.toml")
    with closing(TrialStore(done_db)) as st:
        sid = start_session(st, proto, "D7", seed=1)
        assert session_rule(st, "D7", "tiny", None) == (sid, None)
        with pytest.raises(ConfigError, match=r"open session 2 of protocol 'tiny' \(0 of 2"):
            session_rule(st, "D7", "tiny", "device failed")
        # D9 with a new session open (run again): that one is resumed, no third one
        sid9 = start_session(st, proto, "D9", seed=2, notes="again after completed session "
                             "1: device failed")
        assert session_rule(st, "D9", "tiny", None) == (sid9, None)
        with pytest.raises(ConfigError, match="open session 3"):
            session_rule(st, "D9", "tiny", "again")
        # an aborted session frees the subject (as on the command line)
        st.set_session_status(sid, "aborted", notes="test")
        assert session_rule(st, "D7", "tiny", None) == (None, None)


def test_open_session_stores_the_reason_with_the_new_session(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, done_db: Path) -> None:
    install(monkeypatch, tmp_path / "studies", tiny=TINY)
    with closing(TrialStore(done_db)) as st:
        with pytest.raises(ConfigError, match="already completed"):
            open_session(st, "D9", "tiny", {})
        assert len(st.sessions()) == 1                       # nothing was created
        s = open_session(st, "D9", "tiny", {"ui": "test"}, again="  device failed ")
        assert s.id == 2 and s.status == "running"
        assert open_session(st, "D9", "tiny", {}).id == 2    # resumed, not a third
    assert sessions(done_db)[1] == (2, "D9", "running",
                                    "again after completed session 1: device failed")


@pytest.mark.parametrize("text, expected", [
    ("", None), ("   ", None), (" device failed ", "device failed"),
    ("x" * MAX_REASON_CHARS, "x" * MAX_REASON_CHARS)])
def test_the_reason_field_accepts_one_line(text: str, expected: str | None) -> None:
    assert check_again_reason(text) == expected


@pytest.mark.parametrize("text", ["two\nlines", "a\rb", "x" * (MAX_REASON_CHARS + 1)])
def test_the_reason_field_refuses_more_than_one_line(text: str) -> None:
    with pytest.raises(ConfigError, match=r"field 'Again, because'.*one-line reason"):
        check_again_reason(text)


# -- the controller -----------------------------------------------------------------------
@pytest.fixture
def ctl(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[TrainingController]:
    install(monkeypatch, tmp_path / "studies", tiny=TINY)
    c = TrainingController(TrainingSettings(
        scene="none", db=tmp_path / "v.sqlite", speed=25.0,
        trials=TrialOptions(countdown_s=0.0, pause_s=0.05)))
    try:
        yield c
    finally:
        c.close()


def run_trial(ctl: TrainingController) -> None:
    n = ctl.info.number
    ctl.handle(Command("start"))
    assert drive(ctl, lambda: ctl.info.number > n and not ctl.panel.running, 60.0), \
        ctl.panel.status


def test_the_page_refuses_a_second_session_until_a_reason_is_given(
        ctl: TrainingController) -> None:
    db = ctl.db
    assert db is not None
    for cmd in (Command("mode", "protocol"), Command("subject", "D9"),
                Command("protocol", "tiny")):
        ctl.handle(cmd)
    run_trial(ctl)
    run_trial(ctl)
    # the last trial stored completes the session at once
    assert sessions(db) == [(1, "D9", "completed", None)]
    assert "session 1 is complete" in ctl.panel.status
    # Start again: refused, on the status line too; nothing is created or run
    n = ctl.info.number
    with pytest.raises(ConfigError, match="already completed protocol 'tiny'") as info:
        ctl.handle(Command("start"))
    assert ctl.panel.status == str(info.value) and not ctl.panel.running
    assert ctl.info.number == n and len(sessions(db)) == 1
    # picking the subject again says so before any Start
    ctl.handle(Command("subject", "D9"))
    assert "already completed tiny (session 1): Start is refused" in ctl.panel.status
    # a bad reason is refused and changes nothing
    with pytest.raises(ConfigError, match="one-line reason"):
        ctl.handle(Command("again", "a\nb"))
    assert ctl.panel.again is None
    # with the reason: a new session, the reason stored with it; the field is cleared
    ctl.handle(Command("again", " device failed "))
    assert ctl.panel.again == "device failed"
    run_trial(ctl)
    assert ctl.panel.again is None and ctl.panel.session_id == 2
    assert sessions(db)[1] == (2, "D9", "running",
                               "again after completed session 1: device failed")
    # a reason while that session is open: refused (Start resumes it)
    ctl.handle(Command("again", "once more"))
    with pytest.raises(ConfigError, match="open session 2 of protocol 'tiny'"):
        ctl.handle(Command("start"))
    assert "Start resumes it" in ctl.panel.status and len(sessions(db)) == 2
    ctl.handle(Command("again", ""))                # cleared: Start resumes session 2
    run_trial(ctl)
    assert sessions(db)[1][:3] == (2, "D9", "completed")
    with closing(TrialStore(db, readonly=True)) as st:
        assert list(st.trials()["session_id"]) == [1, 1, 2, 2]
