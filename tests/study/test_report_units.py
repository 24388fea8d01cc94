"""Units of the report: HTML escaping and rendering, figures, and the pure helpers."""

from __future__ import annotations

import html
import math
import struct
from html.parser import HTMLParser

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.study.report import (
    FIXTURE_ORDER,
    complete_subjects,
    fixture_label,
    ids_text,
    ordered_conditions,
    vf_trial_outcomes,
)
from vasim.study.report.figures import (
    CurveGroups,
    CurveText,
    box_figure,
    choice_rating_figure,
    clipped_error_bars,
    counts_figure,
    demographics_figure,
    figure_png,
    label_png,
    learning_curve_figure,
)
from vasim.study.report.html_page import (
    FigureBlock,
    Notes,
    Paragraph,
    ReportDoc,
    Section,
    TableBlock,
    TextList,
    esc,
    format_value,
    render_html,
)

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _png_size(png: bytes) -> tuple[int, int]:
    """Width and height [px] from the PNG IHDR chunk."""
    assert png[:8] == PNG_MAGIC and png[12:16] == b"IHDR"
    return struct.unpack(">II", png[16:24])


# ------------------------------------------------------------------------------- HTML
@given(st.text())
def test_esc_round_trips_and_leaves_no_markup(text: str) -> None:
    e = esc(text)
    assert html.unescape(e) == text
    assert not set(e) & set("<>\"'")


