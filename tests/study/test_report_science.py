"""The report's study science (issue #15 item 2, issue #25 items 2-4): the primary probe
model (fixture just practised, block position, variant, subject; carry-over), the fixture
factor without the baseline trials (the seed's design, secondary), the practice- and
variant-adjusted mixed model, learning curves against the practice count, surgeons vs
residents (group x practice), the measures and their units, ``summary.json`` and the
synthetic label.

Stores are written through the store and session API with per-point metrics drawn from a
seeded model (no samples); expected values are recomputed here from the store with SQL,
pandas, scipy and statsmodels directly.
"""

from __future__ import annotations

import json
import math
import sqlite3
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import statsmodels.formula.api as smf
from scipy import stats as sps

from vasim.records.samples import SampleBuffer
from vasim.records.trial_meta import TrialMeta
from vasim.study import stats
from vasim.study.protocol import load_protocol
from vasim.study.report import build_report
from vasim.study.report.data import SYNTHETIC_LABEL
from vasim.study.report.summary import FIXTURES, TEST_KEYS
from vasim.study.session import record_answers, start_session
from vasim.study.store import TrialStore

N_POINTS = 4
EFFECT = {"none": 1.0, "vg": 0.8, "ag": 0.9, "ms": 1.1, "mag": 0.95, "ff": 0.7}
BASELINE_LEVEL = 6.0
"""The baseline probes are far slower and less accurate: pooling them into 'none' would
move the fixture F a lot."""
DEMO = {"group": "surgeon", "specialisation": "urology", "laparoscopy_experience": ">200",
        "simulator_experience": "none", "robotic_experience": "observed"}
RESIDENT = {**DEMO, "group": "resident", "laparoscopy_experience": "1-10"}


def _points(rng: np.random.Generator, level: float) -> pd.DataFrame:
    lat = level * np.exp(rng.normal(0.0, 0.25, N_POINTS))
    err = 10.0 * level * np.exp(rng.normal(0.0, 0.25, N_POINTS))
    # eq. 6.5 times a 10 ms sample period, in mm s: error_l1 [m·sample] x 0.01 s x 1000
    return pd.DataFrame({"point": np.arange(N_POINTS), "reached": True,
                         "t_reached": np.cumsum(lat), "error_l1": err,
                         "error_l1_mm_s": 10.0 * err, "latency": lat,
                         "path_l1": 0.03, "path_l2": 0.02, "n_samples": 50})


def _session(store: TrialStore, code: str, seed: int, group_bonus: float,
             pre: dict | None, post: dict | None, *, path_dev: bool = False) -> None:
    protocol = load_protocol("vf_learning_curve")
    sid = start_session(store, protocol, code, seed=seed)
    if pre is not None:
        record_answers(store, sid, "pre", pre)
    rng = np.random.default_rng(seed)
    skill = math.exp(rng.normal(0.0, 0.2)) * group_bonus
    for row in store.schedule(sid).itertuples(index=False):
        baseline = bool(row.probe) and int(row.probe_index) <= 3
        level = skill * (BASELINE_LEVEL if baseline else
                         EFFECT[row.condition] * (1 + row.trial_index) ** -0.2)
        meta = TrialMeta(subject=code, task="trajectory", session_id=sid,
                         schedule_index=int(row.trial_index), protocol=protocol.name)
        tid = store.begin_trial(meta)
        metrics = {"path_dev_mean_mm": 2.0 * level * math.exp(rng.normal(0.0, 0.2))} \
            if path_dev else None
        store.finish_trial(tid, SampleBuffer(), _points(rng, level), None,
                           trial_metrics=metrics)
    store.set_session_status(sid, "completed")
    if post is not None:
        record_answers(store, sid, "post", post)


