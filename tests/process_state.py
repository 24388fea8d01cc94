"""What a test may not leave behind in the pytest process: signal handlers, threads,
environment variables, the working directory (used by the autouse guard of
tests/conftest.py; issue #31).

:func:`snapshot` before the test, :func:`undo_changes` after its teardown: it lists what
changed and puts back what it can (handlers, variables, directory), so one leak cannot
cascade into the tests after it. Threads cannot be put back: they get ``grace_s`` to end
(a stopped server's threads wind down asynchronously), then they are reported. Threads are
checked per module (:func:`leftover_threads`): a module-scoped fixture (a viewer app shared
by the module's tests) may start threads lazily during a test and stops them only at the
end of the module.
"""

from __future__ import annotations

import gc
import os
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

PERSISTENT_THREADS: tuple[Callable[[threading.Thread], bool], ...] = (
    # tqdm's monitor thread: one per process, started by the first bar, kept on purpose.
    lambda t: type(t).__name__ == "TMonitor",
    # KNOWN LEAK, tolerated until fixed: an idle worker of an asyncio event loop's default
    # executor ("asyncio_0"), left by the viewer's viser server after ViewerApp.stop() in
    # tests/browser/test_instrument_browser.py (the loop is closed without
    # loop.shutdown_default_executor()); it holds nothing and ends at interpreter exit.
    lambda t: t.name.startswith("asyncio_") and type(t).__name__ == "Thread",
)
"""Threads not counted as leaks: kept by a library for the life of the process by design,
or a known leak named here with where it comes from."""

_SIGNALS = sorted(set(signal.valid_signals()) - {signal.SIGKILL, signal.SIGSTOP, signal.SIGALRM})
"""Every handler but SIGALRM's: pytest-timeout sets it around each test and puts it back
early when the test fails (its pytest_exception_interact hook)."""
_PYTEST_VARIABLES = ("PYTEST_CURRENT_TEST",)  # pytest rewrites it in every phase


@dataclass(frozen=True)
class ProcessState:
    """The parts of the process a test must leave as it found them."""

    handlers: dict[int, object]
    threads: frozenset[threading.Thread]
    environ: dict[str, str]
    cwd: str


def _handlers() -> dict[int, object]:
    out: dict[int, object] = {}
    if threading.current_thread() is not threading.main_thread():
        return out  # handlers belong to the main thread (a worker thread cannot set them)
    for s in _SIGNALS:
        try:
            out[int(s)] = signal.getsignal(s)
        except (ValueError, OSError):
            continue
    return out


def _environ() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k not in _PYTEST_VARIABLES}


def snapshot() -> ProcessState:
    """The process state now."""
    return ProcessState(_handlers(), frozenset(threading.enumerate()), _environ(), os.getcwd())


def _signal_name(number: int) -> str:
    try:
        return signal.Signals(number).name
    except ValueError:
        return f"signal {number}"


def _name(handler: object) -> str:
    return getattr(handler, "__qualname__", None) or repr(handler)


def undo_changes(before: ProcessState, grace_s: float = 10.0, *,
                 threads: bool = True) -> list[str]:
    """What changed since ``before`` (empty: nothing), after putting handlers, variables and
    the working directory back; with ``threads``, threads started since get ``grace_s``
    seconds to end (an executor's idle workers end when it is collected: one
    ``gc.collect()`` first)."""
    problems = []
    for number, handler in _handlers().items():
        old = before.handlers.get(number, handler)
        if handler is not old and handler != old:
            problems.append(f"the {_signal_name(number)} handler changed from {_name(old)} "
                            f"to {_name(handler)}")
            if old is not None:   # None: set outside Python; nothing to put back
                signal.signal(number, old)  # type: ignore[arg-type]
    now = _environ()
    if now != before.environ:
        changed = sorted(k for k in set(now) | set(before.environ)
                         if now.get(k) != before.environ.get(k))
        problems.append(f"environment variables changed: {', '.join(changed)}")
        for k in changed:
            if k in before.environ:
                os.environ[k] = before.environ[k]
            else:
                del os.environ[k]
    if os.getcwd() != before.cwd:
        problems.append(f"the working directory changed to {os.getcwd()}")
        os.chdir(before.cwd)
    if not threads:
        return problems
    return problems + leftover_threads(before, grace_s)


def leftover_threads(before: ProcessState, grace_s: float = 10.0) -> list[str]:
    """Threads started since ``before`` that are still running after ``grace_s`` seconds."""
    gc.collect()
    t_end = time.monotonic() + grace_s
    while True:
        left = [t for t in threading.enumerate()
                if t not in before.threads and t.is_alive()
                and not any(rule(t) for rule in PERSISTENT_THREADS)]
        if not left or time.monotonic() >= t_end:
            break
        time.sleep(0.05)
    if not left:
        return []
    return [f"threads still running {grace_s:g} s after the test: "
            + ", ".join(f"{t.name} ({type(t).__name__})" for t in left)]
