"""``vasim report`` on small synthetic VF studies (vasim/study/report/).

The stores are written through the store and session API (no trial is simulated: each
trial gets a handful of per-point metric rows drawn from a seeded model, no samples). The
numbers of the report are checked against an independent recomputation from the store with
plain SQL and the statistics functions (vasim.study.stats, tested against R/JASP in
tests/study/stats).
"""

from __future__ import annotations

import math
import sqlite3
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from vasim.cli import main
from vasim.core.errors import ConfigError
from vasim.records.samples import SampleBuffer
from vasim.records.trial_meta import TrialMeta
from vasim.study import stats
from vasim.study.protocol import load_protocol, parse_protocol
from vasim.study.report import FIXTURE_LABELS, build_report
from vasim.study.session import record_answers, start_session
from vasim.study.store import TrialStore

SCRIPT = "<script>alert(1)</script>"
N_POINTS = 5
EFFECT = {"none": 1.0, "vg": 0.8, "ag": 0.9, "ms": 1.1, "mag": 0.95, "ff": 0.7}
DEMO = {"group": "surgeon", "specialisation": "urology", "laparoscopy_experience": ">200",
        "simulator_experience": "none", "robotic_experience": "observed"}
RESIDENT = {**DEMO, "group": "resident", "laparoscopy_experience": "1-10"}

NO_PROBE_PROTOCOL = """
name = "vf_no_probe"
description = "two fixture blocks, no VF-free trial"
task = "trajectory"
[[blocks]]
name = "vg"
condition = "vg"
variants = [1, 2]
[[blocks]]
name = "ff"
condition = "ff"
variants = [3, 4]
"""


def _points(rng: np.random.Generator, level: float, *, unreached_last: bool = False
            ) -> pd.DataFrame:
    lat = 1.0 * level * np.exp(rng.normal(0.0, 0.3, N_POINTS))
    err = 10.0 * level * np.exp(rng.normal(0.0, 0.3, N_POINTS))
    reached = np.ones(N_POINTS, dtype=bool)
    if unreached_last:
        reached[-1] = False
        lat[-1] = np.nan
    t = np.cumsum(np.nan_to_num(lat))
    t[~reached] = np.nan
    return pd.DataFrame({"point": np.arange(N_POINTS), "reached": reached, "t_reached": t,
                         "error_l1": err, "error_l1_mm_s": 10.0 * err, "latency": lat,
                         "path_l1": 0.03, "path_l2": 0.02,
                         "n_samples": 100})


def write_session(store: TrialStore, protocol_name: str, code: str, seed: int, *,
                  stop_after: int | None = None, pre: dict | None = None,
                  post: dict | None = None, interrupt: int | None = None,
                  unreached: int | None = None) -> int:
    """One subject's session with synthetic trials (per-point metrics, no samples).

    Args:
        stop_after: run only the first scheduled trials (the session stays 'running').
        interrupt: this scheduled trial is first interrupted (with partial per-point
            rows), then re-run. unreached: in this scheduled trial the last point is not
            reached.
    """
    protocol = load_protocol(protocol_name) if "\n" not in protocol_name else \
        parse_protocol(protocol_name)
    sid = start_session(store, protocol, code, seed=seed)
    if pre is not None:
        record_answers(store, sid, "pre", pre)
    rng = np.random.default_rng(seed)
    skill = math.exp(rng.normal(0.0, 0.3))
    sched = store.schedule(sid)
    for row in sched.itertuples(index=False):
        if stop_after is not None and row.trial_index >= stop_after:
            break
        level = skill * EFFECT[row.condition] * (1 + row.trial_index) ** -0.2
        meta = TrialMeta(subject=code, task="trajectory", session_id=sid,
                         schedule_index=int(row.trial_index), protocol=protocol.name)
        if interrupt == row.trial_index:
            tid = store.begin_trial(meta)
            store.mark_interrupted(tid, reason="test", point_metrics=_points(rng, 50.0))
        tid = store.begin_trial(meta)
        store.finish_trial(tid, SampleBuffer(), _points(
            rng, level, unreached_last=unreached == row.trial_index), None)
    if stop_after is None:
        store.set_session_status(sid, "completed")
    if post is not None:
        record_answers(store, sid, "post", post)
    return sid


def _post(best: str, worst: str, ratings: tuple[int, ...], proposals: list, comment: str
          | None = None) -> dict:
    out: dict = {"best_vf": best, "worst_vf": worst,
                 "rating": dict(zip(("vg", "ag", "ms", "mag", "ff"), ratings, strict=True)),
                 "proposed_schemas": proposals}
    if comment is not None:
        out["comments"] = comment
    return out


