"""Questionnaires of a study protocol: their items (``QuestionItem``, ``Questionnaire``)
(the check of a subject's answers into tidy answer rows, ``validate_answers``, reads the
whole protocol: it is in :mod:`vasim.study.protocol.answers`, above the model; issue #29
item 4, no ``model`` <-> ``questionnaires`` module cycle).

The item types and their fields are described in :mod:`vasim.study.protocol`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from vasim.core.bounds import QUESTION_RANGE, TEXT_LENGTH
from vasim.core.config import (
    check_bool,
    check_choice,
    check_int,
    check_str,
    check_str_tuple,
    expect,
    fail,
)
from vasim.study.store import DEMOGRAPHIC_FIELDS

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
        expect(isinstance(self.id, str) and _ID_RE.fullmatch(self.id), self.id,
                "an identifier (letters, digits, '_')", field="id")
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
        expect(isinstance(self.items, tuple) and all(
                isinstance(i, QuestionItem) for i in self.items), self.items,
                "a tuple of QuestionItem", field="items")
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
