"""vasim: a haptic surgical training simulator with task-oriented virtual fixtures."""

from __future__ import annotations

from vasim.core.numba_cache import configure_numba_cache

__version__ = "0.1.0"

# Before any kernel module imports numba: a read-only install must still run.
configure_numba_cache()
