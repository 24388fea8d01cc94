"""Experiment 3 (issue #28 item 2): the ``mrcp_suture_dynamic`` protocol's schedule and the
report's Table 5.4 / 5.5 layouts and per-subject table on a tiny cohort.

The sessions are written through the store API with the real protocol text and schedule and
per trial the metrics the station stores (as ``test_report_mrcp``); expected numbers are
computed here from the generated values with independent implementations (numpy, scipy,
statsmodels), not read back from the store.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats as sps
from statsmodels.stats.power import TTestPower

from vasim.records.samples import SampleBuffer
from vasim.records.trial_meta import TrialMeta
from vasim.study.protocol import generate_schedule, load_protocol
from vasim.study.report import build_report
from vasim.study.session import load_session, start_session
from vasim.study.store import SessionMeta, TrialStore

METRICS = {"ET": "completion_time", "EM": "path_l2", "contact_time": "contact_time",
           "force": "accumulated_force", "torque": "accumulated_torque"}
UNITS = {"ET": "s", "EM": "m", "contact_time": "s", "force": "N s", "torque": "N m s"}
# subject -> MRCP factor: S1, S2 benefit from MRCP, S3 does not
FACTOR = {"S1": 0.6, "S2": 0.7, "S3": 1.2}


def test_the_schedule_is_two_blocks_of_six_in_random_order() -> None:
    p = load_protocol("mrcp_suture_dynamic")
    assert [(b.condition, b.repetitions) for b in p.blocks] == [("stdt", 6), ("mrcp", 6)]
    firsts = set()
    for seed in range(20):
        sched = generate_schedule(p, seed)
        conds = [t.condition for t in sched]
        assert len(conds) == 12 and sorted(set(conds)) == ["mrcp", "stdt"]
        assert conds[:6] == [conds[0]] * 6 and conds[6:] == [conds[6]] * 6  # blocks
        assert conds[0] != conds[6]
        assert not any(t.probe for t in sched)
        firsts.add(conds[0])
    assert firsts == {"stdt", "mrcp"}     # randomised: both orders occur


def test_each_trial_runs_its_mode_on_the_breathing_tissue_with_its_modes_practice(
        tmp_path: Path) -> None:
    with TrialStore(tmp_path / "s.sqlite") as store:
        session = load_session(store, start_session(
            store, load_protocol("mrcp_suture_dynamic"), "S01", seed=4))
        seen: dict[str, list[int | None]] = {}
        for t in session.schedule:
            cfg = session.trial_config(t)
            assert cfg.mode == t.condition and cfg.scene == "default"   # breathing scene
            seen.setdefault(t.condition, []).append(cfg.mode_practice)
    assert seen == {"stdt": [0, 1, 2, 3, 4, 5], "mrcp": [0, 1, 2, 3, 4, 5]}


def _write(store: TrialStore, code: str, seed: int) -> list[dict[str, object]]:
    protocol = load_protocol("mrcp_suture_dynamic")
    sched = generate_schedule(protocol, seed)
    sid = store.create_session(
        SessionMeta(subject=code, protocol=protocol.name, protocol_toml=protocol.text or "",
                    seed=seed, operator="scripted"), [t.as_row() for t in sched])
    rng = np.random.default_rng(seed)
    rows = []
    for st in sched:
        f = (FACTOR[code] if st.condition == "mrcp" else 1.0) * (1 + st.repetition) ** -0.2
        m = {"completion_time": 150.0 * f * np.exp(rng.normal(0, 0.1)),
             "path_l2": 2.0 * f * np.exp(rng.normal(0, 0.1)),
             "contact_time": 20.0 * f * np.exp(rng.normal(0, 0.2)),
             "accumulated_force": 40.0 * f * np.exp(rng.normal(0, 0.2)),
             "accumulated_torque": 0.8 * f * np.exp(rng.normal(0, 0.2))}
        tid = store.begin_trial(TrialMeta(subject=code, task="needle", session_id=sid,
                                          schedule_index=st.index, protocol=protocol.name))
        store.finish_trial(tid, SampleBuffer(), None, None, trial_metrics=m)
        rows.append({"subject": code, "mode": st.condition, **m})
    store.set_session_status(sid, "completed")
    return rows


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, pd.DataFrame]:
    d = tmp_path_factory.mktemp("suture")
    db = d / "s.sqlite"
    rows: list[dict[str, object]] = []
    with TrialStore(db) as st:
        for i, code in enumerate(FACTOR):
            rows += _write(st, code, 30 + i)
    out = d / "report"
    build_report(db, out, protocol="mrcp_suture_dynamic")
    data = pd.DataFrame(rows)
    cells = data.groupby(["subject", "mode"])[list(METRICS.values())].mean()
    return out, cells


def _csv(out: Path, name: str) -> pd.DataFrame:
    return pd.read_csv(out / "tables" / f"{name}.csv")


def test_descriptives_have_the_issues_metrics_and_modes(report) -> None:
    out, cells = report
    desc = _csv(out, "mrcp_descriptives")
    assert {"metric", "mode", "mean"} <= set(desc.columns)
    assert set(desc["mode"]) == {"StdT", "MRCP"}
    assert set(METRICS) <= set(desc["metric"])
    for key, metric in METRICS.items():
        for mode, label in (("stdt", "StdT"), ("mrcp", "MRCP")):
            row = desc[(desc["metric"] == key) & (desc["mode"] == label)].iloc[0]
            assert row["mean"] == pytest.approx(cells[metric].xs(mode, level="mode").mean(),
                                                rel=1e-12)
            assert row["unit"] == UNITS[key]


def test_table_5_4_layout_mean_sd_and_gain(report) -> None:
    out, cells = report
    t54 = _csv(out, "mrcp_table54").set_index("metric")
    assert set(t54["mode"]) == {"MRCP"}
    for key, metric in METRICS.items():
        s = cells[metric].xs("stdt", level="mode")
        m = cells[metric].xs("mrcp", level="mode")
        r = t54.loc[key]
        assert (r["mean_StdT"], r["mean_mode"]) == pytest.approx((s.mean(), m.mean()),
                                                                 rel=1e-12)
        assert (r["sd_StdT"], r["sd_mode"]) == pytest.approx((s.std(ddof=1), m.std(ddof=1)),
                                                             rel=1e-12)
        assert r["gain"] == pytest.approx(s.mean() / m.mean(), rel=1e-12)
        assert r["n_subjects"] == 3


def test_table_5_5_layout_paired_tests_power_and_subjects_needed(report) -> None:
    out, cells = report
    t55 = _csv(out, "mrcp_table55").set_index("metric")
    for key, metric in METRICS.items():
        s = cells[metric].xs("stdt", level="mode")
        m = cells[metric].xs("mrcp", level="mode")
        ref = sps.ttest_rel(s, m)
        r = t55.loc[key]
        assert (r["group1"], r["group2"], r["n"]) == ("StdT", "MRCP", 3)
        assert r["t"] == pytest.approx(ref.statistic, rel=1e-9)
        assert r["p"] == pytest.approx(ref.pvalue, rel=1e-9)
        d = (s - m)
        dz = d.mean() / d.std(ddof=1)
        power = TTestPower().power(effect_size=abs(dz), nobs=3, alpha=0.05,
                                   alternative="two-sided")
        assert r["power_observed"] == pytest.approx(power, rel=1e-6)
        # the smallest integer n with power >= 0.9 at this effect
        n = int(r["n_power90_ceil"])
        assert TTestPower().power(effect_size=abs(dz), nobs=n, alpha=0.05,
                                  alternative="two-sided") >= 0.9 - 1e-9
        assert n == 2 or TTestPower().power(effect_size=abs(dz), nobs=n - 1, alpha=0.05,
                                            alternative="two-sided") < 0.9


def test_per_subject_results_say_who_benefits(report) -> None:
    out, cells = report
    ps = _csv(out, "mrcp_per_subject")
    et = ps[ps["metric"] == "ET"].set_index("subject")
    for subj in FACTOR:
        s = cells.loc[(subj, "stdt"), "completion_time"]
        m = cells.loc[(subj, "mrcp"), "completion_time"]
        assert et.loc[subj, "gain"] == pytest.approx(s / m, rel=1e-12)
        assert et.loc[subj, "benefits"] == ("yes" if s > m else "no")
    assert list(et.loc[["S1", "S2", "S3"], "benefits"]) == ["yes", "yes", "no"]
    html = (out / "index.html").read_text(encoding="utf-8")
    assert "ET, MRCP vs StdT: smaller for 2 of 3 subjects (not for S3)" in html
    assert not math.isnan(float(et.loc["S3", "mean_StdT"]))
