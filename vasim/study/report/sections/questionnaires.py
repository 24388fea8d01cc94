"""The questionnaire section: choices, ratings, schemas, Likert items, comments."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import pandas as pd

from vasim.core.errors import ConfigError
from vasim.study import stats
from vasim.study.protocol import Protocol, QuestionItem
from vasim.study.report.common import (
    FIXTURE_COLORS,
    FIXTURE_ORDER,
    MODE_COLORS,
    MODE_ORDER,
    SectionOut,
    captured,
    fixture_label,
    ids_text,
    ordered_conditions,
    prov_row,
    subjects_text,
)
from vasim.study.report.data import StudyData
from vasim.study.report.figures import (
    choice_rating_figure,
    counts_figure,
    figure_png,
)
from vasim.study.report.html_page import (
    FigureBlock,
    Section,
    TableBlock,
    TextList,
)


# ------------------------------------------------------------------------ questionnaires
def _items(protocol: Protocol | None) -> list[tuple[str, QuestionItem]]:
    if protocol is None:
        return []
    return [(q, it) for q in ("pre", "post") for it in getattr(protocol, q).items]


@dataclass
class _Answers:
    """The questionnaire's tables as the items add their rows."""

    subject_of: dict[int, str]
    choice_rows: list[dict[str, Any]] = field(default_factory=list)
    rating_rows: list[dict[str, Any]] = field(default_factory=list)
    set_rows: list[dict[str, Any]] = field(default_factory=list)
    fix_rows: list[dict[str, Any]] = field(default_factory=list)
    num_rows: list[dict[str, Any]] = field(default_factory=list)
    numeric_long: list[pd.DataFrame] = field(default_factory=list)
    text_items: list[tuple[str, QuestionItem, list[tuple[int, str]]]] = field(
        default_factory=list)
    best: pd.DataFrame | None = None
    worst: pd.DataFrame | None = None
    rating: tuple[pd.DataFrame, tuple[float, float]] | None = None


_TITLE = "Questionnaires"


def questionnaire_section(data: StudyData) -> tuple[Section, list[dict[str, str]]]:
    """Subjective results: best/worst choices, ratings, proposed schemas, Likert items,
    Spearman correlations and free comments (seed Figs. 6.19, 6.24-6.25; spec §4)."""
    out = SectionOut()
    prov: list[dict[str, str]] = []
    a = data.answers
    s = data.sessions
    if s.empty:
        out.notes.append("no sessions: no questionnaire answers")
        return out.section("questionnaires", _TITLE), prov
    items = _items(data.protocol)
    if data.protocol is None:
        out.notes.append("the protocol's questionnaire items are unknown (see the cohort "
                         "notes): answers cannot be interpreted")
        return out.section("questionnaires", _TITLE), prov
    if not items:
        out.notes.append(f"protocol {data.protocol_name!r} asks no questionnaire item beyond "
                         "the demographics")
        return out.section("questionnaires", _TITLE), prov
    _note_unanswered(out, items, a, s)
    ans = _Answers(dict(zip(s["id"].astype(int), s["subject"], strict=True)))
    for qname, it in items:
        _add_item(ans, qname, it, a[(a["questionnaire"] == qname) & (a["item"] == it.id)])
    if ans.best is not None or ans.worst is not None or ans.rating is not None:
        _choice_rating_block(out, ans)
    if ans.choice_rows:
        out.blocks.append(TableBlock(
            "questionnaire_choices", "Choices (best / worst and other single choices)",
            pd.DataFrame(ans.choice_rows), "percent of the respondents of the item; "
            "session_ids: the sessions whose answer it is.",
            columns=("item", "select", "condition", "count", "n_respondents", "percent")))
    if ans.rating_rows:
        out.blocks.append(TableBlock(
            "questionnaire_ratings", "Ratings per condition", pd.DataFrame(ans.rating_rows),
            "Mean, sd (n-1), median, range of the ratings.",
            columns=("item", "label", "n", "mean", "sd", "median", "min", "max", "scale")))
    if ans.set_rows or ans.fix_rows:
        _schema_blocks(out, ans)
    if ans.num_rows:
        _numeric_blocks(out, ans, prov)
    _comment_blocks(out, ans)
    return out.section("questionnaires", _TITLE), prov


def _note_unanswered(out: SectionOut, items: list[tuple[str, QuestionItem]],
                     a: pd.DataFrame, s: pd.DataFrame) -> None:
    """Notes the sessions without answers to a questionnaire the protocol asks."""
    for qname in ("post", "pre"):
        if not any(q == qname for q, _ in items):
            continue
        answered = set(a.loc[a["questionnaire"] == qname, "session_id"])
        missing = s[~s["id"].isin(answered)]
        if len(missing) == len(s):
            out.notes.append(f"no {qname}-questionnaire answers stored for any of the "
                             f"{len(s)} session(s)")
        elif len(missing):
            out.notes.append(f"{len(missing)} session(s) have no {qname}-questionnaire "
                             f"answers (left out of its tables): subject(s) "
                             f"{subjects_text(missing['subject'])}")