class _Tags(HTMLParser):
    """Collects the start tags (with attribute names) and the text of a page."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.tags: list[tuple[str, tuple[str, ...]]] = []
        self.text: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append((tag, tuple(a for a, _ in attrs)))

    def handle_data(self, data: str) -> None:
        self.text.append(data)


def _doc(text: str) -> ReportDoc:
    df = pd.DataFrame({text: [text, 1.5]})
    return ReportDoc(title=text, meta=((text, text),), sections=(
        Section("s", text, (Paragraph(text), Notes((text,), title=text),
                            TextList(text, (text,)), TableBlock("t", text, df, caption=text),
                            FigureBlock("f", text, PNG_MAGIC, text))),))


@settings(max_examples=60, deadline=None)
@given(st.text(alphabet=st.sampled_from(list("<>&\"'ab /=!-")), min_size=1, max_size=30))
def test_user_text_never_becomes_markup(text: str) -> None:
    """Whatever the text, the page has the same tags as with a harmless text, and the text
    comes back verbatim as character data."""
    got, ref = _Tags(), _Tags()
    got.feed(render_html(_doc(text)))
    ref.feed(render_html(_doc("x")))
    assert got.tags == ref.tags
    assert sum(t == text for t in got.text) >= 8  # title, headings, cells, notes, list...


def test_format_value() -> None:
    assert format_value(None) == "–" and format_value(float("nan")) == "–"
    assert format_value(pd.NA) == "–" and format_value(True) == "yes"
    assert format_value(np.int64(46)) == "46" and format_value(3.0) == "3"
    assert format_value(0.123456) == "0.1235" and format_value(98131.4) == "98131"
    assert format_value(3.6e-45) == "3.6e-45" and format_value(float("inf")) == "inf"
    assert format_value("text") == "text"


def test_tables_fold_and_link_their_csv() -> None:
    df = pd.DataFrame({"a": range(3), "b": ["x", "y", "z"]})
    page = render_html(ReportDoc("t", (), (Section("s", "S", (
        TableBlock("big", "Big", df, display="csv"),
        TableBlock("fold", "Fold", df, display="details", columns=("b",)),)),)))
    assert 'href="tables/big.csv"' in page and "(3 rows)" in page
    assert "<details><summary>show 3 rows</summary>" in page
    fold = page.split('id="tab-fold"')[1]
    assert "<th>b</th>" in fold and "<th>a</th>" not in fold


# ------------------------------------------------------------------------------ helpers
@given(st.lists(st.integers(min_value=0, max_value=10**9), max_size=30))
def test_ids_text_is_sorted_distinct(ids: list[int]) -> None:
    got = [int(x) for x in ids_text(ids).split()]
    assert got == sorted(set(ids))


@given(st.lists(st.sampled_from([*FIXTURE_ORDER, "zz", "aa"]), unique=True))
def test_ordered_conditions_is_a_permutation(present: list[str]) -> None:
    out = ordered_conditions(present, FIXTURE_ORDER)
    assert sorted(out) == sorted(present)
    known = [c for c in out if c in FIXTURE_ORDER]
    assert known == [c for c in FIXTURE_ORDER if c in present]
    assert out[len(known):] == sorted(set(present) - set(FIXTURE_ORDER))


def test_fixture_labels() -> None:
    assert [fixture_label(c) for c in FIXTURE_ORDER] == ["none", "VG", "AG", "MS", "Mag",
                                                          "FF"]
    assert fixture_label("stdt") == "StdT"


@given(st.dictionaries(st.sampled_from(["s1", "s2", "s3", "s4"]),
                       st.sets(st.sampled_from(["a", "b", "c"]), min_size=1), min_size=1))
def test_complete_subjects(cells_of: dict[str, set[str]]) -> None:
    cells = pd.DataFrame([{"subject": s, "f": lev} for s, levs in cells_of.items()
                          for lev in sorted(levs)])
    kept, missing = complete_subjects(cells, "f", ["a", "b", "c"])
    assert set(kept["subject"]) | set(missing) == set(cells_of)
    assert not set(kept["subject"]) & set(missing)
    for s in set(kept["subject"]):
        assert cells_of[s] == {"a", "b", "c"}
    for s, m in missing.items():
        assert set(m) == {"a", "b", "c"} - cells_of[s] and m


@settings(deadline=None)   # no wall-clock limit: the machine is shared
@given(st.lists(st.tuples(st.booleans(), st.floats(0.0, 100.0), st.floats(0.01, 5.0)),
                min_size=1, max_size=12))
def test_trial_outcomes_sum_errors_and_reached_latencies(points: list) -> None:
    reached = np.array([p[0] for p in points])
    err = np.array([p[1] for p in points])
    lat = np.where(reached, [p[2] for p in points], np.nan)
    pm = pd.DataFrame({"trial_id": 7, "reached": reached, "error_l1_mm_s": err,
                       "latency": lat})
    a = pd.DataFrame({"trial_id": [7], "condition": ["ff"], "probe": [False]})
    r = vf_trial_outcomes(a, pm).iloc[0]
    assert r["eq65"] == pytest.approx(err.sum())  # eq. 6.5 times the sample period [mm s]
    assert r["n_points"] == len(points) and r["points_reached"] == reached.sum()
    assert bool(r["completed"]) == bool(reached.all())
    if reached.any():
        assert r["latency"] == pytest.approx(lat[reached].sum())
    else:
        assert math.isnan(r["latency"])
    assert r["fixture"] == "FF"


def test_trial_outcomes_leave_out_teleoperation_modes() -> None:
    a = pd.DataFrame({"trial_id": [1, 2], "condition": ["stdt", "none"], "probe": [False,
                                                                                  True]})
    pm = pd.DataFrame({"trial_id": [1, 2], "reached": [True, True], "error_l1": [1.0, 2.0],
                       "latency": [1.0, 1.0]})
    assert list(vf_trial_outcomes(a, pm)["trial_id"]) == [2]


# ------------------------------------------------------------------------------- figures
def _summary(conditions: tuple[str, ...] = ()) -> pd.DataFrame:
    rows = []
    for c in conditions or (None,):
        for t in range(1, 7):
            m = 10.0 * t ** -0.5
            rows.append({"mode": c, "trial": t, "n": 5, "mean": m, "q25": m - 1, "q75": m + 1})
    df = pd.DataFrame(rows)
    return df if conditions else df.drop(columns="mode")


def test_learning_curve_figure_labels_and_legend() -> None:
    band = pd.DataFrame({"trial": [1.0, 6.0], "fit": [10.0, 4.1], "lower": [9.0, 3.5],
                         "upper": [11.0, 4.7]})
    fig = learning_curve_figure(_summary(), CurveText(ylabel="latency [s]", title="t",
                                                       split_after=3.5),
                                band=band, fit_label="fit")
    ax = fig.axes[0]
    assert ax.get_ylabel() == "latency [s]" and ax.get_xlabel() == "VF-free trial number"
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == ["interquartile range (25-75 %)", "mean over subjects",
                      "95 % confidence band of the fit", "fit"]
    assert [t.get_text() for t in ax.get_xticklabels()] == ["1", "2", "3", "4", "5", "6"]
    w, h = _png_size(figure_png(fig))
    assert (w, h) == (700, 420)
    multi = learning_curve_figure(_summary(("b", "a")), CurveText(ylabel="y [m]", title="t"),
                                  groups=CurveGroups("mode", order=["a", "b"],
                                                     labels={"a": "A", "b": "B"},
                                                     bands={"a": band}))
    texts = [t.get_text() for t in multi.axes[0].get_legend().get_texts()]
    assert texts == ["A", "B", "interquartile range", "power-law fit"]
    empty = learning_curve_figure(_summary().iloc[:0], CurveText(ylabel="y", title="t"))
    assert "no data" in [t.get_text() for t in empty.axes[0].texts]


def test_box_figure_keeps_the_given_order() -> None:
    order = ["none", "VG", "AG", "MS", "Mag", "FF"]
    rng = np.random.default_rng(1)
    data = pd.DataFrame({"fixture": np.repeat(order[::-1], 4), "e": rng.normal(size=24),
                         "l": rng.normal(size=24)})
    fig = box_figure(data, group="fixture", values=[("e", "error [m]"), ("l", "latency [s]")],
                     order=order, xlabel="fixture", title="t")
    for ax in fig.axes:
        assert [t.get_text() for t in ax.get_xticklabels()] == order
        assert ax.get_xlabel() == "fixture (n = 4 per box)"
    assert [ax.get_ylabel() for ax in fig.axes] == ["error [m]", "latency [s]"]
    uneven = box_figure(data.iloc[1:], group="fixture", values=[("e", "e [m]")], order=order,
                        xlabel="fixture", title="t")
    ticks = [t.get_text() for t in uneven.axes[0].get_xticklabels()]
    assert ticks[-1] == "FF\n(n=3)" and ticks[0] == "none\n(n=4)"


def test_choice_rating_and_count_figures() -> None:
    pct = pd.DataFrame({"condition": ["vg", "ff"], "percent": [25.0, 75.0]})
    rat = pd.DataFrame({"condition": ["vg", "ff"], "mean": [5.0, 8.0], "sd": [1.0, 1.5]})
    fig = choice_rating_figure(pct, pct, rat, order=["vg", "ff"],
                               labels={"vg": "VG", "ff": "FF"})
    assert [ax.get_title() for ax in fig.axes] == [
        "chosen as best VF", "chosen as worst VF",
        "rating of each VF (mean ± sd, clipped to the scale)"]
    # ratings stay within their 0-10 scale: the whisker of 9.0 ± 2.5 stops at 10
    rat = pd.DataFrame({"condition": ["vg", "ff"], "mean": [9.0, 0.5], "sd": [2.5, 2.0]})
    ax = choice_rating_figure(None, None, rat, order=["vg", "ff"]).axes[0]
    assert ax.get_ylim()[1] <= 10.2 + 1e-9 and ax.get_ylim()[0] == 0.0
    ys = np.concatenate([np.asarray(seg)[:, 1] for coll in ax.collections
                         for seg in coll.get_segments()])
    assert ys.max() == pytest.approx(10.0) and ys.min() == pytest.approx(0.0)
    fig = choice_rating_figure(pct, None, None, order=["vg", "ff"], noun="mode")
    assert [ax.get_title() for ax in fig.axes] == ["chosen as best mode"]
    counts = pd.DataFrame({"schema": ["AG+Mag", "Mag+FF"], "count": [8, 7]})
    fig = counts_figure(counts, label="schema", title="proposals")
    assert [t.get_text() for t in fig.axes[0].get_yticklabels()] == ["Mag+FF", "AG+Mag"]
    assert figure_png(fig)[:8] == PNG_MAGIC


def test_demographics_figure_stacks_groups() -> None:
    counts = pd.DataFrame({"field": ["f"] * 4, "value": ["x", "x", "y", "y"],
                           "group": ["surgeon", "resident"] * 2, "n": [2, 1, 0, 3]})
    fig = demographics_figure(counts, fields=[("f", "F")], groups=["surgeon", "resident"],
                              levels={"f": ["x", "y"]})
    ax = fig.axes[0]
    widths = sorted(round(p.get_width()) for p in ax.patches)
    assert widths == [0, 1, 2, 3]
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["surgeon", "resident"]


@given(st.lists(st.tuples(st.floats(0, 10), st.floats(0, 20)), min_size=1, max_size=6))
def test_clipped_error_bars_stay_in_scale(ms: list[tuple[float, float]]) -> None:
    m = np.array([a for a, _ in ms])
    sd = np.array([b for _, b in ms])
    err = clipped_error_bars(m, sd, (0.0, 10.0))
    assert (err >= 0).all() and (err <= sd + 1e-12).all()
    assert (m - err[0] >= -1e-12).all() and (m + err[1] <= 10.0 + 1e-12).all()
    inside = (m - sd >= 0) & (m + sd <= 10)
    assert np.allclose(err[:, inside], np.vstack([sd, sd])[:, inside])


def test_label_png_adds_a_band_and_keeps_width() -> None:
    fig = counts_figure(pd.DataFrame({"schema": ["a"], "count": [1]}), label="schema",
                        title="t")
    png = figure_png(fig)
    w, h = _png_size(png)
    out = label_png(png, "synthetic data: test")
    w2, h2 = _png_size(out)
    assert w2 == w and h2 > h
    assert label_png(png, "") == png
