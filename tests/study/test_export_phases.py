"""Export of the retention/transfer phases (vasim/study/export.py): every scheduled and
completed trial carries its block's phase, its sitting and the sitting's nominal day."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from vasim.study.export import export_study, read_export
from vasim.study.protocol import parse_protocol
from vasim.study.session import SessionSettings, run_session, start_session
from vasim.study.store import TrialStore
from vasim.trials.registry import run_trial
from vasim.trials.vf import TrialConfig

# baseline (1) + ff (1 + 1 probe) | 3 days later: retention (2) + transfer (1) | 4 days
# later: a second retention (1): 7 trials in 3 sittings on days 0, 3, 7
PROTOCOL = """
name = "export_phases"
description = "acquisition, a retention sitting with transfer, a late retention sitting"
task = "trajectory"
max_trial_time_s = 0.2
[[blocks]]
name = "baseline"
condition = "none"
probe = true
counterbalance = false
[[blocks]]
name = "ff"
condition = "ff"
variants = [1]
probes_after = 1
[[blocks]]
name = "retention"
condition = "none"
phase = "retention"
delay_days = 3.0
repetitions = 2
probe = true
counterbalance = false
[[blocks]]
name = "transfer"
condition = "none"
phase = "transfer"
variants = [5]
probe = true
counterbalance = false
[[blocks]]
name = "late"
condition = "none"
phase = "retention"
delay_days = 4.0
probe = true
counterbalance = false
"""

EXPECTED = pd.DataFrame({
    "block": ["baseline", "ff", "ff", "retention", "retention", "transfer", "late"],
    "phase": ["acquisition", "acquisition", "acquisition", "retention", "retention",
              "transfer", "retention"],
    "sitting": [1, 1, 1, 2, 2, 2, 3],
    "day": [0.0, 0.0, 0.0, 3.0, 3.0, 3.0, 7.0],
})


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("phases")
    p = parse_protocol(PROTOCOL, source="export_phases.toml")
    with TrialStore(d / "s.db") as st:
        sid = start_session(st, p, "P01", seed=4, settings=SessionSettings(max_trial_time=0.1))
        assert run_session(st, sid, progress=False) == 3                   # sitting 1
        assert run_session(st, sid, progress=False, simulate_delay=True) == 3  # sitting 2
        assert run_session(st, sid, progress=False, simulate_delay=True) == 1  # sitting 3
        run_trial(TrialConfig(schema="ff", seed=1, max_time=0.1, subject="P02"), st)
    return export_study(d / "s.db", d / "out", formats=("csv", "parquet"))


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_schedule_and_trial_metrics_carry_phase_sitting_and_day(exported: Path,
                                                                fmt: str) -> None:
    cols = ["block", "phase", "sitting", "day"]
    sched = read_export(exported, "schedule", fmt).sort_values("trial_index")
    got = sched[cols].reset_index(drop=True)
    pd.testing.assert_frame_equal(got.astype(object), EXPECTED.astype(object))
    tm = read_export(exported, "trial_metrics", fmt)
    in_session = tm[tm["session_id"].notna()].sort_values("trial_index")
    pd.testing.assert_frame_equal(in_session[cols].reset_index(drop=True).astype(object),
                                  EXPECTED.astype(object))
    free = tm[tm["session_id"].isna()]                  # a trial outside any session
    assert len(free) == 1 and free["phase"].isna().all() and free["sitting"].isna().all()
    pm = read_export(exported, "point_metrics", fmt)
    by_trial = pm.groupby("trial_id")[["phase", "sitting"]].first()
    want = in_session.set_index("trial_id")[["phase", "sitting"]]
    pd.testing.assert_frame_equal(by_trial.loc[by_trial.index.isin(want.index)],
                                  want.loc[want.index.isin(by_trial.index)],
                                  check_dtype=False)


def test_the_manifest_gives_the_day_unit(exported: Path) -> None:
    import json

    man = json.loads((exported / "manifest.json").read_text(encoding="utf-8"))
    cols = {c["name"]: c for c in man["tables"]["schedule"]["columns"]}
    assert cols["day"]["unit"] == "d" and cols["sitting"]["dtype"] == "Int64"
    assert cols["phase"]["dtype"] == "str"
