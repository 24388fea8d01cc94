"""Validation of long-format study data: columns, numeric values, factors and balance.

Every statistic in :mod:`vasim.study.stats` takes a *long-format* ``pandas.DataFrame``
(one row per observation, pingouin style) and validates it here before computing anything,
so that bad input ends in one :class:`vasim.core.errors.ConfigError` naming the file, the column
and the offending values or cells, never in a traceback or in a silently wrong table.

The file a frame came from is read from ``data.attrs["source"]`` (set by
:func:`read_long_csv`); frames read that way also carry their CSV line numbers as index,
so messages can point at ``line 7`` of the file.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from vasim.core.errors import ConfigError

#: Maximum number of offending values or cells quoted in one error message.
MAX_LISTED = 8

#: The missing-value marker of ``vasim study export`` CSV files (``vasim.study.export.CSV_NA``;
#: a test checks they agree). Written here, not imported: the statistics import nothing of
#: the store or the export (issue #14; an import-linter contract in pyproject.toml).
CSV_NA = "\\N"


#: Relative size (to the total sum of squares) below which an error sum of squares is zero.
ZERO_SS_REL = 1e-12


def error_ss_is_zero(ss_error: float, values: np.ndarray) -> bool:
    """Whether an error sum of squares is zero within round-off of the data it comes from.

    **Decision** (issue #16): an error SS counts as zero when

    ``ss_error <= max(1e-12 * SS_total, N * (64 * eps * max|v|)^2)``

    with ``SS_total`` the sum of squares of ``values`` about their mean, ``N`` their count
    and ``eps`` the float64 machine epsilon. The first term is the relative test of
    ``rm_anova``; the second is the round-off of the values themselves, so constant data
    whose means differ only by rounding (``0.1`` averaged from ``0.1, 0.1, 0.1``) also
    count as zero, where the relative test alone would compare two round-off residues.
    A non-finite ``ss_error`` is not zero (the caller reports it as an overflow).

    Args:
        ss_error: the error sum of squares, in the dependent variable's unit squared.
        values: the data (cell means) it was computed from, any shape.

    >>> error_ss_is_zero(0.0, np.array([1.0, 2.0])), error_ss_is_zero(0.5, np.array([1.0, 2.0]))
    (True, False)
    """
    v = np.asarray(values, dtype=float).ravel()
    if not math.isfinite(ss_error):
        return False
    if v.size == 0:
        return ss_error <= 0.0
    with np.errstate(over="ignore", invalid="ignore"):
        ss_total = float(((v - v.mean()) ** 2).sum())
        roundoff = v.size * (64.0 * np.finfo(float).eps * float(np.abs(v).max())) ** 2
    threshold = max(ZERO_SS_REL * ss_total if math.isfinite(ss_total) else 0.0, roundoff)
    return not ss_error > threshold


class StatsWarning(UserWarning):
    """A statistic is undefined or degenerate for this data (the value is NaN, see the note)."""


def read_long_csv(path: str | Path, *, text_columns: Sequence[str] = ()) -> pd.DataFrame:
    """Reads a long-format CSV file for the statistics functions.

    Every cell is read as text first. The columns named in ``text_columns`` (the subject
    and factor columns of the analysis) stay text, so ``01`` and ``1``, or ``1`` and
    ``1.0``, are different subjects or levels; in them only an empty cell or ``\\N`` is
    missing (a subject ``NA`` or a fixture ``None`` is a label, where pandas' defaults
    would read it as missing). Every other column becomes numbers when all
    its values are numbers **and** the conversion keeps distinct texts distinct; a column
    where two different texts would become the same number (``01`` and ``1``) stays text,
    so that labels never merge even when the caller names no column. The statistics
    convert their dependent variable themselves (:func:`numeric_column`), so a value
    column that stayed text is still analysed correctly.

    **Decision**: labels are compared as written (``"1"`` and ``"1.0"`` differ) because a
    subject code is an identifier, not a quantity; pandas' default inference, which merged
    them (issue #16), is not used for label columns.

    Args:
        path: CSV file with a header row; empty cells and ``\\N`` (``vasim study export``)
            are missing values.
        text_columns: columns always kept as text (names absent from the file are ignored;
            the statistic then names the missing column).

    Returns:
        The table; ``attrs["source"]`` holds the path and the index holds the CSV line
        number of each row (the header is line 1; exact when the file has no blank lines or
        quoted line breaks), so validation errors can name both.

    Raises:
        ConfigError: the file is missing, is a directory, is empty, cannot be parsed, or
            its header names a column twice (pandas would silently rename the second).
    """
    p = Path(path)
    if not p.exists():
        raise ConfigError("CSV file not found", file=p)
    if p.is_dir():
        raise ConfigError("is a directory, expected a CSV file", file=p)
    try:
        header = pd.read_csv(p, header=None, nrows=1, dtype=str, keep_default_na=False)
        names = [str(v) for v in header.iloc[0].tolist()]
        _check_header(p, names)
        raw = pd.read_csv(p, dtype=str, na_values=[CSV_NA])  # also reads `study export` files
        text = [c for c in names if c in set(text_columns)]
        if text:  # labels: only an empty cell or \N is missing ("NA", "None" are labels)
            labels = pd.read_csv(p, dtype=str, usecols=text, keep_default_na=False,
                                 na_values=["", CSV_NA])
            for c in text:
                raw[c] = labels[c]
    except pd.errors.EmptyDataError:
        raise ConfigError("CSV file is empty (no header row)", file=p) from None
    except (pd.errors.ParserError, UnicodeDecodeError, ValueError) as exc:
        if isinstance(exc, ConfigError):
            raise
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ConfigError(f"cannot parse CSV: {first}", file=p) from None
    except OSError as exc:
        raise ConfigError(f"cannot read CSV: {exc.strerror or exc}", file=p) from None
    if raw.empty:
        raise ConfigError("CSV file has a header but no data rows", file=p)
    df = pd.DataFrame({c: raw[c] if c in text else _as_numbers_if_lossless(raw[c])
                       for c in raw.columns})
    df.index = pd.RangeIndex(2, 2 + len(df))
    df.attrs["source"] = str(p)
    df.attrs["line_index"] = True
    df.attrs["text_columns"] = text
    return df


def _check_header(path: Path, names: list[str]) -> None:
    """Refuses a header that names a column twice (1-based positions in the message)."""
    seen: dict[str, list[int]] = {}
    for i, name in enumerate(names, start=1):
        seen.setdefault(name, []).append(i)
    for name, positions in seen.items():
        if len(positions) > 1:
            raise ConfigError(f"column {name!r} appears {len(positions)} times in the header "
                              f"(columns {', '.join(map(str, positions))}); column names must "
                              f"be unique", file=path, field=name)


def _as_numbers_if_lossless(col: pd.Series) -> pd.Series:
    """A text column as numbers when every value is one and distinct texts stay distinct."""
    present = col.dropna()
    if present.empty:
        return pd.to_numeric(col, errors="coerce")
    nums = pd.to_numeric(present, errors="coerce")
    if nums.isna().any() or nums.nunique() != present.nunique():
        return col
    return pd.to_numeric(col)


def source_of(data: pd.DataFrame) -> str | None:
    """The file ``data`` was read from, if known (``data.attrs["source"]``)."""
    src = data.attrs.get("source")
    return None if src is None else str(src)


def _where(data: pd.DataFrame, labels: Sequence[Hashable]) -> str:
    """Describes row labels as CSV lines (frames from :func:`read_long_csv`) or index labels."""
    shown = ", ".join(str(v) for v in list(labels)[:MAX_LISTED])
    more = f" and {len(labels) - MAX_LISTED} more" if len(labels) > MAX_LISTED else ""
    noun = "line" if data.attrs.get("line_index") else "row index"
    plural = "s" if len(labels) > 1 and noun == "line" else ""
    return f"{noun}{plural} {shown}{more}"


def require_frame(data: Any) -> pd.DataFrame:
    """Checks that ``data`` is a non-empty DataFrame.

    Raises:
        ConfigError: ``data`` is not a DataFrame or has no rows.
    """
    if not isinstance(data, pd.DataFrame):
        raise ConfigError(f"expected a pandas DataFrame in long format, got {type(data).__name__}")
    if data.empty:
        raise ConfigError("the data table has no rows", file=source_of(data))
    return data


def require_columns(data: pd.DataFrame, columns: Sequence[str]) -> None:
    """Checks that every column exists and that no column is used for two roles.

    Raises:
        ConfigError: naming the first missing column, the file and the available columns.
    """
    src = source_of(data)
    seen: set[str] = set()
    for col in columns:
        if not isinstance(col, str) or not col:
            raise ConfigError(f"column names must be non-empty strings, got {col!r}", file=src)
        if col in seen:
            raise ConfigError(f"column {col!r} is given for two different roles", file=src,
                              field=col)
        seen.add(col)
        if col not in data.columns:
            avail = ", ".join(repr(str(c)) for c in data.columns)
            raise ConfigError(f"column {col!r} not found; available columns: {avail}",
                              file=src, field=col)


def numeric_column(data: pd.DataFrame, column: str, *, allow_missing: bool = False) -> pd.Series:
    """Returns ``data[column]`` as float64 after checking every value is a finite number.

    Args:
        data: long-format table.
        column: the dependent-variable column.
        allow_missing: if True, empty cells (NaN) are kept as NaN instead of rejected;
            non-numeric text and infinities are always rejected.

    Raises:
        ConfigError: naming the column, the offending rows and their values.
    """
    src = source_of(data)
    raw = data[column]
    if pd.api.types.is_bool_dtype(raw):
        raise ConfigError(f"column {column!r} is boolean, expected numbers", file=src,
                          field=column)
    values = pd.to_numeric(raw, errors="coerce").astype("float64")
    text_bad = values.isna() & raw.notna()
    if text_bad.any():
        labels = list(raw.index[text_bad])
        vals = ", ".join(repr(v) for v in raw[text_bad].tolist()[:MAX_LISTED])
        raise ConfigError(f"column {column!r} has non-numeric values at {_where(data, labels)}: "
                          f"{vals}", file=src, field=column)
    inf_bad = np.isinf(values.to_numpy())
    if inf_bad.any():
        labels = list(values.index[inf_bad])
        vals = ", ".join(repr(v) for v in values[inf_bad].tolist()[:MAX_LISTED])
        raise ConfigError(f"column {column!r} has non-finite values at {_where(data, labels)}: "
                          f"{vals}", file=src, field=column)
    if not allow_missing and values.isna().any():
        labels = list(values.index[values.isna()])
        raise ConfigError(f"column {column!r} has missing (NaN/empty) values at "
                          f"{_where(data, labels)}", file=src, field=column)
    return values


def factor_column(data: pd.DataFrame, column: str) -> pd.Series:
    """Returns a factor (or subject) column after checking it has no missing labels.

    Raises:
        ConfigError: naming the column and the rows with an empty label.
    """
    col = data[column]
    missing = col.isna()
    if missing.any():
        labels = list(col.index[missing])
        raise ConfigError(f"column {column!r} has missing labels at {_where(data, labels)}",
                          file=source_of(data), field=column)
    return col


def levels_of(col: pd.Series) -> list[Any]:
    """The levels of a factor column in a stable, documented order.

    A categorical column keeps its category order (unobserved categories dropped); any
    other column is sorted: numbers numerically, text alphabetically except that text
    labels which all read as numbers (``"2"``, ``"10"``, ``"01"``) are ordered by that
    number, then by their text (``"1" < "01" < "1.0" < "2" < "10"``), so trials and
    subjects read as text keep their natural order. Labels that cannot be compared with
    each other keep their order of first appearance.
    """
    if isinstance(col.dtype, pd.CategoricalDtype):
        present = set(col.dropna().unique().tolist())
        return [python_scalar(c) for c in col.cat.categories if c in present]
    uniq = [python_scalar(v) for v in pd.unique(col.dropna()).tolist()]
    if uniq and all(isinstance(v, str) for v in uniq):
        nums = pd.to_numeric(pd.Series(uniq, dtype=object), errors="coerce")
        if nums.notna().all() and np.isfinite(nums.to_numpy(dtype=float)).all():
            return [v for _, v in sorted(zip(nums.tolist(), uniq, strict=True),
                                         key=lambda t: (t[0], len(t[1]), t[1]))]
    try:
        return sorted(uniq)
    except TypeError:
        return uniq


def python_scalar(value: Any) -> Any:
    """A numpy scalar as the equivalent Python scalar (for JSON and readable messages)."""
    return value.item() if isinstance(value, np.generic) else value


@dataclass(frozen=True)
class CellMeans:
    """Subject-level cell means of a fully within-subject design.

    Attributes:
        values: (n_subjects, n_levels_1[, n_levels_2]) cell means of the dependent variable.
        subjects: the n_subjects subject labels, in row order.
        factors: the within-factor column names.
        levels: per factor, its level labels in axis order.
        n_obs: (same shape as ``values``) number of raw rows averaged into each cell.
    """

    values: np.ndarray
    subjects: list[Any]
    factors: list[str]
    levels: list[list[Any]]
    n_obs: np.ndarray


def cell_means(data: pd.DataFrame, dv: str, subject: str, within: Sequence[str],
               *, min_levels: int = 2) -> CellMeans:
    """Validates a within-subject design and averages it to one value per subject x cell.

    Several rows for the same subject and cell (e.g. repeated trials or per-sample rows)
    are averaged first: the repeated-measures statistics work on cell means, one
    observation per subject and cell.

    Args:
        data: long-format table.
        dv: dependent-variable column (finite numbers).
        subject: subject-identifier column.
        within: one or two within-subject factor columns.
        min_levels: minimum number of levels per factor.

    Returns:
        The balanced cell means.

    Raises:
        ConfigError: a column is missing, a value is not a finite number, a label is
            missing, there are fewer than 2 subjects or fewer than ``min_levels`` levels, or
            the design is unbalanced (the message lists the missing subject x cell pairs).
    """
    data = require_frame(data)
    within = list(within)
    require_columns(data, [dv, subject, *within])
    src = source_of(data)
    y = numeric_column(data, dv)
    subj = factor_column(data, subject)
    facs = [factor_column(data, w) for w in within]
    subjects = levels_of(subj)
    if len(subjects) < 2:
        raise ConfigError(f"need at least 2 subjects in column {subject!r}, found "
                          f"{len(subjects)}: {subjects!r}", file=src, field=subject)
    levels = [levels_of(f) for f in facs]
    for w, lev in zip(within, levels, strict=True):
        if len(lev) < min_levels:
            raise ConfigError(f"within factor {w!r} needs at least {min_levels} levels, found "
                              f"{len(lev)}: {lev!r}", file=src, field=w)
    frame = pd.DataFrame({"_s": subj.to_numpy(), "_y": y.to_numpy()})
    for i, f in enumerate(facs):
        frame[f"_f{i}"] = f.to_numpy()
    keys = ["_s", *[f"_f{i}" for i in range(len(facs))]]
    grouped = frame.groupby(keys, sort=False, dropna=False)["_y"]
    means = grouped.mean()
    counts = grouped.size()
    full = pd.MultiIndex.from_product([subjects, *levels], names=keys)
    means = means.reindex(full)
    counts = counts.reindex(full).fillna(0)
    missing = means.index[means.isna().to_numpy()]
    if len(missing):
        cells = [_cell_text(subject, within, key) for key in missing[:MAX_LISTED]]
        more = f" and {len(missing) - MAX_LISTED} more" if len(missing) > MAX_LISTED else ""
        raise ConfigError(
            f"unbalanced design: every subject needs every cell of {', '.join(within)}; "
            f"{len(missing)} subject x cell combination(s) have no data: "
            f"{'; '.join(cells)}{more}", file=src, field=subject)
    shape = (len(subjects), *[len(lev) for lev in levels])
    return CellMeans(values=means.to_numpy(dtype=float).reshape(shape), subjects=subjects,
                     factors=within, levels=levels,
                     n_obs=counts.to_numpy(dtype=int).reshape(shape))


def _cell_text(subject: str, within: Sequence[str], key: Any) -> str:
    key = key if isinstance(key, tuple) else (key,)
    cell = ", ".join(f"{w}={python_scalar(v)!r}" for w, v in zip(within, key[1:], strict=True))
    return f"{subject}={python_scalar(key[0])!r} x {cell}"


def finite_array(values: Any, name: str) -> np.ndarray:
    """A 1-D float array of finite values with at least one element.

    Raises:
        ConfigError: empty, not numeric, or containing NaN/inf (positions named).
    """
    try:
        arr = np.asarray(values, dtype=float).ravel()
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be numbers, got {values!r}") from None
    if arr.size == 0:
        raise ConfigError(f"{name} is empty")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        shown = ", ".join(f"[{i}]={arr[i]!r}" for i in bad[:MAX_LISTED])
        raise ConfigError(f"{name} has non-finite values at positions {shown}")
    return arr


def nan_to_none(value: Any) -> Any:
    """JSON-ready scalar: NaN/NA become None, numpy scalars become Python scalars."""
    if value is None or value is pd.NA:
        return None
    value = python_scalar(value)
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
