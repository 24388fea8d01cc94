"""Store schema version 6: packed sample columns (vasim/study/store/packing.py, schema.py,
readers.py; issue #27 item 5).

The migration runs on ``data/store_v5.sqlite``, written by the schema-5 vasim itself
(``data/make_store_v5.py``); the reference values are what that store reads as before the
migration (read-only, the version-5 row reader). Every column must come back bit for bit.
"""

from __future__ import annotations

import shutil
import sqlite3
import zlib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import vasim.study.store.packing as packing
from vasim.core.errors import StoreError
from vasim.records.samples import FRAME_COLUMNS, FRAME_DTYPES, SampleBuffer
from vasim.study.export import EXPORT_TABLES, export_study, read_export
from vasim.study.store import SCHEMA_VERSION, TrialStore

V5_STORE = Path(__file__).parent / "data" / "store_v5.sqlite"


@pytest.fixture
def v5(tmp_path: Path) -> Path:
    p = tmp_path / "v5.sqlite"
    shutil.copyfile(V5_STORE, p)
    return p


def _snapshot(path: Path) -> dict[str, object]:
    with TrialStore(path, readonly=True) as ro:
        trials = ro.trials()
        ids = [int(i) for i in trials["id"]]
        return {"version": ro.schema_version, "trials": trials,
                "samples": {i: ro.samples(i) for i in ids},
                "points": {i: ro.point_metrics(i) for i in ids},
                "metrics": ro.trial_metrics(), "events": {i: ro.events(i) for i in ids}}


def test_a_store_written_by_the_v5_code_migrates_bit_for_bit(v5: Path):
    before = _snapshot(v5)
    assert before["version"] == 5
    samples_before: dict[int, pd.DataFrame] = before["samples"]  # type: ignore[assignment]
    assert [len(s) for s in samples_before.values()] == [250, 250, 250]
    size_before = v5.stat().st_size
    with TrialStore(v5) as st_:
        assert st_.schema_version == SCHEMA_VERSION == 6
        assert [v for v, _ in st_.con.execute("SELECT * FROM schema_version")] == list(
            range(1, 7))
        tables = {r[0] for r in st_.con.execute(
            "SELECT name FROM sqlite_master WHERE type = 'table'")}
        assert "samples" not in tables and "sample_columns" in tables
        assert st_.integrity_check() == "ok"
        assert st_.con.execute("PRAGMA foreign_key_check").fetchall() == []
    after = _snapshot(v5)
    pd.testing.assert_frame_equal(after["trials"], before["trials"])  # type: ignore[arg-type]
    pd.testing.assert_frame_equal(after["metrics"], before["metrics"])  # type: ignore[arg-type]
    for tid, s in samples_before.items():
        got = after["samples"][tid]  # type: ignore[index]
        pd.testing.assert_frame_equal(got, s, check_exact=True)
        for c in FRAME_COLUMNS:
            assert got[c].to_numpy().tobytes() == s[c].to_numpy().tobytes(), c
        pd.testing.assert_frame_equal(after["points"][tid],  # type: ignore[index]
                                      before["points"][tid], check_exact=True)  # type: ignore[index]
        pd.testing.assert_frame_equal(after["events"][tid],  # type: ignore[index]
                                      before["events"][tid])  # type: ignore[index]
    # the FF trial ran at gain 0.75 and rendered forces
    ff = after["samples"][1]  # type: ignore[index]
    assert set(ff["gain"]) == {0.75} and ff[["f_x", "f_y", "f_z"]].abs().to_numpy().max() > 0
    # VACUUM gave the per-sample rows' pages back: without it the file could only grow
    # (the fixed cost of the trial rows, configs and schemas dominates so small a store)
    assert v5.stat().st_size < 0.8 * size_before, (size_before, v5.stat().st_size)


