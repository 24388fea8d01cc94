"""Which process owns a 'running' trial row, and whether it still runs (through psutil).

A ``trials`` row records its writer: ``pid``, ``host`` and ``proc_token``, a token of that
process incarnation (its start time). A row stays 'running' while that writer is alive;
opening a store marks the rows of dead writers on this host 'interrupted'
(``lifecycle.recover_interrupted``). Rows of other hosts are left alone: their liveness
cannot be checked from here.

**Decision**: the token is ``"ct:<start time>"`` with psutil's ``Process.create_time()``
(seconds since the epoch; it differs across boots, so no separate boot id is needed), and
two tokens name the same incarnation when their start times agree within
``SAME_START_S``: psutil derives the start time from the boot time, which the kernel may
restate by up to a second (clock steps), while a recycled pid belongs to a process started
after the writer, normally much later than that. A token of any other form (e.g. the
``<boot id>:<ticks>`` of vasim before psutil) is never the same incarnation, so such a row
counts as its writer's only if it carries no token at all.
"""

from __future__ import annotations

import os

import psutil

SAME_START_S = 1.0
"""Start times closer than this [s] name the same process incarnation."""

_PREFIX = "ct:"


def proc_token(pid: int) -> str | None:
    """A token of the process ``pid``'s incarnation (its start time), or None if unknown.

    Example:
        >>> proc_token(os.getpid()).startswith("ct:")
        True
    """
    try:
        return f"{_PREFIX}{psutil.Process(pid).create_time():.6f}"
    except (psutil.Error, OSError, ValueError):
        return None


def _start(token: str | None) -> float | None:
    if token is None or not token.startswith(_PREFIX):
        return None
    try:
        return float(token[len(_PREFIX):])
    except ValueError:
        return None


def same_process(token: str | None, other: str | None) -> bool:
    """True if two tokens name the same process incarnation (both known, start times
    within ``SAME_START_S``)."""
    a, b = _start(token), _start(other)
    return a is not None and b is not None and abs(a - b) < SAME_START_S


def process_alive(pid: int | None, token: str | None) -> bool:
    """True unless the process ``pid`` (on this host) has surely ended.

    Args:
        pid: the writer's pid (None: unknown writer, never guessed dead).
        token: its ``proc_token`` when it began the trial, or None.

    Returns:
        False if no process has that pid, if it is a zombie (finished, awaiting its parent)
        or if the pid now belongs to another incarnation (token mismatch); True otherwise,
        including when the process cannot be inspected (another user's, access denied).
    """
    if pid is None:
        return True  # unknown writer: never guess
    if pid == os.getpid():
        # Our pid, but maybe not us: a row left by an earlier process that had this pid
        # (pids are reused, e.g. in containers) carries another start-time token.
        now = proc_token(pid)
        return token is None or now is None or same_process(token, now)
    try:
        proc = psutil.Process(pid)
        status = proc.status()
    except psutil.NoSuchProcess:
        return False
    except (psutil.AccessDenied, psutil.Error, OSError):
        return True  # exists (or cannot tell): keep it running
    if status in (psutil.STATUS_ZOMBIE, psutil.STATUS_DEAD):
        return False
    if token is not None:
        now = proc_token(pid)
        if now is not None and not same_process(token, now):
            return False  # the pid now belongs to another process
    return True


def is_writer(pid: int | None, token: str | None) -> bool:
    """True if this very process is the one ``pid``/``token`` name (the host is checked by
    the caller)."""
    return pid == os.getpid() and token is not None and same_process(
        token, proc_token(os.getpid()))


__all__ = ["SAME_START_S", "is_writer", "proc_token", "process_alive", "same_process"]
