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


# --- labels are text (issue #16 item 2) ---------------------------------------------


def test_subject_codes_01_and_1_stay_different(tmp_path: Path) -> None:
    p = tmp_path / "codes.csv"
    p.write_text("s,c,y\n01,a,1\n01,b,2\n1,a,3\n1,b,5\n1.0,a,2\n1.0,b,2.5\n")
    for df in (read_long_csv(p), read_long_csv(p, text_columns=["s", "c"])):
        assert df["s"].tolist() == ["01", "01", "1", "1", "1.0", "1.0"]
        cm = cell_means(df, "y", "s", ["c"])
        assert cm.subjects == ["1", "01", "1.0"]  # three subjects, natural order
        np.testing.assert_array_equal(cm.values, [[3.0, 5.0], [1.0, 2.0], [2.0, 2.5]])
        assert (cm.n_obs == 1).all()


def test_named_text_columns_stay_text_lossless_columns_become_numbers(tmp_path: Path) -> None:
    p = tmp_path / "t.csv"
    p.write_text("s,trial,y,note\n1,2,1.5,\n2,10,2.0,\n")
    df = read_long_csv(p, text_columns=["s", "trial", "absent"])
    assert df["s"].tolist() == ["1", "2"] and df["trial"].tolist() == ["2", "10"]
    assert df["y"].dtype == np.float64 and df["y"].tolist() == [1.5, 2.0]
    assert df["note"].isna().all()
    assert df.attrs["text_columns"] == ["s", "trial"]
    inferred = read_long_csv(p)
    assert inferred["s"].tolist() == [1, 2] and inferred["trial"].dtype == np.int64
    assert levels_of(df["trial"]) == ["2", "10"]  # numeric-looking text: natural order


def test_export_missing_marker_is_missing(tmp_path: Path) -> None:
    p = tmp_path / "e.csv"
    p.write_text("s,y\nA,\\N\nB,2\n")
    df = read_long_csv(p, text_columns=["s"])
    assert df["y"].isna().tolist() == [True, False] and df["y"].dtype == np.float64


def test_duplicated_column_refused_naming_file_and_column(tmp_path: Path) -> None:
    p = tmp_path / "dup.csv"
    p.write_text("s,y,c,y\n1,2.0,a,3.0\n")
    with pytest.raises(ConfigError, match=r"column 'y' appears 2 times in the header "
                                          r"\(columns 2, 4\)") as err:
        read_long_csv(p)
    assert err.value.file == str(p) and err.value.field == "y"


def test_levels_of_numeric_text_order() -> None:
    assert levels_of(pd.Series(["10", "2", "01", "1", "1.0"])) == ["1", "01", "1.0", "2", "10"]
    assert levels_of(pd.Series(["b", "10", "a"])) == ["10", "a", "b"]  # not all numbers


def test_text_columns_keep_na_and_none_as_labels(tmp_path: Path) -> None:
    p = tmp_path / "labels.csv"
    p.write_text("s,fixture,y\nNA,None,1\nNA,VG,NA\nAB,None,\\N\nAB,VG,4\n,VG,5\n")
    df = read_long_csv(p, text_columns=["s", "fixture"])
    assert df["s"].tolist()[:4] == ["NA", "NA", "AB", "AB"] and pd.isna(df["s"].iloc[4])
    assert df["fixture"].tolist() == ["None", "VG", "None", "VG", "VG"]
    assert df["y"].isna().tolist() == [False, True, True, False, False]  # value columns: NA
    with pytest.raises(ConfigError, match="missing labels at line 6"):
        cell_means(df.fillna({"y": 0.0}), "y", "s", ["fixture"])


def test_stats_reads_the_export_missing_value_marker(tmp_path: Path) -> None:
    p = tmp_path / "t.csv"
    p.write_text("subject,condition,completion_time\nS01,vg,1.5\nS01,ff,\\N\n")
    df = read_long_csv(p)
    assert math.isnan(df["completion_time"].iloc[1]) and df["completion_time"].iloc[0] == 1.5
