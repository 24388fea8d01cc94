"""How a trial's samples are stored: one losslessly compressed blob per column (schema
version 6, issue #27 item 5).

Version 5 stored one SQLite row of 33 columns per sample: ~120 bytes a sample on disk
(measured on a simulated ``vf_learning_curve`` subject, 416,015 samples in 50 MB), so the
seed's 46-subject cohort took ~2.3 GB. Version 6 stores each trial's column as one blob: the
values in their buffer dtype (``vasim.records.samples.FRAME_DTYPES``), each value's bit
pattern replaced by its wrapping integer difference from the previous value's (smooth
signals and constant columns give small differences: zero or few non-zero bytes), the bytes
shuffled (byte j of every value together) and deflated with ``zlib`` (level 1). On the five
simulated 12 s trials of ``bench/store.py`` (none, VG, FF, AG, Mag; 60,000 samples) that is
25.1 bytes a sample against version 5's 119.9 (files measured the same way), 4.8x less, so a
46-subject cohort is ~480 MB instead of ~2.3 GB (2026-11-28, on a loaded machine; sizes do
not depend on the load).

Precision kept per column (the **decision**): **every column bit for bit**.

===========================================  ========  ====================================
columns                                      stored    precision kept
===========================================  ========  ====================================
``k``                                        int64     exact
``t`` [s], ``x_*``, ``g_*`` [m],             float64   exact: every bit, NaN payloads, +-inf
``f_*``, ``fc_*`` [N], ``tc_*`` [N m],                 and -0.0 included (version 5 stored
``ms_*``, ``zoom``, ``audio_pitch``,                   NaN as NULL and read -0.0 as 0.0)
``audio_period`` [s], ``audio_volume``,
``gain``
``goal_index``                               int32     exact
``contact``, ``delicate``, ``clutch``,       int8      exact
``in_view``
===========================================  ========  ====================================

Why lossless everywhere and not float32 where the precision would do (0.03 um in the
workspace): a replay (``vasim trial --replay``, the viewer's replay), the teleoperation
recomputations and the exports compare stored samples with recomputed ones exactly (e.g.
``abs=1e-12``), and a store is the record of what a trial did; float32 broke those
comparisons (it was tried on branch ``lean``, 2026-11-27, at ~12 bytes a sample, and
reverted). The delta step is lossless for any bit pattern (integer subtraction modulo 2^64 is
a bijection, undone by a wrapping cumulative sum), so no column needs a policy.
The compressor is the standard library's ``zlib``: ``lzma`` or ``zlib`` level 9 gave ~5 %
smaller blobs at 4-40x the packing time; without the delta step blobs are 8 % larger
(measured on four simulated 6 s trials, none/FF/AG/Mag, 2026-11-28: 26.4 bytes a sample
with delta and level 1, 24.9 at level 9, 24.8 with lzma preset 6, 28.6 without delta).
The position columns, whose low mantissa bits are the operator model's noise, are most of
what is left (~17 of the 26 bytes) and no lossless coder removes that.
"""

from __future__ import annotations

import zlib
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vasim.core.errors import StoreError
from vasim.records.samples import FRAME_COLUMNS, FRAME_DTYPES

CODEC = "delta-shuffle-zlib1"
"""Name of the blob encoding: wrapping first differences of the values' bit patterns (as
signed integers of the value's width), byte shuffle, then ``zlib.compress(level=1)``.

**Decision**: level 1, not 6 or 9: ~6 % larger blobs for ~4x faster packing (see the module
docstring); the stdlib's zlib, no compression dependency."""

ZLIB_LEVEL = 1

STORAGE_DTYPES: dict[str, np.dtype[Any]] = {c: np.dtype(FRAME_DTYPES[c]) for c in FRAME_COLUMNS}
"""The dtype each flat sample column is stored in (little-endian on disk): its buffer dtype."""

_BITS: dict[int, np.dtype[Any]] = {n: np.dtype(f"<i{n}") for n in (1, 2, 4, 8)}
"""The signed integer type of each value width: the bit patterns the delta step works on."""


def encode(values: NDArray[Any], dtype: np.dtype[Any]) -> bytes:
    """``values`` as ``dtype`` (little-endian), delta-coded, byte-shuffled and deflated.

    >>> a = np.array([0.5, 1.0, -0.0, np.nan, np.inf])
    >>> back = decode(encode(a, np.dtype(np.float64)), "<f8", 5)
    >>> back.tobytes() == a.tobytes(), bool(np.signbit(back[2]))
    (True, True)
    """
    a = np.ascontiguousarray(values, dtype=dtype.newbyteorder("<"))
    bits = a.view(_BITS[a.itemsize])
    d = np.empty_like(bits)
    if bits.size:
        d[0] = bits[0]
        np.subtract(bits[1:], bits[:-1], out=d[1:])   # wraps modulo 2^(8 * itemsize)
    shuffled = d.view(np.uint8).reshape(d.size, d.itemsize).T.tobytes()
    return zlib.compress(shuffled, ZLIB_LEVEL)


def decode(blob: bytes, dtype: str, n: int) -> NDArray[Any]:
    """The inverse of :func:`encode`: ``n`` values of ``dtype``.

    Raises:
        StoreError: the blob does not hold ``n`` values of ``dtype`` (a damaged store).
    """
    try:
        dt = np.dtype(dtype)
    except TypeError:
        dt = None
    if dt is None or dt.kind not in "iuf" or dt.itemsize not in _BITS:
        raise StoreError(f"a sample blob names the dtype {dtype!r}, expected a number of "
                         f"{', '.join(map(str, _BITS))} bytes")
    try:
        raw = zlib.decompress(blob)
    except zlib.error as exc:
        raise StoreError(f"a sample blob does not inflate ({exc})") from None
    if len(raw) != n * dt.itemsize:
        raise StoreError(f"a sample blob holds {len(raw)} bytes, expected {n} values of "
                         f"{dt.str} ({n * dt.itemsize} bytes)")
    b = np.ascontiguousarray(np.frombuffer(raw, dtype=np.uint8).reshape(dt.itemsize, n).T)
    bits = np.cumsum(b.view(_BITS[dt.itemsize]).reshape(n), dtype=_BITS[dt.itemsize])
    return bits.view(dt.newbyteorder("<")).astype(dt, copy=False)


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
        s = np.asarray(v, dtype=STORAGE_DTYPES[name])
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
                             "(written by a newer or an unreleased vasim?)")
        got[name] = decode(blob, dtype, int(n))
    missing = [c for c in FRAME_COLUMNS if c not in got]
    if missing:
        raise StoreError(f"the stored samples lack the columns {missing}")
    lengths = {got[c].size for c in FRAME_COLUMNS}
    if len(lengths) != 1:
        raise StoreError(f"the stored sample columns differ in length: {sorted(lengths)}")
    return {c: got[c].astype(FRAME_DTYPES[c], copy=False) for c in FRAME_COLUMNS}


__all__ = ["CODEC", "STORAGE_DTYPES", "ZLIB_LEVEL", "decode", "encode", "pack_columns",
           "rows_to_columns", "unpack_columns"]
