"""Playing the viewer's controller thread in a test: ``handle`` commands, then
:func:`drive` polls (``poll``) until a condition holds."""

from __future__ import annotations

import time
from collections.abc import Callable

from vasim.viewer.controller import TrainingController


def drive(ctl: TrainingController, cond: Callable[[], bool], timeout: float = 30.0) -> bool:
    """Polls ``ctl`` like the controller thread until ``cond`` holds (False at
    ``timeout`` [s] of wall time)."""
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        ctl.poll()
        if cond():
            return True
        time.sleep(0.01)
    return cond()
