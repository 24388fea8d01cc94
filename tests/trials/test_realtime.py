"""The real-time trial: the task in the servo loop, physics beside it, record and replay.

Real-time runs here are short (about a second of wall time) and assert behaviour, never
timing figures (those are printed by ``bench/haptics.py``).
"""

from __future__ import annotations

import math
import sqlite3
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trimesh

from tests.abdomen.test_runner import _Snap
from tests.polling import wait_until
from vasim.abdomen.contact import ToolPose
from vasim.abdomen.world import Abdomen
from vasim.core.errors import ConfigError
from vasim.haptics.device import BUTTON_2, OMNI_LIMITS, DeviceLimits, DeviceSample
from vasim.haptics.devices.emulator import EmulatorDevice
from vasim.haptics.devices.replay import DeviceStream, ReplayDevice, stream_path
from vasim.study.store import TrialStore
from vasim.tasks import trajectory_task
from vasim.trials.realtime import (
    PhysicsLog,
    RealtimeRecording,
    RealtimeTrial,
    ServoSettings,
    realtime_path,
    replay_trial,
    run_realtime_trial,
)
from vasim.trials.realtime.plant import ThreadFeed
from vasim.trials.vf import TrialConfig

# An Omni's forces and resolution in a box large enough for the task's travel (the task
# starts ~5-9 cm from the organs; the real Omni would clutch, the emulator just reaches).
WIDE_OMNI = DeviceLimits((-0.3, -0.3, -0.3), (0.3, 0.3, 0.3), OMNI_LIMITS.max_force_n,
                         OMNI_LIMITS.max_continuous_force_n,
                         position_resolution_m=OMNI_LIMITS.position_resolution_m)


# ---------------------------------------------------------------------------------------
# Record and replay


@pytest.fixture(scope="module")
def stored_realtime(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, int]:
    """A 1.2 s real-time trial (scripted operator, ff, default abdomen in its thread)."""
    db = tmp_path_factory.mktemp("rt") / "study.sqlite"
    with TrialStore(db) as store:
        config = TrialConfig(schema="ff", seed=4, max_time=1.2)
        result, trial_id, timing = run_realtime_trial(config, store)
    assert trial_id is not None
    assert len(result.samples) == 1200  # the trial ran to its time limit, one row per step
    assert timing.servo.n_ticks >= 1200
    return db, trial_id


def test_stored_realtime_trial_keeps_timing_and_recording(stored_realtime) -> None:
    db, trial_id = stored_realtime
    with TrialStore(db, readonly=True) as store:
        row = store.trial(trial_id)
    assert row["status"] == "completed"
    t = row["timing"]
    assert t["mode"] == "realtime" and t["nominal_hz"] == 1000.0
    for key in ("achieved_hz", "period_p50_ms", "period_p99_ms", "period_max_ms", "overruns"):
        assert key in t
    assert t["physics_mode"] == "thread" and t["physics"]["steps"] > 0
    assert t["recording"] == {"device_stream": stream_path(db, trial_id).name,
                              "realtime": realtime_path(db, trial_id).name}
    rec = RealtimeRecording.load(db, trial_id)
    assert len(rec.stream) == t["n_ticks"]  # one reading per tick
    assert rec.physics is not None
    # the runner took physics snapshots during the trial (the replay has work to do; how
    # many in 1.2 s depends on the machine's load: ~300 at 250 Hz when idle)
    assert len(rec.physics.applied) > 0
    assert rec.physics.n_steps >= rec.physics.applied[-1][1]


def test_replay_gives_the_same_samples_and_metrics(stored_realtime) -> None:
    db, trial_id = stored_realtime
    with TrialStore(db, readonly=True) as store:
        report = replay_trial(store, trial_id)
        stored_summary = store.trial(trial_id)["summary"]
    assert report.differences == ()
    assert report.samples_equal and report.metrics_equal
    assert len(report.result.samples) == 1200
    for key in ("points_reached", "sim_time", "steps", "tissue_contact_time"):
        if key in stored_summary:
            assert report.result.summary[key] == stored_summary[key], key


def test_replay_notices_a_changed_recording(stored_realtime, tmp_path: Path) -> None:
    """The comparison can fail: one reading moved by 1 mm changes the replayed samples."""
    db, trial_id = stored_realtime
    copy = tmp_path / "copy.sqlite"
    with sqlite3.connect(db) as src, sqlite3.connect(copy) as dst:
        src.backup(dst)
    rec = RealtimeRecording.load(db, trial_id)
    pos = rec.stream.position.copy()
    pos[600:, 0] += 1e-3
    changed = DeviceStream(rec.stream.device, rec.stream.rate_hz, rec.stream.limits,
                           rec.stream.tick, rec.stream.t, pos, rec.stream.orientation,
                           rec.stream.buttons, rec.stream.valid)
    RealtimeRecording(changed, rec.physics, rec.meta).save(copy, trial_id)
    with TrialStore(copy, readonly=True) as store:
        report = replay_trial(store, trial_id)
    assert not report.samples_equal
    assert "samples.x" in report.differences


