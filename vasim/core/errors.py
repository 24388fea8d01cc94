"""The exception hierarchy of vasim (one place, as Gymnasium's ``error.py``).

Every message names the offending file, field and value where there is one, so that a
user can fix a protocol or schema file without reading code.
"""

from __future__ import annotations

from pathlib import Path


class VasimError(Exception):
    """Base class of every error vasim raises on purpose."""


class ConfigError(VasimError, ValueError):
    """A configuration value (schema, protocol, scene, parameter) is invalid.

    Args:
        message: what is wrong, including the bad value.
        file: the file the value came from, if any.
        field: dotted path of the field inside that file (e.g. ``fixtures.ff.k``).
    """

    def __init__(self, message: str, *, file: str | Path | None = None, field: str | None = None):
        self.file = str(file) if file is not None else None
        self.field = field
        self.reason = message
        where = []
        if self.file:
            where.append(self.file)
        if field:
            where.append(f"field '{field}'")
        prefix = ": ".join(where)
        super().__init__(f"{prefix}: {message}" if prefix else message)


class StoreError(VasimError):
    """The study store (SQLite) cannot be opened or is inconsistent."""


class DeviceError(VasimError):
    """A haptic/input device failed or delivered unusable data."""


class TransitionError(VasimError):
    """An illegal transition of a state machine (MRCP kernel states, teleoperation modes)."""