def _post(best: str, worst: str, ratings: tuple[int, ...]) -> dict:
    return {"best_vf": best, "worst_vf": worst,
            "rating": dict(zip(FIXTURES, ratings, strict=True)),
            "proposed_schemas": [["mag", "ff"]]}


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """8 subjects (S1-S4 surgeons, S5-S8 residents, residents 30 % slower); S1-S3 answer the
    post-questionnaire; sessions stored by the scripted operator (synthetic)."""
    d = tmp_path_factory.mktemp("science")
    db = d / "study.sqlite"
    posts = {1: _post("ff", "ms", (6, 7, 3, 5, 10)), 2: _post("ff", "vg", (2, 6, 4, 7, 8)),
             3: _post("mag", "ms", (5, 5, 1, 9, 9))}
    with TrialStore(db) as st:
        st.con.execute("PRAGMA synchronous = OFF")
        for i in range(1, 9):
            _session(st, f"S{i}", 100 + i, 1.0 if i <= 4 else 1.3,
                     DEMO if i <= 4 else RESIDENT, posts.get(i))
    out = d / "report"
    build_report(db, out)
    return db, out


def _csv(out: Path, name: str) -> pd.DataFrame:
    return pd.read_csv(out / "tables" / f"{name}.csv")


def _trials_sql(db: Path) -> pd.DataFrame:
    """Per analysed trial, from SQL only: subject, condition, probe, probe index, position,
    variant, block index, E = Σ e_i Δt [mm s], L = Σ l_i, and whether it is a baseline probe
    (a probe before the session's first assisted trial)."""
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    df = pd.read_sql_query("""
    SELECT s.subject, q.session_id, q.trial_index, q.condition, q.probe, q.probe_index,
           q.trial_id, q.variant, q.block_index,
           (SELECT sum(error_l1_mm_s) FROM point_metrics p WHERE p.trial_id = q.trial_id)
             AS E,
           (SELECT sum(latency) FROM point_metrics p WHERE p.trial_id = q.trial_id
                                                      AND p.reached = 1) AS L,
           q.probe = 1 AND q.trial_index < (SELECT min(r.trial_index) FROM scheduled_trials r
                                            WHERE r.session_id = q.session_id
                                              AND r.probe = 0) AS baseline
    FROM scheduled_trials q JOIN sessions s ON s.id = q.session_id
    WHERE q.trial_id IS NOT NULL""", con)
    con.close()
    return df


# ----------------------------------------------------------------------- fixture factor
def test_fixture_anova_excludes_the_baseline_trials(study: tuple[Path, Path]) -> None:
    db, out = study
    t = _trials_sql(db)
    assert sorted(t.loc[t["baseline"] == 1, "probe_index"].unique()) == [1, 2, 3]
    aov = _csv(out, "vf_rm_anova")
    for dv, col in (("eq65", "E"), ("latency", "L")):
        row = aov[(aov["dv"] == dv) & (aov["factor"] == "fixture")].iloc[0]
        without = t[t["baseline"] == 0].groupby(["subject", "condition"])[col].mean()
        ref = stats.rm_anova(without.reset_index(), dv=col, subject="subject",
                             within="condition")
        pooled = t.groupby(["subject", "condition"])[col].mean()
        bad = stats.rm_anova(pooled.reset_index(), dv=col, subject="subject",
                             within="condition")
        # the hand-built data make the choice matter: including the baseline moves F
        assert abs(float(bad.loc[0, "F"]) - float(ref.loc[0, "F"])) > 1.0
        assert row["F"] == pytest.approx(float(ref.loc[0, "F"]), rel=1e-9)
        assert row["p_unc"] == pytest.approx(float(ref.loc[0, "p_unc"]), rel=1e-9)
        assert (row["df1"], row["df2"]) == (5, 35)
    cells = _csv(out, "vf_cells_fixture")
    none = cells[cells["condition"] == "none"]
    assert (none["n_trials"] == 5).all()  # probes 4..8, never the 3 baseline probes
    base_ids = set(t.loc[t["baseline"] == 1, "trial_id"])
    used = {int(x) for ids in none["trial_ids"] for x in str(ids).split()}
    assert used and not used & base_ids


