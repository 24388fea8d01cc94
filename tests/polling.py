"""Waiting for a condition in tests: poll it against a deadline, fail with what was awaited.

A fixed ``time.sleep`` races with a loaded machine (2 cores shared by many runs) and an
unbounded ``while`` loop hangs the suite; tests poll through :func:`wait_until` instead.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest

WAIT_S = 180.0
"""How long a test waits for a condition the code under test will reach: a bound against a
hang, not a timing goal (a test that passes never waits it out). At load 25-48 on 2 cores
(the suite beside six other agents) a combobox choice took over 45 s to reach the server, a
first MRCP wrist turn over 60 s and a score card's visibility over 30 s."""


def wait_for(cond: Callable[[], object], timeout: float = WAIT_S, step: float = 0.02) -> bool:
    """Polls ``cond`` until it is truthy or ``timeout`` seconds pass; returns its last value
    as a bool (for ``assert wait_for(...), context``)."""
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        if cond():
            return True
        time.sleep(step)
    return bool(cond())


def wait_until(cond: Callable[[], object], *, what: str, timeout: float = WAIT_S,
               step: float = 0.01) -> None:
    """Polls ``cond`` every ``step`` seconds until it is truthy.

    Args:
        cond: the condition (called from the test's thread).
        what: what is awaited, for the failure message ("the servo loop to tick").
        timeout: wall-clock limit [s].
        step: polling period [s].

    Raises:
        pytest.fail.Exception: if ``cond`` is still falsy after ``timeout`` seconds.
    """
    t_end = time.monotonic() + timeout
    while not cond():
        if time.monotonic() >= t_end:
            pytest.fail(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(step)
