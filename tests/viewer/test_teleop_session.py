"""Teleoperation sessions a person runs in the viewer (issue #28; vasim.viewer.teleop_live):
the page's device drives the station's master, and a protocol's stdt / mrcp trials are
stored through the controller like simulated ones, then the questionnaire, then
``vasim report`` on a store that mixes them.

Justified numbers: a device moved at a constant 2 cm/s for 55 cycles of 18 ms moves the
master 19.8 mm; in MRCP (TOp, no transfer this early) the kernel applies the master's
increments to the needle and in StdT the held instrument carries it, so the needle moves
by the same vector (the kernel's and the IK's residuals are far below 1 µm here). A
browser device whose samples stop extrapolates at most one sample step (its policy,
``vasim.haptics.devices.browser``): 2 cm/s x 18 ms = 0.36 mm. The scripted hand of the
same trial moves the needle by about 1 cm in its first second; a person's trial without
input must not move it at all.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import closing
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tests.study.tiny_protocols import install
from tests.viewer.driving import drive
from vasim.core.errors import ConfigError, InputError
from vasim.haptics.devices.browser import BrowserDevice
from vasim.study.protocol import load_protocol
from vasim.study.report import build_report
from vasim.study.session import run_session, start_session
from vasim.study.store import TrialStore
from vasim.trials.configs import TeleopTrialConfig
from vasim.trials.teleop import CAMERA_ZOOM, CYCLE_DT, TeleopTrial
from vasim.trials.vf import TrialConfig
from vasim.viewer.app_options import TrialOptions
from vasim.viewer.controller import Command, TrainingController, TrainingSettings
from vasim.viewer.questionnaire_form import answers_template
from vasim.viewer.teleop_live import LiveTeleopTrial, person_config


def teleop_protocol(name: str, max_time: float, modes: tuple[str, ...],
                    question: bool = True, repetitions: int = 1) -> str:
    """A tiny teleoperation protocol: ``repetitions`` trials per mode, the modes in this
    order, ``max_time`` [s] each, and (``question``) a post questionnaire of one item."""
    blocks = "".join(f'\n[[blocks]]\nname = "{m}"\ncondition = "{m}"\n'
                     f'repetitions = {repetitions}\n' for m in modes)
    post = ('\n[[questionnaires.post.items]]\nid = "best_mode"\ntype = "condition_choice"'
            '\nselect = "best"\nprompt = "Which mode did you prefer?"\n') if question else ""
    return (f'name = "{name}"\ndescription = "tiny teleoperation protocol"\n'
            f'task = "point"\nmax_trial_time_s = {max_time}\n\n[randomisation]\n'
            'block_order = "fixed"\nvariant_order = "fixed"\n' + blocks + post)


TELEOP_TINY = teleop_protocol("teleop_tiny", 0.5, ("mrcp", "stdt"))
"""One MRCP and one StdT trial of half a second, then the post questionnaire."""

STEP = 0.02 * CYCLE_DT   # the device's displacement per cycle [m]


def drag_toward_ring(mode: str, cycles: int) -> tuple[LiveTeleopTrial, np.ndarray, np.ndarray,
                                                         list[float]]:
    """A person's trial of ``mode`` (no tissue) whose device moves at 2 cm/s toward the
    first ring for ``cycles`` cycles; returns the trial, the needle's start, the device's
    unit direction and the fake clock."""
    now = [0.0]
    dev = BrowserDevice(delay_s=0.0, clock=lambda: now[0])
    lt = LiveTeleopTrial(person_config(TeleopTrialConfig(mode=mode, seed=1, max_time=3.0,
                                                   scene="none")), dev)
    dev.start()
    x0 = np.array(lt.trial.state.needle)
    u = np.array(lt.trial.state.rings[0]) - x0
    u /= np.linalg.norm(u)
    p0 = np.array([0.1, 0.2, 0.3])
    for k in range(cycles):
        now[0] = k * CYCLE_DT
        dev.push(now[0], p0 + u * STEP * k)
        assert lt.advance(1) == 1
    return lt, x0, u, now


@pytest.mark.parametrize("mode", ["mrcp", "stdt", "mrcp_cam"])
def test_the_person_s_device_moves_the_needle(mode: str) -> None:
    lt, x0, u, now = drag_toward_ring(mode, 56)
    try:
        moved = np.array(lt.trial.state.needle) - x0
        np.testing.assert_allclose(moved, u * STEP * 55, atol=1e-6)
        assert np.array_equal(lt.frame().tcp, lt.trial.state.needle) and lt.frame().k == 55
        camera = lt.frame().outputs.camera   # mrcp_cam: the camera robot's aim, for the scope
        if mode == "mrcp_cam":
            assert camera is not None and camera.zoom == pytest.approx(CAMERA_ZOOM)
            np.testing.assert_array_equal(camera.look_at, lt.trial.camera.aim)
        else:
            assert camera is None
        before = np.array(lt.trial.state.needle)
        for k in range(56, 112):     # the samples stop: at most one step of extrapolation
            now[0] = k * CYCLE_DT
            lt.advance(1)
        drift = float(np.linalg.norm(np.array(lt.trial.state.needle) - before))
        assert drift == pytest.approx(STEP, abs=1e-6)
    finally:
        lt.stop()
    res = lt.result()
    assert res.summary["mode"] == mode and res.summary["outcome"] == "stopped"
    assert res.trial_metrics["path_l2"] == pytest.approx(STEP * 56, rel=1e-6)


def test_without_input_the_needle_stays_where_the_scripted_hand_would_move_it() -> None:
    cfg = TeleopTrialConfig(mode="mrcp", seed=1, max_time=1.0, scene="none")
    scripted = TeleopTrial(cfg)
    try:
        x0 = np.array(scripted.state.needle)
        for _ in scripted.cycles():
            pass
        assert np.linalg.norm(np.array(scripted.state.needle) - x0) > 5e-3
    finally:
        scripted.station.close()
    dev = BrowserDevice(delay_s=0.0, clock=lambda: 0.0)
    lt = LiveTeleopTrial(person_config(cfg), dev)
    dev.start()
    try:
        assert lt.advance(1000) == 56 and lt.done   # 1 s of 18 ms cycles, then done
        np.testing.assert_array_equal(lt.trial.state.needle, x0)
    finally:
        lt.stop()
    assert lt.result().summary["outcome"] == "timed_out"


def test_a_person_s_trial_has_no_simulated_jaw_misjudgement() -> None:
    cfg = person_config(TeleopTrialConfig(mode="stdt", seed=1, skill="novice"))
    assert cfg.profile is not None and cfg.profile.perception_noise == 0.0
    from vasim.operator.needle import grasp_sigma

    assert grasp_sigma(cfg.profile, 0) == 0.0
    with pytest.raises(ConfigError, match="teleoperation mode"):
        LiveTeleopTrial(TrialConfig(), None)


# -- a session through the controller -----------------------------------------------------
@pytest.fixture
def ctl(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[TrainingController]:
    install(monkeypatch, tmp_path / "protocols", teleop_tiny=TELEOP_TINY,
            teleop_twice=teleop_protocol("teleop_twice", 0.3, ("mrcp", "stdt"),
                                         question=False, repetitions=2))
    with closing(TrainingController(TrainingSettings(
        scene="none", db=tmp_path / "s.sqlite", speed=4.0,
        trials=TrialOptions(countdown_s=0.0, pause_s=0.05)))) as c:
        yield c


def test_a_teleop_session_runs_stores_its_trials_and_its_questionnaire(
        ctl: TrainingController, tmp_path: Path) -> None:
    for cmd in (Command("mode", "protocol"), Command("input", "browser"),
                Command("subject", "S01"), Command("protocol", "teleop_tiny"),
                Command("auto_advance", True), Command("start")):
        ctl.handle(cmd)
    assert ctl.info.condition == "mrcp" and ctl.info.task_name == "needle"
    assert ctl.browser is not None            # the page's gizmo feeds this trial
    assert len(ctl.info.points) == ctl.frame().n_points == 6
    assert drive(ctl, lambda: ctl.panel.completed == 2 and not ctl.panel.running,
                 timeout=120)
    assert "session 1 is complete" in ctl.panel.status
    with closing(TrialStore(ctl.db, readonly=True)) as st:  # type: ignore[arg-type]
        trials = st.trials().sort_values("id")
        assert list(trials["task"]) == ["needle", "needle"]
        assert list(trials["operator"]) == ["browser", "browser"]
        assert list(trials["schedule_index"]) == [0, 1]
        assert list(trials["status"]) == ["completed", "completed"]
        assert list(trials["outcome"]) == ["timed_out", "timed_out"]  # nobody moved
        cfgs = [st.trial(int(i))["config"] for i in trials["id"]]
        assert [c["mode"] for c in cfgs] == ["mrcp", "stdt"]
        assert all(c["viewer"]["input"] == "browser" and c["operator"] == "browser"
                   and c["profile"]["perception_noise"] == 0.0 for c in cfgs)
        m = st.trial_metrics(int(trials["id"].iloc[0])).set_index("metric")["value"]
        for name in ("duration", "path_l2", "contact_time", "accumulated_force",
                     "accumulated_torque", "transfers", "master_path_l2"):
            assert name in m.index
        assert m["path_l2"] == 0.0 and m["duration"] == pytest.approx(0.504)
        sched = st.schedule(1)
        assert list(sched["trial_id"]) == list(trials["id"])
        assert st.session(1)["status"] == "completed"
    # The post questionnaire: the form's template, a bad answer refused, a good one stored.
    text = answers_template(load_protocol("teleop_tiny"), "post")
    assert 'best_mode = ""' in text
    with pytest.raises(InputError, match="best_mode"):   # answers are input data
        ctl.handle(Command("answers", ("post", text)))
    assert "not recorded" in ctl.panel.status
    ctl.handle(Command("answers", ("post", text.replace('best_mode = ""',
                                                        'best_mode = "mrcp"'))))
    assert ctl.panel.status == "post questionnaire of session 1 recorded (1 answer rows)"
    with closing(TrialStore(ctl.db, readonly=True)) as st:  # type: ignore[arg-type]
        answers = st.answers()
    assert answers[["item", "value"]].values.tolist() == [["best_mode", "mrcp"]]
    # A simulated session of the same protocol in the same store: vasim report reads both.
    with closing(TrialStore(ctl.db)) as st:  # type: ignore[arg-type]
        sid = start_session(st, load_protocol("teleop_tiny"), "S02", seed=3)
        run_session(st, sid, progress=False)
    build_report(ctl.db, tmp_path / "report", protocol="teleop_tiny", progress=False)
    trials_csv = pd.read_csv(tmp_path / "report" / "tables" / "mrcp_trials.csv")
    assert sorted(trials_csv["subject"]) == ["S01", "S01", "S02", "S02"]
    assert set(trials_csv["mode"]) == {"MRCP", "StdT"}


def test_bad_answers_commands_are_refused_with_the_field(ctl: TrainingController) -> None:
    with pytest.raises(ConfigError, match="protocol mode"):
        ctl.handle(Command("answers", ("post", "")))
    ctl.handle(Command("mode", "protocol"))
    with pytest.raises(ConfigError) as exc:
        ctl.handle(Command("answers", ("during", "")))
    assert exc.value.field == "answers"
    ctl.handle(Command("subject", "S03"))
    ctl.handle(Command("protocol", "teleop_tiny"))
    with pytest.raises(ConfigError, match="invalid TOML"):
        ctl.handle(Command("answers", ("post", "best_mode = ")))
    assert ctl.panel.status.startswith("post questionnaire not recorded: ")
    with closing(TrialStore(ctl.db, readonly=True)) as st:  # type: ignore[arg-type]
        assert st.sessions().empty    # a refused answer opens no session


def test_the_pre_template_filled_in_records_the_demographics(ctl: TrainingController) -> None:
    from vasim.study.store import DEMOGRAPHIC_FIELDS

    for cmd in (Command("mode", "protocol"), Command("subject", "S04"),
                Command("protocol", "mrcp_suture_dynamic")):
        ctl.handle(cmd)
    text = answers_template(load_protocol("mrcp_suture_dynamic"), "pre")
    for name, allowed in DEMOGRAPHIC_FIELDS.items():   # the first allowed value of each
        text = text.replace(f'{name} = ""', f'{name} = "{allowed[0]}"')
    ctl.handle(Command("answers", ("pre", text)))
    with closing(TrialStore(ctl.db, readonly=True)) as st:  # type: ignore[arg-type]
        sessions = st.sessions()
        demo = st.demographics()
    # No session was open: answering the pre questionnaire opened the subject's first one.
    assert sessions[["subject", "protocol", "status"]].values.tolist() == [
        ["S04", "mrcp_suture_dynamic", "running"]]
    row = demo.set_index("subject").loc["S04"]
    column = {"group": "subject_group"}   # the store's column of the "group" field
    assert {k: row[column.get(k, k)] for k in DEMOGRAPHIC_FIELDS} == {
        k: v[0] for k, v in DEMOGRAPHIC_FIELDS.items()}


def test_the_score_card_compares_earlier_trials_of_the_same_mode(
        ctl: TrainingController) -> None:
    for cmd in (Command("mode", "protocol"), Command("input", "browser"),
                Command("subject", "S05"), Command("protocol", "teleop_twice"),
                Command("auto_advance", True), Command("start")):
        ctl.handle(cmd)
    seen: dict[int, int] = {}    # schedule index -> earlier trials on its score card

    def collect() -> bool:
        card, i = ctl.panel.scorecard, ctl.info.schedule_index
        if card is not None and not ctl.panel.running and i is not None:
            seen[i] = card.n_earlier
        return len(seen) == 4
    assert drive(ctl, collect, timeout=180), (seen, ctl.panel.status)
    # mrcp, mrcp, stdt, stdt: the second of each mode has the first as its earlier trial
    assert seen == {0: 0, 1: 1, 2: 0, 3: 1}
