"""The cohort section: subjects, groups, demographics, sessions."""

from __future__ import annotations

import math

import pandas as pd

from vasim.study.report.common import (
    SectionOut,
    ids_text,
    subjects_text,
)
from vasim.study.report.data import StudyData
from vasim.study.report.figures import (
    demographics_figure,
    figure_png,
)
from vasim.study.report.html_page import (
    FigureBlock,
    Section,
    TableBlock,
)
from vasim.study.store import (
    GROUPS,
    LAPAROSCOPY_LEVELS,
    ROBOTIC_LEVELS,
    SIMULATOR_LEVELS,
    SPECIALISATIONS,
)

_DEMOGRAPHIC_PANELS: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("specialisation", "specialisation", SPECIALISATIONS),
    ("laparoscopy_experience", "laparoscopy (procedures as first surgeon)",
     LAPAROSCOPY_LEVELS),
    ("simulator_experience", "surgical simulators", SIMULATOR_LEVELS),
    ("robotic_experience", "robotic surgery", ROBOTIC_LEVELS),
)



# ----------------------------------------------------------------------------- cohort
def cohort_section(data: StudyData) -> tuple[Section, list[dict[str, str]]]:
    """Cohort description: subjects, groups, specialisations, experience, sessions.

    Returns:
        The section and its provenance rows.
    """
    out = SectionOut()
    out.notes.extend(data.notes)
    if data.n_outside:
        out.notes.append(f"{data.n_outside} trial row(s) of the store were run outside any "
                         "session (stand-alone `vasim trial`): not analysed")
    s = data.sessions
    if s.empty:
        out.notes.append("no sessions stored" + (f" for protocol {data.protocol_name!r}"
                                                 if data.protocol_name else "")
                         + ": the store holds no study data to describe or analyse")
        return out.section("cohort", "Cohort"), []
    subjects = sorted(set(s["subject"]))
    demo = data.demographics
    with_demo = set(demo["subject"])
    no_demo = [x for x in subjects if x not in with_demo]
    if no_demo:
        out.notes.append(f"no demographics (pre-questionnaire) for {len(no_demo)} subject(s): "
                         f"{subjects_text(no_demo)}; they count as group 'unknown'")
    group_of = dict(zip(demo["subject"], demo["subject_group"], strict=True))
    reruns = data.schedule[data.schedule["attempts"] > 1]
    out.blocks.append(TableBlock(
        "cohort_summary", "Cohort and sessions",
        _summary_table(data, subjects, group_of, no_demo),
        "Counts over the sessions of this protocol; 'subjects' and 'session_ids' list whom "
        "each count covers.", columns=("quantity", "value")))
    _demographic_blocks(out, demo)
    sess = s[["id", "subject", "status", "n_trials", "n_completed", "n_interrupted", "seed",
              "created_at", "ended_at", "notes"]].rename(columns={"id": "session_id"})
    out.blocks.append(TableBlock(
        "cohort_sessions", "Sessions", sess,
        "One row per session: progress, randomisation seed and notes (e.g. why a session "
        "was aborted).", display="details"))
    if len(reruns):
        _reruns_block(out, reruns, data.trials)
    return out.section("cohort", "Cohort"), []


def _subjects_of(frame: pd.DataFrame) -> str:
    return " ".join(sorted(set(frame["subject"])))


