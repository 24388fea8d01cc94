"""What the real-time trial does when things go wrong: Ctrl-C reaching the servo process,
a physics failure, a servo process dying before it is ready, a device that cannot start,
truncated or foreign recordings, a torn pose read and a non-finite tissue force."""

from __future__ import annotations

import functools
import logging
import os
import signal
import sqlite3
import threading
from pathlib import Path

import numpy as np
import pytest

from vasim.core.errors import DeviceError
from vasim.haptics.coupling import LinearForce
from vasim.haptics.devices.emulator import EmulatorDevice
from vasim.haptics.devices.replay import DeviceStream, stream_path
from vasim.haptics.servo import CoupledToolPlant, ServoLoop
from vasim.study.store import TrialStore
from vasim.trials.realtime import (
    ProcessRealtimeTrial,
    RealtimeRecording,
    realtime_path,
    replay_trial,
    run_realtime_trial,
)
from vasim.trials.realtime.process import _PoseBoard
from vasim.trials.registry import run_trial
from vasim.trials.vf import TrialConfig


def _frame_threads() -> int:
    return sum(t.name == "vasim-frames" and t.is_alive() for t in threading.enumerate())


def test_sigint_to_the_servo_process_keeps_the_trial() -> None:
    """A terminal Ctrl-C reaches the servo process too: it must not die there, so that the
    parent stops it and still gets the samples and the recording."""
    before = _frame_threads()
    trial = ProcessRealtimeTrial(TrialConfig(schema="none", scene="none", max_time=5.0))
    trial.start()
    os.kill(trial._proc.pid, signal.SIGINT)
    trial._proc.join(0.5)
    assert trial._proc.is_alive()                   # ignored the SIGINT
    trial.stop()
    assert trial.error is None
    result = trial.result()
    assert len(result.samples) > 0
    assert trial.recording().stream is not None
    assert _frame_threads() == before               # the frame reader ended with the child


def test_a_servo_process_dying_before_ready_is_reported_with_its_exit_code() -> None:
    trial = ProcessRealtimeTrial(TrialConfig(schema="none", scene="none", max_time=0.3),
                                 functools.partial(os._exit, 3), start_timeout_s=600.0)
    with pytest.raises(DeviceError, match=r"exited \(code 3\) before it was ready"):
        trial.start()
    trial.stop()


def _failing_physics(monkeypatch: pytest.MonkeyPatch) -> None:
    import vasim.abdomen.world as world

    step = world.Abdomen.step

    def bad(self: world.Abdomen, *args: object, **kwargs: object) -> object:
        if self.seq >= 20:
            raise RuntimeError("physics blew up")
        return step(self, *args, **kwargs)

    monkeypatch.setattr(world.Abdomen, "step", bad)


