"""The viewer's MRCP panel (issue 6, MRCP bullet): a scripted slave-station scenario served
live — the robots as posed link hulls, who holds the task, NTT / texec / tus plots and the
transfer log — checked through the Python API with a viser server on port 0.

The module's app runs the runner's coarse (36 ms) cycle in real time: cube_rotation's
hand-over (R1 -> R0 at 6.3 s, seed Fig. 4.27; see tests/mrcp/test_scen_cube_rotation) comes
6 s after the start, well after the first tests have seen R1 holding the cube. The other
apps run as fast as the machine allows (speed 50).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator
from dataclasses import replace
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from tests.polling import WAIT_S, wait_for
from tests.viewer.lighting_state import environment_maps
from vasim.cli import main
from vasim.core.errors import ConfigError
from vasim.mrcp.scenarios import ScenarioOptions, get_scenario
from vasim.viewer import ViewerApp
from vasim.viewer.mrcp_panel import (
    History,
    MrcpPace,
    MrcpViewerApp,
    event_log_text,
    plot_value,
    resolve_scenario,
    scenario_from_scene,
    status_text,
)
from vasim.viewer.mrcp_view import (
    StationFrame,
    holder_text,
    link_poses,
    pose7,
    robot_role,
    station_frame,
    station_geometry,
    task_pose,
)


@pytest.fixture(scope="module")
def app() -> Iterator[MrcpViewerApp]:
    a = MrcpViewerApp(port=0, scenario="mrcp:cube_rotation", coarse=True,
                      pace=MrcpPace(speed=1.0, view_hz=30.0, plot_hz=10.0)).start()
    try:
        yield a
    finally:
        a.stop()


def link_state(app: MrcpViewerApp, robot: str, k: int) -> np.ndarray:
    h = app.station.links[robot][k]  # type: ignore[union-attr]
    return np.r_[np.asarray(h.position, float), np.asarray(h.wxyz, float)]


# -- the app --------------------------------------------------------------------------------
def test_scene_nodes_exist_for_every_robot_link_obstacle_and_the_task(
        app: MrcpViewerApp) -> None:
    nodes = set(app.scene_nodes())
    for r in ("R0", "R1"):  # the RX60B: base link + 6 links
        assert {f"/mrcp/robots/{r}/link{k}" for k in range(7)} <= nodes
        assert f"/mrcp/robots/{r}/label" in nodes
    assert {"/mrcp/obstacles/view_cone", "/mrcp/task/body", "/mrcp/task/points",
            "/mrcp/task/holder"} <= nodes
    # The meshes are the link hulls the collision world uses (uploaded once).
    from vasim.mrcp.dh import load_robot
    from vasim.mrcp.urdf import link_hulls

    hull = link_hulls(load_robot("rx60b"))[3]
    assert np.allclose(app.station.links["R0"][3].vertices, hull.vertices, atol=1e-6)  # type: ignore[union-attr]


def test_robots_move_over_cycles(app: MrcpViewerApp) -> None:
    # Bounds on conditions, not timing goals (WAIT_S): the first cycle took over 30 s at
    # load 6 on 2 cores (issue #31's stress run)
    assert wait_for(lambda: app.live.latest() is not None and app.view_updates > 0, WAIT_S)
    before = {r: link_state(app, r, 6) for r in ("R0", "R1")}
    seq = app.live.latest().seq  # type: ignore[union-attr]
    assert wait_for(lambda: app.live.latest().seq > seq + 20, WAIT_S)  # type: ignore[union-attr]
    assert wait_for(lambda: any(not np.allclose(link_state(app, r, 6), before[r], atol=1e-6)
                                for r in ("R0", "R1")), WAIT_S)
    # R1 holds the turning cube: its wrist link turns with it.
    assert wait_for(lambda: not np.allclose(link_state(app, "R1", 6), before["R1"],
                                            atol=1e-4), WAIT_S)


def test_holder_label_changes_at_the_transfer(app: MrcpViewerApp) -> None:
    seen: list[str] = []

    def transferred() -> bool:
        text = app.station.holder.text  # type: ignore[union-attr]
        if not seen or seen[-1] != text:
            seen.append(text)
        return text.startswith("task: R0")

    assert wait_for(transferred, WAIT_S, step=0.01), (seen, app.errors)
    # The first holder shown is R1 (before the first cycle is drawn, a loaded host shows
    # the label's initial "task": issue #31's stress run)
    held = [text for text in seen if text != "task"]
    assert held[0].startswith("task: R1 @ point 0"), seen
    # The new holder is coloured and labelled as RSel, the old one as waiting.
    assert wait_for(lambda: app.station.labels["R0"].text == "R0: holds the task", WAIT_S)  # type: ignore[union-attr]
    assert tuple(app.station.links["R0"][0].color) == (235, 120, 30)  # type: ignore[union-attr]
    assert app.station.labels["R1"].text in ("R1: waiting", "R1: grasping (hand-over)")  # type: ignore[union-attr]


def test_plots_and_event_log_receive_data(app: MrcpViewerApp) -> None:
    assert wait_for(lambda: any(tr["t_done"] for tr in app.live.history().transfers))
    app.render(force_plots=True)
    panel = app.panel
    assert panel is not None
    t, ntt, thr, tt = panel.ntt.data
    assert len(t) > 20 and np.all(np.diff(t) > 0)
    assert np.allclose(thr, 0.9)
    # The hand-over (TT, 6.30-6.55 s) is shaded: its first cycle is the one whose NTT
    # crossed the threshold, the next ones are not evaluated (NaN).
    in_tt = tt > 0
    assert in_tt.any() and ntt[in_tt][0] >= 0.9 and np.all(np.isnan(ntt[in_tt][1:]))
    assert np.all((t[in_tt] > 6.2) & (t[in_tt] < 6.7))
    assert np.nanmax(ntt) >= 0.9  # the transfer started when NTT crossed the threshold
    tex = panel.texec.data
    assert len(tex) == 3 and all(len(a) == len(t) for a in tex)
    assert np.isfinite(tex[1]).any() and np.isfinite(tex[2]).any()
    tus = panel.tus.data
    assert np.nanmax(tus[1]) >= 0 and np.isfinite(tus[2]).any()
    log = panel.log.content
    assert "R1 → R0 @ 4" in log and "| rj |" in log  # the seed's cause: R1's joint limit
    assert "transfer_done" in log
    assert "holds the task: **R0**" in panel.status.content or \
        "holds the task: **R1**" in panel.status.content


def test_finished_run_loops() -> None:
    with MrcpViewerApp(port=0, scenario="cube_rotation", coarse=True, duration=0.4,
                       pace=MrcpPace(speed=50.0)) as a:
        assert wait_for(lambda: a.live.run >= 2), a.errors
        assert a.alive() and not a.errors


class FailingScenario:
    """cube_rotation whose operator raises after 0.2 s: a failing cycle."""

    name = "failing_cube"
    duration = 10.0

    def build(self, options: ScenarioOptions) -> Any:
        setup = get_scenario("cube_rotation").build(options)
        op = setup.operator

        def operator(t: float) -> Any:
            if t > 0.2:
                raise RuntimeError("scripted failure")
            return op(t)

        return replace(setup, operator=operator)


def test_failing_cycle_is_notified_logged_and_restarts(caplog: pytest.LogCaptureFixture
                                                       ) -> None:
    caplog.set_level(logging.ERROR, logger="vasim.viewer.mrcp_panel")
    with MrcpViewerApp(port=0, scenario=FailingScenario(), coarse=True,
                       pace=MrcpPace(speed=50.0, retry_s=0.05)) as a:
        assert wait_for(lambda: a.live.failures >= 2)
        assert a.alive()  # the app survives and the scenario restarts
        assert "scripted failure" in a.errors[0] and "restarting" in a.errors[0]
        assert any("failing_cube" in r.getMessage() for r in caplog.records)


def test_unknown_scenario_is_a_clear_error_before_any_socket() -> None:
    with pytest.raises(ConfigError,
                       match=r"got 'nope', expected an MRCP scenario: one of .*mrcp:cube_rotation"):
        MrcpViewerApp(port=0, scenario="mrcp:nope")
    with pytest.raises(ConfigError, match="MrcpViewerApp"):
        ViewerApp(port=0, scene="mrcp:cube_rotation")
    with pytest.raises(ConfigError, match="speed"):
        MrcpViewerApp(port=0, pace=MrcpPace(speed=0.0))


def test_vasim_serve_mrcp(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["serve", "--port", "0", "--scene", "mrcp:faucet", "--mrcp-coarse",
                 "--duration", "0.5"]) == 0
    assert "MRCP scenario faucet" in capsys.readouterr().out
    assert main(["serve", "--port", "0", "--scene", "mrcp:nope"]) == 2
    err = capsys.readouterr().err
    assert "got 'nope', expected an MRCP scenario: one of" in err and "mrcp:obstacle_hole" in err
    with pytest.raises(SystemExit):
        main(["serve", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    from vasim.mrcp.scenarios import SCENARIOS

    assert all(f"mrcp:{name}" in out for name in SCENARIOS)


# -- pure parts -----------------------------------------------------------------------------
@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3),
       st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3))
def test_pose7_round_trips(rotvec: list[float], pos: list[float]) -> None:
    m = np.eye(4)
    m[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    m[:3, 3] = pos
    p = pose7(m)
    assert np.isclose(np.linalg.norm(p[3:]), 1.0)
    back = Rotation.from_quat(np.r_[p[4:], p[3]]).as_matrix()
    assert np.allclose(back, m[:3, :3], atol=1e-9) and np.allclose(p[:3], pos)


def test_link_poses_match_the_compiled_forward_kinematics() -> None:
    from vasim.mrcp.dh import fk, load_robot

    robot = load_robot("rx60b")
    base = np.eye(4)
    base[:3, 3] = [0.5, 0.0, 0.0]
    base[:3, :3] = Rotation.from_euler("z", np.pi).as_matrix()
    q = np.array([0.3, -0.5, 1.2, 0.4, 0.8, -1.0])
    poses = link_poses(robot, base, q)
    assert poses.shape == (7, 7)
    assert np.allclose(poses[0], pose7(base))
    tcp, rot = fk(robot, q, base)  # TCP = link 6 frame + the model's TCP offset
    r6 = Rotation.from_quat(np.r_[poses[6, 4:], poses[6, 3]]).as_matrix()
    assert np.allclose(poses[6, :3] + r6 @ robot.tcp, tcp, atol=1e-9)
    assert np.allclose(r6, rot, atol=1e-9)


def test_station_frame_poses_every_robot_as_link_poses_does() -> None:
    # the per-cycle frame takes the compiled chain and one quaternion call for all robots
    setup = get_scenario("eight_robots").build(ScenarioOptions(coarse=True))
    try:
        g = station_geometry("eight_robots", setup)
        sample = SimpleNamespace(task_position=np.array([0.0, 0.0, 0.05]), task_rotation=None,
                                 rsel="R0", cutp=0, holders=("R0",), rcnt=None, state="TOp")
        frame = station_frame(g, setup.world, sample)
        assert sorted(frame.links) == [f"R{i}" for i in range(8)]
        for r in g.robots:
            expected = link_poses(r.model, r.base, setup.world.configuration(r.name))
            np.testing.assert_allclose(frame.links[r.name], expected, atol=1e-12)
    finally:
        setup.close()


def test_station_geometry_reads_obstacles_as_pybullet_holds_them() -> None:
    setup = get_scenario("cube_translation").build(ScenarioOptions(coarse=True))
    try:
        g = station_geometry("cube_translation", setup)
    finally:
        setup.close()
    assert g.robot_names == ("R0", "R1") and all(r.in_task for r in g.robots)
    table = {o.name: o for o in g.obstacles}["table"]
    assert np.allclose(table.mesh.extents, [0.44, 0.80, 0.04])  # half extents 0.22/0.40/0.02
    assert np.allclose(g.task.extents, [0.10] * 3)  # the 100 mm cube
    assert g.task_points.shape == (6, 3)


def test_laparoscopic_station_draws_the_camera_robot_outside_the_task() -> None:
    setup = get_scenario("laparoscopic_rings").build(ScenarioOptions(coarse=True))
    try:
        g = station_geometry("laparoscopic_rings", setup)
    finally:
        setup.close()
    roles = {r.name: r.in_task for r in g.robots}
    assert roles == {"R0": True, "R1": True, "C": False}
    # the tool model: the last link's hull reaches the tool tip (35 cm tool)
    assert g.robots[0].hulls[-1].extents.max() > 0.3
    assert sum(o.name.startswith("ring_") for o in g.obstacles) == 8


def test_roles_and_holder_text() -> None:
    f = StationFrame({}, {}, task_pose(np.zeros(3), None), "R1", 0, ("R1", "R0"), "R0", "TT")
    assert robot_role("R1", f, True) == "rsel"
    assert robot_role("R0", f, True) == "holder"
    assert robot_role("C", f, False) == "other"
    g = replace(f, holders=("R1",))
    assert robot_role("R0", g, True) == "rcnt" and robot_role("R2", g, True) == "idle"
    assert holder_text(f) == "task: R1 @ point 0 → R0"
    assert holder_text(replace(f, rcnt=None)) == "task: R1 @ point 0"


def test_plot_values_and_texts() -> None:
    assert plot_value(math.inf, 1.5) == 1.5 and math.isnan(plot_value(-math.inf, 1.5))
    assert plot_value(-math.inf, bottom=-1.0) == -1.0 and plot_value(7.0, 1.5, -1.0) == 1.5
    assert math.isnan(plot_value(math.nan, 1.5))
    assert scenario_from_scene("mrcp:faucet") == "faucet"
    assert scenario_from_scene("default") is None
    assert resolve_scenario("faucet").name == "faucet"
    h = History(1, np.zeros(0), np.zeros(0), {}, {},
                ((1.0, "transfer_start R0@1 (ntt=0.95, cause=<b>cr</b>)"),),
                ({"t_start": 1.0, "from": "R1", "to": "R0", "point": 1, "ntt": 0.95,
                  "cause": "<b>cr</b>", "t_done": None},))
    text = event_log_text(h)
    assert "<b>" not in text and "&lt;b&gt;cr&lt;/b&gt;" in text  # markdown is not sanitised
    assert "| 1.00 | R1 → R0 @ 1 |" in text and "| — |" in text
    assert "building" in status_text("x", None, 1.0)


def test_a_safety_stop_is_shown_with_its_cause_and_the_scenario_restarts() -> None:
    """Issue #26 §4: the panel names the stop's cause (not only "mode fault"), the event log
    keeps it (no "fault: no motion" flood), and the next run starts after the pause."""
    from tests.mrcp.colliding import CollidingScenario

    with MrcpViewerApp(port=0, scenario=CollidingScenario(), coarse=True,
                       pace=MrcpPace(speed=20.0, stop_pause_s=0.5)) as a:
        assert wait_for(lambda: a.live.stopped is not None), a.errors
        assert wait_for(lambda: "safety stop" in a.panel.status.content)  # type: ignore[union-attr]
        status = a.panel.status.content  # type: ignore[union-attr]
        assert "rsel_collision R1" in status and "nearest body ball" in status
        assert wait_for(lambda: a.live.run >= 2)
        assert not a.errors and a.alive()
        h = a.live.history()
        assert not [e for _, e in h.events if e.startswith("fault:")]


def test_the_station_page_draws_without_viser_s_environment_map(app) -> None:
    """Issue #26.2 (``vasim.viewer.lighting``): the MRCP page is lit like the
    experimenter's, without the map a software-drawn frame paid most for."""
    assert app.server is not None
    maps = environment_maps(app.server)
    assert len(maps) == 1 and maps[0].hdri_data is None
