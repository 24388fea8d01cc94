"""The viewer's TrainingController without a server: modes, storage exactly like a headless
trial, protocol sessions (no duplicate, interrupted attempts stay pending), f5PL editing,
and bad commands that leave the running trial alone. The test thread plays the
controller thread (``handle`` + ``poll``); trials run faster than real time (``speed``)."""

from __future__ import annotations

import json
import shutil
import time
from collections.abc import Iterator
from contextlib import closing
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

import vasim.viewer.controller as controller_mod
from tests.viewer.driving import drive
from vasim.cli import main
from vasim.core.errors import ConfigError
from vasim.fixtures.logistic import Logistic5
from vasim.fixtures.schema import load_schema, schema_path
from vasim.study.store import TrialStore
from vasim.trials.registry import run_trial
from vasim.viewer.app_options import TrialOptions
from vasim.viewer.controller import (
    Command,
    TrainingController,
    TrainingSettings,
    f5pl_fields,
    schema_choices,
    with_f5pl,
)

SPEED = 25.0


@pytest.fixture
def ctl(tmp_path: Path) -> Iterator[TrainingController]:
    c = TrainingController(TrainingSettings(
        scene="none", db=tmp_path / "s.sqlite", speed=SPEED,
        trials=TrialOptions(countdown_s=0.0, pause_s=0.05, max_time=20.0)))
    try:
        yield c
    finally:
        c.close()


def run(ctl: TrainingController, *cmds: Command) -> None:
    for cmd in cmds:
        ctl.handle(cmd)


def store(ctl: TrainingController) -> TrialStore:
    return TrialStore(ctl.db, readonly=True)  # type: ignore[arg-type]


def test_demo_loops_over_variants_and_stores_nothing(tmp_path: Path) -> None:
    c = TrainingController(TrainingSettings(
        scene="none", db=tmp_path / "d.sqlite", speed=SPEED,
        trials=TrialOptions(countdown_s=0.0, pause_s=0.02, max_time=0.5)))
    try:
        assert c.panel.mode == "demo" and c.info.trial_id is None
        assert drive(c, lambda: c.info.number >= 3)
        assert c.info.config.variant == 2 and c.info.config.seed == 2
    finally:
        c.close()
    assert not (tmp_path / "d.sqlite").exists()  # the store was never opened


def test_free_and_protocol_need_a_database() -> None:
    c = TrainingController(TrainingSettings(scene="none", db=None, speed=SPEED))
    try:
        with pytest.raises(ConfigError, match="--db"):
            c.handle(Command("mode", "free"))
        assert c.panel.mode == "demo" and c.active()  # the demo goes on
    finally:
        c.close()


def test_a_free_trial_is_stored_exactly_like_a_headless_one(ctl: TrainingController,
                                                            tmp_path: Path) -> None:
    run(ctl, Command("mode", "free"), Command("subject", "S01"), Command("task", "point"),
        Command("start"))
    info = ctl.info
    assert info.mode == "free" and info.trial_id is not None and ctl.panel.running
    assert drive(ctl, lambda: not ctl.panel.running)
    assert "stored" in ctl.panel.status and ctl.panel.summary["completed"] is True
    assert [n for n, *_ in ctl.panel.curve] == [1]
    # The same config run headless: same rows, same per-point metrics, same summary.
    with closing(TrialStore(tmp_path / "headless.sqlite")) as hs:
        _, hid = run_trial(info.config, hs)
        h_row = hs.trial(hid)
        h_pm = hs.point_metrics(hid)
        h_n = len(hs.samples(hid))
    with closing(store(ctl)) as st:
        row = st.trial(info.trial_id)
        pm = st.point_metrics(info.trial_id)
        assert len(st.samples(info.trial_id)) == h_n > 100
        assert row["timing_json"]  # the live loop's timing, which a headless run lacks
    assert row["status"] == h_row["status"] == "completed"
    for k in ("subject", "task", "variant", "schema", "operator", "seed", "dt",
              "active_fixtures", "config_json", "schema_toml", "n_samples"):
        assert row[k] == h_row[k], k
    assert json.loads(row["summary_json"]) == json.loads(h_row["summary_json"])
    pd.testing.assert_frame_equal(pm, h_pm)