def _summary_table(data: StudyData, subjects: list[str], group_of: dict[str, str],
                   no_demo: list[str]) -> pd.DataFrame:
    """The cohort's counts: subjects per group, sessions per status, trials run and re-run;
    with the subjects and sessions each count covers."""
    s, sched, tr = data.sessions, data.schedule, data.trials
    interrupted = tr[tr["status"] == "interrupted"]
    reruns = sched[sched["attempts"] > 1]
    completed_s = s[s["status"] == "completed"]
    running_s = s[s["status"] == "running"]
    aborted_s = s[s["status"] == "aborted"]
    n_done = int(sched["trial_id"].notna().sum())
    rows = [
        ("subjects", len(subjects), " ".join(subjects), ""),
        ("surgeons", sum(group_of.get(x) == "surgeon" for x in subjects),
         " ".join(x for x in subjects if group_of.get(x) == "surgeon"), ""),
        ("residents", sum(group_of.get(x) == "resident" for x in subjects),
         " ".join(x for x in subjects if group_of.get(x) == "resident"), ""),
        ("group unknown (no demographics)", len(no_demo), " ".join(no_demo), ""),
        ("sessions", len(s), _subjects_of(s), ids_text(s["id"])),
        ("sessions completed", len(completed_s), _subjects_of(completed_s),
         ids_text(completed_s["id"])),
        ("sessions incomplete (running)", len(running_s), _subjects_of(running_s),
         ids_text(running_s["id"])),
        ("sessions aborted", len(aborted_s), _subjects_of(aborted_s), ids_text(aborted_s["id"])),
        ("scheduled trials", len(sched), _subjects_of(s), ids_text(s["id"])),
        ("scheduled trials completed (analysed)", n_done, _subjects_of(sched[sched["trial_id"]
                                                                       .notna()]), ""),
        ("interrupted trial rows", len(interrupted), _subjects_of(interrupted),
         ids_text(interrupted["session_id"])),
        ("scheduled trials re-run after an interruption", len(reruns), _subjects_of(reruns),
         ids_text(reruns["session_id"])),
    ]
    return pd.DataFrame(rows, columns=["quantity", "value", "subjects", "session_ids"])


def _demographic_blocks(out: SectionOut, demo: pd.DataFrame) -> None:
    """Specialisation and experience per group: the table and (with demographics) the
    seed's Fig. 6.16."""
    drows = []
    for fld, _, levels in _DEMOGRAPHIC_PANELS:
        for lev in levels:
            who = demo[demo[fld] == lev]
            sur = who[who["subject_group"] == "surgeon"]
            res = who[who["subject_group"] == "resident"]
            drows.append({"field": fld, "value": lev, "surgeon": len(sur), "resident": len(res),
                          "total": len(who),
                          "percent": 100.0 * len(who) / len(demo) if len(demo) else math.nan,
                          "subjects": " ".join(sorted(who["subject"])),
                          "session_ids": ids_text(who["session_id"])})
    dtab = pd.DataFrame(drows)
    out.blocks.append(TableBlock(
        "cohort_demographics", "Specialisation and experience (pre-questionnaire)", dtab,
        f"Subjects per answer and group; percent of the {len(demo)} subject(s) with "
        "demographics; session_ids: the sessions whose pre-questionnaire gave them.",
        columns=("field", "value", "surgeon", "resident", "total", "percent")))
    if len(demo):
        counts = pd.DataFrame(
            [{"field": r["field"], "value": r["value"], "group": g, "n": r[g]}
             for r in drows for g in GROUPS])
        fig = demographics_figure(counts, fields=[(f, t) for f, t, _ in _DEMOGRAPHIC_PANELS],
                                  groups=GROUPS,
                                  levels={f: lv for f, _, lv in _DEMOGRAPHIC_PANELS})
        out.blocks.append(FigureBlock(
            "demographics", "Composition of the cohort (as the seed's Fig. 6.16)", figure_png(fig),
            "Subjects per specialisation and experience level, stacked by group; numbers "
            "in tables/cohort_demographics.csv."))


def _reruns_block(out: SectionOut, reruns: pd.DataFrame, tr: pd.DataFrame) -> None:
    """The scheduled trials re-run after an interruption, with their interrupted attempts."""
    rr = []
    for r in reruns.itertuples(index=False):
        att = tr[(tr["session_id"] == r.session_id)
                 & (tr["schedule_index"] == r.trial_index)]
        rr.append({"session_id": int(r.session_id), "subject": r.subject,
                   "trial_index": int(r.trial_index), "condition": r.condition,
                   "attempts": int(r.attempts),
                   "trial_id": None if pd.isna(r.trial_id) else int(r.trial_id),
                   "interrupted_trial_ids": ids_text(
                       att.loc[att["status"] == "interrupted", "id"])})
    out.blocks.append(TableBlock(
        "cohort_reruns", "Scheduled trials re-run after an interruption",
        pd.DataFrame(rr), "The completed attempt (trial_id) is the one analysed; the "
        "interrupted attempts are kept in the store but not analysed."))


