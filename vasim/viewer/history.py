"""The trainee's history in the study store, as the viewer shows it: the learning curve, the
score card's comparisons (earlier trials, the benchmark) and the protocol session's
progress. Called on the controller thread, which owns the store; only
:func:`open_session` writes (it starts a session when the subject has none running, and
only with a reason when the subject completed the protocol: :func:`session_rule`)."""

from __future__ import annotations

import json
import math
from typing import Any

from vasim.core.config import expect
from vasim.trials.configs import TeleopTrialConfig
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
    trainee is the subject, else the free-practice label, else the anonymous free trials;
    for a teleoperation trial, of the needle task in the same mode (``stdt``, ``mrcp``,
    ``mrcp_cam``: their schema is ``none`` in every mode).
    The **benchmark** is the mean of the completed trials of that schema and task by
    experienced laparoscopists (demographics ``laparoscopy_experience`` ">200", the study
    vocabulary's top level); without such trials there is no benchmark column.

    Args:
        st: the ``TrialStore``. info: the trial. metrics: its ``trial_metrics``.
        outcome: how it ended.
    """
    df = st.trials("completed")
    if not isinstance(info.config, TeleopTrialConfig):
        same = (df["schema"] == info.schema) & (df["task"] == info.config.task)
    else:   # a teleoperation trial: the needle task in the same mode (teleop_live)
        modes = df["config_json"].map(lambda c: json.loads(c).get("mode")
                                      if isinstance(c, str) else None)
        same = (df["task"] == "needle") & (modes == info.config.mode)
    same &= df["id"] != info.trial_id
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


AGAIN_FIELD = "Again, because"
"""The experimenter page's field for the reason to run a completed protocol again (the
page's ``vasim study run --again REASON``)."""

AGAIN_OPTION = AGAIN_FIELD
"""The ``field`` of the page's refusals about that reason (``ConfigError.field``): the
page's field, by its label."""

AGAIN_ASK = f"enter the reason in '{AGAIN_FIELD}', press Set reason, then Start"
"""How the page asks for the reason (``check_again``'s ``ask``)."""


def check_again_reason(text: str) -> str | None:
    """The reason typed in the page's :data:`AGAIN_FIELD`, stripped (None: empty, no reason).

    Raises:
        ConfigError: a multi-line or over-long reason (``check_again``'s limits).
    """
    from vasim.study.session import MAX_REASON_CHARS

    reason = str(text).strip()
    if not reason:
        return None
    expect("\n" not in reason and "\r" not in reason and len(reason) <= MAX_REASON_CHARS,
           reason, f"a one-line reason of 1-{MAX_REASON_CHARS} characters", field=AGAIN_OPTION)
    return reason


def session_rule(st: Any, subject: str, protocol: str, again: str | None,
                 ) -> tuple[int | None, str | None]:
    """Which session a protocol Start of ``subject`` runs in (issue #30 item 3, the rule of
    ``vasim study run`` on the page): ``(running session id, None)`` to resume the
    subject's open session, or ``(None, notes)`` for a new one (``notes``: what
    ``check_again`` stores with it, None without a reason).

    **Decisions**: an open (running) session is resumed, as it always was on the page (a
    reload, the next trial, another day's sitting) -- never a second one: a reason given
    while a session is open is refused (the reason would be false, and the store keeps one
    running session per subject and protocol). A subject who *completed* the protocol gets
    a new session only with a reason, stored with it exactly as ``--again`` stores it
    (``sessions.notes``: "again after completed session N: REASON"); an aborted session
    frees the subject. The same words as the command line, naming the page's field.

    Raises:
        ConfigError: (field :data:`AGAIN_FIELD`) the subject completed the protocol and no reason
            was given; a reason for a subject with an open session or without a completed
            one; a bad reason.
    """
    from vasim.core.errors import ConfigError
    from vasim.study.session import check_again

    df = st.sessions(subject=subject, protocol=protocol)
    running = df[df["status"] == "running"]
    if len(running):
        row = running.iloc[-1]
        sid = int(row["id"])
        if again is not None:
            raise ConfigError(
                f"subject {subject!r} has an open session {sid} of protocol {protocol!r} "
                f"({int(row['n_completed'])} of {int(row['n_trials'])} trials done): Start "
                f"resumes it; a reason in '{AGAIN_FIELD}' is only for a new session after a "
                "completed one (clear it, or abort the open session first: vasim study "
                "abort)", field=AGAIN_OPTION)
        return sid, None
    return None, check_again(st, protocol, subject, again, option=AGAIN_OPTION,
                             ask=AGAIN_ASK)


def open_session(st: Any, subject: str | None, protocol: str | None,
                 extra: dict[str, Any], again: str | None = None) -> Any:
    """The subject's running session of ``protocol``, or a new one (with ``extra`` stored
    in its settings) when :func:`session_rule` allows it: a subject who completed the
    protocol needs ``again`` (the reason, stored with the new session).

    Raises:
        ConfigError: no subject or no protocol chosen yet; the rule's refusals.
    """
    from vasim.core.errors import ConfigError
    from vasim.study.protocol import load_protocol
    from vasim.study.session import SessionSettings, load_session, start_session

    if subject is None:
        raise ConfigError("enter a subject code first", field="subject")
    if protocol is None:
        raise ConfigError("pick a protocol first", field="protocol")
    sid, notes = session_rule(st, subject, protocol, again)
    if sid is None:
        sid = start_session(st, load_protocol(protocol), subject,
                            settings=SessionSettings(extra=extra), notes=notes)
    return load_session(st, sid)


def completed_note(st: Any, subject: str, protocol: str) -> str | None:
    """One line for the panel when ``subject`` completed ``protocol`` (no session open):
    Start is refused until a reason is given; None otherwise."""
    df = st.sessions(subject=subject, protocol=protocol)
    if (df["status"] == "running").any():
        return None
    done = df[df["status"] == "completed"]
    if done.empty:
        return None
    ids = ", ".join(str(int(i)) for i in done["id"])
    return (f"{subject} already completed {protocol} (session{'s' if len(done) > 1 else ''} "
            f"{ids}): Start is refused; to run it again {AGAIN_ASK}")


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


__all__ = ["AGAIN_ASK", "AGAIN_FIELD", "AGAIN_OPTION", "BENCHMARK_LEVEL", "CURVE_METRICS",
           "check_again_reason", "completed_note", "learning_curve", "open_session",
           "record_browser_sitting", "refuse_early_sitting", "session_progress",
           "session_rule", "trial_gate_card", "trial_score_card"]
