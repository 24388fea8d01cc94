"""One power cohort (vasim/study/power/cohort.py): the in-memory path gives the trials,
the frames and the tests that the same cohort written to a study database and read back
by the report's loader gives; scaled effects re-derive the session's configurations."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from vasim.operator.learning import DEFAULT_EFFECTS
from vasim.study.power.cohort import (
    cohort_subjects_of,
    cohort_tests,
    simulate_in_memory,
    study_data,
    subject_session,
    trial_configs,
)
from vasim.study.power.design import COARSE_DT, PowerDesign, scaled_effects
from vasim.study.protocol import Protocol
from vasim.study.report.build import build_report
from vasim.study.report.data import load_study


def test_in_memory_cohort_equals_the_stored_one(tiny_protocol: Protocol,
                                                tmp_path: Path) -> None:
    design = PowerDesign(subjects=(3,), cohorts=1, dt=COARSE_DT, max_trial_time=1.5)
    mem = cohort_tests(tiny_protocol, design, 3, 0)
    kept = cohort_tests(tiny_protocol, design, 3, 0, keep_dir=str(tmp_path))
    assert mem.n_trials == kept.n_trials == 3 * 8
    assert mem.sim_seconds == kept.sim_seconds > 0
    pd.testing.assert_frame_equal(mem.tests, kept.tests)
    assert mem.tests["F"].notna().any()
    # the frames the analysis reads are the store's, value for value
    db = tmp_path / "power_N3_c0.sqlite"
    stored = load_study(db, tiny_protocol.name)
    subjects = cohort_subjects_of(tiny_protocol, 3, int(mem.tests["seed"].iloc[0]))
    memory = study_data(tiny_protocol, simulate_in_memory(
        tiny_protocol, subjects, dt=COARSE_DT, max_trial_time=1.5))
    cols = ["session_id", "trial_index", "condition", "probe", "probe_index", "trial_id",
            "subject", "stage"]
    pd.testing.assert_frame_equal(memory.analysed[cols], stored.analysed[cols],
                                  check_dtype=False)
    pd.testing.assert_frame_equal(memory.points.reset_index(drop=True),
                                  stored.points.reset_index(drop=True), check_dtype=False)
    common = [c for c in memory.metrics.columns if c in stored.metrics.columns]
    assert "path_dev_mean_mm" in common
    np.testing.assert_allclose(memory.metrics[common].to_numpy(float),
                               stored.metrics[common].to_numpy(float), rtol=1e-12)
    assert stored.sessions["status"].eq("completed").all()
    # and `vasim report` on the kept database prints the very tests power counted
    build_report(db, tmp_path / "report", progress=False)
    summary = json.loads((tmp_path / "report" / "summary.json").read_text())
    key = {"eq65": "eq65", "latency": "latency", "path_deviation": "path_deviation"}
    assert set(mem.tests["factor"]) == {"practised", "fixture", "trial"}
    for r in mem.tests.itertuples():
        m = summary["measures"][key[r.dv]]
        if r.factor == "practised":   # the PRIMARY probe model's fixture F test
            x = (m["mixed_model"] or {}).get("fixture_test")
            if np.isnan(r.F):
                assert x is None or x["F"] is None
            else:
                assert np.isclose(x["F"], r.F, rtol=1e-12) and np.isclose(x["p"], r.p_unc)
                assert r.p_gg == r.p_unc
            continue
        t = m["fixture" if r.factor == "fixture" else "practice"]
        if np.isnan(r.F):
            assert t["F"] is None
        else:
            assert np.isclose(t["F"], r.F, rtol=1e-12) and np.isclose(t["p_gg"], r.p_gg)
            assert np.isclose(t["p"], r.p_unc, rtol=1e-12)


def test_scaled_effects_rederive_the_session_configurations(tiny_protocol: Protocol) -> None:
    subj = cohort_subjects_of(tiny_protocol, 2, 11)[0]
    session = subject_session(tiny_protocol, subj, dt=COARSE_DT, max_trial_time=1.0)
    default = trial_configs(session, subj.profile)
    same = trial_configs(session, subj.profile, dict(DEFAULT_EFFECTS))  # a copy: re-derived
    assert [c for _, c in default] == [c for _, c in same]
    assert [c.profile for _, c in default] == [c.profile for _, c in same]
    none = trial_configs(session, subj.profile, scaled_effects(0.0))
    for (st, c0), (_, c1) in zip(default, none, strict=True):
        assert c1.seed == c0.seed and c1.variant == c0.variant and c1.schema == c0.schema
        assert c1.practice == st.index            # every earlier trial counts as one
        assert c1.profile is not None and c0.profile is not None
        if st.condition == "ff":                   # FF's calibrated noise factor is gone
            assert c1.profile.noise == subj.profile.noise
            assert np.isclose(c0.profile.noise, DEFAULT_EFFECTS["ff"].accuracy * subj.profile.noise)
