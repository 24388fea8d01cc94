"""The viewer through its Python API (no browser; browser tests come with the full viewer):
the server serves the page, the scene nodes exist, the trial runs in real time, commands
change the schema/task, errors do not kill it, and stop() ends every thread."""

from __future__ import annotations

import argparse
import dataclasses
import socket
import subprocess
import sys
import time
import urllib.request
from types import SimpleNamespace
from typing import ClassVar

import numpy as np
import pytest

from tests.polling import wait_for, wait_until
from tests.viewer.lighting_state import environment_maps, state_messages
from vasim.cli import main
from vasim.cli import viewer as viewer_cli
from vasim.core.errors import ConfigError, InputError
from vasim.core.geometry import matrix_z_to, quat_z_to
from vasim.fixtures.types import Arrow, AudioCue, CameraView
from vasim.viewer import CameraController, CameraPose, TrialOptions, ViewerApp
from vasim.viewer.trainee import audio_text, hud_markdown
from vasim.viewer.views import (
    arrow_mesh,
    arrow_vertices,
)


@pytest.fixture(scope="module")
def app():
    a = ViewerApp(port=0, trials=TrialOptions(schema="trajectory_following", seed=1)).start()
    try:
        assert wait_for(lambda: a.stats()["view_updates"] >= 5)
        yield a
    finally:
        a.stop()


def use_schema(app: ViewerApp, name: str) -> None:
    app.request_schema(name)
    assert wait_for(lambda: app.snapshot.info.schema == name
                    and app._shown is app.snapshot.info), name


# -- the running app ------------------------------------------------------------------


def test_serves_the_page_on_loopback(app: ViewerApp) -> None:
    assert app.url == f"http://127.0.0.1:{app.port}/"
    assert app.port != 0
    with urllib.request.urlopen(app.url, timeout=5) as resp:
        assert resp.status == 200
        assert b"<html" in resp.read(4096).lower()


def test_scene_nodes_exist(app: ViewerApp) -> None:
    nodes = set(app.scene_nodes())
    for name in ("liver", "stomach", "vessel", "abdominal_wall", "intestine_0"):
        assert f"/organs/{name}" in nodes
    assert {"/tool/shaft", "/tool/tip", "/trajectory/points", "/trajectory/path",
            "/trajectory/goal", "/overlays/arrow_0", "/overlays/ghost"} <= nodes
    # The views' handles are registered on the server itself.
    registry = app.server.scene._handle_from_node_name  # private: no public listing
    assert nodes <= set(registry)


def test_trial_runs_in_real_time_and_the_tool_moves(app: ViewerApp) -> None:
    use_schema(app, "trajectory_following")
    p0 = np.array(app.tool.tip.position)
    t0, w0 = app.snapshot.frame.t, time.monotonic()
    # at least a 0.6 s window (for the pacing ratio), and until the tool has moved
    wait_until(lambda: time.monotonic() - w0 >= 0.6
               and np.linalg.norm(np.array(app.tool.tip.position) - p0) > 1e-4,
               what="the tool to move", timeout=30.0, step=0.05)
    p1 = np.array(app.tool.tip.position)
    t1, w1 = app.snapshot.frame.t, time.monotonic()
    assert np.linalg.norm(p1 - p0) > 1e-4
    np.testing.assert_allclose(p1, app.snapshot.frame.tcp, atol=0.01)  # views follow
    # Paced by the wall clock: never faster than real time (how close to 1.0 it gets on a
    # loaded machine is a benchmark figure, not a unit-test assertion).
    assert 0.0 < (t1 - t0) / (w1 - w0) < 1.1
    assert app.alive()


def test_vg_and_ff_schema_draws_both_arrows_and_the_ghost(app: ViewerApp) -> None:
    use_schema(app, "trajectory_following")
    seen: set[str] = set()

    def both() -> bool:
        seen.update(app.arrows.kinds)
        return {"guidance", "force"} <= seen

    assert wait_for(both), seen
    assert wait_for(lambda: app.ghost.handle.visible)
    text = app.hud.text
    assert "Points reached" in text and "From the path" in text and "To the next point" in text
    # The condition's internals stay on the experimenter's page (issue #19 §4).
    assert "trajectory_following" not in text and "Audio (AG)" not in text
    assert "MS factors" not in text and "Zoom" not in text


