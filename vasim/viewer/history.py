"""The trainee's history in the study store, as the viewer shows it: the learning curve, the
score card's comparisons (earlier trials, the benchmark) and the protocol session's
progress. Called on the controller thread, which owns the store; only
:func:`open_session` writes (it starts a session when the subject has none running)."""

from __future__ import annotations

import math
from typing import Any

from vasim.viewer.state import TrialInfo
from vasim.viewer.trainee import GateCard, ScoreCard, gate_card, score_card

CURVE_METRICS: tuple[str, ...] = ("completion_time", "mean_latency")
"""Per-trial metrics of the learning curve (seconds both: one axis)."""

BENCHMARK_LEVEL = ">200"
"""``demographics.laparoscopy_experience`` of the subjects whose trials are the benchmark."""


def _rows(st: Any, ids: list[int]) -> list[dict[str, float]]:
    if not ids:
        return []
    wide = st.trial_metrics(wide=True)
    return [wide.loc[i].to_dict() for i in ids if i in wide.index]


def trial_score_card(st: Any, info: TrialInfo, metrics: dict[str, float],
                     outcome: str | None) -> ScoreCard:
    """The score card of a stored trial.

    **Decision**: "earlier trials" are the same trainee's earlier completed trials of the
    same schema (by stored name: an edited schema is its own condition) and task — the
    trainee is the subject, else the free-practice label, else the anonymous free trials.
    The **benchmark** is the mean of the completed trials of that schema and task by
    experienced laparoscopists (demographics ``laparoscopy_experience`` ">200", the study
    vocabulary's top level); without such trials there is no benchmark column.

    Args:
        st: the ``TrialStore``. info: the trial. metrics: its ``trial_metrics``.
        outcome: how it ended.
    """
    df = st.trials("completed")
    same = ((df["schema"] == info.schema) & (df["task"] == info.config.task)
            & (df["id"] != info.trial_id))
    subject, label = info.config.subject, info.config.label
    if subject:
        mine = df["subject"] == subject
    elif label:
        mine = df["subject"].isna() & (df["label"] == label)
    else:
        mine = df["subject"].isna() & df["label"].isna()
    earlier = [int(i) for i in df[same & mine & (df["id"] < (info.trial_id or 0))]["id"]]
    demo = st.demographics()
    experts = set(demo[demo["laparoscopy_experience"] == BENCHMARK_LEVEL]["subject"])
    bench = [int(i) for i in df[same & df["subject"].isin(experts)]["id"]]
    return score_card(metrics, title=info.title, outcome=outcome, n_points=len(info.points),
                      earlier=_rows(st, earlier), benchmark=_rows(st, bench),
                      gate=trial_gate_card(st, info.trial_id))


def trial_gate_card(st: Any, trial_id: int | None) -> GateCard | None:
    """The proficiency gate's verdict on a stored trial of a gated block: its stored
    decision (``vasim.study.gates``) with the block's earlier decisions in the session as
    the trainee's curve; None for a trial without a decision (or an expert's)."""
    from vasim.study.gates import gate_records

    if trial_id is None:
        return None
    row = st.trial(trial_id)
    if row.get("session_id") is None:
        return None
    records = gate_records(st, int(row["session_id"]))
    mine = [r for tid, r in records if tid == trial_id]
    if not mine:
        return None
    rec = mine[-1]
    earlier = [r for tid, r in records if r.get("block") == rec.get("block")
               and r.get("n_trials", 0) < rec.get("n_trials", 0)]
    return gate_card(rec, earlier)


def record_browser_sitting(st: Any, session_id: int, index: int) -> None:
    """A browser session's trial that began a later sitting (a retention block's delay) gets
    its ``'sitting'`` event, with the real gap from the previous trial's end to its start
    (``vasim.study.session.sitting_record``)."""
    from vasim.study.session import (
        load_session,
        record_sitting,
        sitting_begins,
        sitting_record,
    )

    s = load_session(st, session_id)
    scheduled = s.schedule[index]
    delay = sitting_begins(s, scheduled)
    tid = s.completed[index]
    if delay is not None and tid is not None:
        rec = sitting_record(st, s, scheduled, delay, False, at=st.trial(tid)["started_at"])
        record_sitting(st, s, scheduled, rec)


