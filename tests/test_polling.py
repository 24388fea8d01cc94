"""tests/polling.py: the wait helper returns once the condition holds and fails after the
deadline otherwise."""

from __future__ import annotations

import time

import pytest

from tests.polling import wait_until


def test_returns_once_the_condition_holds() -> None:
    calls = iter(range(100))
    wait_until(lambda: next(calls) >= 3, what="three calls", step=0.0)
    assert next(calls) == 4


def test_fails_after_the_deadline_naming_what_it_waited_for() -> None:
    t0 = time.monotonic()
    with pytest.raises(pytest.fail.Exception, match=r"0\.05 s waiting for the moon"):
        wait_until(lambda: False, what="the moon", timeout=0.05, step=0.01)
    assert 0.05 <= time.monotonic() - t0 < 60.0  # it ends, no hang (how soon: the load)