def _add_item(ans: _Answers, qname: str, it: QuestionItem, rows: pd.DataFrame) -> None:
    """One item's answers ``rows`` into the table of its type."""
    if it.type in ("condition_choice", "choice"):
        _add_choice(ans, qname, it, rows)
    elif it.type == "condition_rating":
        _add_rating(ans, qname, it, rows)
    elif it.type == "condition_sets":
        _add_sets(ans, qname, it, rows)
    elif it.type in ("likert", "integer"):
        v = rows["value_num"].astype(float)
        ans.num_rows.append({"item": it.id, "questionnaire": qname, "type": it.type,
                             "prompt": it.prompt, "n": int(v.notna().sum()),
                             "mean": float(v.mean()) if v.notna().any() else math.nan,
                             "sd": float(v.std(ddof=1)) if v.notna().sum() > 1 else math.nan,
                             "median": float(v.median()) if v.notna().any() else math.nan,
                             "session_ids": ids_text(rows["session_id"])})
        ans.numeric_long.append(pd.DataFrame({
            "subject": rows["session_id"].map(ans.subject_of), "item": it.id,
            "value": v.to_numpy()}))
    elif it.type == "text":
        texts = [(int(r.session_id), str(r.value)) for r in rows.itertuples(index=False)
                 if str(r.value).strip()]
        ans.text_items.append((qname, it, texts))


def _respondents(rows: pd.DataFrame) -> list[int]:
    return sorted(set(int(v) for v in rows["session_id"]))


def _add_choice(ans: _Answers, qname: str, it: QuestionItem, rows: pd.DataFrame) -> None:
    """A single choice: count and percent per option; the first best / worst condition
    choices feed the choice figure."""
    resp = _respondents(rows)
    opts = list(it.conditions) if it.type == "condition_choice" else list(it.options)
    tab = []
    for o in opts:
        who = rows[rows["value"] == o]
        tab.append({"item": it.id, "questionnaire": qname, "select": it.select or "",
                    "condition": fixture_label(o) if it.type == "condition_choice"
                    else o, "value": o, "count": len(who), "n_respondents": len(resp),
                    "percent": 100.0 * len(who) / len(resp) if resp else math.nan,
                    "session_ids": ids_text(who["session_id"])})
    ans.choice_rows += tab
    if it.type == "condition_choice" and resp:
        frame = pd.DataFrame(tab)[["value", "percent"]].rename(
            columns={"value": "condition"})
        if it.select == "best" and ans.best is None:
            ans.best = frame
        elif it.select == "worst" and ans.worst is None:
            ans.worst = frame


def _add_rating(ans: _Answers, qname: str, it: QuestionItem, rows: pd.DataFrame) -> None:
    """A rating per condition: n, mean, sd, median, range; the first feeds the figure."""
    tab = []
    for c in it.conditions:
        v = rows.loc[rows["key"] == c, "value_num"].astype(float)
        tab.append({"item": it.id, "questionnaire": qname, "condition": c,
                    "label": fixture_label(c), "n": int(v.notna().sum()),
                    "mean": float(v.mean()) if v.notna().any() else math.nan,
                    "sd": float(v.std(ddof=1)) if v.notna().sum() > 1 else math.nan,
                    "median": float(v.median()) if v.notna().any() else math.nan,
                    "min": float(v.min()) if v.notna().any() else math.nan,
                    "max": float(v.max()) if v.notna().any() else math.nan,
                    "scale": f"{it.min}-{it.max}",
                    "session_ids": ids_text(rows.loc[rows["key"] == c, "session_id"])})
    ans.rating_rows += tab
    if ans.rating is None and _respondents(rows):
        ans.rating = (pd.DataFrame(tab), (float(it.min), float(it.max)))


def _add_sets(ans: _Answers, qname: str, it: QuestionItem, rows: pd.DataFrame) -> None:
    """Proposed sets of conditions: count per set, and per condition within the sets."""
    counts: dict[str, list[int]] = {}
    for r in rows.itertuples(index=False):
        counts.setdefault(str(r.value), []).append(int(r.session_id))
    for schema, sids in sorted(counts.items(), key=lambda kv: (-len(kv[1]), kv[0])):
        ans.set_rows.append({"item": it.id, "questionnaire": qname, "schema": "+".join(
            fixture_label(c) for c in schema.split("+")), "value": schema,
            "count": len(sids), "session_ids": ids_text(sids)})
    for c in it.conditions:
        sids = [sid for schema, ss in counts.items() if c in schema.split("+")
                for sid in ss]
        ans.fix_rows.append({"item": it.id, "questionnaire": qname, "condition": c,
                             "label": fixture_label(c), "count": len(sids),
                             "session_ids": ids_text(sids)})


