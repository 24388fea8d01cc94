"""When a later sitting may begin (issue #18 §2): the one rule `vasim study resume` and the
viewer's protocol sessions share. Pure functions of times; the session runner
(:func:`vasim.study.session.run_session`) and the browser
(:mod:`vasim.viewer.controller`) supply the stored times.

A block with ``delay_days`` = D > 0 begins a sitting that may start once D days have
passed since the previous trial *ended* (``trials.ended_at``, UTC). Before then it is
refused with a message naming the sitting, the block, the delay, when the previous trial
ended, when the sitting is due and how long that is from now.

**Decision**: the browser has no counterpart of ``--simulate-delay``: a trainee page is
where real subjects sit, so a real delay is always required there; a simulated delay is a
command-line (``vasim study resume --simulate-delay``) and ``vasim study simulate`` matter.
"""

from __future__ import annotations

from dataclasses import dataclass

import pandas as pd

SECONDS_PER_DAY = 86_400.0


@dataclass(frozen=True)
class EarlySitting:
    """A later sitting requested before its delay passed.

    Attributes:
        sitting: its 1-based number. block: the block that begins it. delay_days: its
            delay [d]. previous_ended_at: when the trial before it ended. due: when it may
            begin. now: when it was requested.
    """

    sitting: int
    block: str
    delay_days: float
    previous_ended_at: pd.Timestamp
    due: pd.Timestamp
    now: pd.Timestamp

    @property
    def remaining_days(self) -> float:
        """Days from ``now`` until ``due`` (> 0)."""
        return (self.due - self.now).total_seconds() / SECONDS_PER_DAY

    def message(self, session_id: int, subject: str, remedy: str) -> str:
        """The refusal, e.g. ``session 3 of subject 'S01': sitting 2 (block 'retention')
        begins 7 d after the previous trial (ended ...), due ... (in 6 d 23 h); <remedy>``.
        """
        return (f"session {session_id} of subject {subject!r}: sitting {self.sitting} "
                f"(block {self.block!r}) begins {self.delay_days:g} d after the previous "
                f"trial (ended {self.previous_ended_at.isoformat()}), due "
                f"{self.due.isoformat()} (in {format_wait(self.remaining_days)})"
                f"{self.future_hint}; {remedy}")

    @property
    def future_hint(self) -> str:
        """When the previous trial's stored end lies after ``now`` (issue #30 item 8: a
        sitting stored while the clock was 30 days fast): a note saying so, else ``""``.

        **Decision**: the rule itself is unchanged (the delay counts from the stored end,
        so a sitting cannot be begun early by a wrong clock either way); the message says
        that the stored time is in the future, by how much, and what to check.
        """
        ahead = (self.previous_ended_at - self.now).total_seconds() / SECONDS_PER_DAY
        if ahead <= 0:
            return ""
        return (f"; note: the previous trial's stored end is {format_wait(ahead)} in the "
                "future: the clock was fast when it was stored, or is slow now; check the "
                "clock of this computer (`date -u`) and of the one that ran it")


def format_wait(days: float) -> str:
    """A wait in days as ``"6 d 23 h"``, ``"5 h 12 min"`` or ``"3 min"`` (rounded up to the
    minute, so it never says 0 while the sitting is still early).

    >>> format_wait(7.0), format_wait(6.999), format_wait(0.25), format_wait(1e-6)
    ('7 d 0 h', '6 d 23 h', '6 h 0 min', '1 min')
    """
    minutes = max(1, int(-(-days * 1440 // 1)))
    d, rem = divmod(minutes, 1440)
    h, m = divmod(rem, 60)
    if d:
        return f"{d} d {h} h"
    if h:
        return f"{h} h {m} min"
    return f"{m} min"


def early_sitting(*, sitting: int, block: str, delay_days: float,
                  previous_ended_at: str | pd.Timestamp | None,
                  now: str | pd.Timestamp) -> EarlySitting | None:
    """The refusal of a sitting requested at ``now``, or None when it may begin.

    It may begin when ``now - previous_ended_at >= delay_days`` (exactly at the due time
    too), or when no earlier trial has ended (``previous_ended_at`` None: nothing to
    measure the delay from).

    Example:
        >>> e = early_sitting(sitting=2, block="retention", delay_days=7.0,
        ...                   previous_ended_at="2026-11-20T10:00:00+00:00",
        ...                   now="2026-11-27T09:00:00+00:00")
        >>> e.due.isoformat(), format_wait(e.remaining_days)
        ('2026-11-27T10:00:00+00:00', '1 h 0 min')
        >>> early_sitting(sitting=2, block="retention", delay_days=7.0,
        ...               previous_ended_at="2026-11-20T10:00:00+00:00",
        ...               now="2026-11-27T10:00:00+00:00") is None
        True
    """
    if previous_ended_at is None:
        return None
    last = pd.Timestamp(previous_ended_at)
    t = pd.Timestamp(now)
    if last.tz is None:       # the store writes UTC times with their offset; be safe
        last = last.tz_localize("UTC")
    if t.tz is None:
        t = t.tz_localize("UTC")
    due = last + pd.Timedelta(days=float(delay_days))
    if t >= due:
        return None
    return EarlySitting(sitting=int(sitting), block=str(block), delay_days=float(delay_days),
                        previous_ended_at=last, due=due, now=t)


__all__ = ["SECONDS_PER_DAY", "EarlySitting", "early_sitting", "format_wait"]