def test_mixed_model_equals_statsmodels(study: tuple[Path, Path]) -> None:
    db, out = study
    t = _trials_sql(db)
    t["log_practice"] = np.log(t["trial_index"] + 1.0)
    t["fixture"] = pd.Categorical(t["condition"], categories=["none", *FIXTURES])
    t["variant"] = "v" + t["variant"].astype(str)
    mm = _csv(out, "vf_mixed_model")
    for dv, col in (("eq65", "E"), ("latency", "L")):
        fit = smf.mixedlm(f"{col} ~ C(fixture) + log_practice + C(variant)", t,
                          groups=t["subject"]).fit(reml=True)
        got = mm[mm["dv"] == dv].set_index("term")
        for f in FIXTURES:
            term = f"C(fixture)[T.{f}]"
            assert got.loc[term, "coef"] == pytest.approx(fit.params[term], rel=1e-6, abs=1e-9)
            assert got.loc[term, "p"] == pytest.approx(fit.pvalues[term], rel=1e-5, abs=1e-12)
        assert got.loc["log_practice", "coef"] == pytest.approx(fit.params["log_practice"],
                                                                 rel=1e-6)
        for v in range(2, 7):  # the variant enters the analysis (issue #25)
            term = f"C(variant)[T.v{v}]"
            assert got.loc[term, "coef"] == pytest.approx(fit.params[term], rel=1e-6)
        assert (got["n_obs"] == len(t)).all() and (got["n_subjects"] == 8).all()
    text = (out / "index.html").read_text()
    assert "MixedLM" in text and "primary" in text
    assert "per-fixture RM-ANOVA (secondary)" in text


# ------------------------------------------------------- primary: the post-block probes
def _post_block_probes(t: pd.DataFrame) -> pd.DataFrame:
    """The probes closing a fixture block, with the fixture practised (the trial before)
    and the one practised in the block before (8 trials earlier; 'none' for block 1),
    from the SQL rows alone."""
    key = t.set_index(["session_id", "trial_index"])["condition"]
    p = t[(t["probe"] == 1) & (t["baseline"] == 0)].copy()
    p["practised"] = [key[(s, i - 1)] for s, i in zip(p["session_id"], p["trial_index"],
                                                      strict=True)]
    p["previous"] = [key[(s, i - 8)] if b > 1 else "none" for s, i, b in
                     zip(p["session_id"], p["trial_index"], p["block_index"], strict=True)]
    p["practised"] = pd.Categorical(p["practised"], categories=list(FIXTURES))
    p["variant"] = "v" + p["variant"].astype(str)
    return p