def test_physics_log_round_trips_through_arrays() -> None:
    log = PhysicsLog([None, (0.1, 0.2, 0.3, 0.0, 0.0, 0.1)], [(0, 1), (4, 2)])
    back = PhysicsLog.from_arrays(**log.arrays())
    assert back.poses == log.poses and back.applied == log.applied
    assert back.pose(1) is None
    assert back.pose(2).tip.tolist() == [0.1, 0.2, 0.3]


def test_replay_without_recording_says_what_is_missing(tmp_path: Path) -> None:
    from vasim.core.errors import DeviceError
    from vasim.trials.registry import run_trial

    db = tmp_path / "s.sqlite"
    with TrialStore(db) as store:
        _, tid = run_trial(TrialConfig(schema="none", scene="none", max_time=0.05), store)
        with pytest.raises(DeviceError, match="no real-time recording"):
            replay_trial(store, tid)


# ---------------------------------------------------------------------------------------
# No buzz at rest against the tissue


def _press_into(organ: str, depth: float) -> tuple[TrialConfig, np.ndarray]:
    """A hand path (device frame) from the task's start to ``depth`` [m] under the surface
    of ``organ`` at its vertex nearest to the start, along the vertex normal."""
    config = TrialConfig(schema="none", seed=0, max_time=20.0)
    task = trajectory_task(0)
    abdomen = Abdomen("default")
    surf = abdomen.latest.organ(organ).surface
    normals = trimesh.Trimesh(surf, abdomen.faces(organ), process=False).vertex_normals
    start = np.asarray(task.start, dtype=np.float64)
    i = int(np.argmin(np.linalg.norm(surf - start, axis=1)))
    return config, surf[i] - depth * normals[i] - start