def test_protocol_trials_follow_the_schedule_without_duplicates(
        ctl: TrainingController) -> None:
    run(ctl, Command("mode", "protocol"), Command("subject", "S02"),
        Command("protocol", "vf_point_targeting"))
    p = ctl.panel
    assert (p.position, p.total, p.completed) == (1, 27, 0)
    ctl.speed = 1.0  # slow enough to stop and to double-start it
    run(ctl, Command("start"))
    first = ctl.info
    assert first.schedule_index == 0 and first.condition == "none"
    with pytest.raises(ConfigError, match="already running"):
        ctl.handle(Command("start"))  # a second tab's Start
    assert ctl.info is first
    run(ctl, Command("stop"))
    assert "stays pending" in ctl.panel.status and not ctl.panel.running
    ctl.speed = SPEED
    run(ctl, Command("start"))  # the same scheduled trial, a second attempt
    second = ctl.info
    assert second.schedule_index == 0 and second.trial_id != first.trial_id
    assert drive(ctl, lambda: not ctl.panel.running)
    assert (ctl.panel.position, ctl.panel.completed) == (2, 1)
    with closing(store(ctl)) as st:
        trials = st.trials(subject="S02").set_index("id")
        assert trials.loc[first.trial_id, "status"] == "interrupted"
        assert trials.loc[second.trial_id, "status"] == "completed"
        assert list(trials["schedule_index"]) == [0, 0]
        sched = st.schedule(ctl.panel.session_id)
        assert int(sched["trial_id"].iloc[0]) == second.trial_id
        assert sched["trial_id"].iloc[1:].isna().all()
    # The protocol fixes the schema: free-training edits are refused.
    with pytest.raises(ConfigError, match="protocol"):
        ctl.handle(Command("schema", "vg"))


def test_f5pl_edit_runs_and_stores_the_edited_schema(ctl: TrainingController) -> None:
    run(ctl, Command("mode", "free"), Command("schema", "trajectory_following"))
    inst, p0 = f5pl_fields(load_schema("trajectory_following"))[0]
    edited = Logistic5(a=p0.a, b=p0.b, c=p0.c * 2.0, d=p0.d, g=p0.g)
    run(ctl, Command("f5pl", (inst, edited)))
    assert dict(ctl.panel.f5pl)[inst] == edited
    run(ctl, Command("task", "trajectory"), Command("start"))
    tid = ctl.info.trial_id
    run(ctl, Command("stop"))
    with closing(store(ctl)) as st:
        toml = st.trial(tid)["schema_toml"]
    assert f"c = {edited.c!r}" in toml or f"c = {edited.c}" in toml
    with pytest.raises(ConfigError, match="got 'ff', expected a fixture of schema 'vg'"):
        with_f5pl(load_schema("vg"), "ff", edited)


def test_bad_commands_leave_the_running_trial_alone(ctl: TrainingController) -> None:
    info = ctl.info
    for cmd, needle in ((Command("mode", "juggle"), "juggle"),
                        (Command("schema", "no_such_schema"), "no_such_schema"),
                        (Command("subject", "<script>alert(1)</script>"), "subject code"),
                        (Command("protocol", "nope"), "nope"),
                        (Command("launch"), "launch")):
        with pytest.raises(ConfigError, match=needle):
            ctl.handle(cmd)
    assert ctl.info is info and ctl.active()
    t = ctl.frame().t
    assert drive(ctl, lambda: ctl.frame().t > t)
    assert ctl.panel.subject is None


def test_browser_input_moves_the_tool_by_the_dragged_increment(
        ctl: TrainingController) -> None:
    ctl.speed = 1.0  # the device renders browser samples in wall time
    run(ctl, Command("mode", "free"), Command("schema", "none"), Command("input", "browser"),
        Command("start"))
    dev = ctl.browser
    assert dev is not None and ctl.info.input == "browser"
    x0 = np.array(ctl.frame().tcp)
    p = np.array([0.1, 0.2, 0.3])
    for i in range(11):  # a 2 cm drag along x at 50 Hz
        dev.push(time.perf_counter(), p + np.array([0.002 * i, 0.0, 0.0]))
        time.sleep(0.02)
    assert drive(ctl, lambda: abs(ctl.frame().tcp[0] - x0[0] - 0.02) < 1e-3)
    np.testing.assert_allclose(ctl.frame().tcp[1:], x0[1:], atol=1e-6)
    run(ctl, Command("stop"))
    with closing(store(ctl)) as st:
        row = st.trial(ctl.info.trial_id)
    assert row["operator"] == "browser" and row["status"] == "interrupted"