def test_primary_probe_model_equals_statsmodels(study: tuple[Path, Path]) -> None:
    """Fixture effects = sum-to-zero contrasts of an independent statsmodels fit; the
    fixture and carry-over tests = F of nested least-squares fits computed with numpy."""
    db, out = study
    p = _post_block_probes(_trials_sql(db))
    assert len(p) == 8 * 5 and p["variant"].nunique() == 6
    est, tests = _csv(out, "vf_transfer_model"), _csv(out, "vf_transfer_tests")
    for dv, col in (("eq65", "E"), ("latency", "L")):
        formula = f"{col} ~ C(practised, Sum) + block_index + C(variant)"
        fit = smf.mixedlm(formula, p, groups=p["subject"]).fit(reml=True)
        sums = [f"C(practised, Sum)[S.{f}]" for f in FIXTURES[:-1]]
        got = est[(est["dv"] == dv) & (est["term"] == "fixture")].set_index("condition")
        for f, term in zip(FIXTURES[:-1], sums, strict=True):
            assert got.loc[f, "coef"] == pytest.approx(fit.params[term], rel=1e-5, abs=1e-9)
            assert got.loc[f, "p"] == pytest.approx(fit.pvalues[term], rel=1e-4, abs=1e-10)
        assert got.loc["ff", "coef"] == pytest.approx(-fit.params[sums].sum(), rel=1e-5,
                                                      abs=1e-9)
        row = tests[(tests["dv"] == dv)].set_index("test")
        # the tests: F of nested within-subject least-squares fits, by hand (numpy)
        def rss(cols: list[str], data: pd.DataFrame = p, y: str = col) -> tuple[float, int]:
            x = pd.get_dummies(data[cols].astype(str), drop_first=True).astype(float)
            x = np.column_stack([np.ones(len(data)), x.to_numpy(),
                                 data["block_index"].to_numpy(float)])
            beta, *_ = np.linalg.lstsq(x, data[y].to_numpy(float), rcond=None)
            res = data[y].to_numpy(float) - x @ beta
            return float(res @ res), len(data) - np.linalg.matrix_rank(x)
        for test, red, full in (("fixture", ["subject", "variant"],
                                 ["subject", "variant", "practised"]),
                                ("carry_over", ["subject", "variant", "practised"],
                                 ["subject", "variant", "practised", "previous"])):
            (r0, d0), (r1, d1) = rss(red), rss(full)
            f = ((r0 - r1) / (d0 - d1)) / (r1 / d1)
            assert (row.loc[test, "df1"], row.loc[test, "df2"]) == (d0 - d1, d1)
            assert row.loc[test, "F"] == pytest.approx(f, rel=1e-8)
            assert row.loc[test, "p"] == pytest.approx(sps.f.sf(f, d0 - d1, d1), rel=1e-6)
        assert row.loc["fixture", "df1"] == 4 and row.loc["carry_over", "df1"] == 5
        slope = est[(est["dv"] == dv) & (est["term"] == "block_position")].iloc[0]
        assert slope["coef"] == pytest.approx(fit.params["block_index"], rel=1e-5)
        assert (row["n_obs"] == 40).all() and (row["n_subjects"] == 8).all()
    text = (out / "index.html").read_text()
    assert "Transfer: the VF-free probe after each fixture block (primary analysis)" in text
    assert text.index("primary analysis)") < text.index("per-fixture RM-ANOVA (secondary)")


# ---------------------------------------------------------------------- learning curves
def test_learning_curve_x_axis_is_the_practice_count(study: tuple[Path, Path]) -> None:
    db, out = study
    t = _trials_sql(db)
    probes = t[t["probe"] == 1]
    lc = _csv(out, "vf_learning_curve")
    err = lc[lc["dv"] == "eq65"]
    # probe k sits at the same session position for every subject: 1, 2, 3, 10, 17, ...
    expect = probes.groupby("probe_index")["trial_index"].agg(["min", "max"])
    assert (expect["min"] == expect["max"]).all()
    assert list(err["practice"]) == list(expect["min"] + 1)
    assert list(err["practice"])[:4] == [1, 2, 3, 10]
    assert list(err["probe"].astype(int)) == list(range(1, 9))
    m = probes.assign(practice=probes["trial_index"] + 1).groupby("practice")["E"].mean()
    assert np.allclose(err["mean"].to_numpy(), m.to_numpy(), rtol=1e-12)
    fit = _csv(out, "vf_learning_fit")
    row = fit[fit["dv"] == "eq65"].iloc[0]
    ref = stats.fit_power_law((probes["trial_index"] + 1).to_numpy(float),
                              probes["E"].to_numpy(float))
    assert row["a"] == pytest.approx(ref.a, rel=1e-6)  # least-squares optimiser tolerance
    assert row["b"] == pytest.approx(ref.b, rel=1e-6)
    assert "practice count" in (out / "index.html").read_text()


