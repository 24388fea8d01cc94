"""The study store: per-sample append cost in the 1 kHz loop, the one-transaction commit,
and what a sample costs on disk and to read back, schema 5 (one row a sample) against
schema 6 (lossless packed columns, issue #27 item 5).

Prints µs per ``SampleBuffer.append`` (the only storage work inside the control loop), the
time ``TrialStore.finish_trial`` takes to make a 100,000-sample trial durable (WAL,
synchronous=FULL), then, on simulated trials of five conditions (none, VG, FF, AG, Mag; the
scripted operator), bytes per sample on disk, write and read speed for both layouts, and the
size of a 46-subject ``vf_learning_curve`` cohort extrapolated from bytes per sample.

Schema 5 is written here the way vasim wrote it (the frozen DDL of versions 1-5 from
``vasim.study.store.schema.MIGRATIONS``, one ``executemany`` of ``SampleBuffer.rows()`` in
one transaction) and read back through ``TrialStore`` read-only (the version-5 row reader).
Bytes per sample = growth of the checkpointed database file / samples. Both layouts must
read back every sample bit for bit (schema 5: its SQLite caveats aside, none of which these
trials meet), else the benchmark fails. ``VASIM_BENCH_SMOKE=1``
(``python -m bench --smoke``) cuts every run to seconds; its figures then mean nothing.
"""

from __future__ import annotations

import os
import sqlite3
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
from tqdm import tqdm

from vasim.records.point_metrics import evaluate_trial
from vasim.records.samples import FRAME_COLUMNS, SampleBuffer
from vasim.records.trial_meta import TrialMeta
from vasim.study.store import APPLICATION_ID, TrialStore
from vasim.study.store.schema import MIGRATIONS, split_sql
from vasim.trials.registry import run_trial
from vasim.trials.vf import TrialConfig

SMOKE = os.environ.get("VASIM_BENCH_SMOKE") == "1"
"""``python -m bench --smoke``: every run cut to seconds (it checks the bench runs; its
figures mean nothing)."""
FINISH_N = 5000 if SMOKE else 100_000
TRIAL_S = 0.5 if SMOKE else 12.0
"""Simulated seconds of each condition's trial (12,000 samples at 1 kHz)."""
CONDITIONS = ("none",) if SMOKE else ("none", "vg", "ff", "ag", "mag")
COHORT_SUBJECTS = 46
SUBJECT_SAMPLES = 416_015
"""Samples of one simulated ``vf_learning_curve`` subject (38 trials, 416 s simulated):
``vasim study simulate --protocol vf_learning_curve --subjects 1 --seed 7`` (2026-11-27)."""


def _append_cost(n: int = 1000 if SMOKE else 20_000, repeats: int = 1 if SMOKE else 5
                 ) -> float:
    buf = SampleBuffer(capacity=n)
    x, g, f = np.array([0.1, 0.2, 0.3]), np.array([0.0, 0.0, 0.01]), np.array([1.0, 0, 0])
    ms = np.ones(3)
    runs = []
    for _ in range(repeats):
        buf.clear()
        t0 = time.perf_counter()
        for k in range(n):
            buf.append(k, k * 1e-3, x, g, 0, f, ms, 1.0, 440.0, 0.5, 0.2, 0)
        runs.append((time.perf_counter() - t0) / n * 1e6)
    return statistics.median(runs)