def test_a_failing_trial_loop_is_stored_as_interrupted_and_reported(tmp_path: Path) -> None:
    from vasim.core.errors import VasimError
    from vasim.viewer.live import SimThreadTrial

    def factory(config, device=None, *, schema=None, speed=1.0):
        trial = SimThreadTrial(config, device, schema=schema, speed=speed)
        advance, calls = trial.runner.advance, [0]

        def flaky(dt: float):
            calls[0] += 1
            if calls[0] > 5 and config.subject == "S05":
                raise FloatingPointError("solver diverged")
            return advance(dt)

        trial.runner.advance = flaky  # type: ignore[method-assign]
        return trial

    c = TrainingController(TrainingSettings(
        scene="none", db=tmp_path / "f.sqlite", speed=SPEED, trial_factory=factory))
    try:
        run(c, Command("mode", "free"), Command("subject", "S05"), Command("start"))
        tid = c.info.trial_id
        with pytest.raises(VasimError, match="solver diverged"):
            drive(c, lambda: False, timeout=10)
        assert not c.panel.running and "solver diverged" in c.panel.status
        c.poll()  # reported once; the controller stays usable
        with closing(store(c)) as st:
            row = st.trial(tid)
            assert row["status"] == "interrupted"
            assert len(st.samples(tid)) > 0  # what it recorded before failing
    finally:
        c.close()


def test_a_real_time_trial_keeps_its_recording_and_replays_identically(
        tmp_path: Path) -> None:
    from vasim.trials.realtime import replay_trial

    c = TrainingController(TrainingSettings(scene="none", db=tmp_path / "r.sqlite", speed=1.0))
    try:
        run(c, Command("mode", "free"), Command("task", "point"), Command("start"))
        tid = c.info.trial_id
        assert type(c.trial).__name__ == "RealtimeTrial"  # the 1 kHz servo loop
        assert drive(c, lambda: not c.panel.running, timeout=60), c.panel.status
    finally:
        c.close()
    with closing(TrialStore(tmp_path / "r.sqlite")) as st:
        timing = json.loads(st.trial(tid)["timing_json"])
        assert timing["achieved_hz"] > 0
        files = timing["recording"]
        assert all((tmp_path / name).exists() for name in files.values())
        report = replay_trial(st, tid)
    assert report.samples_equal and report.metrics_equal, report.differences


def test_a_stopped_real_time_trial_replays_identically(tmp_path: Path) -> None:
    """Stop mid-trial: the trial is interrupted, names its recording, and replays."""
    from vasim.trials.realtime import recorded_files, replay_trial

    c = TrainingController(TrainingSettings(scene="none", db=tmp_path / "r.sqlite", speed=1.0))
    try:
        run(c, Command("mode", "free"), Command("task", "point"), Command("start"))
        tid = c.info.trial_id
        assert drive(c, lambda: c.trial is not None and c.trial.frame().k > 300, timeout=60)
        run(c, Command("stop"))
    finally:
        c.close()
    with closing(TrialStore(tmp_path / "r.sqlite")) as st:
        row = st.trial(tid)
        assert row["status"] == "interrupted"
        files = recorded_files(st, row)
        assert files is not None and all((tmp_path / n).exists() for n in files.values())
        report = replay_trial(st, tid)
    assert report.samples_equal and report.metrics_equal, report.differences


# -- issue #20: edited schemas, labels, one trial number, outcomes, protocol locks ----------


def test_an_edited_schema_is_stored_under_its_own_name_beside_its_toml(
        ctl: TrainingController) -> None:
    from vasim.fixtures.schema import dumps_schema, parse_schema
    from vasim.viewer.condition import edited_schema_name, shipped_name

    run(ctl, Command("mode", "free"), Command("schema", "trajectory_following"))
    shipped = load_schema("trajectory_following")
    inst, p0 = f5pl_fields(shipped)[0]
    edited = Logistic5(a=p0.a, b=p0.b, c=p0.c, d=2.0, g=p0.g)   # the d = 2.0
    run(ctl, Command("f5pl", (inst, edited)), Command("start"))
    tid = ctl.info.trial_id
    name = ctl.info.schema
    assert name.startswith("trajectory_following.edited-") and len(name) == 20 + 8 + 10
    assert shipped_name(name) == "trajectory_following"
    run(ctl, Command("stop"))
    with closing(store(ctl)) as st:
        row = st.trial(tid)
    assert row["schema"] == name
    stored = parse_schema(row["schema_toml"])
    assert dict(f5pl_fields(stored))[inst].d == 2.0
    assert stored.name == name and edited_schema_name(stored) == name  # the hash reproduces
    # Another value, another name; the shipped values again: the shipped name.
    other = Logistic5(a=p0.a, b=p0.b, c=p0.c, d=2.5, g=p0.g)
    run(ctl, Command("f5pl", (inst, other)), Command("start"))
    assert ctl.info.schema.startswith("trajectory_following.edited-")
    assert ctl.info.schema != name
    run(ctl, Command("stop"), Command("f5pl", (inst, p0)), Command("start"))
    assert ctl.info.schema == "trajectory_following"
    assert dumps_schema(load_schema("trajectory_following")) == dumps_schema(shipped)