BROWSER_SITTING_REMEDY = ("come back then: a browser session waits the real delay "
                          "(a simulated delay is vasim study resume --simulate-delay)")
"""What the trainee page's refusal of an early sitting tells the subject to do."""


def refuse_early_sitting(st: Any, session: Any, scheduled: Any,
                         now: str | None = None) -> None:
    """Refuses to begin ``scheduled`` when it begins a later sitting whose delay has not
    passed since the previous trial ended: the rule of ``vasim study resume`` without
    ``--simulate-delay`` (``vasim.study.session.check_sitting_due``).

    Raises:
        StoreError: naming the sitting, when it is due and how long that is.
    """
    from vasim.study.session import check_sitting_due, sitting_begins, sitting_record

    delay = sitting_begins(session, scheduled)
    if delay is None:
        return
    rec = sitting_record(st, session, scheduled, delay, False)
    check_sitting_due(session, rec, BROWSER_SITTING_REMEDY, now=now)


def learning_curve(st: Any, session_id: int | None, subject: str | None,
                   label: str | None = None) -> tuple[tuple[int, float, float], ...]:
    """The learning curve so far, ``(n, completion_time, mean_latency)`` per trial: the
    session's completed trials in schedule order (a protocol session), or the subject's
    completed free trials — without a subject, the label's free trials, or with neither
    every free trial without a subject."""
    if session_id is not None:
        ids = [int(i) for i in st.schedule(session_id)["trial_id"].dropna()]
    else:
        df = st.trials("completed")
        if subject:
            mine = df["subject"] == subject
        elif label:
            mine = df["subject"].isna() & (df["label"] == label)
        else:
            mine = df["subject"].isna()
        ids = [int(i) for i in df[mine & df["session_id"].isna()]["id"]]
    if not ids:
        return ()
    wide = st.trial_metrics(wide=True)
    out = []
    for n, tid in enumerate(ids, start=1):
        if tid not in wide.index:
            continue
        row = wide.loc[tid]
        out.append((n, *(float(row.get(m, math.nan)) for m in CURVE_METRICS)))
    return tuple(out)  # type: ignore[arg-type]  # (n, *metrics) rows


def open_session(st: Any, subject: str | None, protocol: str | None,
                 extra: dict[str, Any]) -> Any:
    """The subject's running session of ``protocol``, started (with ``extra`` stored in its
    settings) if there is none.

    Raises:
        ConfigError: no subject or no protocol chosen yet.
    """
    from vasim.core.errors import ConfigError
    from vasim.study.protocol import load_protocol
    from vasim.study.session import SessionSettings, load_session, start_session

    if subject is None:
        raise ConfigError("enter a subject code first", field="subject")
    if protocol is None:
        raise ConfigError("pick a protocol first", field="protocol")
    df = st.sessions(subject=subject, protocol=protocol)
    running = df[df["status"] == "running"]
    if len(running):
        sid = int(running["id"].iloc[-1])
    else:
        sid = start_session(st, load_protocol(protocol), subject,
                            settings=SessionSettings(extra=extra))
    return load_session(st, sid)


def session_progress(st: Any, session_id: int, running_index: int | None) -> dict[str, Any]:
    """The panel's progress fields of a session: scheduled trials in all and completed, and
    the 1-based position and condition of the trial running (``running_index``) or next."""
    from vasim.study.session import load_session

    s = load_session(st, session_id)
    pending = s.pending
    cur = running_index if running_index is not None else (pending[0].index if pending
                                                           else None)
    return {"total": len(s.schedule), "completed": len(s.schedule) - len(pending),
            "position": None if cur is None else cur + 1,
            "condition": None if cur is None else s.schedule[cur].condition}


__all__ = ["BENCHMARK_LEVEL", "CURVE_METRICS", "learning_curve", "open_session",
           "record_browser_sitting", "refuse_early_sitting", "session_progress", "trial_gate_card",
           "trial_score_card"]
