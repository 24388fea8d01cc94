"""Replaying a stored real-time trial from its recording, bit for bit: the recorded device
readings through the same loop in simulated time, the abdomen re-stepped with the recorded
tool poses (``vasim trial --replay ID``)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from vasim.core.errors import ConfigError, DeviceError
from vasim.fixtures.schema import parse_schema
from vasim.haptics.coupling import CouplingParams
from vasim.haptics.devices.replay import ReplayDevice
from vasim.trials.realtime.loop import RealtimeTrial, ServoSettings
from vasim.trials.realtime.plant import PhysicsMode
from vasim.trials.realtime.recording import PhysicsLog, RealtimeRecording, recorded_files
from vasim.trials.sink import TrialSource
from vasim.trials.vf import (
    TrialConfig,
    TrialResult,
)


@dataclass(frozen=True, eq=False)
class ReplayReport:
    """A replayed trial and how it compares with the stored one.

    Attributes:
        result: the replay's result. ticks: servo ticks replayed.
        samples_equal: every sample column bit-identical (NaN = NaN) to the stored samples.
        metrics_equal: per-point metrics and trial metrics identical to the stored ones.
        differences: names of the columns / metrics that differ.
    """

    result: TrialResult
    ticks: int
    samples_equal: bool
    metrics_equal: bool
    differences: tuple[str, ...]


def stored_config(row: dict[str, Any]) -> TrialConfig:
    """The ``TrialConfig`` of a stored trial row (``TrialStore.trial``); the operator is
    reset to ``"scripted"`` (a replay's device is the recording)."""
    rec = row.get("config")
    if not rec:
        raise ConfigError(f"trial {row.get('id')} has no stored configuration",
                          field="config_json")
    names = {f.name for f in fields(TrialConfig)} - {"profile", "operator"}
    return TrialConfig(**{k: v for k, v in rec.items() if k in names})


def replay_trial(store: TrialSource, trial_id: int) -> ReplayReport:
    """Re-runs a stored real-time trial from its recording and compares it.

    The recorded device readings are replayed through the same loop, plant and runner in
    simulated time; the abdomen is re-stepped with the recorded tool poses and each
    snapshot handed over at the recorded control step (module docstring).

    Raises:
        DeviceError: the trial has no recording. StoreError: unknown trial.
    """
    if not isinstance(store, TrialSource):
        raise TypeError(f"store must be a TrialSource (e.g. a TrialStore), got "
                        f"{type(store).__name__}")
    row = store.trial(trial_id)
    files = recorded_files(store, row)
    if files is None:
        raise DeviceError(f"trial {trial_id} has no real-time recording: it was not run with "
                          "--realtime (or its recording could not be saved)")
    rec = RealtimeRecording.load(store.path, trial_id)
    config = stored_config(row)
    schema = parse_schema(row["schema_toml"], source=f"trial {trial_id}") \
        if row.get("schema_toml") else None
    meta = rec.meta
    physics: PhysicsMode | PhysicsLog = rec.physics if rec.physics is not None else "off"
    servo = ServoSettings(rate_hz=float(meta["rate_hz"]),
                          coupling=CouplingParams(**meta["coupling"]),
                          clutch_button=int(meta["clutch_button"]), record=False,
                          blend_s=float(meta["blend_s"]))
    trial = RealtimeTrial(config, ReplayDevice(rec.stream), schema=schema, physics=physics,
                          servo=servo)
    trial.loop.workspace_margin_m = float(meta["workspace_margin_m"])
    t0 = time.perf_counter()
    ticks = trial.run_ticks(len(rec.stream))
    trial.stop()
    result = trial.result(wall_time=time.perf_counter() - t0)
    diffs: list[str] = []
    stored = store.sample_buffer(trial_id).view()
    mine = result.samples.view()
    for c in stored:
        a, b = np.asarray(stored[c]), np.asarray(mine.get(c, np.empty(0)))
        if a.shape != b.shape or not np.array_equal(a, b, equal_nan=a.dtype.kind == "f"):
            diffs.append(f"samples.{c}")
    samples_equal = not diffs
    pm = store.point_metrics(trial_id)
    for c in pm.columns:
        a = pm[c].to_numpy()
        b = result.metrics[c].to_numpy() if c in result.metrics else np.empty(0)
        if a.shape != b.shape or not np.array_equal(
                a.astype(np.float64), b.astype(np.float64), equal_nan=True):
            diffs.append(f"point_metrics.{c}")
    tm = store.trial_metrics(trial_id)
    stored_tm = dict(zip(tm["metric"], tm["value"], strict=True))
    for name, v in result.trial_metrics.items():
        s = stored_tm.get(name, math.nan)
        if not (s == v or (s != s and (v is None or v != v))):
            diffs.append(f"trial_metrics.{name}")
    metrics_equal = not any(d.startswith(("point_metrics", "trial_metrics")) for d in diffs)
    return ReplayReport(result, ticks, samples_equal, metrics_equal, tuple(diffs))


__all__ = ["ReplayReport", "replay_trial", "stored_config"]
