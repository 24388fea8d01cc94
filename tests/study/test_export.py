"""Export (vasim/study/export.py): CSV and Parquet read back equal, and equal to the store."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from vasim.cli import main
from vasim.core.errors import ConfigError
from vasim.records.samples import FRAME_COLUMNS
from vasim.records.trial_metrics import TRIAL_METRICS
from vasim.study.export import EXPORT_TABLES, export_study, read_export, table_columns
from vasim.study.protocol import parse_protocol
from vasim.study.session import SessionSettings, record_answers, run_session, start_session
from vasim.study.store import SCHEMA_VERSION, TrialStore
from vasim.trials.registry import run_trial
from vasim.trials.vf import TrialConfig

PROTOCOL = """
name = "export_test"
description = "two blocks for the export test"
task = "trajectory"
max_trial_time_s = 0.2
[randomisation]
block_order = "random"
[[blocks]]
name = "baseline"
condition = "none"
probe = true
counterbalance = false
[[blocks]]
name = "vg"
condition = "vg"
variants = [1, 2]
probes_after = 1
[[blocks]]
name = "mag"
condition = "mag"
variants = [3]
probes_after = 1
[questionnaires.pre]
demographics = true
[[questionnaires.post.items]]
id = "rating"
type = "condition_rating"
prompt = "rate"
[[questionnaires.post.items]]
id = "comments"
type = "text"
prompt = "comments"
required = false
"""

COMMENT = 'commas, "quotes", a \\N look-alike\nand a second line'


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    db = tmp_path_factory.mktemp("export") / "study.db"
    p = parse_protocol(PROTOCOL, source="export_test.toml")
    with TrialStore(db) as st:
        sid = start_session(st, p, "E01", seed=9, settings=SessionSettings(skill="expert"))
        record_answers(st, sid, "pre", {
            "group": "resident", "specialisation": "other", "laparoscopy_experience": "none",
            "simulator_experience": "none", "robotic_experience": "none"})
        run_session(st, sid, progress=False)
        record_answers(st, sid, "post", {"rating": {"vg": 7, "mag": 4}, "comments": COMMENT})
        sid2 = start_session(st, p, "E02", seed=10)  # an empty comment, partly run
        run_session(st, sid2, progress=False, max_trials=2)
        record_answers(st, sid2, "post", {"rating": {"vg": 0, "mag": 10}, "comments": ""})
        run_trial(TrialConfig(schema="ff", seed=1, max_time=0.1, subject="E03"), st)
        tid = st.begin_trial({"subject": "E03", "task": "trajectory"})
        st.mark_interrupted(tid, reason="test")  # interrupted: in trials, not in metrics
    return db


@pytest.mark.parametrize("table", EXPORT_TABLES)
def test_csv_and_parquet_read_back_equal(study: Path, tmp_path: Path, table: str) -> None:
    out = export_study(study, tmp_path / "out", formats=("csv", "parquet"), tables=[table])
    a = read_export(out, table, "csv")
    b = read_export(out, table, "parquet")
    assert list(a.columns) == list(table_columns(table))
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert len(a) > 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["tables"][table]["rows"] == len(a)
    assert manifest["schema_version"] == SCHEMA_VERSION


def test_exported_values_equal_the_store(study: Path, tmp_path: Path) -> None:
    out = export_study(study, tmp_path / "out", formats=("csv",))
    samples = read_export(out, "samples")
    tm = read_export(out, "trial_metrics")
    trials = read_export(out, "trials")
    q = read_export(out, "questionnaires")
    subjects = read_export(out, "subjects")
    with TrialStore(study, readonly=True) as st:
        all_trials = st.trials()
        assert trials["trial_id"].tolist() == all_trials["id"].tolist()
        assert trials["status"].tolist() == all_trials["status"].tolist()
        # samples: every stored row, exactly (floats written with round-trip precision)
        for tid in all_trials["id"]:
            mine = samples[samples["trial_id"] == tid].drop(columns="trial_id")
            ref = st.samples(int(tid))
            assert np.array_equal(mine[list(FRAME_COLUMNS)].to_numpy(np.float64),
                                  ref.to_numpy(np.float64), equal_nan=True)
        # trial metrics: completed trials only, with their schedule context
        done = all_trials[all_trials["status"] == "completed"]
        assert tm["trial_id"].tolist() == done["id"].tolist()
        wide = st.trial_metrics(wide=True)
        np.testing.assert_array_equal(tm[list(TRIAL_METRICS)].to_numpy(),
                                      wide.loc[done["id"], list(TRIAL_METRICS)].to_numpy())
        sched = st.schedule(1)
    s1 = tm[tm["session_id"] == 1].sort_values("trial_index")
    assert s1["condition"].tolist() == sched["condition"].tolist()
    assert s1["probe_index"].tolist() == sched["probe_index"].tolist()  # VF-free number
    assert s1["probe_index"].dropna().tolist() == [1, 2, 3]
    assert set(s1["group"]) == {"resident"}
    lone = tm[tm["session_id"].isna()]
    assert lone["condition"].tolist() == ["ff"] and lone["subject"].tolist() == ["E03"]
    # text as given; an empty string stays empty (not missing)
    comments = q[q["item"] == "comments"].set_index("subject")["value"]
    assert comments["E01"] == COMMENT and comments["E02"] == ""
    assert q.loc[(q["item"] == "rating") & (q["key"] == "mag"), "value_num"].tolist() == [
        4.0, 10.0]
    act = trials.set_index("trial_id")["active_fixtures"]
    assert "" in set(act) and not act.isna().any()  # VF-free trials keep ''
    assert subjects.set_index("subject").loc["E02"].isna()["group"]  # no pre answers


def test_cli_export_and_bad_requests(study: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "cli"
    assert main(["study", "export", "--db", str(study), "--out", str(out), "--format",
                 "parquet", "--tables", "trial_metrics,sessions"]) == 0
    assert sorted(p.name for p in out.iterdir()) == [
        "manifest.json", "sessions.parquet", "trial_metrics.parquet"]
    assert "trial_metrics" in capsys.readouterr().out
    with pytest.raises(ConfigError, match="format"):
        export_study(study, out, formats=("xlsx",))
    with pytest.raises(ConfigError, match="got 'trialz', expected one of"):
        export_study(study, out, tables=("trialz",))
    assert main(["study", "export", "--db", str(tmp_path / "none.db"), "--out",
                 str(out)]) == 2
    assert "expected an existing study database file" in capsys.readouterr().err


def test_units_are_in_the_manifest(study: Path, tmp_path: Path) -> None:
    out = export_study(study, tmp_path / "m", tables=("samples",))
    cols = {c["name"]: c for c in json.loads((out / "manifest.json").read_text())
            ["tables"]["samples"]["columns"]}
    assert cols["x_x"]["unit"] == "m" and cols["fc_z"]["unit"] == "N"
    assert cols["in_view"]["dtype"] == "int64" and "unit" not in cols["in_view"]
    assert math.isclose(len(cols), len(FRAME_COLUMNS) + 1)