def test_a_free_practice_label_replaces_an_invented_subject(ctl: TrainingController) -> None:
    run(ctl, Command("mode", "free"))
    with pytest.raises(ConfigError, match="subject code") as exc:
        run(ctl, Command("label", "warmup"))
    assert exc.value.field == "label"
    run(ctl, Command("subject", "S03"), Command("label", "free: warm-up"))
    assert ctl.panel.label == "free: warm-up" and ctl.panel.subject is None
    run(ctl, Command("start"))
    tid = ctl.info.trial_id
    run(ctl, Command("stop"))
    with closing(store(ctl)) as st:
        row = st.trial(tid)
    assert row["label"] == "free: warm-up" and row["subject"] is None
    run(ctl, Command("subject", "S03"))
    assert ctl.panel.label is None and ctl.panel.subject == "S03"


def test_one_trial_number_and_how_the_trial_ended(ctl: TrainingController) -> None:
    assert ctl.info.title == f"demo run {ctl.info.number} (not stored)"
    run(ctl, Command("stop"))
    assert ctl.outcome == (ctl.info.number, "stopped")
    assert ctl.panel.status == f"demo run {ctl.info.number} (not stored) stopped"
    run(ctl, Command("mode", "free"), Command("subject", "S02"), Command("start"))
    tid = ctl.info.trial_id
    assert tid is not None and ctl.info.title == f"trial {tid}"
    assert ctl.outcome == (ctl.info.number, None)
    run(ctl, Command("stop"))
    assert ctl.outcome[1] == "stopped" and ctl.panel.status.startswith(f"trial {tid} stopped")
    with closing(store(ctl)) as st:
        assert st.trial(tid)["outcome"] == "stopped"


def test_a_timed_out_trial_says_so_and_gets_a_score_card(tmp_path: Path) -> None:
    c = TrainingController(TrainingSettings(
        scene="none", db=tmp_path / "s.sqlite", speed=SPEED,
        trials=TrialOptions(countdown_s=0.0, pause_s=0.05, max_time=1.0)))
    try:
        run(c, Command("mode", "free"), Command("subject", "S04"), Command("start"))
        tid = c.info.trial_id
        assert drive(c, lambda: not c.panel.running)
        assert c.outcome == (c.info.number, "timed_out")
        card = c.panel.scorecard
        assert card is not None and card.title == f"trial {tid}" and card.outcome == "timed_out"
        assert card.n_earlier == 0 and card.n_benchmark == 0
        rows = {r.name: r for r in card.rows}
        with closing(store(c)) as st:
            tm = st.trial_metrics(tid, wide=True).loc[tid]
            assert st.trial(tid)["outcome"] == "timed_out"
        assert rows["duration"].value == pytest.approx(float(tm["duration"]))
        assert rows["path_l2"].value == pytest.approx(1e3 * float(tm["path_l2"]))  # mm
        assert rows["points_reached"].value == float(tm["points_reached"]) < 30
        # A second trial compares with the first.
        run(c, Command("start"))
        assert drive(c, lambda: not c.panel.running)
        card2 = c.panel.scorecard
        assert card2 is not None and card2.n_earlier == 1
        assert {r.name: r for r in card2.rows}["duration"].earlier == pytest.approx(
            float(tm["duration"]))
    finally:
        c.close()


def test_protocol_trials_keep_the_sessions_input_and_store_the_condition(
        ctl: TrainingController) -> None:
    run(ctl, Command("mode", "protocol"), Command("input", "browser"),
        Command("subject", "S07"), Command("protocol", "vf_learning_curve"), Command("start"))
    assert ctl.info.input == "browser" and ctl.info.trial_id is not None
    tid = ctl.info.trial_id
    for cmd, field in ((Command("input", "scripted"), "input"),
                       (Command("schema", "vg"), "schema")):
        with pytest.raises(ConfigError) as exc:
            run(ctl, cmd)
        assert exc.value.field == field
    run(ctl, Command("stop"))
    # Between trials too: the session was created with the browser input.
    with pytest.raises(ConfigError, match="stored with the session"):
        run(ctl, Command("input", "laparoscopic"))
    with closing(store(ctl)) as st:
        cfg = st.trial(tid)["config"]
    assert cfg["viewer"] == {"input": "browser", "optics_deg": 0.0,
                             "mag_camera": ctl.info.fixtures.count("mag") > 0}