def test_schema_change_through_the_queue_takes_effect(app: ViewerApp) -> None:
    use_schema(app, "trajectory_following")
    n = app.snapshot.info.number
    use_schema(app, "vg")
    assert app.snapshot.info.number == n + 1
    assert app.snapshot.info.fixtures == ("vg",)
    assert app.panel_view.schema.value == "vg"
    assert wait_for(lambda: not app.ghost.handle.visible and "force" not in app.arrows.kinds)
    # The GUI path: the dropdown's callback only queues a command.
    app.panel_view.schema.value = "ff"
    assert wait_for(lambda: app.snapshot.info.schema == "ff")
    assert wait_for(lambda: "guidance" not in app.arrows.kinds)


def test_point_schema_switches_the_task_and_back(app: ViewerApp) -> None:
    use_schema(app, "point_targeting")
    info = app.snapshot.info
    assert info.config.task == "point" and len(info.points) == 1
    assert wait_for(lambda: app.panel_view.task.value == "point")
    assert "/trajectory/normal" in app.scene_nodes()
    assert "/trajectory/path" not in app.scene_nodes()
    app.request_task("trajectory")  # point_targeting does not fit: falls back
    assert wait_for(lambda: app.snapshot.info.config.task == "trajectory")
    assert app.snapshot.info.schema == "trajectory_following"


def test_restart_and_bad_commands_do_not_kill_the_app(app: ViewerApp) -> None:
    n = app.snapshot.info.number
    app.request_restart()
    assert wait_for(lambda: app.snapshot.info.number == n + 1)
    errors = len(app.errors)
    app.request_schema("no_such_schema")
    app.request_task("juggling")
    assert wait_for(lambda: len(app.errors) >= errors + 2)
    assert "no_such_schema" in app.errors[-2]
    assert app.snapshot.info.number == n + 1  # the running trial went on
    t = app.snapshot.frame.t
    assert wait_for(lambda: app.snapshot.frame.t > t + 0.1)
    assert app.alive()


def test_view_thread_keeps_updating(app: ViewerApp) -> None:
    n = app.stats()["view_updates"]   # how many so far depends on the machine's load
    wait_until(lambda: app.stats()["view_updates"] >= n + 5, what="five more view updates",
               timeout=30.0, step=0.05)


# -- trial loop, stop ------------------------------------------------------------------


def test_trials_loop_and_stop_joins_everything() -> None:
    a = ViewerApp(port=0, trials=TrialOptions(schema="none", max_time=0.3, pause_s=0.1)).start()
    port = a.port
    try:
        assert wait_for(lambda: a.snapshot.info.number >= 3)
        assert a.snapshot.info.config.variant >= 1  # the next trajectory variant
        assert a.snapshot.info.config.seed >= 2
    finally:
        a.stop()
    assert not any(t.is_alive() for t in a.threads)
    assert not a.alive()
    a.stop()  # idempotent
    with pytest.raises(OSError), socket.create_connection(("127.0.0.1", port), timeout=1):
        pass


# -- CLI ---------------------------------------------------------------------------------


class _FakeApp:
    """Stands in for ViewerApp so the exposure test never binds a public interface."""

    instances: ClassVar[list[_FakeApp]] = []

    def __init__(self, host, port, *, trials, access, **kw):
        self.host, self.port, self.schema, self.task = host, port, trials.schema, trials.task
        self.trials, self.access = trials, access
        self.kw = kw
        self.url = f"http://{host}:{port}/"
        self.stopped = False
        _FakeApp.instances.append(self)

    def start(self):
        return self

    def alive(self) -> bool:
        return True

    def stop(self) -> None:
        self.stopped = True


def _serve_args(**kw) -> argparse.Namespace:
    base = dict(host="127.0.0.1", port=0, schema=None, task="trajectory", seed=0,
                skill="intermediate", duration=0.0)
    base.update(kw)
    return argparse.Namespace(**base)


