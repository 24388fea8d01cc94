"""The exception hierarchy of vasim (one place, as Gymnasium's ``error.py``).

Every message names the offending file, field and value where there is one, so that a
user can fix a protocol or schema file without reading code.
"""

from __future__ import annotations

from pathlib import Path


class VasimError(Exception):
    """Base class of every error vasim raises on purpose."""


class FieldError(VasimError, ValueError):
    """A value the user gave is invalid; the message names where it came from.

    The common base of :class:`ConfigError` and :class:`InputError` (the command line prints
    either as one line and exits with status 2). Catch this to handle both.

    Args:
        message: what is wrong, including the bad value.
        file: the file the value came from, if any.
        field: dotted path of the field inside that file (e.g. ``fixtures.ff.k``), or the
            command-line option (``--seed``).
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


class ConfigError(FieldError):
    """A configuration value (schema, protocol, scene, robot, parameter of a library call)
    is invalid: a field of a config file or of a frozen config dataclass."""


class InputError(FieldError):
    """A user input that is not a config field is invalid: a command-line argument (a path
    that does not exist, a value the argument's type cannot check alone), or a row or value
    of an input data file (an answers file, a trial store given by path).

    **Decision** (issue #29 item 3): kept apart from :class:`ConfigError` so that a caller
    can tell "your config file is wrong" from "what you typed or fed in is wrong"; both are
    :class:`FieldError`, which the command line reports the same way (exit status 2).
    """


class StoreError(VasimError):
    """The study store (SQLite) cannot be opened or is inconsistent."""


class DeviceError(VasimError):
    """A haptic/input device failed or delivered unusable data."""


class TransitionError(VasimError):
    """An illegal transition of a state machine (MRCP kernel states, teleoperation modes)."""