def test_exports_of_the_migrated_store_are_identical(v5: Path, tmp_path: Path):
    old = export_study(v5, tmp_path / "old", formats=("csv",))     # read-only: still v5
    with TrialStore(v5):
        pass                                                          # migrates
    new = export_study(v5, tmp_path / "new", formats=("csv",))
    for table in EXPORT_TABLES:
        a, b = read_export(old, table), read_export(new, table)
        pd.testing.assert_frame_equal(b, a, check_exact=True, obj=table)
        # the files themselves, byte for byte (the manifest names its own export time)
        assert (new / f"{table}.csv").read_bytes() == (old / f"{table}.csv").read_bytes()


def test_a_failed_migration_leaves_the_v5_store_untouched(v5: Path, monkeypatch):
    def boom(_cols: object) -> object:
        raise sqlite3.OperationalError("disk I/O error (simulated)")

    monkeypatch.setattr(packing, "pack_columns", boom)
    with pytest.raises(StoreError, match="simulated"):
        TrialStore(v5)
    con = sqlite3.connect(v5)
    assert con.execute("PRAGMA user_version").fetchone()[0] == 5
    assert con.execute("SELECT count(*) FROM samples").fetchone()[0] == 3 * 250
    names = {r[0] for r in con.execute("SELECT name FROM sqlite_master")}
    assert "sample_columns" not in names
    con.close()


# ---------------------------------------------------------------------------- the codec
def _bits_equal(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.tobytes() == b.tobytes()


@settings(max_examples=200, deadline=None)
@given(arrays(np.float64, st.integers(0, 300),
              elements=st.floats(allow_nan=True, allow_infinity=True, width=64)))
def test_float_columns_round_trip_bit_for_bit(a: np.ndarray) -> None:
    for name in ("t", "x_x", "f_y", "zoom", "gain"):
        dt = packing.STORAGE_DTYPES[name]
        assert dt == np.float64
        back = packing.decode(packing.encode(a, dt), dt.newbyteorder("<").str, a.size)
        assert _bits_equal(back, a), name           # -0.0, inf and NaN too


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(0, 2**64 - 1), max_size=200))
def test_any_bit_pattern_round_trips(words: list[int]) -> None:
    """The delta step wraps modulo 2^64: every bit pattern (NaN payloads, signalling NaNs,
    extreme differences between neighbours) comes back as it was."""
    a = np.array(words, dtype=np.uint64).view(np.float64)
    back = packing.decode(packing.encode(a, np.dtype(np.float64)), "<f8", a.size)
    assert _bits_equal(back, a)


@settings(max_examples=100, deadline=None)
@given(arrays(np.int64, st.integers(0, 50), elements=st.integers(-2**63, 2**63 - 1)),
       arrays(np.int32, st.integers(0, 50), elements=st.integers(-2**31, 2**31 - 1)),
       arrays(np.int8, st.integers(0, 50), elements=st.integers(-128, 127)))
def test_integer_columns_round_trip_bit_for_bit(k: np.ndarray, gi: np.ndarray,
                                                 flag: np.ndarray) -> None:
    for name, a in (("k", k), ("goal_index", gi), ("contact", flag), ("in_view", flag)):
        dt = packing.STORAGE_DTYPES[name]
        assert dt == FRAME_DTYPES[name]
        back = packing.decode(packing.encode(a, dt), dt.str, a.size)
        assert _bits_equal(back, a.astype(dt)), name


def test_every_column_is_stored_in_its_buffer_dtype() -> None:
    """The precision the schema docs state: nothing is narrowed."""
    assert {c: packing.STORAGE_DTYPES[c] for c in FRAME_COLUMNS} == {
        c: np.dtype(FRAME_DTYPES[c]) for c in FRAME_COLUMNS}
    rows = packing.pack_columns(_columns(3, np.arange(3)))
    assert [(name, dtype) for name, dtype, *_ in rows] == [
        (c, np.dtype(FRAME_DTYPES[c]).newbyteorder("<").str) for c in FRAME_COLUMNS]
    assert {codec for *_, codec, _ in rows} == {"delta-shuffle-zlib1"}