@pytest.mark.parametrize("process", [True, False])
def test_a_physics_failure_interrupts_the_trial(tmp_path: Path, process: bool,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """The tissue froze: the trial is not completed (it used to be, in the servo process)."""
    _failing_physics(monkeypatch)
    db = tmp_path / "s.sqlite"
    with TrialStore(db) as store:
        with pytest.raises(DeviceError, match="physics blew up"):
            run_realtime_trial(TrialConfig(schema="ff", seed=1, max_time=30.0), store,
                               process=process)
        rows = store.trials()
    assert rows["status"].tolist() == ["interrupted"]
    assert int(rows["n_samples"].iloc[0]) < 30_000          # stopped early, not at time-out


class _DeadDevice(EmulatorDevice):
    def start(self) -> None:
        raise DeviceError("no device on this machine")


def test_a_device_that_cannot_start_leaves_no_trial_row(tmp_path: Path,
                                                        caplog: pytest.LogCaptureFixture
                                                        ) -> None:
    db = tmp_path / "s.sqlite"
    with TrialStore(db) as store, caplog.at_level(logging.WARNING):
        with pytest.raises(DeviceError, match="no device on this machine"):
            run_realtime_trial(TrialConfig(schema="none", scene="none", max_time=1.0), store,
                               device=_DeadDevice(hand=np.zeros(3)), process=False)
        assert len(store.trials()) == 0
    assert not [r for r in caplog.records if r.exc_info]          # no traceback printed
    assert not list(tmp_path.glob("*.npz"))


def _recorded_trial(tmp_path: Path) -> tuple[Path, int]:
    db = tmp_path / "r.sqlite"
    with TrialStore(db) as store:
        _, tid, _ = run_realtime_trial(TrialConfig(schema="none", scene="none", seed=2,
                                                   max_time=0.3), store, process=False)
    assert tid is not None
    return db, tid


@pytest.mark.parametrize("which", ["device", "realtime"])
def test_a_truncated_recording_is_a_clear_error(tmp_path: Path, which: str) -> None:
    db, tid = _recorded_trial(tmp_path)
    path = stream_path(db, tid) if which == "device" else realtime_path(db, tid)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(DeviceError, match="truncated"):
        if which == "device":
            DeviceStream.load(path)
        else:
            RealtimeRecording.load(db, tid)


def test_replay_refuses_a_trial_that_was_not_recorded(tmp_path: Path) -> None:
    """A database re-created under the same name: trial 1 is now a headless trial, and the
    old run's recording files are still beside it."""
    db, tid = _recorded_trial(tmp_path)
    for suffix in ("", "-wal", "-shm"):
        Path(f"{db}{suffix}").unlink(missing_ok=True)
    with TrialStore(db) as store:
        _, new_id = run_trial(TrialConfig(schema="none", scene="none", seed=3, max_time=0.3),
                              store)
        assert new_id == tid and stream_path(db, tid).exists()
        with pytest.raises(DeviceError, match="not run with --realtime"):
            replay_trial(store, tid)


def test_torn_pose_read_returns_the_last_consistent_pose() -> None:
    import multiprocessing as mp

    from vasim.abdomen.contact import ToolPose

    board = _PoseBoard(mp.get_context("spawn"))
    assert board.read() is None                                     # nothing written yet
    pose = ToolPose(fulcrum=np.array([0.0, 0.0, 0.1]), tip=np.array([0.01, 0.02, 0.0]))
    board.write(pose)
    got = board.read()
    assert got is not None and np.array_equal(got.tip, pose.tip)
    board.a[0] += 1.0                         # a writer preempted in the middle of a write
    stale = board.read()
    assert stale is not None and np.array_equal(stale.tip, pose.tip)


def test_one_non_finite_tissue_force_does_not_switch_force_feedback_off() -> None:
    plant = CoupledToolPlant()

    class Plant:
        k = 0

        def on_start(self, t: float) -> None:
            plant.on_start(t)

        def on_stop(self) -> None:
            pass

        def tick(self, t: float, m: np.ndarray, b: int) -> tuple[float, float, float]:
            self.k += 1
            if self.k == 100:
                plant.set_tissue(LinearForce(np.array([np.nan, 0, 0]), np.zeros(9), m))
            elif self.k == 101:
                plant.set_tissue(LinearForce(np.array([0.5, 0, 0]), np.zeros(9), m))
            return plant.tick(t, m, b)

    loop = ServoLoop(EmulatorDevice(hand=np.array([0.0, 0.0, 0.01])), Plant())
    loop.run_ticks(1100)
    assert plant.proxy_resets == 1
    assert loop.latest is not None and np.all(np.isfinite(loop.latest.force))
    assert abs(loop.latest.force[0]) > 0.1           # the 0.5 N tissue force is felt again
    assert np.all(np.isfinite(plant.proxy.x))


def test_sqlite_rows_survive(tmp_path: Path) -> None:
    """The recorded trial of these tests is a real stored row (guards the helper)."""
    db, tid = _recorded_trial(tmp_path)
    rows = sqlite3.connect(db).execute("SELECT id, status FROM trials").fetchall()
    assert rows == [(tid, "completed")]