def test_a_person_driven_start_counts_down_first(tmp_path: Path) -> None:
    # A countdown no stall of a loaded machine can outlast between the checks (a 0.3 s one
    # could end between start and poll); then it is run out by moving its end to now.
    c = TrainingController(TrainingSettings(
        scene="none", db=tmp_path / "s.sqlite", speed=SPEED,
        trials=TrialOptions(countdown_s=600.0)))
    try:
        run(c, Command("mode", "free"), Command("input", "browser"), Command("start"))
        n = c.info.number
        assert c.countdown_until is not None and c.panel.running
        c.poll()
        assert c.info.number == n            # still counting down
        with pytest.raises(ConfigError, match="already running"):
            run(c, Command("start"))
        c.countdown_until = time.monotonic()
        assert drive(c, lambda: c.info.number == n + 1)
        assert c.countdown_until is None and c.info.input == "browser"
        run(c, Command("stop"), Command("start"), Command("stop"))   # cancelled in countdown
        assert c.countdown_until is None and not c.panel.running and c.info.number == n + 1
    finally:
        c.close()


# -- The schema menu accepts only its own entries (no file path from a client is ever read); a
# --db directory is refused at start-up.
# -- The schema menu accepts only its own entries (no file path from a client is ever read); a
# --db directory is refused at start-up.
def test_a_schema_outside_the_menu_is_refused_without_reading_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    secret = tmp_path / "notaschema.toml"
    secret.write_text('secret_token = "hunter2"\n')
    c = TrainingController(TrainingSettings(
        scene="none", db=tmp_path / "s.sqlite", speed=25.0,
        trials=TrialOptions(countdown_s=0.0, max_time=20.0)))
    try:
        c.handle(Command("mode", "free"))
        read: list[str] = []
        real = controller_mod.load_schema

        def spy(name: Any, *a: Any, **k: Any) -> Any:
            read.append(str(name))
            return real(name, *a, **k)

        monkeypatch.setattr(controller_mod, "load_schema", spy)
        before = c.panel.schema
        for value in (str(secret), "/etc/passwd", "/nonexistent/x.toml", "x" * 500):
            with pytest.raises(ConfigError) as exc:
                c.handle(Command("schema", value))
            msg = str(exc.value)
            assert "hunter2" not in msg and "unknown schema" in msg
            assert value[:40] in msg and len(msg) < 200
        assert read == [] and c.panel.schema == before
        # Menu entries still work.
        assert "vg" in schema_choices(before)
        c.handle(Command("schema", "vg"))
        assert c.panel.schema == "vg"
    finally:
        c.close()


def test_a_schema_file_given_at_start_up_stays_selectable(tmp_path: Path) -> None:
    own = tmp_path / "own.toml"
    shutil.copy(schema_path("trajectory_following"), own)
    c = TrainingController(TrainingSettings(
        scene="none", db=tmp_path / "s.sqlite", speed=25.0,
        trials=TrialOptions(countdown_s=0.0, schema=str(own), max_time=20.0)))
    try:
        assert str(own) in schema_choices(str(own))
        c.handle(Command("mode", "free"))
        c.handle(Command("schema", "vg"))
        c.handle(Command("schema", str(own)))  # the menu offers it: accepted
        assert c.panel.schema == str(own)
    finally:
        c.close()


def test_a_db_directory_is_refused_at_start_up(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ConfigError, match="is a directory"):
        TrainingController(TrainingSettings(scene="none", db=tmp_path))
    code = main(["serve", "--db", str(tmp_path), "--scene", "none", "--port", "0",
                 "--duration", "0"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("vasim serve: error:")
    assert "is a directory" in err and str(tmp_path) in err


def test_a_protocol_trial_shows_its_own_condition_and_schedule_name(
        ctl: TrainingController) -> None:
    """Issue #26 §5-6: the greyed f5PL editor shows the running trial's schema (not the
    free-training one), both pages name it "trial k of N", and free training gets its own
    schema's curves back."""
    free = f5pl_fields(load_schema(ctl.panel.schema))
    assert free                                            # trajectory_following: 4 curves
    run(ctl, Command("mode", "protocol"), Command("subject", "S05"),
        Command("protocol", "vf_point_targeting"))
    ctl.speed = 1.0
    run(ctl, Command("start"))
    assert ctl.info.title == "trial 1 of 27" and ctl.panel.position == 1
    assert ctl.panel.f5pl == f5pl_fields(load_schema(ctl.info.config.schema))
    assert ctl.panel.f5pl != free
    run(ctl, Command("stop"), Command("mode", "free"))
    assert ctl.panel.f5pl == free