def _choice_rating_block(out: SectionOut, ans: _Answers) -> None:
    """The seed's Fig. 6.19: best / worst choices and ratings per condition."""
    best, worst, rating = ans.best, ans.worst, ans.rating
    cond = [c for c in ordered_conditions(
        (list(best["condition"]) if best is not None else [])
        + (list(worst["condition"]) if worst is not None else [])
        + (list(rating[0]["condition"]) if rating is not None else []),
        FIXTURE_ORDER + MODE_ORDER)]
    known = FIXTURE_COLORS | MODE_COLORS
    fig = choice_rating_figure(best, worst, None if rating is None else rating[0],
                               order=cond, labels={c: fixture_label(c) for c in cond},
                               colors={c: known[fixture_label(c)]
                                       for c in FIXTURE_ORDER + MODE_ORDER},
                               rating_range=(0.0, 10.0) if rating is None else rating[1],
                               noun="mode" if set(cond) & set(MODE_ORDER) else "VF")
    out.blocks.append(FigureBlock(
        "subjective", "Choices and ratings (as the seed's Fig. 6.19)", figure_png(fig),
        "Percent of the respondents choosing each condition as best / worst, and the "
        "mean rating with ± 1 sd (the panels of the items the protocol asks). Numbers: "
        "tables/questionnaire_choices.csv and tables/questionnaire_ratings.csv."))


def _schema_blocks(out: SectionOut, ans: _Answers) -> None:
    """The proposed schemas (seed Figs. 6.24-6.25): the figure and its two tables."""
    st = pd.DataFrame(ans.set_rows, columns=["item", "questionnaire", "schema", "value",
                                             "count", "session_ids"])
    ft = pd.DataFrame(ans.fix_rows)
    n_prop = int(st["count"].sum()) if len(st) else 0
    fig = counts_figure(st, label="schema", title=f"proposed schemas ({n_prop} proposals, "
                        f"{len(st)} distinct)", second=ft.sort_values(
                            "count", ascending=False, kind="stable"),
                        second_label="label",
                        second_title="fixtures within the proposals",
                        xlabel="proposals")
    out.blocks.append(FigureBlock(
        "schemas", "Proposed schemas (as the seed's Figs. 6.24-6.25)", figure_png(fig),
        "Left: how often each set of fixtures was proposed; right: in how many proposals "
        "each fixture appears. Numbers: tables/questionnaire_schemas.csv and "
        "tables/questionnaire_schema_fixtures.csv."))
    out.blocks.append(TableBlock("questionnaire_schemas", "Proposed schemas", st,
                                 columns=("item", "schema", "count")))
    out.blocks.append(TableBlock("questionnaire_schema_fixtures",
                                 "Fixtures within the proposed schemas", ft,
                                 columns=("item", "label", "count")))


def _numeric_blocks(out: SectionOut, ans: _Answers, prov: list[dict[str, str]]) -> None:
    """The Likert and numeric items' table and the Spearman correlations between them."""
    out.blocks.append(TableBlock(
        "questionnaire_numeric", "Likert and numeric items", pd.DataFrame(ans.num_rows),
        "Five-point Likert items (1 = strongly disagree ... 5 = strongly agree) and "
        "integer items: n, mean, sd (n-1), median.",
        columns=("item", "prompt", "n", "mean", "sd", "median")))
    likert = [d for d in ans.numeric_long if len(d)]
    if len(likert) < 2:
        if ans.numeric_long:
            out.notes.append("fewer than 2 Likert/numeric items answered: no Spearman "
                             "correlations")
        return
    long = pd.concat(likert, ignore_index=True)
    try:
        sp, msgs = captured(stats.spearman_items, long, subject="subject",
                            item="item", value="value")
    except ConfigError as exc:
        out.notes.append(f"Spearman correlations not computed: {exc.reason}")
        return
    out.notes.extend(msgs)
    out.blocks.append(TableBlock(
        "questionnaire_spearman", "Spearman correlations between items", sp,
        "rho over the respondents answering both items (n); p: two-sided (t "
        "approximation). provenance.csv lists the sessions."))
    for r in sp.itertuples(index=False):
        both = long[long["item"].isin([r.var1, r.var2])].dropna()
        ss = [sid for sid, subj in ans.subject_of.items()
              if subj in set(both["subject"])]
        prov.append(prov_row("questionnaire_spearman", f"{r.var1} ~ {r.var2}",
                             session_ids=ss))


def _comment_blocks(out: SectionOut, ans: _Answers) -> None:
    """The free-text answers: a list per item and the comments' table."""
    comment_rows = []
    for qname, it, texts in ans.text_items:
        out.blocks.append(TextList(
            f"Free text: {it.id} ({qname}-questionnaire, {len(texts)} answer(s))",
            tuple(f"{ans.subject_of.get(sid, '?')}: {t}" for sid, t in texts),
            empty="no answer"))
        comment_rows += [{"item": it.id, "questionnaire": qname, "session_id": sid,
                          "subject": ans.subject_of.get(sid, ""), "text": t}
                         for sid, t in texts]
    if comment_rows:
        out.blocks.append(TableBlock(
            "questionnaire_comments", "Free-text answers", pd.DataFrame(
                comment_rows, columns=["item", "questionnaire", "session_id", "subject",
                                       "text"]),
            "As entered (the CSV keeps the text verbatim).", display="csv"))