def _finish_cost(n: int = FINISH_N, repeats: int = 1 if SMOKE else 3) -> float:
    rng = np.random.default_rng(0)
    buf = SampleBuffer(capacity=n)
    buf.extend(k=np.arange(n), t=np.arange(n) * 1e-3, x=rng.normal(size=(n, 3)),
               g=rng.normal(size=(n, 3)), goal_index=(np.arange(n) * 30) // n)
    v = buf.view()
    pm, summary = evaluate_trial(v["t"], v["x"], v["g"], v["goal_index"], 30)
    runs = []
    with tempfile.TemporaryDirectory() as tmp, TrialStore(Path(tmp) / "b.sqlite") as store:
        for _ in tqdm(range(repeats), desc="finish_trial", leave=False):
            tid = store.begin_trial(TrialMeta(subject="B01", task="trajectory"))
            t0 = time.perf_counter()
            store.finish_trial(tid, buf, pm, summary)
            runs.append(time.perf_counter() - t0)
    return statistics.median(runs)


def _trials() -> list[SampleBuffer]:
    """One simulated trial per condition (scripted operator, no scene), in memory."""
    out = []
    for i, schema in enumerate(tqdm(CONDITIONS, desc="simulating trials", leave=False)):
        res, _ = run_trial(TrialConfig(schema=schema, seed=i + 1, max_time=TRIAL_S,
                                       scene="none", subject="B01"), None)
        out.append(res.samples)
    return out


def _file_bytes(path: Path, con: sqlite3.Connection) -> int:
    con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    return path.stat().st_size


def _v5_store(path: Path) -> sqlite3.Connection:
    """An empty schema-5 store, as vasim 5 made it (WAL, synchronous=FULL)."""
    con = sqlite3.connect(path, isolation_level=None)
    con.execute("PRAGMA journal_mode = WAL")
    con.execute("PRAGMA synchronous = FULL")
    con.execute("BEGIN")
    for v in range(1, 6):
        for stmt in split_sql(MIGRATIONS[v]):
            con.execute(stmt)
    con.execute(f"PRAGMA application_id = {APPLICATION_ID}")
    con.execute("PRAGMA user_version = 5")
    con.execute("INSERT INTO subjects VALUES ('B01', '2026-01-01', NULL)")
    con.execute("COMMIT")
    return con


def _check_exact(trials: list[SampleBuffer], back: list[pd.DataFrame], name: str) -> None:
    """Every sample read back bit for bit, or the benchmark fails."""
    for buf, df in zip(trials, back, strict=True):
        want = buf.to_frame()
        for c in FRAME_COLUMNS:
            if df[c].to_numpy().tobytes() != want[c].to_numpy().tobytes():
                raise SystemExit(f"{name}: column {c} did not read back bit for bit")


def _layouts(trials: list[SampleBuffer]) -> dict[str, dict[str, float]]:
    n = sum(len(b) for b in trials)
    out: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        # schema 5: one row per sample
        p5 = Path(tmp) / "v5.sqlite"
        con = _v5_store(p5)
        empty = _file_bytes(p5, con)
        write = 0.0
        for tid, buf in enumerate(trials, 1):
            t0 = time.perf_counter()
            con.execute("BEGIN IMMEDIATE")
            con.execute("INSERT INTO trials (id, subject, task, status, started_at) VALUES "
                        "(?, 'B01', 'trajectory', 'running', '2026-01-01')", (tid,))
            con.executemany(f"INSERT INTO samples (trial_id, {', '.join(FRAME_COLUMNS)}) "
                            f"VALUES ({tid}, {', '.join('?' * len(FRAME_COLUMNS))})",
                            buf.rows())
            con.execute("COMMIT")
            write += time.perf_counter() - t0
        size = _file_bytes(p5, con) - empty
        con.close()
        with TrialStore(p5, readonly=True) as ro:
            t0 = time.perf_counter()
            back = [ro.samples(tid) for tid in range(1, len(trials) + 1)]
            read = time.perf_counter() - t0
        _check_exact(trials, back, "schema 5")
        out["schema 5 (rows)"] = {"bytes": size / n, "write": n / write, "read": n / read}
        # schema 6: packed columns, through TrialStore
        p6 = Path(tmp) / "v6.sqlite"
        with TrialStore(p6) as st:
            empty = _file_bytes(p6, st.con)
            write = 0.0
            ids = []
            for buf in trials:
                tid = st.begin_trial(TrialMeta(subject="B01", task="trajectory"))
                t0 = time.perf_counter()
                st.finish_trial(tid, buf)
                write += time.perf_counter() - t0
                ids.append(tid)
            size = _file_bytes(p6, st.con) - empty
            t0 = time.perf_counter()
            back = [st.samples(tid) for tid in ids]
            read = time.perf_counter() - t0
        _check_exact(trials, back, "schema 6")
        out["schema 6 (packed)"] = {"bytes": size / n, "write": n / write, "read": n / read}
    return out


def main() -> None:
    app = _append_cost()
    fin = _finish_cost()
    print(f"{'SampleBuffer.append (in the 1 kHz loop)':<52} {app:8.2f} µs/sample")
    print(f"{'  share of the 1 ms haptic budget':<52} {app / 10:8.2f} %")
    print(f"{f'finish_trial, {FINISH_N:,} samples, one transaction':<52} {fin:8.3f} s")
    print(f"{'  rows made durable per second':<52} {FINISH_N / fin:8.0f}")
    trials = _trials()
    n = sum(len(b) for b in trials)
    print(f"on disk, {len(trials)} simulated trials ({', '.join(CONDITIONS)}; {n:,} samples):")
    res = _layouts(trials)
    for name, r in res.items():
        cohort = r["bytes"] * SUBJECT_SAMPLES * COHORT_SUBJECTS / 1e6
        print(f"  {name:<20} {r['bytes']:7.1f} bytes/sample  write {r['write'] / 1e3:7.0f} "
              f"k samples/s  read {r['read'] / 1e3:7.0f} k samples/s  "
              f"46-subject cohort ~{cohort:,.0f} MB")
    a, b = res["schema 5 (rows)"], res["schema 6 (packed)"]
    print(f"  schema 6 vs 5: {a['bytes'] / b['bytes']:.1f}x smaller, writes "
          f"{b['write'] / a['write']:.2f}x, reads {b['read'] / a['read']:.2f}x as fast")


if __name__ == "__main__":
    main()
