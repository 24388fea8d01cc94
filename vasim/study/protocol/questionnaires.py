"""Questionnaires of a study protocol: their items (``QuestionItem``, ``Questionnaire``)
and the check of a subject's answers (``validate_answers``) into tidy answer rows.

The item types and their fields are described in :mod:`vasim.study.protocol`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

from vasim.core.bounds import QUESTION_RANGE, TEXT_LENGTH
from vasim.core.config import (
    check_bool,
    check_choice,
    check_int,
    check_str,
    check_str_tuple,
    fail,
    rewrap,
    show,
)
from vasim.core.errors import ConfigError
from vasim.study.store import DEMOGRAPHIC_FIELDS, Demographics

if TYPE_CHECKING:
    from vasim.study.protocol.model import Protocol

ITEM_TYPES: tuple[str, ...] = ("choice", "text", "integer", "likert", "condition_choice",
                               "condition_rating", "condition_sets")
LIKERT_POINTS = 5
_ID_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")  # fullmatch


@dataclass(frozen=True)
class QuestionItem:
    """One questionnaire item (see the module docstring for the types and fields).

    Attributes:
        id: identifier, unique within its questionnaire (the ``answers.item`` value).
        type: one of ``ITEM_TYPES``. prompt: the question shown. required: must be answered.
        options: ``choice`` options. conditions: ``condition_*`` conditions (filled with the
            protocol's assisted conditions when not given). select: ``condition_choice``:
            ``"best"``, ``"worst"`` or None. min, max: ``integer`` / ``condition_rating``
            range. anchors: ``likert`` labels of 1..5 (or empty). max_entries, min_size:
            ``condition_sets`` limits. max_length: ``text`` limit [characters].
    """

    id: str
    type: str
    prompt: str
    required: bool = True
    options: tuple[str, ...] = ()
    conditions: tuple[str, ...] = ()
    select: str | None = None
    min: int = 0
    max: int = 10
    anchors: tuple[str, ...] = ()
    max_entries: int = 3
    min_size: int = 2
    max_length: int = 2000

    def __post_init__(self) -> None:
        if not isinstance(self.id, str) or not _ID_RE.fullmatch(self.id):
            raise ConfigError(f"got {show(self.id)}, expected an identifier (letters, digits, "
                              "'_')",
                              field="id")
        check_choice(self.type, "type", ITEM_TYPES)
        check_str(self.prompt, "prompt")
        check_bool(self.required, "required")
        check_str_tuple(self.options, "options", empty=True)
        check_str_tuple(self.conditions, "conditions", empty=True)
        check_str_tuple(self.anchors, "anchors", unique=False, empty=True)
        for name in ("min", "max"):
            check_int(getattr(self, name), name, bound=QUESTION_RANGE)
        for name in ("max_entries", "min_size"):
            check_int(getattr(self, name), name, lo=0, hi=1000)
        t = self.type
        if t == "choice" and len(self.options) < 2:
            raise fail(self.options, "at least 2 options (a choice item)", field="options")
        if t != "choice" and self.options:
            raise fail(self.options, f"no options (only choice items have them; this is "
                       f"{t!r})", field="options")
        if self.select is not None:
            if t != "condition_choice":
                raise fail(self.select, f"no select (only condition_choice items have it; this "
                           f"is {t!r})", field="select")
            check_choice(self.select, "select", ("best", "worst"))
        if t in ("integer", "condition_rating") and self.min >= self.max:
            raise fail(self.max, f"max > min = {self.min!r}", field="max")
        if t == "likert" and self.anchors and len(self.anchors) != LIKERT_POINTS:
            raise fail(self.anchors, f"{LIKERT_POINTS} anchors (a likert item)",
                       field="anchors")
        if t == "condition_sets":
            check_int(self.max_entries, "max_entries", lo=1, hi=20)
            check_int(self.min_size, "min_size", lo=1)
        check_int(self.max_length, "max_length", bound=TEXT_LENGTH)

    @property
    def numeric(self) -> bool:
        """Whether the answers are numbers (integer, likert, condition_rating)."""
        return self.type in ("integer", "likert", "condition_rating")


@dataclass(frozen=True)
class Questionnaire:
    """A questionnaire: the standard demographics (pre only) and further items.

    Attributes:
        demographics: ask the demographic fields of ``vasim.study.store.DEMOGRAPHIC_FIELDS``
            (group, specialisation, laparoscopy / simulator / robotic experience).
        items: the other items, in order.
    """

    demographics: bool = False
    items: tuple[QuestionItem, ...] = ()

    def __post_init__(self) -> None:
        check_bool(self.demographics, "demographics")
        if not isinstance(self.items, tuple) or not all(
                isinstance(i, QuestionItem) for i in self.items):
            raise ConfigError(f"must be a tuple of QuestionItem, got {show(self.items)}",
                              field="items")
        seen: set[str] = set()
        for k, item in enumerate(self.items):
            if item.id in seen:
                raise fail(item.id, "an item id not used before (duplicate item id)",
                           field=f"items[{k}].id")
            if self.demographics and item.id in DEMOGRAPHIC_FIELDS:
                raise fail(item.id, "an id other than the demographic fields (asked by "
                           "demographics = true)", field=f"items[{k}].id")
            seen.add(item.id)

    @property
    def empty(self) -> bool:
        return not self.demographics and not self.items



# ------------------------------------------------------------------------ answers
AnswerRow = tuple[str, str, str, float | None]
"""``(item, key, value, value_num)``: one row of the store's ``answers`` table."""


def validate_answers(protocol: Protocol, questionnaire: Literal["pre", "post"],
                     answers: Mapping[str, Any], *, source: str | None = None,
                     ) -> tuple[list[AnswerRow], Any]:
    """Checks one questionnaire's answers against the protocol and makes tidy rows.

    Args:
        protocol: the session's protocol. questionnaire: ``"pre"`` or ``"post"``.
        answers: item id -> answer: a string (choice, text, condition_choice, demographic
            fields), an integer (integer, likert), a mapping condition -> integer
            (condition_rating), a list of lists of conditions (condition_sets).
        source: the file the answers came from (named in errors).

    Returns:
        (rows, demographics): the answer rows (``AnswerRow``; keys: the condition for
        ratings, the 1-based entry number for sets, ``''`` otherwise; a set is stored as its
        conditions in the item's order joined by ``'+'``) and a
        ``vasim.study.store.Demographics`` when the questionnaire asks for demographics
        (else None).

    Raises:
        ConfigError: an unknown item, a missing required answer, or a bad value (field =
            the item id).
    """
    q: Questionnaire = getattr(protocol, questionnaire)
    if not isinstance(answers, Mapping):
        raise ConfigError(f"answers must be a table of item -> answer, got {show(answers)}",
                          file=source, field=questionnaire)
    known = [*(DEMOGRAPHIC_FIELDS if q.demographics else ()), *(i.id for i in q.items)]
    for key in answers:
        if key not in known:
            raise ConfigError(f"unknown item (the {questionnaire} questionnaire of "
                              f"{protocol.name!r} has: {', '.join(known) or 'no items'})",
                              file=source, field=f"{questionnaire}.{key}")
    rows: list[AnswerRow] = []
    demo = None
    if q.demographics:
        try:
            demo = Demographics.from_mapping({k: answers[k] for k in DEMOGRAPHIC_FIELDS
                                              if k in answers})
        except ConfigError as exc:
            raise rewrap(exc, questionnaire, source) from exc
        rows += [(k, "", str(answers[k]), None) for k in DEMOGRAPHIC_FIELDS]
    for item in q.items:
        path = f"{questionnaire}.{item.id}"
        if item.id not in answers:
            if item.required:
                raise ConfigError("missing answer to a required item", file=source, field=path)
            continue
        try:
            rows += _item_rows(item, answers[item.id])
        except ConfigError as exc:
            # An inner field (a condition of a rating: "rating.vg") keeps its detail.
            inner = exc.field or ""
            field = (f"{questionnaire}.{inner}" if inner.startswith(f"{item.id}.")
                     else path)
            raise ConfigError(exc.reason, file=source, field=field) from exc
    return rows, demo


def _item_rows(item: QuestionItem, a: Any) -> list[AnswerRow]:
    t = item.type
    if t == "choice":
        check_choice(a, item.id, item.options)
        return [(item.id, "", a, None)]
    if t == "text":
        check_str(a, item.id, one_line=False, empty=True)
        if len(a) > item.max_length:
            raise ConfigError(f"text longer than {item.max_length} characters ({len(a)})")
        return [(item.id, "", a, None)]
    if t == "integer":
        check_int(a, item.id, lo=item.min, hi=item.max)
        return [(item.id, "", str(int(a)), float(a))]
    if t == "likert":
        check_int(a, item.id, lo=1, hi=LIKERT_POINTS)
        return [(item.id, "", str(int(a)), float(a))]
    if t == "condition_choice":
        check_choice(a, item.id, item.conditions)
        return [(item.id, "", a, None)]
    if t == "condition_rating":
        if not isinstance(a, Mapping):
            raise ConfigError(f"must be a table condition -> rating, got {show(a)}")
        for c in a:
            if c not in item.conditions:
                raise ConfigError(f"unknown condition {c!r} (expected "
                                  f"{', '.join(item.conditions)})")
        missing = [c for c in item.conditions if c not in a]
        if missing and item.required:
            raise ConfigError(f"missing ratings for {', '.join(missing)}")
        out: list[AnswerRow] = []
        for c in item.conditions:
            if c in a:
                check_int(a[c], f"{item.id}.{c}", lo=item.min, hi=item.max)
                out.append((item.id, c, str(int(a[c])), float(a[c])))
        return out
    # condition_sets
    if not isinstance(a, list | tuple) or len(a) > item.max_entries:
        raise ConfigError(f"must be a list of at most {item.max_entries} sets of conditions, "
                          f"got {show(a)}")
    out = []
    seen: set[frozenset[str]] = set()
    for e, entry in enumerate(a, start=1):
        if not isinstance(entry, list | tuple) or not all(isinstance(c, str) for c in entry):
            raise ConfigError(f"entry {e} must be a list of conditions, got {show(entry)}")
        members = set(entry)
        unknown = sorted(members - set(item.conditions))
        if unknown:
            raise ConfigError(f"entry {e}: unknown condition(s) {unknown} (expected "
                              f"{', '.join(item.conditions)})")
        if len(members) != len(entry) or len(members) < item.min_size:
            raise ConfigError(f"entry {e} must list at least {item.min_size} different "
                              f"conditions, got {show(entry)}")
        if frozenset(members) in seen:
            raise ConfigError(f"entry {e} repeats an earlier proposal: {show(entry)}")
        seen.add(frozenset(members))
        canon = "+".join(c for c in item.conditions if c in members)
        out.append((item.id, str(e), canon, None))
    return out
