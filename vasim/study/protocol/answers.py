"""The check of a subject's questionnaire answers against the protocol
(:func:`validate_answers`) into tidy answer rows (the store's ``answers`` table).

**Decision** (issue #29 item 4): apart from :mod:`vasim.study.protocol.questionnaires` (the
items, which the model holds) because it reads the whole :class:`Protocol`: the former
``model`` <-> ``questionnaires`` module cycle is gone.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Literal

from vasim.core.config import (
    check_choice,
    check_int,
    check_str,
    check_table,
    expect,
    rewrap,
)
from vasim.core.errors import FieldError, InputError
from vasim.study.protocol.model import Protocol
from vasim.study.protocol.questionnaires import LIKERT_POINTS, QuestionItem, Questionnaire
from vasim.study.store import DEMOGRAPHIC_FIELDS, Demographics

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
        InputError: (the answers are input data, not a config file; issue #29) an unknown
            item, a missing required answer, or a bad value (field = the item id).
    """
    q: Questionnaire = getattr(protocol, questionnaire)
    check_table(answers, questionnaire, file=source, what="a table of item -> answer",
                error=InputError)
    known = [*(DEMOGRAPHIC_FIELDS if q.demographics else ()), *(i.id for i in q.items)]
    for key in answers:
        expect(key in known, key, f"an item of the {questionnaire} questionnaire of "
                f"{protocol.name!r} ({', '.join(known) or 'no items'}; unknown item)",
                file=source, field=f"{questionnaire}.{key}", error=InputError)
    rows: list[AnswerRow] = []
    demo = None
    if q.demographics:
        try:
            demo = Demographics.from_mapping({k: answers[k] for k in DEMOGRAPHIC_FIELDS
                                              if k in answers})
        except FieldError as exc:
            raise rewrap(exc, questionnaire, source, error=InputError) from exc
        rows += [(k, "", str(answers[k]), None) for k in DEMOGRAPHIC_FIELDS]
    for item in q.items:
        path = f"{questionnaire}.{item.id}"
        if item.id not in answers:
            expect(not item.required, None, "an answer (a required item)", file=source,
                    field=path, error=InputError)
            continue
        try:
            rows += _item_rows(item, answers[item.id])
        except FieldError as exc:
            # An inner field (a condition of a rating: "rating.vg") keeps its detail.
            inner = exc.field or ""
            field = (f"{questionnaire}.{inner}" if inner.startswith(f"{item.id}.")
                     else path)
            raise InputError(exc.reason, file=source, field=field) from exc
    return rows, demo


def _item_rows(item: QuestionItem, a: Any) -> list[AnswerRow]:
    """One answer's rows (errors name ``item.id`` or ``item.id.condition``; the caller
    words them as the answers file's)."""
    t, name = item.type, item.id
    if t in ("choice", "condition_choice"):
        check_choice(a, name, item.options if t == "choice" else item.conditions)
        return [(name, "", a, None)]
    if t == "text":
        check_str(a, name, one_line=False, empty=True, max_length=item.max_length)
        return [(name, "", a, None)]
    if t in ("integer", "likert"):
        lo, hi = (item.min, item.max) if t == "integer" else (1, LIKERT_POINTS)
        check_int(a, name, lo=lo, hi=hi)
        return [(name, "", str(int(a)), float(a))]
    if t == "condition_rating":
        check_table(a, name, what="a table condition -> rating")
        for c in a:
            check_choice(c, name, item.conditions)
        missing = [c for c in item.conditions if c not in a]
        expect(not (missing and item.required), sorted(a), f"ratings for every condition "
                f"(missing: {', '.join(missing)})", field=name)
        out: list[AnswerRow] = []
        for c in item.conditions:
            if c in a:
                check_int(a[c], f"{name}.{c}", lo=item.min, hi=item.max)
                out.append((name, c, str(int(a[c])), float(a[c])))
        return out
    # condition_sets
    expect(isinstance(a, list | tuple) and len(a) <= item.max_entries, a,
            f"a list of at most {item.max_entries} sets of conditions", field=name)
    out = []
    seen: set[frozenset[str]] = set()
    for e, entry in enumerate(a, start=1):
        expect(isinstance(entry, list | tuple) and all(isinstance(c, str) for c in entry),
                entry, f"entry {e}: a list of conditions", field=name)
        members = set(entry)
        unknown = sorted(members - set(item.conditions))
        expect(not unknown, unknown, f"entry {e}: conditions of "
                f"{', '.join(item.conditions)} (unknown condition(s))", field=name)
        expect(len(members) == len(entry) and len(members) >= item.min_size, entry,
                f"entry {e}: at least {item.min_size} different conditions", field=name)
        expect(frozenset(members) not in seen, entry,
                f"entry {e}: a set not proposed before (it repeats an earlier proposal)",
                field=name)
        seen.add(frozenset(members))
        canon = "+".join(c for c in item.conditions if c in members)
        out.append((name, str(e), canon, None))
    return out
