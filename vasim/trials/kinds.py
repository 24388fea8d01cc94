"""Names and limits every trial kind shares (the study layer's protocols use them too).

A trial is a virtual-fixture trial (a fixture schema assists one tool) or a
teleoperation trial (spec/study.md §4: StdT, MRCP or MRCP+Cam on the needle task).
"""

from __future__ import annotations

import math

from vasim.core.errors import ConfigError

TELEOPERATION_MODES: tuple[str, ...] = ("stdt", "mrcp", "mrcp_cam")
"""Conditions of the MRCP vs standard-teleoperation protocols (spec/study.md §4): StdT
(2 masters : 2 slaves), MRCP (1 master : 2 slaves, task oriented), MRCP+Cam."""

MAX_TRIAL_TIME_S = 86_400.0
"""Longest trial time limit accepted [s] (**decision**: a day; a trial's sample buffer and
loop counters are sized from the limit, and 1e308 s overflowed them)."""


def check_trial_time(v: object, name: str) -> None:
    """A trial time limit: a finite number of seconds in (0, :data:`MAX_TRIAL_TIME_S`]."""
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) \
            or not 0 < v <= MAX_TRIAL_TIME_S:
        raise ConfigError(f"must be a number of seconds in (0, {MAX_TRIAL_TIME_S:g}], got "
                          f"{v!r}", field=name)


__all__ = ["MAX_TRIAL_TIME_S", "TELEOPERATION_MODES", "check_trial_time"]
