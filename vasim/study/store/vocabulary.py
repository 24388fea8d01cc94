"""The study's vocabulary: the values a stored field may take (statuses, outcomes, groups,
specialisations, experience levels) and the ``Demographics`` record checked against them.

Pure data and validation; nothing here touches SQLite (the DDL in
``vasim.study.store.schema`` turns these tuples into CHECK constraints).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

from vasim.core.config import check_choice, check_keys, check_str
from vasim.core.errors import ConfigError
from vasim.records.trial_meta import SUBJECT_CODE_PATTERN

TrialStatus = Literal["running", "completed", "interrupted"]
TRIAL_STATUSES: tuple[str, ...] = ("running", "completed", "interrupted")
"""Life cycle of a ``trials`` row: begun, closed with all its data, closed early."""

TrialOutcome = Literal["reached_all", "timed_out", "stopped", "interrupted", "failed"]
TRIAL_OUTCOMES: tuple[str, ...] = ("reached_all", "timed_out", "stopped", "interrupted",
                                   "failed")
"""How a trial ended (``trials.outcome``), separate from its life cycle status:
``reached_all`` every point reached; ``timed_out`` the time limit came first (the summary's
``points_reached`` says how far it got); ``stopped`` by the experimenter (Stop, Ctrl-C);
``interrupted`` the writing process died; ``failed`` an error, or an abort by the system."""

SessionStatus = Literal["running", "completed", "aborted"]
SESSION_STATUSES: tuple[str, ...] = ("running", "completed", "aborted")

GROUPS: tuple[str, ...] = ("surgeon", "resident")
"""Allowed ``demographics.subject_group`` values."""
SPECIALISATIONS: tuple[str, ...] = (
    "general_surgery", "gynaecology", "urology", "thoracic_surgery", "paediatric_surgery",
    "other",
)
"""Allowed ``demographics.specialisation`` values (the surgical speciality, or the one a
resident trains in)."""
LAPAROSCOPY_LEVELS: tuple[str, ...] = ("none", "1-10", "11-50", "51-200", ">200")
"""Allowed ``laparoscopy_experience``: laparoscopic procedures performed as first surgeon."""
SIMULATOR_LEVELS: tuple[str, ...] = ("none", "occasional", "regular")
"""Allowed ``simulator_experience``: earlier use of surgical simulators."""
ROBOTIC_LEVELS: tuple[str, ...] = ("none", "observed", "assisted", "performed")
"""Allowed ``robotic_experience``: the most involved role in robotic surgery so far."""

DEMOGRAPHIC_FIELDS: dict[str, tuple[str, ...]] = {
    "group": GROUPS,
    "specialisation": SPECIALISATIONS,
    "laparoscopy_experience": LAPAROSCOPY_LEVELS,
    "simulator_experience": SIMULATOR_LEVELS,
    "robotic_experience": ROBOTIC_LEVELS,
}
"""Demographic field -> allowed values (``group`` is stored as ``subject_group``)."""

_SUBJECT_RE = re.compile(SUBJECT_CODE_PATTERN)


def validate_outcome(outcome: object, *, field: str = "outcome") -> str:
    """Returns ``outcome`` if it is one of ``TRIAL_OUTCOMES``, else raises ``ConfigError``.

    Example:
        >>> validate_outcome("timed_out")
        'timed_out'
    """
    check_choice(outcome, field, TRIAL_OUTCOMES)
    return str(outcome)


def validate_label(label: object) -> str:
    """Returns a free-practice ``label`` if it cannot be mistaken for a subject code.

    **Decision**: a trial without a subject may carry a label the experimenter chose (its
    own ``trials.label`` column, never ``subject``), 1-64 characters of which at least one
    is not allowed in a subject code (a space, ':', '.', ...): ``"free: warm-up"`` is a
    label, ``"S00"`` or ``"warmup"`` are refused because they read as subject codes. The
    same rule is a CHECK in the table.

    Raises:
        ConfigError: naming the field ``label`` and the value.

    Example:
        >>> validate_label("free: warm-up")
        'free: warm-up'
    """
    label = check_str(label, "label", one_line=False, max_length=64,
              what="a trial label of 1-64 characters of text")
    if _SUBJECT_RE.fullmatch(label):
        raise ConfigError(
            f"trial label {label!r} could be mistaken for a subject code: give a subject "
            "with --subject, or a label with a space or ':' in it (e.g. 'free: warm-up')",
            field="label")
    return label


def outcome_of_summary(summary: Mapping[str, Any] | None) -> str | None:
    """The outcome a completed trial's summary states, or None if it states none.

    The runners put ``outcome`` in the summary; a summary without it (an older runner, a
    test sink) is read like a version-2 row (``schema.OUTCOME_FROM_V2_SQL``): ``completed``
    true -> ``'reached_all'``, false -> ``'timed_out'``.

    Raises:
        ConfigError: an ``outcome`` value not in ``TRIAL_OUTCOMES``.

    Example:
        >>> outcome_of_summary({"completed": False, "points_reached": 3})
        'timed_out'
    """
    if not summary:
        return None
    if summary.get("outcome") is not None:
        return validate_outcome(summary["outcome"], field="summary.outcome")
    done = summary.get("completed")
    if isinstance(done, bool):
        return "reached_all" if done else "timed_out"
    return None


_ERROR_RE = re.compile(r"\b[A-Z][A-Za-z0-9_]*: |\bfailed\b")
"""An exception named as ``Type: message`` (how the runners and the viewer word an error),
or the word "failed"."""


def outcome_of_reason(reason: str) -> str:
    """The outcome of a trial closed early, from the reason it was closed with.

    **Decision**: the sink protocol has no outcome argument (``vasim.trials.sink`` stays as
    it is), so the store reads it from the reason its callers already give: the runners
    close a failed trial with ``"<ExceptionType>: <message>"``, the viewer a failed loop with
    ``"the trial loop failed: ..."`` and a deliberate stop with a plain phrase (``"stopped
    by the experimenter"``, ``"schema changed"``, ``"restarted"``). So: a
    ``KeyboardInterrupt`` (Ctrl-C at the experimenter's terminal) is ``'stopped'``; a reason
    naming an exception (``Type: ``) or saying "failed", or no reason at all, is
    ``'failed'``; any other phrase is ``'stopped'``. The recovery of a dead writer passes
    ``'interrupted'`` explicitly, and any caller may pass the outcome itself.

    Example:
        >>> [outcome_of_reason(r) for r in ("KeyboardInterrupt: ", "DeviceError: x",
        ...                                 "schema changed", "")]
        ['stopped', 'failed', 'stopped', 'failed']
    """
    text = reason.strip()
    if text.startswith("KeyboardInterrupt"):
        return "stopped"
    if not text or _ERROR_RE.search(text):
        return "failed"
    return "stopped"


@dataclass(frozen=True)
class Demographics:
    """A subject's demographic answers (pre-questionnaire), validated against the allowed
    values of ``DEMOGRAPHIC_FIELDS``.

    Raises:
        ConfigError: naming the field and the bad value, with the allowed ones.

    Example:
        >>> Demographics("resident", "urology", "1-10", "none", "observed").group
        'resident'
    """

    group: str
    specialisation: str
    laparoscopy_experience: str
    simulator_experience: str
    robotic_experience: str

    def __post_init__(self) -> None:
        for name, allowed in DEMOGRAPHIC_FIELDS.items():
            v = getattr(self, name)
            check_choice(v, name, allowed)

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> Demographics:
        """Builds it from a dict with exactly the ``DEMOGRAPHIC_FIELDS`` keys.

        Raises:
            ConfigError: a missing or unknown key, or a bad value.
        """
        check_keys(values, list(DEMOGRAPHIC_FIELDS), required=list(DEMOGRAPHIC_FIELDS))
        return cls(**{k: values[k] for k in DEMOGRAPHIC_FIELDS})


__all__ = [
    "DEMOGRAPHIC_FIELDS",
    "GROUPS",
    "LAPAROSCOPY_LEVELS",
    "ROBOTIC_LEVELS",
    "SESSION_STATUSES",
    "SIMULATOR_LEVELS",
    "SPECIALISATIONS",
    "TRIAL_OUTCOMES",
    "TRIAL_STATUSES",
    "Demographics",
    "SessionStatus",
    "TrialOutcome",
    "TrialStatus",
    "outcome_of_reason",
    "outcome_of_summary",
    "validate_label",
    "validate_outcome",
]
