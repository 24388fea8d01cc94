"""Waiting for a condition in tests: poll it against a deadline, fail with what was awaited.

A fixed ``time.sleep`` races with a loaded machine (2 cores shared by many runs) and an
unbounded ``while`` loop hangs the suite; tests poll through :func:`wait_until` instead.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest


def wait_until(cond: Callable[[], object], *, what: str, timeout: float = 30.0,
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
