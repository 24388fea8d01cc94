"""How a trial's samples are stored: one compressed blob per column (schema version 6,
issue #27 item 5).

Version 5 stored one SQLite row of 33 columns per sample: ~120 bytes a sample on disk
(measured on a simulated ``vf_learning_curve`` subject, 416,015 samples in 50 MB), so the
seed's 46-subject cohort took ~2.3 GB. Version 6 stores each trial's column as one blob:
the values in their *storage dtype* (below), byte-shuffled (byte j of every value together:
the high bytes of a smooth signal repeat) and deflated with ``zlib`` (level 1): ~12.5 bytes
a sample on the same subject, ~10x less, so a 46-subject cohort is ~250 MB.

Precision kept per column (the **decision**; every reader returns the buffer dtypes of
``vasim.records.samples`` as before, so the float32 columns come back as float64 whose value
is the nearest float32 of what was written):

===========================================  ========  ====================================
columns                                      stored    precision kept
===========================================  ========  ====================================
``k``                                        int64     exact
``t`` [s]                                    float64   exact (latencies and times are
                                                       differences of t)
``x_*``, ``g_*`` [m]                         float32   relative 2^-24 (6.0e-8): <= 3.0e-8 m
                                                       (0.03 um) in the +-0.5 m workspace
``f_*``, ``fc_*`` [N], ``tc_*`` [N m]        float32   relative 2^-24: <= 6e-7 N at 10 N
``ms_*``, ``zoom``, ``audio_pitch``,         float32   relative 2^-24 (0, 1, 0.5, 440 ...
``audio_period`` [s], ``audio_volume``,                are exact)
``gain``
``goal_index``                               int32     exact
``contact``, ``delicate``, ``clutch``,       int8      exact
``in_view``
===========================================  ========  ====================================

NaN, +-inf and -0.0 survive (version 5 stored NaN as NULL and read -0.0 as 0.0). A float32
column with a finite value beyond float32's range (|v| > 3.4e38, which would become inf) is
stored as float64 instead: each blob names its dtype, so the reader needs no policy.
Position errors of 0.03 um are 5 orders of magnitude below the 5 mm reach radius and the
0.1 mm resolution of the path-deviation measures; the stored per-point and per-trial
metrics are computed from the full-precision buffer before it is stored.
"""

from __future__ import annotations

import zlib
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vasim.core.errors import StoreError
from vasim.records.samples import FRAME_COLUMNS, FRAME_DTYPES

CODEC = "shuffle-zlib1"
"""Name of the blob encoding: byte shuffle, then ``zlib.compress(level=1)``.

**Decision**: level 1, not 6: 5 % larger blobs (12.5 vs 11.9 bytes a sample) for ~1.8x
faster packing (``bench/store.py``); the stdlib's zlib, no compression dependency."""

ZLIB_LEVEL = 1

EXACT_COLUMNS: frozenset[str] = frozenset({"k", "t"})
"""Float or integer columns stored in their buffer dtype, exactly."""

STORAGE_DTYPES: dict[str, np.dtype[Any]] = {
    c: np.dtype(np.float32) if FRAME_DTYPES[c] is np.float64 and c not in EXACT_COLUMNS
    else np.dtype(FRAME_DTYPES[c])
    for c in FRAME_COLUMNS
}
"""The dtype each flat sample column is stored in (little-endian on disk)."""

def storage_dtype(name: str, values: NDArray[Any]) -> np.dtype[Any]:
    """The dtype ``values`` of column ``name`` are stored in: ``STORAGE_DTYPES``, except a
    float32 column holding a finite value float32 cannot represent (stored float64)."""
    return _stored(name, values).dtype


def _stored(name: str, values: NDArray[Any]) -> NDArray[Any]:
    """``values`` cast to their storage dtype (:func:`storage_dtype`), one pass for the
    common case: a float32 cast whose result has no inf needs no further check."""
    dt = STORAGE_DTYPES[name]
    if dt != np.float32:
        return np.asarray(values, dtype=dt)
    with np.errstate(over="ignore"):
        f = np.asarray(values).astype(np.float32)
    inf = np.isinf(f)
    if bool(inf.any()) and bool(np.any(inf & np.isfinite(values))):
        return np.asarray(values, dtype=np.float64)   # a finite value beyond float32
    return f


def encode(values: NDArray[Any], dtype: np.dtype[Any]) -> bytes:
    """``values`` as ``dtype`` (little-endian), byte-shuffled and deflated.

    >>> a = np.array([0.5, 1.0, -0.0, np.nan])
    >>> back = decode(encode(a, np.dtype(np.float32)), "<f4", 4)
    >>> back.dtype.str, back[:3].tolist(), bool(np.isnan(back[3])), bool(np.signbit(back[2]))
    ('<f4', [0.5, 1.0, -0.0], True, True)
    """
    a = np.ascontiguousarray(values, dtype=dtype.newbyteorder("<"))
    shuffled = a.view(np.uint8).reshape(a.size, a.itemsize).T.tobytes()
    return zlib.compress(shuffled, ZLIB_LEVEL)


