"""The identity of a stored trial: its subject code and what is known when it starts.

``TrialMeta`` is the record a trial sink (``vasim.trials.sink``) receives when a trial
begins; the study store (``vasim.study.store``) writes it as the ``trials`` row.
Subjects are pseudonymous codes, never names.
"""

from __future__ import annotations

import os
import re
import socket
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

from vasim.core.config import check_int, check_number, check_str, check_type, expect

SUBJECT_CODE_PATTERN = r"^[A-Za-z0-9_-]{1,32}$"
"""Allowed subject codes: 1-32 letters, digits, '_' or '-' (a pseudonym, never a name)."""

_SUBJECT_RE = re.compile(SUBJECT_CODE_PATTERN)


def validate_subject_code(code: object) -> str:
    """Returns ``code`` if it is a valid subject code, else raises ``ConfigError``.

    Example:
        >>> validate_subject_code("S01")
        'S01'
    """
    expect(isinstance(code, str) and _SUBJECT_RE.fullmatch(code), code,
           "a subject code of 1-32 letters, digits, '_' or '-' (a pseudonymous code, never "
           "a name)", field="subject")
    return str(code)


@dataclass(frozen=True)
class TrialMeta:
    """What is known about a trial when it starts (the ``trials`` row).

    Attributes:
        subject: subject code (``SUBJECT_CODE_PATTERN``; registered on first use), or None
            for a trial without a subject (free practice): no code is invented for it.
        task: task kind, e.g. ``"trajectory"`` or ``"point"``.
        variant: trajectory variant (0 = original), or None.
        schema: fixture schema name, or None. operator: input device name, or None.
        seed: random seed of the trial, or None. dt: control step [s], or None.
        active_fixtures: active fixture names, e.g. ``"VG,FF"``; ``""`` for VF-free.
        session_id: session id, or None. protocol: protocol name.
        schedule_index: the scheduled trial of the session this trial is an attempt at, or
            None (then ``session_id`` is only informative).
        pid, host: the writing process (defaults: this process, this host).
        config: the full trial configuration (JSON-serialisable mapping), or None.
        schema_toml: the resolved fixture schema as TOML text, or None.
        label: a free-practice label the experimenter chose, or None; it must not read as
            a subject code (``vasim.study.store.vocabulary.validate_label``: at least one
            character a code cannot have, e.g. ``"free: warm-up"``).
    """

    subject: str | None
    task: str
    variant: int | None = None
    schema: str | None = None
    operator: str | None = None
    seed: int | None = None
    dt: float | None = None
    active_fixtures: str = ""
    session_id: int | None = None
    protocol: str | None = None
    pid: int = field(default_factory=os.getpid)
    host: str = field(default_factory=socket.gethostname)
    config: Mapping[str, Any] | None = None
    schema_toml: str | None = None
    schedule_index: int | None = None
    label: str | None = None

    def __post_init__(self) -> None:
        if self.subject is not None:
            validate_subject_code(self.subject)
        if self.label is not None:
            expect(isinstance(self.label, str) and 1 <= len(self.label) <= 64
                   and not _SUBJECT_RE.fullmatch(self.label), self.label,
                   "a label of 1-64 characters that cannot be mistaken for a subject code "
                   "(give one with a space or ':' in it, e.g. 'free: warm-up')", field="label")
        check_str(self.task, "task", one_line=False)
        for name in ("variant", "seed", "session_id", "pid", "schedule_index"):
            if getattr(self, name) is not None:
                check_int(getattr(self, name), name)
        if self.dt is not None:
            check_number(self.dt, "dt", gt=0)
        check_type(self.active_fixtures, "active_fixtures", str, "a string")
        expect(self.schedule_index is None or self.session_id is not None,
               self.schedule_index, "no schedule_index without its session_id",
               field="schedule_index")

    @classmethod
    def from_mapping(cls, meta: Mapping[str, Any]) -> TrialMeta:
        """Builds a ``TrialMeta`` from a dict; unknown keys raise ``ConfigError``."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(meta) - known)
        expect(not unknown, unknown, f"known trial meta fields ({', '.join(sorted(known))})",
               field="meta")
        return cls(**meta)
