"""Input checks found in review: schema values of the wrong type, names with a trailing
newline, a bad top-level scale, a locked database, export's missing-value marker read back
by `vasim stats`, the rating path in errors, NaN through the f5PL derivative."""

from __future__ import annotations

import math
import sqlite3
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from vasim.core.errors import ConfigError, StoreError
from vasim.fixtures.logistic import Logistic5, f5pl_derivative
from vasim.fixtures.schema import parse_schema
from vasim.study.stats._data import read_long_csv
from vasim.study.store import TrialStore

GOOD = '''name = "s"
description = "d"
[fixtures.ms]
'''


@pytest.mark.parametrize("text, field", [
    (GOOD + 'preset = ["trajectory"]\n', "fixtures.ms.preset"),
    (GOOD + "preset = {a = 1}\n", "fixtures.ms.preset"),
    (GOOD + 'type = ["vg"]\n', "fixtures.ms.type"),
    ('scale_m = -0.03\n' + GOOD, "scale_m"),
    (GOOD.replace('name = "s"', 'name = "s\\n"'), "name"),
])
def test_bad_schema_values_are_named(text: str, field: str) -> None:
    with pytest.raises(ConfigError) as info:
        parse_schema(text, source="bad.toml")
    assert info.value.field == field and "bad.toml" in str(info.value)


def test_protocol_names_with_a_trailing_newline_are_refused(tmp_path: Path) -> None:
    from vasim.study.protocol import load_protocol

    src = Path(__file__).parents[2] / "protocols" / "studies" / "vf_learning_curve.toml"
    text = src.read_text().replace('name = "vf_learning_curve"', 'name = "vf_learning_curve\\n"')
    assert text != src.read_text()
    p = tmp_path / "p.toml"
    p.write_text(text)
    with pytest.raises(ConfigError, match="name"):
        load_protocol(p)


def test_a_locked_database_is_a_store_error(tmp_path: Path) -> None:
    db = tmp_path / "s.db"
    TrialStore(db).close()
    holder = sqlite3.connect(db, timeout=0.1)
    holder.execute("BEGIN IMMEDIATE")
    try:
        with TrialStore(db) as st:
            st.con.execute("PRAGMA busy_timeout = 100")
            with pytest.raises(StoreError, match="busy or locked"):
                st.add_subject("S01")
    finally:
        holder.rollback()
        holder.close()


def test_stats_reads_the_export_missing_value_marker(tmp_path: Path) -> None:
    p = tmp_path / "t.csv"
    p.write_text("subject,condition,completion_time\nS01,vg,1.5\nS01,ff,\\N\n")
    df = read_long_csv(p)
    assert math.isnan(df["completion_time"].iloc[1]) and df["completion_time"].iloc[0] == 1.5


def test_f5pl_derivative_keeps_nan_inputs_nan() -> None:
    p = Logistic5(a=0.0, d=1.0, c=0.01, b=2.0, g=1.0)
    y = f5pl_derivative(np.array([np.nan, 0.01, 1e300]), p)
    assert math.isnan(y[0]) and y[1] > 0 and y[2] == 0.0
    assert isinstance(pd.isna(f5pl_derivative(float("nan"), p)), bool)


def test_cli_one_line_errors_for_limits_paths_and_flags(tmp_path: Path, capsys) -> None:
    """A time limit beyond a day, an --out under a file, a real-time flag without
    --realtime: each a one-line error with exit status 2 (they were tracebacks, or ignored)."""
    from vasim.cli import main

    afile = tmp_path / "afile"
    afile.write_text("x")
    db = tmp_path / "s.sqlite"
    TrialStore(db).close()
    cases = [
        (["trial", "--scene", "none", "--max-time", "1e308"], "--max-time"),
        (["mrcp", "run", "faucet", "--duration", "1e308"], "--duration"),
        (["study", "export", "--db", str(db), "--out", str(afile / "x")], "afile"),
        (["report", "--db", str(db), "--out", str(afile / "x")], "afile"),
        (["trial", "--scene", "none", "--device", "emulator"], "only with --realtime"),
        (["trial", "--realtime", "--replay", "1", "--db", str(db)], "--replay"),
    ]
    for argv, needle in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert needle in err and err.count("\n") == 1 and "Traceback" not in err, (argv, err)


def test_a_protocol_time_limit_beyond_a_day_is_refused(tmp_path: Path) -> None:
    from vasim.study.protocol import load_protocol

    src = Path(__file__).parents[2] / "protocols" / "studies" / "vf_learning_curve.toml"
    text = src.read_text()
    assert "max_trial_time_s" in text
    lines = [("max_trial_time_s = 1e308" if ln.startswith("max_trial_time_s") else ln)
             for ln in text.splitlines()]
    p = tmp_path / "p.toml"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(ConfigError, match="max_trial_time_s"):
        load_protocol(p)
