"""``vasim report`` on a full-size study: 46 subjects x 38 trials of the VF protocol.

Benchmark fixture (not a model of real subjects, not used by vasim): a seeded generative
model writes, through the store API, sessions shaped like ``vf_learning_curve`` -- the real
protocol text, the realised schedule of ``generate_schedule``, demographics and
post-questionnaire answers -- and for every trial 30 per-point metric rows and the trial
metrics. **No samples are written**: the report never reads the ``samples`` table (it uses
the per-point and per-trial metrics stored with each trial), so omitting them changes
nothing it measures. The store is written with ``PRAGMA synchronous = OFF`` (a throw-away
fixture needs no fsync per trial). One scheduled trial is interrupted and re-run, so the
cohort section has something to count.

Model (subject j, scheduled trial k = 0..37, point i = 0..29; all draws from
``SeedSequence([seed, j])``):

* subject error level m_j = 14 mm x exp(N(0, 0.25^2)); pace l_j = 1.2 s/point x
  exp(N(0, 0.2^2)); surgeons are 10 % more accurate than residents;
* learning: error x (1 + k)^(-0.12), latency x (1 + k)^(-0.08);
* fixture effect during assisted trials (``ERROR_EFFECT``, ``LATENCY_EFFECT``);
* per point: l_i = l x exp(N(0, 0.35^2)) [s]; mean error x exp(N(0, 0.3^2)); e_i = l_i x
  1000 Hz x mean error [m] (a sum over 1 kHz samples, as the trial runner logs).

Prints the time to build the fixture and the wall time of ``vasim report`` (a subprocess,
imports included) against the 30 s goal.
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
from tqdm import tqdm

from vasim.records.samples import SampleBuffer
from vasim.records.trial_meta import TrialMeta
from vasim.study.protocol import generate_schedule, load_protocol
from vasim.study.session import SessionSettings, record_answers, start_session
from vasim.study.store import TrialStore

SMOKE = os.environ.get("VASIM_BENCH_SMOKE") == "1"
"""``python -m bench --smoke``: every run cut to seconds (it checks the bench runs; its
figures mean nothing)."""
N_SUBJECTS = 46
FIXTURE_SUBJECTS = 2 if SMOKE else N_SUBJECTS
N_SURGEONS = 31
N_POINTS = 30
GOAL_S = 30.0
ERROR_EFFECT = {"none": 1.0, "vg": 0.80, "ag": 0.85, "ms": 0.90, "mag": 0.95, "ff": 0.70}
"""Multiplier of the mean error while a fixture assists (benchmark model)."""
LATENCY_EFFECT = {"none": 1.0, "vg": 1.05, "ag": 0.95, "ms": 1.10, "mag": 0.90, "ff": 1.00}
"""Multiplier of the per-point latency while a fixture assists (benchmark model)."""
_SPECIALISATIONS = ("general_surgery", "gynaecology", "urology", "other")


def _points(rng: np.random.Generator, err: float, lat: float) -> pd.DataFrame:
    l_i = lat * np.exp(rng.normal(0.0, 0.35, N_POINTS))
    m_i = err * np.exp(rng.normal(0.0, 0.3, N_POINTS))
    e_i = l_i * 1000.0 * m_i
    path = 0.035 * np.exp(rng.normal(0.0, 0.3, N_POINTS))
    return pd.DataFrame({"point": np.arange(N_POINTS), "reached": True,
                         "t_reached": np.cumsum(l_i), "error_l1": e_i, "latency": l_i,
                         "path_l1": path, "path_l2": 0.68 * path,
                         "n_samples": np.round(l_i * 1000).astype(np.int64)})


def _trial_metrics(pm: pd.DataFrame) -> dict[str, float]:
    t = float(pm["t_reached"].iloc[-1])
    return {"n_points": float(N_POINTS), "points_reached": float(N_POINTS), "completed": 1.0,
            "completion_time": t, "duration": t + 0.001,
            "total_error_l1": float(pm["error_l1"].sum()),
            "mean_latency": float(pm["latency"].mean()),
            "path_l1": float(pm["path_l1"].sum()), "path_l2": float(pm["path_l2"].sum())}


def build_store(db: Path, *, n_subjects: int = N_SUBJECTS, seed: int = 2024,
                progress: bool = True) -> int:
    """Writes the benchmark fixture (module docstring) into a new store ``db``.

    Returns:
        The number of completed trials written.
    """
    protocol = load_protocol("vf_learning_curve")
    n = 0
    with TrialStore(db) as store:
        store.con.execute("PRAGMA synchronous = OFF")  # throw-away fixture: no fsync
        for j in tqdm(range(n_subjects), desc="fixture subjects", disable=not progress,
                      file=sys.stderr, leave=False):
            rng = np.random.default_rng(np.random.SeedSequence([seed, j]))
            code = f"B{j + 1:03d}"
            group = "surgeon" if j < N_SURGEONS * n_subjects // N_SUBJECTS else "resident"
            err0 = 0.014 * math.exp(rng.normal(0.0, 0.25)) * (0.9 if group == "surgeon" else 1)
            lat0 = 1.2 * math.exp(rng.normal(0.0, 0.2))
            sid = start_session(store, protocol, code, seed=seed * 1000 + j,
                                settings=SessionSettings())
            record_answers(store, sid, "pre", {
                "group": group, "specialisation": _SPECIALISATIONS[int(rng.integers(4))],
                "laparoscopy_experience": ">200" if group == "surgeon" else "1-10",
                "simulator_experience": ("none", "occasional", "regular")[int(rng.integers(3))],
                "robotic_experience": ("none", "observed")[int(rng.integers(2))]})
            sched = generate_schedule(protocol, seed * 1000 + j)
            errors: dict[str, list[float]] = {}
            for st in sched:
                cond = st.condition
                err = err0 * (1 + st.index) ** -0.12 * ERROR_EFFECT.get(cond, 1.0)
                lat = lat0 * (1 + st.index) ** -0.08 * LATENCY_EFFECT.get(cond, 1.0)
                meta = TrialMeta(subject=code, task="trajectory", variant=st.variant,
                                 schema=st.schema, session_id=sid, protocol=protocol.name,
                                 schedule_index=st.index, seed=st.index,
                                 active_fixtures="" if cond == "none" else cond.upper())
                if j == 2 and st.index == 10:  # one interruption, then the re-run
                    tid = store.begin_trial(meta)
                    store.mark_interrupted(tid, reason="benchmark: simulated crash")
                pm = _points(rng, err, lat)
                tid = store.begin_trial(meta)
                store.finish_trial(tid, SampleBuffer(), pm, {"completed": True},
                                   trial_metrics=_trial_metrics(pm))
                errors.setdefault("none" if st.probe else cond, []).append(
                    float(pm["error_l1"].sum()))
                n += 1
            store.set_session_status(sid, "completed")
            base = np.mean(errors["none"])
            perceived = {c: math.log(base / np.mean(v)) + rng.normal(0, 0.15)
                         for c, v in errors.items() if c != "none"}
            ranked = sorted(perceived, key=perceived.get)  # type: ignore[arg-type]
            proposals = [sorted(ranked[-2:]), sorted(ranked[-3:])][: int(rng.integers(3))]
            post: dict[str, object] = {
                "best_vf": ranked[-1], "worst_vf": ranked[0],
                "rating": {c: int(np.clip(round(5 + 10 * p + rng.normal(0, 1)), 0, 10))
                           for c, p in perceived.items()},
                "proposed_schemas": proposals}
            if j % 9 == 0:
                post["comments"] = f"benchmark subject {code}: <b>FF</b> felt natural"
            record_answers(store, sid, "post", post)
    return n


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "bench_report.sqlite"
        t0 = time.perf_counter()
        n = build_store(db, n_subjects=FIXTURE_SUBJECTS, progress=sys.stderr.isatty())
        t_build = time.perf_counter() - t0
        out = Path(tmp) / "report"
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "vasim", "report", "--db", str(db),
                               "--out", str(out), "--no-progress"],
                              capture_output=True, text=True, check=False)
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            raise SystemExit(f"vasim report failed ({proc.returncode}): {proc.stderr.strip()}")
        size = (out / "index.html").stat().st_size
        n_csv = len(list((out / "tables").glob("*.csv")))
    label = f"{FIXTURE_SUBJECTS} subjects x 38 trials x {N_POINTS} points"
    print(f"{'fixture: ' + label:<52} {n:8d} trials in {t_build:6.1f} s")
    print(f"{'vasim report (subprocess, imports included)':<52} {wall:8.2f} s")
    print(f"{'  goal':<52} {GOAL_S:8.2f} s  ({wall / GOAL_S:.2f} of the goal)")
    print(f"{'  index.html, tables':<52} {size / 1e6:8.2f} MB, {n_csv} CSV files")
    m = re.search(r"(\d+) figures, [^)]*\) in ([0-9.]+) s", proc.stdout)
    if m:
        print(f"{'  of which build_report (after imports)':<52} {float(m.group(2)):8.2f} s, "
              f"{m.group(1)} figures")