def decode(blob: bytes, dtype: str, n: int) -> NDArray[Any]:
    """The inverse of :func:`encode`: ``n`` values of ``dtype``.

    Raises:
        StoreError: the blob does not hold ``n`` values of ``dtype`` (a damaged store).
    """
    dt = np.dtype(dtype)
    try:
        raw = zlib.decompress(blob)
    except zlib.error as exc:
        raise StoreError(f"a sample blob does not inflate ({exc})") from None
    if len(raw) != n * dt.itemsize:
        raise StoreError(f"a sample blob holds {len(raw)} bytes, expected {n} values of "
                         f"{dt.str} ({n * dt.itemsize} bytes)")
    b = np.frombuffer(raw, dtype=np.uint8).reshape(dt.itemsize, n).T
    return np.ascontiguousarray(b).view(dt).reshape(n)


NULL_INTEGERS: dict[str, int] = {"goal_index": -1, "in_view": -1}
"""What a NULL in an integer column of a version-5 (or older) ``samples`` row reads as:
-1 (not recorded) for ``goal_index`` and ``in_view``, 0 for the flags (``contact``,
``delicate``, ``clutch``: their defaults) and ``k`` (which the primary key never left NULL)."""


def rows_to_columns(rows: list[tuple[Any, ...]]) -> dict[str, NDArray[Any]]:
    """Flat columns (``FRAME_DTYPES``) of version-5 ``samples`` rows in ``FRAME_COLUMNS``
    order (NULL floats -> NaN); the reader of a version-5 store and the migration use it."""
    if not rows:
        return {c: np.empty(0, dtype=FRAME_DTYPES[c]) for c in FRAME_COLUMNS}
    # one 2-D float conversion (None -> NaN) is ~3x faster than per-column arrays; the
    # integer columns (k < 2**53, goal_index, contact) are exact in float64
    block = np.array(rows, dtype=np.float64)
    out: dict[str, NDArray[Any]] = {}
    for j, c in enumerate(FRAME_COLUMNS):
        dtype = FRAME_DTYPES[c]
        col = block[:, j]
        if dtype is not np.float64:
            # a NULL integer (possible in a version-1/2 row) reads as the column's "not
            # recorded" value instead of an undefined cast of NaN
            col = np.where(np.isnan(col), NULL_INTEGERS.get(c, 0), col)
        out[c] = col.copy() if dtype is np.float64 else col.astype(dtype)
    return out


def pack_columns(columns: Mapping[str, NDArray[Any]],
                 ) -> list[tuple[str, str, int, str, bytes]]:
    """``(name, dtype, n, codec, blob)`` rows of a trial's flat sample columns, sorted by k.

    Args:
        columns: every name of ``FRAME_COLUMNS`` -> a 1-D array, all of one length.

    Raises:
        StoreError: two samples share a step k.
    """
    k = np.asarray(columns["k"])
    order = None
    if k.size > 1 and not bool(np.all(k[1:] > k[:-1])):
        order = np.argsort(k, kind="stable")
        ks = k[order]
        dup = ks[1:] == ks[:-1]
        if bool(np.any(dup)):
            raise StoreError(f"duplicate step k = {int(ks[1:][dup][0])} in the samples")
    rows = []
    for name in FRAME_COLUMNS:
        v = np.asarray(columns[name])
        if order is not None:
            v = v[order]
        s = _stored(name, v)
        rows.append((name, s.dtype.newbyteorder("<").str, int(s.size), CODEC,
                     encode(s, s.dtype)))
    return rows


def unpack_columns(rows: Iterable[tuple[str, str, int, str, bytes]],
                   ) -> dict[str, NDArray[Any]]:
    """The flat columns (buffer dtypes of ``FRAME_DTYPES``) of ``pack_columns`` rows.

    Raises:
        StoreError: an unknown codec, a missing column or columns of different lengths.
    """
    got: dict[str, NDArray[Any]] = {}
    for name, dtype, n, codec, blob in rows:
        if codec != CODEC:
            raise StoreError(f"sample column {name!r} has codec {codec!r}, expected {CODEC!r} "
                             "(written by a newer vasim?)")
        got[name] = decode(blob, dtype, int(n))
    missing = [c for c in FRAME_COLUMNS if c not in got]
    if missing:
        raise StoreError(f"the stored samples lack the columns {missing}")
    lengths = {got[c].size for c in FRAME_COLUMNS}
    if len(lengths) != 1:
        raise StoreError(f"the stored sample columns differ in length: {sorted(lengths)}")
    return {c: got[c].astype(FRAME_DTYPES[c]) for c in FRAME_COLUMNS}


__all__ = ["CODEC", "STORAGE_DTYPES", "ZLIB_LEVEL", "decode", "encode", "pack_columns",
           "rows_to_columns", "storage_dtype", "unpack_columns"]