# ---------------------------------------------------------------- surgeons vs residents
def test_group_mixed_anova_and_curves(study: tuple[Path, Path]) -> None:
    db, out = study
    t = _trials_sql(db)
    probes = t[t["probe"] == 1].copy()
    probes["group"] = np.where(probes["subject"].str[1:].astype(int) <= 4, "surgeon",
                               "resident")
    g = _csv(out, "vf_group_anova")
    for dv, col in (("eq65", "E"), ("latency", "L")):
        rows = g[g["dv"] == dv].set_index("Source")
        assert list(rows.index) == ["group", "trial", "Interaction"]
        # balanced within: the between-groups F is the one-way ANOVA of subject means
        sm = probes.groupby(["subject", "group"])[col].mean().reset_index()
        f, p = sps.f_oneway(*(sm.loc[sm["group"] == k, col] for k in ("surgeon", "resident")))
        assert rows.loc["group", "F"] == pytest.approx(f, rel=1e-9)
        assert rows.loc["group", "p_unc"] == pytest.approx(p, rel=1e-9)
        assert (rows.loc["group", "DF1"], rows.loc["group", "DF2"]) == (1, 6)
        assert (rows.loc["trial", "DF1"], rows.loc["trial", "DF2"]) == (7, 42)
        assert rows.loc["group", "n_surgeon"] == 4 and rows.loc["group", "n_resident"] == 4
    curves = _csv(out, "vf_learning_curve_group")
    c = curves[(curves["dv"] == "latency") & (curves["group"] == "resident")]
    ref = (probes[probes["group"] == "resident"].assign(practice=probes["trial_index"] + 1)
           .groupby("practice")["L"].mean())
    assert list(c["practice"]) == list(ref.index)
    assert np.allclose(c["mean"].to_numpy(), ref.to_numpy(), rtol=1e-12)


# ------------------------------------------------------------------------- summary.json
def _check_test(t: dict, *, null: bool) -> None:
    assert set(t) == set(TEST_KEYS)
    for k in TEST_KEYS:
        if null:
            assert t[k] is None
        elif k in ("df1", "df2"):
            assert isinstance(t[k], int)
        elif t[k] is not None:
            assert isinstance(t[k], float) and math.isfinite(t[k])


def _check_primary(m: dict, *, null: bool) -> None:
    assert set(m) == {"formula", "n_obs", "n_subjects", "fixture_test", "carry_over",
                      "variant_test", "block_position", "fixture"}
    assert set(m["fixture"]) == set(FIXTURES)
    for k in ("fixture_test", "carry_over", "variant_test"):
        assert set(m[k]) == {"F", "df1", "df2", "p"}
        assert (m[k]["F"] is None) == null
    for e in (m["block_position"], *m["fixture"].values()):
        if null:
            assert e is None
        else:
            assert set(e) == {"coef", "ci_low", "ci_high", "p"}
            assert e["ci_low"] <= e["coef"] <= e["ci_high"] and 0.0 <= e["p"] <= 1.0


