"""When a later sitting may begin (vasim/study/sitting_rule.py): D days after the previous
trial ended, the same rule for `vasim study resume` and the viewer."""

from __future__ import annotations

import pandas as pd
import pytest

from vasim.study.sitting_rule import early_sitting, format_wait

ENDED = "2026-11-20T10:00:00+00:00"


def _rule(now: str, delay: float = 7.0, ended: str | None = ENDED):
    return early_sitting(sitting=2, block="retention", delay_days=delay,
                         previous_ended_at=ended, now=now)


@pytest.mark.parametrize(("now", "early"), [
    ("2026-11-20T10:00:01+00:00", True),        # just after the previous trial
    ("2026-11-27T09:59:59+00:00", True),        # one second early
    ("2026-11-27T10:00:00+00:00", False),       # exactly 7 d: may begin
    ("2026-12-20T10:00:00+00:00", False),       # long after
    ("2026-11-27T11:59:59+02:00", True),        # 09:59:59 UTC: offsets are compared as times
])
def test_a_sitting_may_begin_once_its_delay_has_passed(now: str, early: bool) -> None:
    assert (_rule(now) is not None) == early


def test_the_refusal_names_when_the_sitting_is_due() -> None:
    e = _rule("2026-11-21T16:30:00+00:00")
    assert e is not None
    assert e.due == pd.Timestamp("2026-11-27T10:00:00+00:00")
    # 5 d 17 h 30 min remain: rounded up to the minute, shown as days and hours
    assert e.remaining_days == pytest.approx(5 + 17.5 / 24)
    msg = e.message(3, "S01", "come back then")
    assert msg == ("session 3 of subject 'S01': sitting 2 (block 'retention') begins 7 d "
                   "after the previous trial (ended 2026-11-20T10:00:00+00:00), due "
                   "2026-11-27T10:00:00+00:00 (in 5 d 17 h); come back then")


def test_fractional_delays_and_naive_times() -> None:
    # 0.5 d = 12 h; a time without offset is read as UTC (the store writes UTC)
    assert _rule("2026-11-20T21:59:00", delay=0.5) is not None
    assert _rule("2026-11-20T22:00:00", delay=0.5) is None
    e = _rule("2026-11-20T21:59:00", delay=0.5)
    assert e is not None and format_wait(e.remaining_days) == "1 min"


def test_no_previous_trial_means_nothing_to_wait_for() -> None:
    assert _rule("2026-11-20T10:00:00+00:00", ended=None) is None


@pytest.mark.parametrize(("days", "text"), [
    (7.0, "7 d 0 h"), (1.5, "1 d 12 h"), (2 / 24, "2 h 0 min"), (90 / 1440, "1 h 30 min"),
    (30 / 86_400, "1 min"), (59.5 / 1440, "1 h 0 min"),
])
def test_waits_are_rounded_up_to_the_minute(days: float, text: str) -> None:
    assert format_wait(days) == text
