"""The trainee's texts (issue #19 §4, issue #20 §1, §5): one trial number, how a trial ended,
the instruction, and the score card against earlier trials and a benchmark."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vasim.records.trial_metrics import TRIAL_METRICS
from vasim.viewer.trainee import (
    OUTCOME_TEXT,
    SCORE_METRICS,
    frame_outcome,
    instruction,
    score_card,
    score_card_markdown,
    score_key,
    trial_title,
)

METRICS = {"duration": 42.25, "points_reached": 12.0, "contact_count": 3.0,
           "excessive_force_time": 0.5, "path_l2": 0.3127, "completion_time": math.nan}


def test_every_outcome_has_words_and_a_timed_out_trial_never_says_done() -> None:
    from vasim.study.store.vocabulary import TRIAL_OUTCOMES

    assert set(OUTCOME_TEXT) == set(TRIAL_OUTCOMES)
    assert frame_outcome(True, 12, 30) == "timed_out" and frame_outcome(True, 30, 30) == \
        "reached_all" and frame_outcome(False, 3, 30) is None
    assert "done" not in OUTCOME_TEXT["timed_out"]


def test_the_score_card_in_plain_units_with_dashes_for_absent_metrics() -> None:
    card = score_card(METRICS, title=trial_title(17, 3), outcome="timed_out", n_points=30)
    rows = {r.name: r for r in card.rows}
    assert rows["path_l2"].value == pytest.approx(312.7) and rows["path_l2"].unit == "mm"
    assert rows["path_dev_attempted_mm"].value is None      # not stored: shown as "—"
    md = score_card_markdown(card)
    assert "Score card — trial 17" in md and "**time ran out**" in md
    assert "| Time | 42.2 s |" in md or "| Time | 42.3 s |" in md
    assert "| Points reached | 12 of 30 |" in md and "| Path length | 313 mm |" in md
    assert "| Mean distance from the path \\(part attempted\\) | — |" in md or \
        "| Mean distance from the path (part attempted) | — |" in md
    assert "| Tissue contacts | 3 |" in md
    assert "| Excessive-force time | 0.5 s |" in md and "earlier" not in md.lower()[:200]
    # Every metric the card reads is a trial metric (or one announced in parallel).
    assert {n for n, *_ in SCORE_METRICS} <= set(TRIAL_METRICS)


def test_earlier_trials_and_the_benchmark_are_their_means() -> None:
    earlier = [{"duration": 60.0, "path_dev_attempted_mm": 4.0}, {"duration": 50.0}]
    bench = [{"duration": 20.0, "path_l2": 0.2}]
    card = score_card({**METRICS, "path_dev_attempted_mm": 3.5}, title="trial 9",
                      outcome="reached_all", n_points=30, earlier=earlier, benchmark=bench)
    rows = {r.name: r for r in card.rows}
    assert rows["duration"].earlier == 55.0 and rows["duration"].benchmark == 20.0
    assert rows["path_dev_attempted_mm"].earlier == 4.0 and rows["path_l2"].benchmark == 200.0
    md = score_card_markdown(card)
    assert "Your earlier 2 (mean)" in md and "Benchmark (1 expert trials)" in md
    assert "| Time | 42.2 s | 55.0 s | 20.0 s |" in md or "| Time | 42.3 s | 55.0 s |" in md


@given(st.text(max_size=40))
def test_card_text_is_escaped(title: str) -> None:
    md = score_card_markdown(score_card({}, title=title, outcome=None, n_points=1))
    assert "<" not in md.replace("&lt;", "")


def test_one_sentence_instructions() -> None:
    for task, n, kind in (("trajectory/v2", 30, "laparoscopic"), ("point", 1, "browser")):
        text = instruction(task, n, kind)
        assert text.count(".") == 1 and text.endswith(".") and str(n) in text


STILL = {"duration": 180.0, "points_reached": 0.0, "path_covered_frac": 0.0,
         "path_dev_attempted_mm": math.nan, "path_dev_max_mm": 0.0, "path_l2": 0.0}
MOVED = {"duration": 180.0, "points_reached": 0.0, "path_covered_frac": 0.05,
         "path_dev_attempted_mm": 25.0, "path_dev_max_mm": 40.0, "path_l2": 0.2}


def test_not_moving_scores_worst_not_best() -> None:
    card = score_card(STILL, title="trial 1 of 38", outcome="timed_out", n_points=30)
    md = score_card_markdown(card)
    assert "| Path covered | 0 % |" in md
    assert md.count("— (nothing attempted)") == 2        # mean and maximum distance
    assert "0.0 mm" not in md                            # never "0.0 mm from the path"
    # Even a bad trial that moved ranks above it; so does a faster one with more points.
    assert score_key(MOVED) > score_key(STILL)
    assert score_key({**MOVED, "points_reached": 1.0}) > score_key(MOVED)
    assert score_key({**MOVED, "path_dev_attempted_mm": 5.0}) > score_key(MOVED)
    assert score_key({**MOVED, "duration": 60.0}) > score_key(MOVED)


def test_the_card_says_how_many_earlier_trials_it_beats() -> None:
    card = score_card(MOVED, title="trial 3 of 38", outcome="timed_out", n_points=30,
                      earlier=[STILL, {**MOVED, "points_reached": 2.0}])
    assert card.better_than == 1
    assert "Better than 1 of your 2 earlier trials" in score_card_markdown(card)


def test_one_trial_name_on_both_pages() -> None:
    """The trainee's HUD, the score card and the experimenter's live metrics all use
    ``TrialInfo.title``; a protocol trial is named by its place in the schedule."""
    import numpy as np

    from vasim.trials.vf import TrialConfig
    from vasim.viewer.state import TrialInfo

    def info(**kw: object) -> TrialInfo:
        return TrialInfo(number=7, config=TrialConfig(), schema="vg", fixtures=("vg",),
                         task_name="trajectory/v1", points=np.zeros((3, 3)), normals=None,
                         reach_radius=0.005, start=np.zeros(3), **kw)  # type: ignore[arg-type]

    assert info(trial_id=57, schedule_index=0, schedule_total=38,
                mode="protocol").title == "trial 1 of 38"
    assert info(trial_id=57, mode="free").title == "trial 57"
    assert info(mode="demo").title == "demo run 7 (not stored)"
