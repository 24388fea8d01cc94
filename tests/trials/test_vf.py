"""The trial loop: determinism, metrics against an independent recomputation, NaN input,
and the `vasim trial` command (storage, errors, a SIGKILL mid-trial)."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from vasim.cli import main
from vasim.core.errors import ConfigError
from vasim.study.store import TrialStore
from vasim.trials.registry import run_trial
from vasim.trials.vf import TrialConfig, TrialRunner


@pytest.fixture(scope="module")
def ff_trial():
    return run_trial(TrialConfig(schema="ff", seed=1, skill="expert"))[0]


def test_same_seed_same_samples() -> None:
    a = TrialRunner(TrialConfig(schema="trajectory_following", seed=5))
    b = TrialRunner(TrialConfig(schema="trajectory_following", seed=5))
    a.advance(2.0)
    b.advance(2.0)
    np.testing.assert_array_equal(a.samples.view()["x"], b.samples.view()["x"])
    np.testing.assert_array_equal(a.samples.view()["force"], b.samples.view()["force"])
    c = TrialRunner(TrialConfig(schema="trajectory_following", seed=6))
    c.advance(2.0)
    assert not np.array_equal(a.samples.view()["x"], c.samples.view()["x"])


def test_trial_reaches_every_point_and_metrics_match_recomputation(ff_trial) -> None:
    r = ff_trial
    v = r.samples.view()
    pts = r.task.points
    assert r.summary["finished"] and int(r.metrics["reached"].sum()) == len(pts)
    # Independent recomputation of eq. 6.5 with plain loops over the samples.
    e = np.zeros(len(pts))
    reach_t = np.full(len(pts), np.nan)
    # The POIs ride on the breathing tissue: each row is compared with its logged goal g(j).
    for j in range(len(v["t"])):
        i = int(v["goal_index"][j])
        e[i] += np.abs(v["x"][j] - v["g"][j]).sum()
        if np.isnan(reach_t[i]) and np.linalg.norm(v["x"][j] - v["g"][j]) <= r.task.reach_radius:
            reach_t[i] = v["t"][j]
    lat = np.diff(np.concatenate([[0.0], reach_t]))
    np.testing.assert_allclose(r.metrics["error_l1"].to_numpy(), e, rtol=1e-12)
    np.testing.assert_allclose(r.metrics["latency"].to_numpy(), lat, rtol=1e-9, atol=1e-12)
    # The control step is 1 ms and the trial ends when the last point is reached.
    np.testing.assert_allclose(np.diff(v["t"]), 1e-3, atol=1e-12)
    assert v["t"][-1] == pytest.approx(reach_t[-1])


def test_ff_force_is_saturated_and_finite(ff_trial) -> None:
    f = ff_trial.samples.view()["force"]
    assert np.isfinite(f).all()
    assert np.linalg.norm(f, axis=1).max() <= 3.3 + 1e-9
    assert np.linalg.norm(f, axis=1).max() > 0.0


class _NaNOperator:
    """Wraps an operator and returns NaN/inf increments on some steps (a faulty device)."""

    def __init__(self, inner, bad_steps: set[int]):
        self.inner, self.bad, self.k = inner, bad_steps, -1

    def reset(self, tcp):
        self.inner.reset(tcp)

    profile = None

    def act(self, percept):
        """The trial operator protocol (``vasim.operator.port.TrialOperator``)."""
        self.k += 1
        dx = self.inner.act(percept)
        if self.k in self.bad:
            return np.array([np.nan, np.inf, 0.0])
        return dx


def test_nonfinite_device_input_never_reaches_task_or_force() -> None:
    runner = TrialRunner(TrialConfig(schema="trajectory_following", seed=2, max_time=1.0))
    runner.operator = _NaNOperator(runner.operator, {10, 11, 500})
    runner.advance(1.0)
    v = runner.samples.view()
    assert np.isfinite(v["x"]).all() and np.isfinite(v["force"]).all()
    kinds = [e[1] for e in runner.events]
    assert kinds.count("nonfinite_input") == 3
    # The dropped steps did not move the tool.
    assert np.array_equal(v["x"][10], v["x"][9]) and np.array_equal(v["x"][11], v["x"][10])


def test_schema_for_the_wrong_task_is_refused() -> None:
    with pytest.raises(ConfigError, match="point_targeting"):
        TrialRunner(TrialConfig(task="trajectory", schema="point_targeting"))


def test_bad_config_values_name_the_field() -> None:
    with pytest.raises(ConfigError, match="dt"):
        TrialConfig(dt=0.5)
    with pytest.raises(ConfigError, match="operator"):
        TrialConfig(operator="omni")


def test_cli_trial_stores_samples_and_metrics(tmp_path: Path, capsys) -> None:
    db = tmp_path / "study.sqlite"
    code = main(["trial", "--task", "trajectory", "--schema", "ff", "--operator", "scripted",
                 "--seed", "1", "--skill", "expert", "--db", str(db)])
    assert code == 0
    out = capsys.readouterr().out
    assert "points reached" in out and "cumulative error" in out
    with TrialStore(db) as store:
        trials = store.trials()
        assert list(trials["status"]) == ["completed"]
        tid = int(trials["id"].iloc[0])
        samples = store.samples(tid)
        metrics = store.point_metrics(tid)
    assert len(samples) == int(trials["n_samples"].iloc[0]) > 1000
    assert metrics["reached"].all()
    e = sum(
        np.abs(samples.loc[samples.goal_index == i, ["x_x", "x_y", "x_z"]].to_numpy()
               - samples.loc[samples.goal_index == i, ["g_x", "g_y", "g_z"]].to_numpy()).sum()
        for i in range(len(metrics))
    )
    assert metrics["error_l1"].sum() == pytest.approx(e, rel=1e-12)


def test_cli_errors_are_one_line_exit_2(tmp_path: Path) -> None:
    exe = [sys.executable, "-m", "vasim"]
    p = subprocess.run([*exe, "trial", "--schema", "nope"], capture_output=True, text=True)
    assert p.returncode == 2
    assert p.stderr.count("\n") == 1 and "nope" in p.stderr and "Traceback" not in p.stderr
    p = subprocess.run([*exe, "trial", "--subject", "Jane Doe", "--db",
                        str(tmp_path / "s.sqlite"), "--max-time", "0.01"],
                       capture_output=True, text=True)
    assert p.returncode == 2 and "Jane Doe" in p.stderr and "Traceback" not in p.stderr


def test_sigkill_mid_trial_leaves_earlier_trials_intact(tmp_path: Path) -> None:
    db = tmp_path / "study.sqlite"
    for seed in (1, 2):
        assert main(["trial", "--schema", "ff", "--seed", str(seed), "--skill", "expert",
                     "--db", str(db)]) == 0
    with TrialStore(db) as store:
        before = {int(i): store.samples(int(i)) for i in store.trials()["id"]}
    # A long trial in a child process, killed once its 'running' row is visible.
    child = subprocess.Popen(
        [sys.executable, "-m", "vasim", "trial", "--schema", "trajectory_following",
         "--skill", "novice", "--max-time", "600", "--seed", "3", "--db", str(db)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            con = sqlite3.connect(db, timeout=5)
            n = con.execute("select count(*) from trials where status='running'").fetchone()[0]
            con.close()
            if n:
                break
            time.sleep(0.05)
        else:
            pytest.fail("the child never started its trial")
        time.sleep(0.1)  # inside the trial loop (the 'running' row precedes the first step)
        os.kill(child.pid, signal.SIGKILL)
    finally:
        child.wait(timeout=30)
    with TrialStore(db) as store:
        trials = store.trials().set_index("id")
        assert store.integrity_check() == "ok"
        for tid, df in before.items():
            assert trials.loc[tid, "status"] == "completed"
            assert store.samples(tid).equals(df)
        killed = [int(i) for i in trials.index if int(i) not in before]
        assert len(killed) == 1
        assert trials.loc[killed[0], "status"] == "interrupted"
        assert len(store.samples(killed[0])) == 0


def _distance_to_path(x: np.ndarray, task, goal_index: np.ndarray) -> np.ndarray:
    """Distance of each sample to its current segment [p_(i-1), p_i] (start for i = 0)."""
    starts = np.vstack([task.start, task.points[:-1]])
    a, b = starts[goal_index], task.points[goal_index]
    ab = b - a
    u = np.clip(((x - a) * ab).sum(1) / (ab * ab).sum(1), 0.0, 1.0)
    return np.linalg.norm(x - (a + u[:, None] * ab), axis=1)


def test_fixtures_are_transparent_on_the_path() -> None:
    # Decision in vasim/trials/vf.py: trajectory fixtures act on the deviation from the
    # path. AG's dead zone is 0.15 D = 4.5 mm (D = 3 cm), so every sample within 1 mm of the
    # path is silent although the next POI is up to ~10 mm away.
    # A static task (no abdomen): the distance is measured to the task's fixed path.
    r = TrialRunner(TrialConfig(schema="ag", seed=1, skill="expert", max_time=8.0,
                                scene="none"))
    r.advance(8.0)
    v = r.samples.view()
    dist = _distance_to_path(v["x"], r.task, v["goal_index"])
    to_poi = np.linalg.norm(v["x"] - v["g"], axis=1)
    # The cue of a row is rendered after the goal test: on the row where p_i is reached it
    # already belongs to the next segment, so those rows are left out.
    advancing = np.append(np.diff(v["goal_index"]) > 0, False)
    near = (dist < 1e-3) & ~advancing
    assert near.sum() > 100 and (to_poi[near] > 4.5e-3).any()
    assert (v["audio_volume"][near] == 0.0).all()
    assert (v["audio_volume"][(dist > 0.02) & ~advancing] > 0.0).all()


def test_ff_force_grows_with_the_deviation_from_the_path() -> None:
    r = TrialRunner(TrialConfig(schema="ff", seed=3, skill="novice", max_time=20.0,
                                scene="none"))
    r.advance(20.0)
    v = r.samples.view()
    dist = _distance_to_path(v["x"], r.task, v["goal_index"])
    f = np.linalg.norm(v["force"], axis=1)
    assert f[dist < 1e-3].max() < 0.01  # negligible on the path (< 10 mN)
    assert np.corrcoef(dist, f)[0, 1] > 0.8


def test_interrupted_trial_keeps_its_partial_samples(tmp_path: Path, monkeypatch) -> None:
    from vasim.operator.scripted import ScriptedOperator

    calls = {"n": 0}
    real = ScriptedOperator.step_floats

    def flaky(self, *a, **kw):
        calls["n"] += 1
        if calls["n"] == 1500:
            raise KeyboardInterrupt
        return real(self, *a, **kw)

    monkeypatch.setattr(ScriptedOperator, "step_floats", flaky)
    with TrialStore(tmp_path / "s.sqlite") as store:
        with pytest.raises(KeyboardInterrupt):
            run_trial(TrialConfig(schema="ff", seed=1), store)
        tr = store.trials().iloc[0]
        assert tr["status"] == "interrupted" and tr["n_samples"] == 1499
        assert len(store.samples(int(tr["id"]))) == 1499
        assert "KeyboardInterrupt" in " ".join(store.events(int(tr["id"]))["detail"])


def test_stored_trial_carries_its_config_and_schema(tmp_path: Path) -> None:
    from vasim.fixtures.schema import load_schema, parse_schema

    with TrialStore(tmp_path / "s.sqlite") as store:
        _, tid = run_trial(TrialConfig(schema="vg", seed=4, skill="expert", max_time=1.0),
                           store)
        tr = store.trial(tid)
    assert tr["config"]["seed"] == 4 and tr["config"]["skill"] == "expert"
    assert tr["config"]["profile"]["skill"] == pytest.approx(0.9)
    assert parse_schema(tr["schema_toml"], source="stored") == load_schema("vg")


@pytest.mark.parametrize(("kw", "field"), [
    ({"task": "point", "variant": 3}, "variant"),
    ({"seed": -1}, "seed"),
    ({"subject": "Jane Doe"}, "Jane Doe"),
])
def test_more_bad_config_values_are_refused(kw: dict, field: str) -> None:
    with pytest.raises(ConfigError, match=field):
        TrialConfig(**kw)


def test_goals_ride_on_the_breathing_tissue() -> None:
    # With the default abdomen the logged goal of one POI moves with breathing (0.25 Hz,
    # ~1 cm cranio-caudal on the liver); with no scene it is fixed.
    moving = TrialRunner(TrialConfig(schema="none", seed=2, skill="novice", max_time=6.0))
    moving.advance(6.0)
    g = moving.samples.view()["g"]
    gi = moving.samples.view()["goal_index"]
    rows = gi == gi[0]
    assert rows.sum() > 500
    span = np.ptp(g[rows], axis=0)
    assert span[1] > 5e-4  # cranio-caudal motion within one goal's rows
    assert span[1] >= span[0]
    static = TrialRunner(TrialConfig(schema="none", seed=2, skill="novice", max_time=1.0,
                                     scene="none"))
    static.advance(1.0)
    gs = static.samples.view()["g"]
    assert np.ptp(gs[static.samples.view()["goal_index"] == 0], axis=0).max() == 0.0