def test_cli_binds_beyond_loopback_only_with_expose_and_a_token(
    monkeypatch, capsys, tmp_path
) -> None:
    monkeypatch.setattr("vasim.viewer.app.ViewerApp", _FakeApp)
    monkeypatch.chdir(tmp_path)  # a named study.sqlite lands here, not in the checkout
    # Without --expose a public bind is refused before anything starts.
    with pytest.raises(InputError, match="add --expose"):   # a command-line argument
        viewer_cli.serve(_serve_args(host="0.0.0.0", port=8080))
    n_before = len(_FakeApp.instances)
    assert main(["serve", "--host", "0.0.0.0", "--port", "8080", "--duration", "0"]) == 2
    assert len(_FakeApp.instances) == n_before
    capsys.readouterr()
    # With --expose: the warning, and the app gets a fresh random token.
    assert viewer_cli.serve(_serve_args(host="0.0.0.0", port=8080, expose=True)) == 0
    err = capsys.readouterr().err
    assert "warning" in err and "0.0.0.0" in err and "every network interface" in err
    assert _FakeApp.instances[-1].host == "0.0.0.0" and _FakeApp.instances[-1].stopped
    token = _FakeApp.instances[-1].access.token
    assert isinstance(token, str) and len(token) >= 20
    viewer_cli.serve(_serve_args(host="0.0.0.0", port=8080, expose=True))
    assert _FakeApp.instances[-1].access.token != token
    capsys.readouterr()
    # An address that is not this machine's is the error, without an exposure warning first.
    with pytest.raises(ConfigError, match=r"cannot bind to host '999\.1\.1\.1'"):
        viewer_cli.serve(_serve_args(host="999.1.1.1", expose=True))
    assert "warning" not in capsys.readouterr().err
    for host in ("127.0.0.1", "localhost", "::1"):
        assert viewer_cli.serve(_serve_args(host=host)) == 0
        assert "warning" not in capsys.readouterr().err
        assert _FakeApp.instances[-1].access.token is None
    # --optics reaches the app (the trainee's 0 or 30 deg endoscope).
    viewer_cli.serve(_serve_args(optics=30))
    assert _FakeApp.instances[-1].trials.optics == 30.0
    assert main(["serve", "--optics", "45", "--duration", "0"]) == 2
    capsys.readouterr()
    # --task point without --schema picks the point-targeting VFS.
    viewer_cli.serve(_serve_args(task="point"))
    assert _FakeApp.instances[-1].schema == "point_targeting"
    # --scene and --db reach the app; the banner says where trials are stored.
    viewer_cli.serve(_serve_args(scene="none", db="study.sqlite"))
    assert _FakeApp.instances[-1].kw["scene"] == "none"
    assert _FakeApp.instances[-1].kw["db"] == "study.sqlite"
    assert "trials stored in study.sqlite" in capsys.readouterr().out


def test_vasim_serve_end_to_end(capsys) -> None:
    assert main(["serve", "--port", "0", "--schema", "vg", "--duration", "0.4"]) == 0
    out = capsys.readouterr().out
    assert "http://127.0.0.1:" in out and "schema vg" in out


