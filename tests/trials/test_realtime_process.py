"""The real-time trial with its servo loop in a child process (``vasim.trials.realtime.process``).

Each test spawns a servo process (a few seconds to import and build the trial); the runs
themselves are about a second of wall time, and only behaviour is asserted.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest

from tests.polling import wait_until
from vasim.core.errors import ConfigError, DeviceError
from vasim.haptics.devices.replay import stream_path
from vasim.study.store import TrialStore
from vasim.trials.realtime import (
    ProcessRealtimeTrial,
    RealtimeRecording,
    realtime_path,
    replay_trial,
    run_realtime_trial,
)
from vasim.trials.vf import TrialConfig


def test_process_trial_is_stored_and_replays_exactly(tmp_path: Path) -> None:
    db = tmp_path / "s.sqlite"
    frames: list[int] = []
    with TrialStore(db) as store:
        result, tid, timing = run_realtime_trial(
            TrialConfig(schema="ff", seed=4, max_time=1.2), store, process=True,
            on_poll=lambda trial: frames.append(trial.frame().k))
        assert tid is not None
        row = store.trial(tid)
    assert row["status"] == "completed" and row["operator"] == "scripted"
    assert len(result.samples) == 1200
    assert frames == sorted(frames) and frames[-1] > frames[0]  # frames arrive, in order
    t = row["timing"]
    assert t["physics_mode"] == "process" and t["physics"]["steps"] > 0
    assert t["n_ticks"] >= 1200 and timing.servo.n_ticks == t["n_ticks"]
    assert stream_path(db, tid).exists() and realtime_path(db, tid).exists()
    rec = RealtimeRecording.load(db, tid)
    # physics snapshots were taken up and recorded (how many in 1.2 s depends on the load:
    # ~300 at 250 Hz on an idle machine); the replay below uses every one of them
    assert rec.physics is not None and len(rec.physics.applied) > 0
    with TrialStore(db, readonly=True) as store:
        report = replay_trial(store, tid)
    assert report.differences == () and report.samples_equal and report.metrics_equal


def test_process_trial_viewer_surface() -> None:
    trial = ProcessRealtimeTrial(TrialConfig(schema="vg", seed=2, max_time=0.4)).start()
    wait_until(lambda: trial.done, what="the 0.4 s process trial to end", timeout=30.0,
               step=0.02)
    frame = trial.frame()
    assert frame.abdomen is not None and len(frame.abdomen.organs) > 0  # meshes from here
    result = trial.result()  # stops the child and evaluates its end state here
    assert len(result.samples) == 400 and result.summary["finished"] is False
    assert trial.frame().done and trial.error is None
    assert trial.timing().to_dict()["n_ticks"] >= 400
    trial.stop()  # idempotent


def test_a_device_that_cannot_be_built_fails_start_with_its_error() -> None:
    trial = ProcessRealtimeTrial(TrialConfig(schema="none", scene="none", max_time=1.0),
                                 functools.partial(int, "not a device"))
    with pytest.raises(DeviceError, match="invalid literal"):
        trial.start()
    trial.stop()


def test_a_device_object_cannot_cross_into_the_servo_process() -> None:
    from vasim.haptics.devices.emulator import EmulatorDevice

    with pytest.raises(ConfigError, match="device_factory"):
        run_realtime_trial(TrialConfig(schema="none", scene="none", max_time=0.1),
                           device=EmulatorDevice(hand=np.zeros(3)), process=True)
