"""Pure conversions between Python values and stored rows (ids, JSON, metric rows)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from vasim.core.config import check_int, check_str, expect
from vasim.core.errors import ConfigError
from vasim.core.jsonio import dumps
from vasim.records.path_deviation import PATH_POINT_COLUMNS
from vasim.records.point_metrics import POINT_COLUMNS


def row_id(value: object, name: str = "trial_id") -> int:
    """``value`` as a row id (an integer, not a bool).

    Raises:
        ConfigError: naming ``name`` and the value.
    """
    return check_int(value, name)


def int_or_none(v: int | None) -> int | None:
    """``int(v)``, or None."""
    return None if v is None else int(v)


def to_json(v: Mapping[str, Any] | None) -> str | None:
    """Strict JSON text of a mapping (NaN -> null), or None.

    Raises:
        ConfigError: not JSON-serialisable.
    """
    if v is None:
        return None
    try:
        return dumps(v)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"value is not JSON-serialisable: {e}") from None


def point_metric_rows(df: pd.DataFrame) -> list[tuple[Any, ...]]:
    """The rows of a ``point_metrics`` frame in ``POINT_COLUMNS`` order, as SQLite values.

    Raises:
        ConfigError: a missing column.
    """
    # the v4 path columns are optional: a frame without them stores NULL (not measured)
    df = df.assign(**{c: np.nan for c in PATH_POINT_COLUMNS if c not in df.columns})
    missing = [c for c in POINT_COLUMNS if c not in df.columns]
    expect(not missing, missing, f"all of {list(POINT_COLUMNS)} (point_metrics lacks the "
           "columns shown)", field="point_metrics")
    cols = []
    for c in POINT_COLUMNS:
        v = df[c].to_numpy()
        if c in ("point", "n_samples"):
            cols.append([int(a) for a in v])
        elif c == "reached":
            cols.append([int(bool(a)) for a in v])
        else:
            cols.append(np.asarray(v, dtype=np.float64).tolist())
    return list(zip(*cols, strict=True))


def trial_metric_rows(metrics: Mapping[str, float]) -> list[tuple[str, float | None]]:
    """``(name, value)`` rows of a trial-metrics dict (non-finite -> None).

    Raises:
        ConfigError: a bad name or a value that is not a number.
    """
    rows = []
    for name, v in metrics.items():
        check_str(name, "trial_metrics", one_line=False, what="a trial metric name")
        try:
            f = float(v)
        except (TypeError, ValueError):
            raise ConfigError(f"trial metric {name!r} must be a number, got {v!r}") from None
        rows.append((name, f if math.isfinite(f) else None))
    return rows


__all__ = ["int_or_none", "point_metric_rows", "row_id", "to_json", "trial_metric_rows"]
