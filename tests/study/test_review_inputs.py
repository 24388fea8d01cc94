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

from vasim.errors import ConfigError, StoreError
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
