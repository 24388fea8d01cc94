"""Names and limits every trial kind shares (the study layer's protocols use them too).

A trial is a virtual-fixture trial (a fixture schema assists one tool) or a
teleoperation trial (spec/study.md §4: StdT, MRCP or MRCP+Cam on the needle task).
"""

from __future__ import annotations

from vasim.core.config import check_number

TELEOPERATION_MODES: tuple[str, ...] = ("stdt", "mrcp", "mrcp_cam")
"""Conditions of the MRCP vs standard-teleoperation protocols (spec/study.md §4): StdT
(2 masters : 2 slaves), MRCP (1 master : 2 slaves, task oriented), MRCP+Cam."""

MAX_TRIAL_TIME_S = 86_400.0
"""Longest trial time limit accepted [s] (**decision**: a day; a trial's sample buffer and
loop counters are sized from the limit, and 1e308 s overflowed them)."""


def check_trial_time(v: object, name: str) -> None:
    """A trial time limit: a finite number of seconds in (0, :data:`MAX_TRIAL_TIME_S`]
    (``ConfigError`` at field ``name``, ``core.config.check_number``)."""
    check_number(v, name, gt=0, le=MAX_TRIAL_TIME_S)


__all__ = ["MAX_TRIAL_TIME_S", "TELEOPERATION_MODES", "check_trial_time"]