def test_summary_json_schema_and_values(study: tuple[Path, Path]) -> None:
    _, out = study
    s = json.loads((out / "summary.json").read_text())
    assert set(s) == {"synthetic", "n_subjects", "primary", "measures",
                      "measure_correlations", "ratings", "best_share", "worst_share",
                      "assumed_effects", "recovered_effects"}
    assert s["synthetic"] is True and s["n_subjects"] == 8 and s["primary"] == "mixed_model"
    # a synthetic cohort: the analysis' estimate of the fixture effects (vasim.study.recovery)
    # beside the stored scenario's assumption (None when the sessions stored no scenario)
    assert "fixtures" in s["recovered_effects"]
    assert s["assumed_effects"] is None or "fixtures" in s["assumed_effects"]
    assert set(s["measures"]) == {"path_deviation", "latency", "eq65"}
    assert '"error"' not in (out / "summary.json").read_text()
    aov = _csv(out, "vf_rm_anova")
    grp = _csv(out, "vf_group_anova")
    est = _csv(out, "vf_transfer_model")
    for key in ("eq65", "latency"):
        m = s["measures"][key]
        assert set(m) == {"unit", "fixture", "practice", "group", "group_x_practice",
                          "mixed_model"}
        assert m["unit"] == {"eq65": "mm·s", "latency": "s"}[key]
        for k in ("fixture", "practice", "group", "group_x_practice"):
            _check_test(m[k], null=False)
        assert m["group"]["p_gg"] is None  # a between-subjects effect has no GG correction
        row = aov[(aov["dv"] == key) & (aov["factor"] == "fixture")].iloc[0]
        assert m["fixture"]["F"] == pytest.approx(row["F"], rel=1e-12)
        assert m["fixture"]["p_gg"] == pytest.approx(row["p_gg"], rel=1e-12)
        inter = grp[(grp["dv"] == key) & (grp["Source"] == "Interaction")].iloc[0]
        assert m["group_x_practice"]["F"] == pytest.approx(inter["F"], rel=1e-12)
        assert (m["group_x_practice"]["df1"], m["group_x_practice"]["df2"]) == (7, 42)
        _check_primary(m["mixed_model"], null=False)
        ff = est[(est["dv"] == key) & (est["condition"] == "ff")].iloc[0]
        assert m["mixed_model"]["fixture"]["ff"]["coef"] == pytest.approx(ff["coef"])
        assert m["mixed_model"]["n_obs"] == 40
    # no path deviation stored in these trials: every value null
    pdv = s["measures"]["path_deviation"]
    assert pdv["unit"] == "mm"
    for k in ("fixture", "practice", "group", "group_x_practice"):
        _check_test(pdv[k], null=True)
    _check_primary(pdv["mixed_model"], null=True)
    assert "not stored in this database" in (out / "index.html").read_text()
    # e vs latency: the correlation is reported with its interval
    c = s["measure_correlations"]["eq65~latency"]["pearson"]
    assert c["ci_low"] <= c["r"] <= c["ci_high"] and c["n_obs"] == 8 * 38
    # ratings: mean of S1-S3; shares: fractions of the 3 respondents
    assert s["ratings"] == pytest.approx({"vg": 13 / 3, "ag": 6.0, "ms": 8 / 3, "mag": 7.0,
                                          "ff": 9.0})
    assert s["best_share"] == pytest.approx({"vg": 0, "ag": 0, "ms": 0, "mag": 1 / 3,
                                             "ff": 2 / 3})
    assert s["worst_share"] == pytest.approx({"vg": 1 / 3, "ag": 0, "ms": 2 / 3, "mag": 0,
                                              "ff": 0})


def test_measure_correlations_equal_scipy_and_statsmodels(study: tuple[Path, Path]) -> None:
    db, out = study
    t = _trials_sql(db)
    cor = _csv(out, "vf_measure_correlations")
    row = cor[(cor["x"] == "eq65") & (cor["y"] == "latency")].set_index("method")
    r = sps.pearsonr(t["E"], t["L"])
    ci = r.confidence_interval(0.95)
    assert row.loc["pearson", "r"] == pytest.approx(r.statistic, rel=1e-9)
    assert row.loc["pearson", "ci_low"] == pytest.approx(ci.low, rel=1e-9)
    # within subjects: the correlation of the subject-centred values (same r as the
    # partial correlation given the subject)
    c = t.assign(E=t["E"] - t.groupby("subject")["E"].transform("mean"),
                 L=t["L"] - t.groupby("subject")["L"].transform("mean"))
    assert row.loc["repeated_measures", "r"] == pytest.approx(
        sps.pearsonr(c["E"], c["L"]).statistic, rel=1e-9)
    text = (out / "index.html").read_text()
    assert "mm·s" in text and "not a length" in text


def test_no_length_unit_on_what_is_not_a_length(study: tuple[Path, Path]) -> None:
    """eq. 6.5's e is a distance times time: every '[m]' label in the page, the tables
    and the summary is on a length (the MRCP section's path length and displacement)."""
    _, out = study
    files = [out / "index.html", out / "summary.json",
             *sorted((out / "tables").glob("*.csv"))]
    lengths = ("needle path (path_l2) [m]", "target displacement [m]")
    for f in files:
        text = f.read_text()
        for phrase in lengths:
            text = text.replace(phrase, "")
        assert "[m]" not in text, f.name
        assert "cumulative error" not in text.lower(), f.name
    units = _csv(out, "vf_measures").set_index("measure")["unit"].to_dict()
    assert units["eq65"] == "mm·s" and units["path_deviation"] == "mm"


