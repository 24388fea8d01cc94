"""The MRCP section of ``vasim report`` on synthetic MRCP vs StdT sessions.

The MRCP slave station does not exist yet, so the sessions are written straight into a
temporary store through the store API: the real ``mrcp_vs_stdt`` protocol text and
schedule, and per trial the metrics the station will store (completion_time, path_l2,
contact_time, accumulated_force, accumulated_torque, target_displacement_max).
Expected numbers are computed by hand from the generated values, not from the store.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats as sps

from vasim.records.samples import SampleBuffer
from vasim.records.trial_meta import TrialMeta
from vasim.study import stats
from vasim.study.protocol import generate_schedule, load_protocol
from vasim.study.report import build_report
from vasim.study.session import record_answers
from vasim.study.store import SessionMeta, TrialStore

MODES = ("stdt", "mrcp", "mrcp_cam")
FACTOR = {"stdt": 1.0, "mrcp": 0.7, "mrcp_cam": 0.8}
LIKERT = ("usefulness", "expected_et", "expected_em", "expected_q", "comfort", "abstraction")


def _metrics(rng: np.random.Generator, mode: str, rep: int, skill: float) -> dict[str, float]:
    f = FACTOR[mode] * skill * (1 + rep) ** -0.2
    return {"completion_time": 140.0 * f * np.exp(rng.normal(0, 0.1)),
            "path_l2": 2.0 * f * np.exp(rng.normal(0, 0.1)),
            "contact_time": 10.0 * f * np.exp(rng.normal(0, 0.2)),
            "accumulated_force": 30.0 * f * np.exp(rng.normal(0, 0.2)),
            "accumulated_torque": 1.5 * f * np.exp(rng.normal(0, 0.2)),
            "target_displacement_max": 0.004 * f * np.exp(rng.normal(0, 0.2)),
            "target_deformation": 5.0 * f * np.exp(rng.normal(0, 0.3))}


def write_mrcp(store: TrialStore, code: str, seed: int, *, stop_after: int | None = None,
               likert: dict[str, int] | None = None) -> list[dict]:
    """One synthetic MRCP session; returns the stored trial metrics with their mode."""
    protocol = load_protocol("mrcp_vs_stdt")
    sched = generate_schedule(protocol, seed)
    sid = store.create_session(
        SessionMeta(subject=code, protocol=protocol.name, protocol_toml=protocol.text or "",
                    seed=seed, operator="scripted"), [t.as_row() for t in sched])
    rng = np.random.default_rng(seed)
    skill = float(np.exp(rng.normal(0, 0.2)))
    rows = []
    for st in sched:
        if stop_after is not None and st.index >= stop_after:
            break
        m = _metrics(rng, st.condition, st.repetition, skill)
        tid = store.begin_trial(TrialMeta(subject=code, task="point", session_id=sid,
                                          schedule_index=st.index, protocol=protocol.name))
        store.finish_trial(tid, SampleBuffer(), None, None, trial_metrics=m)
        rows.append({"subject": code, "mode": st.condition, "rep": st.repetition,
                     "trial_id": tid, **m})
    if stop_after is None:
        store.set_session_status(sid, "completed")
    if likert is not None:
        record_answers(store, sid, "post", {**likert, "best_mode": "mrcp"})
    return rows


@pytest.fixture(scope="module")
def mrcp_study(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, pd.DataFrame,
                                                                   pd.DataFrame]:
    d = tmp_path_factory.mktemp("mrcp")
    db = d / "mrcp.sqlite"
    rows: list[dict] = []
    answers = []
    rng = np.random.default_rng(5)
    with TrialStore(db) as st:
        st.con.execute("PRAGMA synchronous = OFF")
        for i in range(6):
            lk = {k: int(rng.integers(1, 6)) for k in LIKERT}
            answers += [{"subject": f"M{i}", "item": k, "value": float(v)}
                        for k, v in lk.items()]
            rows += write_mrcp(st, f"M{i}", 100 + i, likert=lk)
        rows += write_mrcp(st, "M9", 200, stop_after=12)  # two modes only: excluded
    out = d / "report"
    build_report(db, out, protocol="mrcp_vs_stdt")
    return db, out, pd.DataFrame(rows), pd.DataFrame(answers)


def _csv(out: Path, name: str) -> pd.DataFrame:
    return pd.read_csv(out / "tables" / f"{name}.csv")


def test_gains_equal_hand_computed_ratios(mrcp_study) -> None:
    _, out, data, _ = mrcp_study
    complete = data[data["subject"] != "M9"]
    gains = _csv(out, "mrcp_gains")
    for key, metric in (("ET", "completion_time"), ("EM", "path_l2"),
                        ("force", "accumulated_force"), ("Q", "target_deformation"),
                        ("Q_target_displacement", "target_displacement_max")):
        for mode, label in (("mrcp", "MRCP"), ("mrcp_cam", "MRCP+Cam")):
            # balanced design (6 trials per subject and mode): the ratio of the means of all
            # trials equals the ratio of the means of the subject means
            hand = (complete.loc[complete["mode"] == "stdt", metric].mean()
                    / complete.loc[complete["mode"] == mode, metric].mean())
            row = gains[(gains["metric"] == key) & (gains["mode"] == label)].iloc[0]
            assert row["gain"] == pytest.approx(hand, rel=1e-12)
            assert row["reference"] == "StdT" and row["n_subjects"] == 6


def test_descriptives_and_paired_tests(mrcp_study) -> None:
    _, out, data, _ = mrcp_study
    complete = data[data["subject"] != "M9"]
    means = complete.groupby(["subject", "mode"])["completion_time"].mean().unstack()
    desc = _csv(out, "mrcp_descriptives")
    et = desc[desc["metric"] == "ET"].set_index("mode")
    assert et.loc["StdT", "mean"] == pytest.approx(means["stdt"].mean(), rel=1e-12)
    assert et.loc["MRCP", "sd"] == pytest.approx(means["mrcp"].std(ddof=1), rel=1e-12)
    assert et.loc["MRCP+Cam", "n_trials"] == 36
    # ET, EM and Q keep the columns metric, mode, mean (issue #21 §4); Q is in mm s
    q = desc[desc["metric"] == "Q"].set_index("mode")
    qm = complete.groupby(["subject", "mode"])["target_deformation"].mean().unstack()
    assert q.loc["MRCP", "mean"] == pytest.approx(qm["mrcp"].mean(), rel=1e-12)
    assert set(q["unit"]) == {"mm s"} and set(q["family"]) == {"Q"}
    ids = {int(x) for x in et.loc["StdT", "trial_ids"].split()}
    assert ids == set(complete.loc[complete["mode"] == "stdt", "trial_id"])
    paired = _csv(out, "mrcp_paired")
    et = paired[paired["metric"] == "ET"]
    assert list(zip(et["group1"], et["group2"], strict=True)) == list(
        itertools.combinations(["StdT", "MRCP", "MRCP+Cam"], 2))
    ref = sps.ttest_rel(means["stdt"], means["mrcp"])  # independent implementation
    row = et.iloc[0]
    assert row["t"] == pytest.approx(ref.statistic, rel=1e-9)
    assert row["p"] == pytest.approx(ref.pvalue, rel=1e-9)
    assert row["n"] == 6
    assert row["power_observed"] == pytest.approx(
        stats.paired_power(row["cohen_dz"], 6), rel=1e-9)


def test_learning_curves_and_exclusions(mrcp_study) -> None:
    _, out, data, _ = mrcp_study
    lc = _csv(out, "mrcp_learning_curve")
    first = data[(data["mode"] == "stdt") & (data["rep"] == 0)]
    row = lc[(lc["metric"] == "EM") & (lc["mode"] == "StdT") & (lc["trial"] == 1)].iloc[0]
    assert row["n"] == first["subject"].nunique()
    assert row["mean"] == pytest.approx(first["path_l2"].mean(), rel=1e-12)
    assert set(lc["trial"]) == {1, 2, 3, 4, 5, 6}
    fits = _csv(out, "mrcp_learning_fit")
    assert set(fits["mode"]) == {"StdT", "MRCP", "MRCP+Cam"}
    html = (out / "index.html").read_text()
    assert "M9 (no " in html  # the incomplete subject is named as excluded
    assert "<section id=\"mrcp\">" in html and "Learning curve: ET" in html
    # the MRCP study has no VF-free probe trials: those sections say so
    assert "no VF-free probe trial" in html


def test_likert_items(mrcp_study) -> None:
    _, out, _, answers = mrcp_study
    num = _csv(out, "questionnaire_numeric").set_index("item")
    for item in LIKERT:
        v = answers.loc[answers["item"] == item, "value"]
        assert num.loc[item, "mean"] == pytest.approx(v.mean(), rel=1e-12)
        assert num.loc[item, "sd"] == pytest.approx(v.std(ddof=1), rel=1e-12)
        assert num.loc[item, "n"] == 6
    sp = _csv(out, "questionnaire_spearman")
    ref = stats.spearman_items(answers, subject="subject", item="item", value="value")
    np.testing.assert_allclose(sp["rho"], ref["rho"], rtol=1e-12)
    prov = _csv(out, "provenance")
    assert (prov["table"] == "questionnaire_spearman").sum() == len(sp)