def test_vasim_serve_bad_schema_is_a_one_line_error(capsys) -> None:
    assert main(["serve", "--port", "0", "--schema", "no_such_schema"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no_such_schema" in err[0]
    # A schema that does not fit the task is refused before anything binds.
    assert main(["serve", "--port", "0", "--task", "trajectory",
                 "--schema", "point_targeting"]) == 2


# -- views without a server ----------------------------------------------------------------


class _FakeCamera:
    def __init__(self) -> None:
        self.position = np.zeros(3)
        self.look_at = np.array([0.0, 1.0, 0.0])
        self.up_direction = np.array([0.0, 0.0, 1.0])
        self.fov = 1.0
        self.near = 0.01
        self.far = 100.0


class _FakeClient:
    def __init__(self, cid: int) -> None:
        self.client_id = cid
        self.camera = _FakeCamera()

    def atomic(self):
        import contextlib

        return contextlib.nullcontext()


def test_camera_controller_follows_mag_rate_limited_and_falls_back() -> None:
    clients = {1: _FakeClient(1)}
    server = SimpleNamespace(get_clients=lambda: dict(clients))
    default = CameraPose(np.array([0.0, -0.05, 0.15]), np.array([0.0, 0.03, 0.07]),
                         np.array([0.0, 0.0, 1.0]), 1.2)
    cc = CameraController(server, default, max_rate_hz=10.0)  # type: ignore[arg-type]
    cc.on_connect(clients[1])
    np.testing.assert_array_equal(clients[1].camera.position, default.position)
    assert clients[1].camera.near == cc.near
    view = CameraView(position=np.array([0.01, 0.0, 0.2]), look_at=np.array([0.0, 0.02, 0.1]),
                      up=np.array([0.0, 0.0, 1.0]), fov=1.2, zoom=2.0)
    cc.update(view, now=10.0)
    np.testing.assert_array_equal(clients[1].camera.position, view.position)
    writes = cc.writes
    moved = CameraView(position=view.position + 0.01, look_at=view.look_at, up=view.up,
                       fov=1.2)
    cc.update(moved, now=10.05)  # within 0.1 s: not written
    assert cc.writes == writes
    cc.update(moved, now=10.2)
    assert cc.writes == writes + 1
    cc.update(moved, now=10.4)  # unchanged pose: not re-sent
    assert cc.writes == writes + 1
    clients[2] = _FakeClient(2)  # a late client gets the current pose on the next push
    cc.update(moved, now=10.6)
    np.testing.assert_array_equal(clients[2].camera.position, moved.position)
    cc.update(None, now=11.0)  # Mag gone: back to the endoscope pose once
    for c in clients.values():
        np.testing.assert_array_equal(c.camera.position, default.position)
    n = cc.writes
    cc.update(None, now=12.0)
    assert cc.writes == n  # the user may orbit freely now
    cc.follow = False
    cc.update(view, now=13.0)
    assert cc.writes == n


@pytest.mark.parametrize("d", [(0, 0, 1), (0, 0, -1), (1, 0, 0), (0.3, -0.4, 0.2)])
def test_rotation_from_z_maps_z_onto_the_direction(d) -> None:
    d = np.array(d, dtype=float)
    R = matrix_z_to(d)
    np.testing.assert_allclose(R @ [0, 0, 1], d / np.linalg.norm(d), atol=1e-12)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert abs(np.linalg.norm(quat_z_to(d)) - 1.0) < 1e-12


def test_arrow_vertices_span_start_to_end() -> None:
    template, faces = arrow_mesh()
    start, end = np.array([0.01, 0.02, 0.1]), np.array([0.03, -0.01, 0.12])
    v = arrow_vertices(template, start, end, 0.001)
    assert v.dtype == np.float32 and v.shape == template.shape
    assert faces.max() < len(v)
    s = (len(template) - 3) // 3
    np.testing.assert_allclose(v[3 * s], end, atol=1e-6)  # apex
    np.testing.assert_allclose(v[3 * s + 1], start, atol=1e-6)  # tail centre
    axis = (end - start) / np.linalg.norm(end - start)
    proj = (v.astype(float) - start) @ axis
    assert proj.min() > -1e-6 and proj.max() < np.linalg.norm(end - start) + 1e-6


def test_hud_text_escapes_and_shows_only_what_a_trainee_needs() -> None:
    from vasim.viewer.trainee import HudInfo

    info = HudInfo(schema="vg", fixtures=("vg",), task="trajectory/v0",
                   title="trial 7 <b>", t=1.0, error_m=0.004, goal_index=2, n_points=30,
                   last_latency=0.8, audio=AudioCue(600.0, 0.3, 0.0), force_n=1.5,
                   zoom=2.0, ms=(0.5, 0.5, 0.5), done=False, time_left=179.0,
                   path_m=0.0015)
    md = hud_markdown(info)
    assert "<b>" not in md and "&lt;b&gt;" in md
    assert "2 of 30" in md and "4.0 mm" in md and "1.5 mm" in md and "0.80 s" in md
    assert "**trial 7 &lt;b&gt;** — running" in md and "(179 s left)" in md
    for internal in ("silent", "1.50 N", "0.50 / 0.50", "2.00×", "vg"):
        assert internal not in md, internal
    ended = hud_markdown(dataclasses.replace(info, done=True, outcome="timed_out"))
    assert "ended: time ran out" in ended and "done" not in ended
    assert audio_text(None) == "off"
    assert audio_text(AudioCue(620.0, 0.25, 0.5)) == "620 Hz, every 0.25 s"


def test_arrow_view_hides_faint_arrows(app: ViewerApp) -> None:
    from vasim.viewer.views import ArrowView

    view = ArrowView(app.server, slots=2, prefix="/test_arrows")
    try:
        a = Arrow(start=np.zeros(3), end=np.array([0.0, 0.0, 0.02]), color=(0, 1, 1),
                  opacity=0.7)
        faint = Arrow(start=np.zeros(3), end=np.array([0.01, 0.0, 0.0]), color=(1, 0, 1),
                      opacity=0.0, kind="force")
        view.update([a, faint])
        assert view.kinds == ("guidance",)
        assert view.handles[0].visible and not view.handles[1].visible
        assert view.handles[0].opacity == pytest.approx(0.7)
        view.update([])
        assert view.kinds == () and not view.handles[0].visible
    finally:
        for h in view.handles:
            h.remove()


def test_organ_view_deforms_in_place_only(app: ViewerApp) -> None:
    # A view of its own: the app's organ views move with the breathing physics meanwhile.
    from dataclasses import replace

    from vasim.viewer.views import OrganView

    view = OrganView(app.server, replace(app.organs[0].organ, name="test_organ"))
    try:
        v = view.organ.mesh.vertices + np.array([0.0, 0.0, 0.001])
        view.update(v)
        np.testing.assert_allclose(view.handle.vertices, v.astype(np.float32))
        with pytest.raises(ValueError, match="shape"):
            view.update(v[:-1])
    finally:
        view.handle.remove()


def test_organs_breathe_in_the_viewer(app: ViewerApp) -> None:
    # The trial's abdomen drives the organ views: the liver's vertices change over time.
    liver = next(v for v in app.organs if v.organ.name == "liver")
    first = np.array(liver.handle.vertices)
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        time.sleep(0.2)
        if np.abs(np.array(liver.handle.vertices) - first).max() > 1e-4:
            break
    assert np.abs(np.array(liver.handle.vertices) - first).max() > 1e-4


def test_default_camera_sees_the_workspace() -> None:
    from vasim.tasks.base import WORKSPACE_CENTRE, WORKSPACE_MAX, WORKSPACE_MIN
    from vasim.viewer import endoscope_pose

    pose = endoscope_pose()
    fwd = (pose.look_at - pose.position) / np.linalg.norm(pose.look_at - pose.position)
    corners = np.array(np.meshgrid(*zip(WORKSPACE_MIN, WORKSPACE_MAX, strict=True)))
    for p in [WORKSPACE_CENTRE, *corners.reshape(3, -1).T]:
        d = (p - pose.position) / np.linalg.norm(p - pose.position)
        assert np.arccos(np.clip(d @ fwd, -1, 1)) < pose.fov / 2  # inside the vertical fov


@pytest.mark.parametrize(("args", "needle"), [
    (["--port", "99999"], "99999"),
    (["--port", "-1"], "-1"),
    (["--host", "203.0.113.5"], "203.0.113.5"),
])
def test_serve_rejects_a_bad_bind_address_in_one_line(args: list[str], needle: str) -> None:
    p = subprocess.run([sys.executable, "-m", "vasim", "serve", *args, "--duration", "1"],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 2
    err = [ln for ln in p.stderr.splitlines() if ln.startswith("vasim serve: error")]
    assert len(err) == 1 and needle in err[0] and "Traceback" not in p.stderr


class _Device:
    def __init__(self) -> None:
        self.samples: list[tuple[float, tuple[float, ...], int]] = []

    def push(self, t, position, buttons=0) -> bool:
        self.samples.append((t, tuple(float(v) for v in position), int(buttons)))
        return True


def test_drag_gizmo_feeds_the_device_and_snaps_back_clutched(app: ViewerApp) -> None:
    from vasim.haptics.device import BUTTON_2
    from vasim.viewer import DragInput

    dev = _Device()
    current: list[_Device | None] = [dev]
    drag = DragInput(app.server, lambda: current[0], app._guard, name="/test_drag")
    try:
        tip = np.array([0.01, 0.02, 0.1])
        drag.update(tip, active=True)  # a browser-driven trial starts: the gizmo on the tip
        assert drag.handle.visible and dev.samples[-1][1] == tuple(tip)
        for dx in (0.001, 0.002, 0.003):
            drag.handle.position = tuple(tip + np.array([dx, 0.0, 0.0]))
            drag._on_update(SimpleNamespace(phase="update"))
        assert [s[1][0] for s in dev.samples[1:]] == pytest.approx([0.011, 0.012, 0.013])
        assert all(s[2] == 0 for s in dev.samples)
        moved_tip = tip + np.array([0.0026, 0.0, 0.0])  # the tool lagged behind the hand
        drag.update(moved_tip, active=True)
        drag._on_update(SimpleNamespace(phase="end"))
        # Release: the hand's last pose, then clutched there and at the tip: no jump.
        (t0, p0, b0), (t1, p1, b1), (t2, p2, b2) = dev.samples[-3:]
        assert b0 == 0 and b1 == b2 == BUTTON_2 and t0 < t1 < t2
        assert p1 == p0 and p2 == pytest.approx(tuple(moved_tip))
        np.testing.assert_allclose(drag.handle.position, moved_tip)
        drag.update(moved_tip, active=False)  # the trial ends: the gizmo goes away
        assert not drag.handle.visible
        current[0] = None  # no browser-driven trial: a late drag event is ignored
        n = len(dev.samples)
        drag._on_update(SimpleNamespace(phase="update"))
        assert len(dev.samples) == n
    finally:
        drag.handle.remove()


def test_no_page_of_the_viewer_draws_viser_s_environment_map(app) -> None:
    """Issue #26.2 (``vasim.viewer.lighting``): the map cost a software-drawn frame 7-12x
    its CPU. A bare viser server sends no map message (its pages draw the default map),
    so each page of the app must carry one that turns it off."""
    import viser

    bare = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        assert environment_maps(bare) == []
    finally:
        bare.stop()
    for server in (app.server, app.exp_server):
        maps = environment_maps(server)
        assert len(maps) == 1 and maps[0].hdri_data is None
    lights = [type(m).__name__ for m in state_messages(app.exp_server)]
    assert "HemisphereLightMessage" in lights  # the experimenter's fill