def _rest_force(blend_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(device force, runner's tissue force) at rest: 3..5 s of a 5 s press, (n, 3) [N]."""
    config, target = _press_into("liver", 0.01)

    def hand(t: float) -> np.ndarray:
        s = min(1.0, t)  # 1 s smooth reach, then held still
        return (s * s * (3.0 - 2.0 * s)) * target

    trial = RealtimeTrial(config, EmulatorDevice(WIDE_OMNI, hand=hand), physics="inline",
                          servo=ServoSettings(blend_s=blend_s))
    assert trial.run_ticks(5000) == 5000
    trace = trial.loop.trace.array()
    rest = trace[:, 1] >= 3.0
    samples = trial.runner.samples.view()
    assert samples["contact"][samples["t"] >= 3.0].all()  # touching all along
    return trace[rest, 5:8], samples["f_contact"][samples["t"] >= 3.0]


def _buzz(f: np.ndarray, window: int = 25) -> np.ndarray:
    """Per-axis RMS of f minus its centred 25 ms moving mean: the content above ~40 Hz
    (breathing and heartbeat, below 2 Hz, change the mean by < 1e-4 N in 25 ms)."""
    k = np.ones(window) / window
    ma = np.stack([np.convolve(f[:, i], k, mode="valid") for i in range(3)], axis=1)
    h = window // 2
    return np.sqrt(np.mean((f[h:h + len(ma)] - ma) ** 2, axis=0))


BUZZ_BOUND_N = 0.044
"""5% of the Omni's continuous force (0.88 N): force changes of that size are at the
Weber fraction for force (5-10%, Pang, Tan & Durlach 1991) of the forces the device
sustains, so a ripple below it at a steady contact is not felt as buzz."""


def test_no_buzz_when_the_stylus_rests_against_the_tissue() -> None:
    force, _ = _rest_force(blend_s=0.02)
    assert float(np.linalg.norm(force.mean(axis=0))) > 0.1  # a real push, not free space
    assert np.all(np.isfinite(force))
    assert (_buzz(force) < BUZZ_BOUND_N).all(), _buzz(force)


def test_rendering_physics_updates_unblended_buzzes() -> None:
    """The bound is not met for free: the physics' contact force chatters at its update
    rate (the penalty contact of the mass-spring liver, ~125 Hz, ~0.15 N at the time of
    writing), and switching to each new snapshot at once (``blend_s=0``) passes it on."""
    force, tissue = _rest_force(blend_s=0.0)
    if (_buzz(tissue) <= BUZZ_BOUND_N).all():
        pytest.skip(f"the physics' contact force no longer chatters ({_buzz(tissue)} N): "
                    "nothing for the blending to remove")
    assert (_buzz(force) > BUZZ_BOUND_N).any(), _buzz(force)


# ---------------------------------------------------------------------------------------
# The servo loop's guarantees inside a trial


def _stream(positions: np.ndarray, buttons: np.ndarray | None = None) -> ReplayDevice:
    from vasim.haptics.devices.replay import StreamRecorder

    rec = StreamRecorder("test", WIDE_OMNI, 1000.0)
    for k, p in enumerate(positions):
        rec.append(k, DeviceSample(t=k * 1e-3, position=np.asarray(p, dtype=np.float64),
                                   buttons=0 if buttons is None else int(buttons[k])))
    return ReplayDevice(rec.stream())


def test_master_increments_move_the_slave_one_to_one_without_ms() -> None:
    n = 200
    pos = np.zeros((n, 3))
    pos[:, 0] = np.arange(n) * 1e-5  # 1 cm/s along x
    trial = RealtimeTrial(TrialConfig(schema="none", scene="none", max_time=1.0),
                          _stream(pos), physics="off")
    trial.run_ticks(n)
    x = trial.runner.samples.view()["x"]
    start = np.asarray(trial.runner.task.start)
    assert np.allclose(x[-1] - start, pos[-1] - pos[0], atol=1e-12)


def test_clutch_and_bad_readings_never_move_the_task() -> None:
    n = 300
    pos = np.zeros((n, 3))
    pos[:, 1] = np.arange(n) * 1e-5
    buttons = np.zeros(n, dtype=np.int64)
    buttons[100:200] = BUTTON_2  # clutch held: the hand moves 1 mm, the master does not
    pos[250:260] = np.nan  # a driver glitch: held, never reaches the task
    trial = RealtimeTrial(TrialConfig(schema="ff", scene="none", max_time=1.0),
                          _stream(pos, buttons), physics="off")
    trial.run_ticks(n)
    x = trial.runner.samples.view()["x"]
    assert np.isfinite(x).all()
    moved = x[-1, 1] - x[0, 1]
    # 299 steps of 0.01 mm, minus the 100 clutched ones and the 10 held (the first good
    # reading after the glitch re-joins the stream: its increment includes the gap)
    assert math.isclose(moved, 199 * 1e-5, rel_tol=1e-9)
    assert trial.loop.guard.total == 10
    trace = trial.loop.trace.array()
    assert (trace[100:200, 5:8] == 0).all() and (trace[250:260, 5:8] == 0).all()


def test_bad_settings_are_refused_with_the_field_named() -> None:
    config = TrialConfig(schema="none", scene="none", max_time=0.1)
    with pytest.raises(ConfigError, match="rate_hz"):
        RealtimeTrial(config, servo=ServoSettings(rate_hz=500.0))
    with pytest.raises(ConfigError, match="physics"):
        RealtimeTrial(config, physics="process")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="blend_s"):
        RealtimeTrial(config, servo=ServoSettings(blend_s=-1.0))
    with pytest.raises(RuntimeError, match="run_ticks"):
        RealtimeTrial(config, physics="inline").start()


# ---------------------------------------------------------------------------------------
# The surface the viewer uses


def test_viewer_surface_start_frame_done_timing_result() -> None:
    trial = RealtimeTrial(TrialConfig(schema="vg", seed=2, max_time=0.4))
    assert trial.start() is trial
    seen = []
    deadline = time.monotonic() + 10.0
    while not trial.done and time.monotonic() < deadline:
        seen.append(trial.frame().k)
        time.sleep(0.02)
    trial.stop()
    assert trial.done and trial.error is None
    assert seen == sorted(seen) and seen[-1] > seen[0]  # frames advance, never go back
    frame = trial.frame()
    assert frame.done and frame.abdomen is not None and frame.abdomen.seq > 0
    d = trial.timing().to_dict()
    assert d["n_ticks"] >= 400 and d["physics"]["steps"] > 0
    result = trial.result()
    assert len(result.samples) == 400 and result.summary["sim_time"] == pytest.approx(0.4)
    trial.stop()  # idempotent


# ---------------------------------------------------------------------------------------
# The command line


def test_cli_realtime_trial_then_replay(tmp_path: Path, capsys) -> None:
    from vasim.cli import main

    db = tmp_path / "study.sqlite"
    code = main(["trial", "--realtime", "--schema", "none", "--scene", "none",
                 "--max-time", "0.3", "--seed", "3", "--db", str(db)])
    assert code == 0
    out = capsys.readouterr().out
    assert "servo rate" in out and "servo period" in out and "points reached" in out
    with TrialStore(db, readonly=True) as store:
        trials = store.trials()
    assert list(trials["status"]) == ["completed"]
    tid = int(trials["id"].iloc[0])
    assert stream_path(db, tid).exists() and realtime_path(db, tid).exists()
    assert main(["trial", "--replay", str(tid), "--db", str(db)]) == 0
    assert "samples and metrics identical" in capsys.readouterr().out


def test_cli_replay_needs_a_database(capsys) -> None:
    from vasim.cli import main

    assert main(["trial", "--replay", "1"]) == 2
    assert "--replay needs --db" in capsys.readouterr().err


def test_a_device_failing_mid_trial_leaves_an_interrupted_trial_with_its_samples(
        tmp_path: Path) -> None:
    from vasim.core.errors import DeviceError

    db = tmp_path / "s.sqlite"
    device = _stream(np.zeros((300, 3)))  # runs out of readings after 300 ticks
    with TrialStore(db) as store:
        with pytest.raises(DeviceError, match="end of the recording"):
            run_realtime_trial(TrialConfig(schema="none", scene="none", max_time=5.0),
                               store, device, physics="off")
        trials = store.trials()
        assert list(trials["status"]) == ["interrupted"]
        tid = int(trials["id"].iloc[0])
        assert len(store.samples(tid)) == 300
        kinds = list(store.events(tid)["kind"])
    assert "recording" in kinds and "interrupted" in kinds
    assert stream_path(db, tid).exists()


def test_servo_loop_asks_for_real_time_priority_and_reports_the_answer() -> None:
    from vasim.haptics.servo import NullPlant, ServoLoop

    for bad in (0, 100, True, 1.5):
        with pytest.raises(ValueError, match="rt_priority"):
            ServoLoop(EmulatorDevice(hand=np.zeros(3)), NullPlant(), rt_priority=bad)  # type: ignore[arg-type]
    loop = ServoLoop(EmulatorDevice(hand=np.zeros(3)), NullPlant(), rt_priority=10)
    assert loop.priority_granted is None
    loop.start()
    wait_until(lambda: loop.priority_granted is not None,
               what="the servo loop to ask for real-time priority")
    loop.stop()
    assert loop.priority_granted in (True, False)  # granted as root, refused otherwise
    assert [e.kind for e in loop.events].count("priority") == 1
    plain = ServoLoop(EmulatorDevice(hand=np.zeros(3)), NullPlant())  # default: not asked
    plain.start()
    wait_until(lambda: plain.ticks > 0, what="the servo loop's first tick")
    plain.stop()
    assert plain.priority_granted is None


def test_cli_realtime_in_process_runs_the_threaded_loop(tmp_path: Path, capsys) -> None:
    from vasim.cli import main

    db = tmp_path / "study.sqlite"
    assert main(["trial", "--realtime", "--in-process", "--device", "emulator",
                 "--scene", "none", "--max-time", "0.2", "--db", str(db)]) == 0
    assert "servo rate" in capsys.readouterr().out
    with TrialStore(db, readonly=True) as store:
        row = store.trial(int(store.trials()["id"].iloc[0]))
    assert row["operator"] == "emulator" and row["timing"]["mode"] == "realtime"
    assert row["n_samples"] == 200


class _FakePhysics:
    def __init__(self) -> None:
        self.latest = _Snap(0.0, 0)
        self.events: list[tuple[float, str, str]] = []

    def set_tool(self, pose: Any) -> None:
        pass

    def drain_events(self) -> list[tuple[float, str, str]]:
        out, self.events = self.events, []
        return out


def test_the_thread_feed_hands_over_the_events_of_skipped_snapshots() -> None:
    physics = _FakePhysics()
    feed = ThreadFeed(physics, PhysicsLog())  # type: ignore[arg-type]
    pose = ToolPose(np.zeros(3), np.array([0.0, 0.0, -0.1]))
    # steps 1-3 reset (snapshots 1 and 2 skipped); step 4's event was queued after the
    # feed read snapshot 3: it waits for snapshot 4
    physics.events = [(0.004, "organ_reset", "a"), (0.008, "organ_reset", "b"),
                      (0.012, "organ_reset", "c"), (0.016, "organ_reset", "d")]
    physics.latest = _Snap(0.012, 3, (("organ_reset", "c"),))
    snap = feed(0, pose)
    assert snap.events == (("organ_reset", "a"), ("organ_reset", "b"), ("organ_reset", "c"))
    assert feed(1, pose) is None  # same snapshot
    physics.latest = _Snap(0.016, 4, (("organ_reset", "d"),))
    assert feed(2, pose).events == (("organ_reset", "d"),)
