"""Child process of ``test_store.py``'s kill tests (run as a script, never imported by pytest).

Usage: ``python _kill_child.py DB MODE`` with MODE ``between`` or ``finish``.

It completes two trials of ``N_SAMPLES`` samples each, printing one JSON line per trial
(``{"trial": id, "n": ..., "samples_sha": ..., "metrics_sha": ..., "summary": ...}``), then
begins a third trial, prints ``{"trial3": id}`` and:

* ``between``: appends a few samples, prints ``MARKER`` and waits to be killed (a kill
  between ``begin_trial`` and ``finish_trial``);
* ``finish``: calls ``finish_trial`` and, through a statement trace, prints
  ``MARKER wal_bytes=N`` when the transaction has written the samples and is about to close
  the trial row, then waits, so the kill lands *inside* the open write transaction, after
  SQLite has spilled uncommitted pages to the (freshly truncated) WAL: the page cache is made
  tiny, so N > 0 proves the spill.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import time
from collections.abc import Callable

import numpy as np
import pandas as pd

from vasim.records.point_metrics import evaluate_trial
from vasim.records.samples import FRAME_COLUMNS, SampleBuffer
from vasim.records.trial_meta import TrialMeta
from vasim.study.store import TrialStore

N_SAMPLES = 20_000
N_POINTS = 8


def samples_sha(frame: pd.DataFrame) -> str:
    """sha256 of the samples' values (float64, FRAME_COLUMNS order)."""
    block = np.ascontiguousarray(frame[list(FRAME_COLUMNS)].to_numpy(dtype=np.float64))
    return hashlib.sha256(block.tobytes()).hexdigest()


def metrics_sha(frame: pd.DataFrame) -> str:
    """sha256 of a point-metrics frame's values (float64)."""
    block = np.ascontiguousarray(frame.to_numpy(dtype=np.float64))
    return hashlib.sha256(block.tobytes()).hexdigest()


def synthetic_trial(seed: int, n: int) -> SampleBuffer:
    """A completed trajectory trial: random-walk TCP, N_POINTS goals, last sample on goal."""
    rng = np.random.default_rng(seed)
    points = rng.normal(scale=0.05, size=(N_POINTS, 3))
    gi = (np.arange(n) * N_POINTS) // n
    x = np.cumsum(rng.normal(scale=1e-4, size=(n, 3)), axis=0)
    x[-1] = points[-1]
    buf = SampleBuffer(capacity=1024, active_fixtures="VG,FF")
    buf.extend(
        k=np.arange(n), t=(np.arange(n) + 1) * 1e-3, x=x, g=points[gi], goal_index=gi,
        force=rng.normal(size=(n, 3)), ms=rng.uniform(0.5, 2.0, size=(n, 3)),
        zoom=rng.uniform(1.0, 3.0, size=n), audio_pitch=rng.uniform(200, 800, size=n),
        audio_period=rng.uniform(0.1, 1.0, size=n), audio_volume=rng.uniform(size=n),
        contact=rng.integers(0, 2, size=n),
    )
    return buf


def kill_point(wal: str) -> Callable[[str], None]:
    """A statement trace that prints ``MARKER wal_bytes=N`` (N: the WAL file's size then,
    > 0 once uncommitted pages were spilled) when ``finish_trial`` is about to close the
    trial row (its samples written, the transaction open), then blocks."""

    def trace(sql: str) -> None:
        if sql.lstrip().startswith("UPDATE trials SET status"):
            print(f"MARKER wal_bytes={os.path.getsize(wal)}", flush=True)
            time.sleep(60)  # the parent kills us here, mid-transaction

    return trace


def main(db: str, mode: str) -> None:
    store = TrialStore(db)
    for seed in (1, 2):
        buf = synthetic_trial(seed, N_SAMPLES)
        v = buf.view()
        metrics, summary = evaluate_trial(v["t"], v["x"], v["g"], v["goal_index"], N_POINTS)
        tid = store.begin_trial(TrialMeta(subject="K01", task="trajectory", seed=seed))
        store.finish_trial(tid, buf, metrics, summary)
        print(json.dumps({"trial": tid, "n": len(buf), "samples_sha": samples_sha(buf.to_frame()),
                          "metrics_sha": metrics_sha(metrics),
                          # the store's JSON writes NaN (a metric not measured) as null
                          "summary": {k: None if isinstance(x, float) and x != x else x
                                      for k, x in summary.items()}}), flush=True)
    tid3 = store.begin_trial(TrialMeta(subject="K01", task="trajectory", seed=3))
    print(json.dumps({"trial3": tid3}), flush=True)
    if mode == "between":
        buf = SampleBuffer()
        for k in range(500):
            buf.append(k, (k + 1) * 1e-3, (0.0, 0.0, k * 1e-5), (0.0, 0.0, 0.01), 0)
        print("MARKER", flush=True)
        time.sleep(60)
    elif mode == "finish":
        store.con.execute("PRAGMA cache_size = 20")  # force uncommitted pages into the WAL
        store.con.execute("PRAGMA wal_checkpoint(TRUNCATE)")  # empty WAL: growth = spill
        big = synthetic_trial(3, 3 * N_SAMPLES)
        store.con.set_trace_callback(kill_point(db + "-wal"))
        store.finish_trial(tid3, big)
    else:
        raise SystemExit(f"unknown mode {mode!r}")
    print("NOT KILLED", flush=True)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
