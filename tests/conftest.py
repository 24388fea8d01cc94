"""Suite-wide test infrastructure: the markers, by location, and a guard that every test
leaves the pytest process as it found it.

Markers (registered in pyproject.toml, ``--strict-markers``):

* ``browser``: drives a real headless Chromium (``tests/browser``);
* ``cluster``: starts Ray in or beside the pytest process (a local Ray, a ``ray start`` head);
* ``slow``: longer than ~10 s of CPU on an idle 2-core machine (measured with
  ``--durations``; the figures are in :data:`SLOW`'s comments).

They are given here, by location (:data:`MARKS`), rather than in each module, so that one
table says what a quick run leaves out; ``tests/test_markers.py`` checks every entry still
names a file or a test. ``make check`` runs ``-m "not slow and not browser and not cluster"``
in parallel; ``make test`` runs everything.

The guard (:func:`_leaves_no_trace`, autouse): after each test (its fixtures torn down) the
process must have the signal handlers, the threads, the environment and the working
directory it had before. Ray's ``ray.init`` installs a SIGTERM handler (``sys.exit(signum)``)
and sets ``RAY_*`` variables in the process that calls it; left in the pytest process, that
handler once turned a SIGTERM meant for the whole run into the failure of whatever test was
running minutes later (issue #31). A test that changes them fails and the guard restores
them, so one leak cannot cascade into later tests. Threads get :data:`THREAD_GRACE_S` to end
(a stopped server's threads wind down asynchronously); the few process-wide threads a
library keeps by design are in :data:`PERSISTENT_THREADS`. Module- and session-scoped
fixtures (a viewer app shared by a module, the browser) are set up before and torn down
after the guard's window, so what they own is theirs to clean up and is not counted here.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

MARKS: dict[str, tuple[str, ...]] = {
    "browser": ("tests/browser/",),
    "cluster": (
        "tests/study/power/test_cluster.py",   # a `ray start --head` cluster + local Ray
        "tests/study/power/test_driver.py",    # `vasim study power` on a local Ray
    ),
}
"""Marker -> the files (``path.py``), folders (``path/``) or tests (``path.py::name``) it
applies to, relative to the repository root."""

SLOW: tuple[str, ...] = ()
"""Tests marked ``slow`` (filled in below, with the measured durations)."""

PERSISTENT_THREADS: tuple[Callable[[threading.Thread], bool], ...] = (
    # tqdm's monitor thread: one per process, started by the first bar, kept on purpose.
    lambda t: type(t).__name__ == "TMonitor",
)
"""Threads a library keeps for the life of the process by design (not leaks)."""

THREAD_GRACE_S = 10.0
"""How long threads a test started may take to end after its teardown [s]."""


def _marks_for(nodeid: str) -> list[str]:
    path = nodeid.split("::", 1)[0]
    out = []
    for mark, places in {**MARKS, "slow": SLOW}.items():
        for place in places:
            if (path.startswith(place) if place.endswith("/")
                    else nodeid == place or path == place or nodeid.startswith(place + "[")):
                out.append(mark)
                break
    return out


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:  # node ids are relative to the rootdir, the repository root
        for mark in _marks_for(item.nodeid):
            item.add_marker(getattr(pytest.mark, mark))


# -- the guard ------------------------------------------------------------------------

_SIGNALS = sorted(set(signal.valid_signals()) - {signal.SIGKILL, signal.SIGSTOP})


def _handlers() -> dict[signal.Signals, object]:
    out = {}
    for s in _SIGNALS:
        try:
            out[signal.Signals(s)] = signal.getsignal(s)
        except (ValueError, OSError):  # a real-time signal number Python cannot name
            continue
    return out


def _environ() -> dict[str, str]:
    """The environment, but for the variable pytest itself rewrites in every phase."""
    return {k: v for k, v in os.environ.items() if k != "PYTEST_CURRENT_TEST"}


def _persistent(t: threading.Thread) -> bool:
    return any(rule(t) for rule in PERSISTENT_THREADS)


def _name(handler: object) -> str:
    return getattr(handler, "__qualname__", None) or repr(handler)


@pytest.fixture(autouse=True)
def _leaves_no_trace(request: pytest.FixtureRequest) -> Iterator[None]:
    handlers = _handlers()
    threads = set(threading.enumerate())
    env = _environ()
    cwd = os.getcwd()
    yield
    problems = []
    if threading.current_thread() is threading.main_thread():
        for sig, before in handlers.items():
            now = signal.getsignal(sig)
            if now is not before and now != before:
                problems.append(f"the {sig.name} handler changed from {_name(before)} to "
                                f"{_name(now)}")
                if before is not None:
                    signal.signal(sig, before)  # type: ignore[arg-type]
    now_env = _environ()
    if now_env != env:
        changed = sorted(k for k in set(env) | set(now_env) if env.get(k) != now_env.get(k))
        problems.append(f"environment variables changed: {', '.join(changed)}")
        for k in changed:
            if k in env:
                os.environ[k] = env[k]
            else:
                del os.environ[k]
    if os.getcwd() != cwd:
        problems.append(f"the working directory changed to {os.getcwd()}")
        os.chdir(cwd)
    t_end = time.monotonic() + THREAD_GRACE_S
    while True:
        left = [t for t in threading.enumerate()
                if t not in threads and t.is_alive() and not _persistent(t)]
        if not left or time.monotonic() >= t_end:
            break
        time.sleep(0.05)
    if left:
        problems.append(f"threads still running {THREAD_GRACE_S:g} s after the test: "
                        + ", ".join(f"{t.name} ({type(t).__name__})" for t in left))
    if problems:
        pytest.fail(f"{request.node.nodeid} left state in the pytest process: "
                    + "; ".join(problems), pytrace=False)