def test_the_blob_layout_is_delta_shuffle_zlib() -> None:
    """The blob decoded by hand, without the module's decoder: zlib, then byte j of every
    value together, then a cumulative sum of the bit patterns (an independent check of the
    format the schema docs name)."""
    a = np.array([0.25, 0.5, -1.0, 3.0])
    raw = zlib.decompress(packing.encode(a, np.dtype(np.float64)))
    d = np.frombuffer(raw, np.uint8).reshape(8, 4).T.copy().view("<u8").ravel()
    bits = [int(d[0])]
    for v in d[1:]:
        bits.append((bits[-1] + int(v)) % 2**64)
    assert np.array(bits, dtype=np.uint64).view(np.float64).tolist() == a.tolist()
    # a constant column deflates to almost nothing (deflate's limit is ~1:1000 at level 1):
    # its differences are all zero
    assert len(packing.encode(np.full(10_000, 0.75), np.dtype(np.float64))) < 0.01 * 80_000


def _columns(n: int, k: np.ndarray) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(4)
    out = {c: rng.normal(size=n).astype(FRAME_DTYPES[c]) for c in FRAME_COLUMNS}
    out["k"] = k
    return out


def test_samples_are_stored_in_step_order_and_duplicates_refused() -> None:
    cols = _columns(5, np.array([3, 1, 4, 0, 2]))
    back = packing.unpack_columns(packing.pack_columns(cols))
    order = np.argsort(cols["k"])
    assert back["k"].tolist() == [0, 1, 2, 3, 4]
    np.testing.assert_array_equal(back["t"], cols["t"][order])
    with pytest.raises(StoreError, match="duplicate step k = 1"):
        packing.pack_columns(_columns(4, np.array([0, 1, 1, 2])))


def test_a_damaged_or_foreign_blob_is_a_store_error() -> None:
    rows = packing.pack_columns(_columns(3, np.arange(3)))
    name, dtype, n, codec, blob = rows[1]
    for bad, match in (((name, dtype, n, codec, b"junk"), "does not inflate"),
                       ((name, dtype, n + 1, codec, blob), "expected 4 values"),
                       ((name, dtype, n, "zstd", blob), "codec 'zstd'"),
                       ((name, "<c16", n, codec, blob), "dtype '<c16'"),
                       ((name, "nonsense", n, codec, blob), "dtype 'nonsense'")):
        with pytest.raises(StoreError, match=match):
            packing.unpack_columns([rows[0], bad, *rows[2:]])
    with pytest.raises(StoreError, match="lack the columns"):
        packing.unpack_columns(rows[:-1])


def test_an_empty_trial_stores_no_blob_and_reads_empty(tmp_path: Path) -> None:
    from vasim.records.trial_meta import TrialMeta

    with TrialStore(tmp_path / "s.db") as s:
        tid = s.begin_trial(TrialMeta(subject="S01", task="trajectory"))
        s.finish_trial(tid, SampleBuffer())
        assert s.con.execute("SELECT count(*) FROM sample_columns").fetchone()[0] == 0
        df = s.samples(tid)
        assert df.empty and list(df.columns) == list(FRAME_COLUMNS)
        assert s.trial(tid)["n_samples"] == 0


def test_a_real_trial_is_several_times_smaller(tmp_path: Path) -> None:
    """Bytes a sample of a simulated FF trial: packed blobs vs the version-5 row estimate
    (bench/store.py measures files; here the blobs alone, against 33 8-byte values: 264
    bytes; schema 5's rows took ~120 bytes a sample on disk)."""
    from vasim.trials.registry import run_trial
    from vasim.trials.vf import TrialConfig

    with TrialStore(tmp_path / "s.db") as s:
        res, tid = run_trial(TrialConfig(schema="ff", seed=3, max_time=2.0, scene="none",
                                         subject="S01"), s)
        blob = s.con.execute("SELECT sum(length(data)) FROM sample_columns WHERE "
                             "trial_id = ?", (tid,)).fetchone()[0]
    n = len(res.samples)
    assert n == 2000
    assert blob / n < 40, blob / n
