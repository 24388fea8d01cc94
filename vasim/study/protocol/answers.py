"""The check of a subject's questionnaire answers against the protocol
(:func:`validate_answers`) into tidy answer rows (the store's ``answers`` table).

**Decision** (issue #29 item 4): apart from :mod:`vasim.study.protocol.questionnaires` (the
items, which the model holds) because it reads the whole :class:`Protocol`: the former
``model`` <-> ``questionnaires`` module cycle is gone.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Literal

from vasim.core.config import check_choice, check_int, check_str, rewrap, show
from vasim.core.errors import ConfigError
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
