"""Tests of the long-format validation shared by the statistics (vasim/study/stats/_data.py)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from vasim.core.errors import ConfigError
from vasim.study.stats._data import (
    cell_means,
    levels_of,
    nan_to_none,
    numeric_column,
    read_long_csv,
    require_columns,
)


def test_read_long_csv_records_source_and_lines(tmp_path: Path) -> None:
    p = tmp_path / "d.csv"
    p.write_text("s,c,y\n1,a,1.5\n1,b,2\n")
    df = read_long_csv(p)
    assert df.attrs["source"] == str(p)
    assert df.index.tolist() == [2, 3]  # CSV line numbers (header is line 1)


@pytest.mark.parametrize(("content", "match"), [
    (None, "CSV file not found"),
    ("", "CSV file is empty"),
    ("s,c,y\n", "header but no data rows"),
    ('s,c,y\n1,"a,2\n', "cannot parse CSV"),
])
def test_read_long_csv_errors_name_the_file(tmp_path: Path, content: str | None,
                                            match: str) -> None:
    p = tmp_path / "bad.csv"
    if content is not None:
        p.write_text(content)
    with pytest.raises(ConfigError, match=match) as err:
        read_long_csv(p)
    assert err.value.file == str(p)


def test_read_long_csv_directory(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="is a directory"):
        read_long_csv(tmp_path)


def test_require_columns() -> None:
    df = pd.DataFrame({"s": [1], "y": [2.0]})
    df.attrs["source"] = "study.csv"
    with pytest.raises(ConfigError, match="column 'x' not found; available columns: 's', 'y'") \
            as err:
        require_columns(df, ["s", "x"])
    assert str(err.value).startswith("study.csv: field 'x': ")
    with pytest.raises(ConfigError, match="two different roles"):
        require_columns(df, ["s", "s"])


def test_numeric_column_rejects_text_bool_inf() -> None:
    df = pd.DataFrame({"y": ["1.5", "x", "2", "y"]})
    with pytest.raises(ConfigError, match=r"non-numeric values at row index 1, 3: 'x', 'y'"):
        numeric_column(df, "y")
    with pytest.raises(ConfigError, match="boolean"):
        numeric_column(pd.DataFrame({"y": [True, False]}), "y")
    with pytest.raises(ConfigError, match="non-finite values at row index 0: -inf"):
        numeric_column(pd.DataFrame({"y": [-np.inf, 1.0]}), "y")
    kept = numeric_column(pd.DataFrame({"y": [1.0, None]}), "y", allow_missing=True)
    assert kept.isna().tolist() == [False, True]


def test_levels_order() -> None:
    assert levels_of(pd.Series([10, 2, 9, 2])) == [2, 9, 10]  # numeric, not text order
    cat = pd.Series(pd.Categorical(["b", "a", "b"], categories=["b", "c", "a"]))
    assert levels_of(cat) == ["b", "a"]  # category order, unobserved "c" dropped
    assert levels_of(pd.Series(["x", 1, "x"], dtype=object)) == ["x", 1]  # not comparable
    assert all(type(v) is int for v in levels_of(pd.Series(np.array([3, 1]))))


def test_cell_means_average_and_counts() -> None:
    df = pd.DataFrame({"s": [1, 1, 1, 2, 2, 2], "c": ["a", "a", "b", "a", "b", "b"],
                       "y": [1.0, 3.0, 5.0, 2.0, 4.0, 8.0]})
    cm = cell_means(df, "y", "s", ["c"])
    np.testing.assert_array_equal(cm.values, [[2.0, 5.0], [2.0, 6.0]])
    np.testing.assert_array_equal(cm.n_obs, [[2, 1], [1, 2]])
    assert cm.subjects == [1, 2] and cm.levels == [["a", "b"]]


def test_unbalanced_message_is_truncated() -> None:
    rows = [{"s": s, "c": c, "y": 1.0} for s in range(12) for c in ("a", "b")]
    df = pd.DataFrame(rows[:2] + [r for r in rows[2:] if r["c"] == "a"])
    with pytest.raises(ConfigError, match=r"11 subject x cell .* and 3 more"):
        cell_means(df, "y", "s", ["c"])


def test_nan_to_none() -> None:
    assert nan_to_none(float("nan")) is None
    assert nan_to_none(np.float64(2.5)) == 2.5 and type(nan_to_none(np.int64(3))) is int
    assert nan_to_none(pd.NA) is None and nan_to_none(float("inf")) is None


def test_stats_reads_the_export_missing_value_marker(tmp_path: Path) -> None:
    p = tmp_path / "t.csv"
    p.write_text("subject,condition,completion_time\nS01,vg,1.5\nS01,ff,\\N\n")
    df = read_long_csv(p)
    assert math.isnan(df["completion_time"].iloc[1]) and df["completion_time"].iloc[0] == 1.5
