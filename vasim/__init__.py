"""vasim: a haptic surgical training simulator with task-oriented virtual fixtures."""

from __future__ import annotations

__version__ = "0.1.0"