def test_summary_of_an_empty_store_is_all_null(tmp_path: Path) -> None:
    TrialStore(tmp_path / "e.sqlite").close()
    build_report(tmp_path / "e.sqlite", tmp_path / "rep")
    s = json.loads((tmp_path / "rep" / "summary.json").read_text())
    assert s["synthetic"] is False and s["n_subjects"] == 0
    for m in s["measures"].values():
        for k in ("fixture", "practice", "group", "group_x_practice"):
            _check_test(m[k], null=True)
        _check_primary(m["mixed_model"], null=True)
    for k in ("ratings", "best_share", "worst_share"):
        assert s[k] == dict.fromkeys(FIXTURES)


# ---------------------------------------------------------------------- synthetic label
def test_synthetic_label_on_every_figure_and_table(study: tuple[Path, Path],
                                                   tmp_path: Path) -> None:
    db, out = study
    page = (out / "index.html").read_text()
    n_fig = page.count("<figure")
    n_tab = page.count("<table")
    assert n_fig >= 5 and n_tab >= 10
    assert page.count(SYNTHETIC_LABEL) >= n_fig + n_tab
    assert json.loads((out / "tables" / "manifest.json").read_text())["synthetic"] is True
    # the same sessions stored as recorded by another operator: no label, same numbers
    real = tmp_path / "real.sqlite"
    real.write_bytes(db.read_bytes())
    con = sqlite3.connect(real)
    con.execute("UPDATE sessions SET operator = 'haptic_device'")
    con.commit()
    con.close()
    build_report(real, tmp_path / "rep")
    page2 = (tmp_path / "rep" / "index.html").read_text()
    assert SYNTHETIC_LABEL not in page2 and "not evidence" not in page2
    assert json.loads((tmp_path / "rep" / "summary.json").read_text())["synthetic"] is False
    for name in ("vf_rm_anova", "vf_mixed_model", "vf_group_anova", "vf_learning_curve",
                 "vf_transfer_model", "vf_transfer_tests"):
        a = (out / "tables" / f"{name}.csv").read_bytes()
        assert a == (tmp_path / "rep" / "tables" / f"{name}.csv").read_bytes(), name


# ----------------------------------------------------------------------- path deviation
def test_path_deviation_is_analysed_when_stored(tmp_path: Path) -> None:
    db = tmp_path / "pd.sqlite"
    with TrialStore(db) as st:
        st.con.execute("PRAGMA synchronous = OFF")
        for i in range(1, 6):
            _session(st, f"P{i}", 200 + i, 1.0 if i <= 3 else 1.3,
                     DEMO if i <= 3 else RESIDENT, None, path_dev=True)
    out = tmp_path / "rep"
    build_report(db, out)
    t = _trials_sql(db)
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    pdev = dict(con.execute("SELECT trial_id, value FROM trial_metrics "
                            "WHERE metric = 'path_dev_mean_mm'").fetchall())
    con.close()
    t["D"] = t["trial_id"].map(pdev)
    cells = t[t["baseline"] == 0].groupby(["subject", "condition"])["D"].mean().reset_index()
    ref = stats.rm_anova(cells, dv="D", subject="subject", within="condition")
    aov = _csv(out, "vf_rm_anova")
    row = aov[(aov["dv"] == "path_deviation") & (aov["factor"] == "fixture")].iloc[0]
    assert row["unit"] == "mm"
    assert row["F"] == pytest.approx(float(ref.loc[0, "F"]), rel=1e-9)
    s = json.loads((out / "summary.json").read_text())["measures"]["path_deviation"]
    assert s["fixture"]["F"] == pytest.approx(float(ref.loc[0, "F"]), rel=1e-9)
    _check_test(s["practice"], null=False)
    _check_test(s["group"], null=False)
    _check_test(s["group_x_practice"], null=False)
    _check_primary(s["mixed_model"], null=False)
    assert "not stored in this database" not in (out / "index.html").read_text()