@pytest.fixture(scope="module")
def vf_study(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """11 subjects: S1-S3 complete; S4 stopped after 20 trials (unbalanced: no cell for the
    fixtures of its later blocks, no post answers); S5 complete without any questionnaire;
    S6-S11 complete without post answers. S2 has one interrupted-and-rerun trial and one
    trial with an unreached point."""
    d = tmp_path_factory.mktemp("report")
    db = d / "study.sqlite"
    with TrialStore(db) as st:
        st.con.execute("PRAGMA synchronous = OFF")
        write_session(st, "vf_learning_curve", "S1", 11, pre=DEMO,
                      post=_post("ff", "ms", (6, 7, 3, 5, 9), [["mag", "ff"]], SCRIPT))
        write_session(st, "vf_learning_curve", "S2", 12, pre=RESIDENT, interrupt=5,
                      unreached=7, post=_post("ff", "vg", (2, 6, 4, 7, 8),
                                              [["mag", "ff"], ["ag", "mag", "ff"]], ""))
        write_session(st, "vf_learning_curve", "S3", 13, pre=DEMO,
                      post=_post("mag", "ms", (5, 5, 1, 9, 8), [["ag", "mag"]],
                                 "line one\nline <two> & 'three'"))
        write_session(st, "vf_learning_curve", "S4", 14, pre=RESIDENT, stop_after=20)
        write_session(st, "vf_learning_curve", "S5", 15)
        for i in range(6, 12):  # enough subjects for a non-singular 8-level covariance
            write_session(st, "vf_learning_curve", f"S{i}", 10 + i, pre=DEMO)
    out = d / "report"
    build_report(db, out)
    return db, out


def _csv(out: Path, name: str) -> pd.DataFrame:
    return pd.read_csv(out / "tables" / f"{name}.csv", keep_default_na=True)


def _sql_cells(db: Path) -> pd.DataFrame:
    """Independent recomputation: per analysed trial E = Σ e_i Δt [mm s] (eq. 6.5 times the
    sample period) and L = Σ l_i (reached), from the store with SQL only."""
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    q = """
    SELECT s.subject, q.condition, q.probe, q.probe_index, q.trial_id,
           (SELECT sum(error_l1_mm_s) FROM point_metrics p WHERE p.trial_id = q.trial_id)
             AS E,
           (SELECT sum(latency) FROM point_metrics p WHERE p.trial_id = q.trial_id
                                                      AND p.reached = 1) AS L,
           q.probe = 1 AND q.trial_index < (SELECT min(r.trial_index) FROM scheduled_trials r
                                            WHERE r.session_id = q.session_id
                                              AND r.probe = 0) AS baseline
    FROM scheduled_trials q JOIN sessions s ON s.id = q.session_id
    WHERE q.trial_id IS NOT NULL"""
    df = pd.read_sql_query(q, con)
    con.close()
    return df


# ----------------------------------------------------------------------------- outputs
def test_writes_html_and_tables(vf_study: tuple[Path, Path]) -> None:
    _, out = vf_study
    html = (out / "index.html").read_text()
    for key in ("cohort", "measures", "transfer", "learning", "fixture", "boxplots",
                "questionnaires", "mrcp", "traceability"):
        assert f'<section id="{key}">' in html
    assert html.count("data:image/png;base64,") >= 6  # figures embedded, no external file
    assert "<script" not in html and 'src="http' not in html
    names = {p.stem for p in (out / "tables").glob("*.csv")}
    assert {"vf_rm_anova", "vf_posthoc_tukey", "vf_posthoc_paired", "vf_seed_replication",
            "vf_learning_curve", "vf_learning_fit", "vf_cells_fixture", "vf_cells_trial",
            "vf_trials", "vf_transfer_model", "vf_transfer_tests", "vf_measures",
            "vf_measure_correlations", "cohort_summary", "questionnaire_choices",
            "questionnaire_ratings",
            "questionnaire_schemas", "questionnaire_comments", "provenance"} <= names
    assert "not an MRCP study" in html  # the MRCP section says why it is empty


def test_rm_anova_equals_independent_recomputation(vf_study: tuple[Path, Path]) -> None:
    db, out = vf_study
    t = _sql_cells(db)
    aov = _csv(out, "vf_rm_anova")
    # fixture factor: cell = mean over the subject's trials of the condition, the baseline
    # probes excluded ('none' = the probes after the blocks); subjects with every one of the
    # 6 cells only (S4 stopped early)
    cells = t[t["baseline"] == 0].groupby(["subject", "condition"])[["E", "L"]].mean()
    cells = cells.reset_index()
    full = cells.groupby("subject")["condition"].nunique()
    keep = full[full == 6].index
    assert sorted(keep) == sorted(f"S{i}" for i in range(1, 12) if i != 4)
    cells = cells[cells["subject"].isin(keep)]
    for dv, col in (("eq65", "E"), ("latency", "L")):
        ref = stats.rm_anova(cells, dv=col, subject="subject", within="condition")
        row = aov[(aov["dv"] == dv) & (aov["factor"] == "fixture")].iloc[0]
        assert row["n_subjects"] == 10 and row["excluded_subjects"] == "S4"
        for c in ("SS", "SS_error", "df1", "df2", "F", "p_unc", "eps_gg", "p_gg", "np2"):
            assert row[c] == pytest.approx(float(ref.loc[0, c]), rel=1e-9), (dv, c)
    # trial factor: the 8 probe trials, one per cell
    probes = t[t["probe"] == 1]
    full = probes.groupby("subject")["probe_index"].nunique()
    probes = probes[probes["subject"].isin(full[full == 8].index)]
    for dv, col in (("eq65", "E"), ("latency", "L")):
        ref = stats.rm_anova(probes, dv=col, subject="subject", within="probe_index")
        row = aov[(aov["dv"] == dv) & (aov["factor"] == "trial")].iloc[0]
        assert np.isfinite(row["mauchly_W"])  # 10 subjects: the 7 contrasts are estimable
        for c in ("F", "df1", "df2", "p_unc", "eps_gg", "eps_hf", "mauchly_W", "mauchly_p"):
            assert row[c] == pytest.approx(float(ref.loc[0, c]), rel=1e-9)


def test_post_hoc_equals_direct_calls(vf_study: tuple[Path, Path]) -> None:
    db, out = vf_study
    t = _sql_cells(db)
    t = t[(t["subject"] != "S4") & (t["baseline"] == 0)]  # 'none' = probes after the blocks
    t["fixture"] = pd.Categorical(t["condition"].map(FIXTURE_LABELS),
                                  categories=["none", "VG", "AG", "MS", "Mag", "FF"])
    pp = stats.pairwise_paired(t, dv="E", subject="subject", within="fixture")
    got = _csv(out, "vf_posthoc_paired")
    got = got[(got["dv"] == "eq65") & (got["factor"] == "fixture")]
    assert list(got["group1"] + got["group2"]) == list(pp["group1"] + pp["group2"])
    np.testing.assert_allclose(got["p_holm"], pp["p_holm"], rtol=1e-9)
    assert set(got["label"]) == {"paired t-tests, Holm-corrected: the within-subject-correct "
                                 "alternative"}
    tk = stats.tukey_hsd_rm(t, dv="E", subject="subject", within="fixture")
    got = _csv(out, "vf_posthoc_tukey")
    got = got[(got["dv"] == "eq65") & (got["factor"] == "fixture")]
    np.testing.assert_allclose(got["p_adj"], tk.comparisons["p_adj"], rtol=1e-9)
    assert got["label"].str.contains("as in the seed").all()


def test_seed_replication_is_labelled_and_per_point(vf_study: tuple[Path, Path]) -> None:
    db, out = vf_study
    rep = _csv(out, "vf_seed_replication")
    assert rep["label"].str.startswith("seed replication").all()
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    n_points = con.execute("SELECT count(*) FROM point_metrics p JOIN scheduled_trials q "
                           "ON q.trial_id = p.trial_id").fetchone()[0]
    n_lat = con.execute("SELECT count(*) FROM point_metrics p JOIN scheduled_trials q "
                        "ON q.trial_id = p.trial_id WHERE p.latency IS NOT NULL").fetchone()[0]
    con.close()
    err = rep[rep["dv"] == "eq65"]
    lat = rep[rep["dv"] == "latency"]
    # additive model: df2 = rows - 1 - 5 (fixture) - 7 (trial): one row per point
    assert (err["n_rows"] == n_points).all() and (err["df2"] == n_points - 13).all()
    assert (lat["n_rows"] == n_lat).all() and (lat["df2"] == n_lat - 13).all()
    assert list(err["effect"]) == ["fixture", "trial"] and list(err["df1"]) == [5, 7]


def test_learning_curve_is_mean_and_iqr_of_probe_trials(vf_study: tuple[Path, Path]) -> None:
    db, out = vf_study
    t = _sql_cells(db)
    lc = _csv(out, "vf_learning_curve")
    p3 = t[(t["probe"] == 1) & (t["probe_index"] == 3)]
    row = lc[(lc["dv"] == "latency") & (lc["probe"] == 3)].iloc[0]
    assert row["practice"] == 3  # the third trial of the session
    assert row["n"] == len(p3) == 11
    assert row["mean"] == pytest.approx(p3["L"].mean(), rel=1e-12)
    assert row["q25"] == pytest.approx(np.percentile(p3["L"], 25), rel=1e-12)
    assert row["q75"] == pytest.approx(np.percentile(p3["L"], 75), rel=1e-12)
    assert set(map(int, row["trial_ids"].split())) == set(p3["trial_id"])
    fit = _csv(out, "vf_learning_fit")
    assert list(fit["dv"]) == ["latency", "eq65"] and (fit["n_obs"] == len(
        t[t["probe"] == 1])).all()


# ---------------------------------------------------------------------------- tracing
def test_traceability(vf_study: tuple[Path, Path]) -> None:
    db, out = vf_study
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    info = pd.read_sql_query(
        "SELECT t.id AS trial_id, t.subject, t.status, q.condition, q.probe_index "
        "FROM trials t LEFT JOIN scheduled_trials q ON q.trial_id = t.id", con).set_index(
        "trial_id")
    con.close()
    cells = _csv(out, "vf_cells_fixture")
    for r in cells.itertuples(index=False):
        ids = [int(x) for x in r.trial_ids.split()]
        assert len(ids) == r.n_trials
        assert (info.loc[ids, "subject"] == r.subject).all()
        assert (info.loc[ids, "condition"] == r.condition).all()
        assert (info.loc[ids, "status"] == "completed").all()
    prov = _csv(out, "provenance")
    anova = prov[prov["table"] == "vf_rm_anova"]
    assert len(anova) == 10 * 6 + 10 * 8  # complete subjects x (fixture + trial) cells
    for r in anova.itertuples(index=False):
        ids = [int(x) for x in r.trial_ids.split()]
        assert (info.loc[ids, "subject"] == r.subject).all()
        factor, level = r.group.split("=")
        if factor == "fixture":
            assert {FIXTURE_LABELS[c] for c in info.loc[ids, "condition"]} == {level}
        else:
            assert list(info.loc[ids, "probe_index"]) == [int(level)]
    # the interrupted attempt of S2 is never used
    interrupted = set(info.index[info["status"] == "interrupted"])
    assert len(interrupted) == 1
    used = {int(x) for s in prov["trial_ids"].dropna() for x in str(s).split()}
    assert not used & interrupted and not set(_csv(out, "vf_trials")["trial_id"]) & interrupted
    # every table is traced: an id column, or rows in provenance.csv
    traced = set(prov["table"])
    for p in (out / "tables").glob("*.csv"):
        cols = set(pd.read_csv(p, nrows=0).columns)
        assert cols & {"trial_id", "trial_ids", "session_ids", "session_id"} \
            or p.stem in traced or p.stem == "provenance", p.name
    assert "provenance.csv" in (out / "index.html").read_text()


# --------------------------------------------------------------------------- subjective
def test_questionnaires_and_escaping(vf_study: tuple[Path, Path]) -> None:
    _, out = vf_study
    html = (out / "index.html").read_text()
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in html and SCRIPT not in html
    assert "line &lt;two&gt; &amp; &#x27;three&#x27;" in html
    comments = _csv(out, "questionnaire_comments")
    assert SCRIPT in set(comments["text"])  # the CSV keeps the text verbatim
    ch = _csv(out, "questionnaire_choices")
    best = ch[ch["item"] == "best_vf"].set_index("condition")
    # S1, S2 chose FF, S3 Mag: 3 respondents (S4 and S5 answered no post-questionnaire)
    assert best.loc["FF", "count"] == 2 and best.loc["FF", "percent"] == pytest.approx(200 / 3)
    assert (best["n_respondents"] == 3).all()
    rt = _csv(out, "questionnaire_ratings").set_index("label")
    assert rt.loc["VG", "mean"] == pytest.approx(13 / 3)
    assert rt.loc["VG", "sd"] == pytest.approx(np.std([6, 2, 5], ddof=1))
    sc = _csv(out, "questionnaire_schemas").set_index("schema")
    assert sc.loc["Mag+FF", "count"] == 2 and sc.loc["AG+Mag", "count"] == 1
    fx = _csv(out, "questionnaire_schema_fixtures").set_index("label")
    assert fx.loc["Mag", "count"] == 4 and fx.loc["VG", "count"] == 0
    assert "no post-questionnaire answers" in html and "S4" in html


def test_cohort_counts(vf_study: tuple[Path, Path]) -> None:
    _, out = vf_study
    c = _csv(out, "cohort_summary").set_index("quantity")["value"]
    assert c["subjects"] == 11 and c["surgeons"] == 8 and c["residents"] == 2
    assert c["group unknown (no demographics)"] == 1
    assert c["sessions completed"] == 10 and c["sessions incomplete (running)"] == 1
    assert c["interrupted trial rows"] == 1
    assert c["scheduled trials re-run after an interruption"] == 1
    assert c["scheduled trials completed (analysed)"] == 10 * 38 + 20
    html = (out / "index.html").read_text()
    assert "S4 (no " in html  # the unbalanced subject is named with its missing cells


# ---------------------------------------------------------------------------- degradation
def test_store_without_probe_trials(tmp_path: Path) -> None:
    db = tmp_path / "np.sqlite"
    with TrialStore(db) as st:
        for i in range(3):
            write_session(st, NO_PROBE_PROTOCOL, f"N{i}", 20 + i)
    res = build_report(db, tmp_path / "out")
    html = res.index.read_text()
    assert "no VF-free probe trial with per-point metrics" in html
    assert "lacks the level &#x27;none&#x27;" in html
    aov = _csv(res.out, "vf_rm_anova")
    assert list(aov["factor"]) == ["fixture", "fixture"] and (aov["df1"] == 1).all()
    assert not (res.out / "tables" / "vf_learning_curve.csv").exists()
    assert "no post-questionnaire" not in html  # the protocol asks none
    assert "asks no questionnaire item" in html


def test_empty_store_and_empty_file(tmp_path: Path) -> None:
    db = tmp_path / "empty.sqlite"
    TrialStore(db).close()
    res = build_report(db, tmp_path / "out")
    html = res.index.read_text()
    assert "no sessions stored" in html and res.protocol is None
    assert res.tables == ("provenance",)
    zero = tmp_path / "zero.sqlite"
    zero.write_bytes(b"")
    res = build_report(zero, tmp_path / "out2")
    assert "empty (0 bytes)" in res.index.read_text()


def test_bad_arguments(tmp_path: Path, vf_study: tuple[Path, Path], capsys) -> None:
    db, _ = vf_study
    missing = tmp_path / "nope.sqlite"
    assert main(["report", "--db", str(missing), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "nope.sqlite" in err
    assert "(no such file), expected the study database" in err
    with pytest.raises(ConfigError, match="no session of protocol 'mrcp_vs_stdt'"):
        build_report(db, tmp_path / "o", protocol="mrcp_vs_stdt")
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(ConfigError, match="not a folder"):
        build_report(db, f)
    with pytest.raises(ConfigError, match=r"\(a folder\), expected the study database"):
        build_report(tmp_path, tmp_path / "o")
    other = tmp_path / "two.sqlite"
    with TrialStore(other) as st:
        write_session(st, NO_PROBE_PROTOCOL, "A1", 1, stop_after=2)
        write_session(st, "vf_learning_curve", "A2", 2, stop_after=2)
    with pytest.raises(ConfigError, match=r"2 protocols .*choose one with --protocol"):
        build_report(other, tmp_path / "o")
    res = build_report(other, tmp_path / "o", protocol="vf_no_probe")
    assert res.protocol == "vf_no_probe"
    assert "1 level(s) with data (VG); an RM-ANOVA needs 2" in res.index.read_text()


def test_cli_writes_report_and_replaces_stale_tables(tmp_path: Path, capsys) -> None:
    db = tmp_path / "small.sqlite"
    with TrialStore(db) as st:
        for i in range(2):
            write_session(st, NO_PROBE_PROTOCOL, f"C{i}", 30 + i)
    out = tmp_path / "rep"
    (out / "tables").mkdir(parents=True)
    (out / "tables" / "mine.csv").write_text("a\n1\n")  # not the report's: kept
    assert main(["report", "--db", str(db), "--out", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "wrote" in printed and "summary.json" in printed
    assert (out / "tables" / "vf_rm_anova.csv").is_file()
    empty = tmp_path / "empty.sqlite"
    TrialStore(empty).close()
    assert main(["report", "--db", str(empty), "--out", str(out), "--no-progress"]) == 0
    left = {p.name for p in (out / "tables").iterdir()}
    assert left == {"mine.csv", "provenance.csv", "manifest.json"}
