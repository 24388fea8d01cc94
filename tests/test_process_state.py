"""tests/process_state.py: the guard behind tests/conftest.py finds what a test leaves in the
pytest process, and puts back what it can (issue #31)."""

from __future__ import annotations

import os
import signal
import threading
from pathlib import Path

from tests.process_state import snapshot, undo_changes


def test_nothing_changed_is_nothing_reported() -> None:
    assert undo_changes(snapshot(), grace_s=0.0) == []


def test_a_signal_handler_left_behind_is_reported_and_put_back() -> None:
    before = snapshot()
    old = signal.getsignal(signal.SIGTERM)

    def like_ray(signum: int, frame: object) -> None:   # ray.init's: sys.exit(signum)
        raise SystemExit(signum)

    signal.signal(signal.SIGTERM, like_ray)
    problems = undo_changes(before, grace_s=0.0)
    assert len(problems) == 1 and "SIGTERM handler changed" in problems[0]
    assert "like_ray" in problems[0]
    assert signal.getsignal(signal.SIGTERM) is old


def test_environment_variables_are_reported_and_put_back(monkeypatch) -> None:
    monkeypatch.setenv("VASIM_TEST_KEPT", "a")
    before = snapshot()
    os.environ["VASIM_TEST_KEPT"] = "b"            # changed
    os.environ["VASIM_TEST_LEAKED"] = "1"          # added
    problems = undo_changes(before, grace_s=0.0)
    assert problems == ["environment variables changed: VASIM_TEST_KEPT, VASIM_TEST_LEAKED"]
    assert os.environ["VASIM_TEST_KEPT"] == "a" and "VASIM_TEST_LEAKED" not in os.environ


def test_the_working_directory_is_put_back(tmp_path: Path) -> None:
    before = snapshot()
    os.chdir(tmp_path)
    problems = undo_changes(before, grace_s=0.0)
    assert problems == [f"the working directory changed to {tmp_path}"]
    assert os.getcwd() == before.cwd


def test_a_thread_that_ends_within_the_grace_is_no_leak() -> None:
    before = snapshot()
    go = threading.Event()
    t = threading.Thread(target=go.wait, name="winding-down", daemon=True)
    t.start()
    threading.Timer(0.2, go.set).start()     # ends 0.2 s into the 30 s grace
    assert undo_changes(before, grace_s=30.0) == []
    assert not t.is_alive()


def test_a_thread_still_running_after_the_grace_is_reported() -> None:
    before = snapshot()
    stop = threading.Event()
    t = threading.Thread(target=stop.wait, name="left-running", daemon=True)
    t.start()
    try:
        problems = undo_changes(before, grace_s=0.1)
    finally:
        stop.set()
        t.join(timeout=30)
    assert problems == ["threads still running 0.1 s after the test: left-running (Thread)"]
