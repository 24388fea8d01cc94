"""Every client message is untrusted; one bad client never stops the others (issue #30.2,
#30.5): crafted websocket messages against a running server."""

from __future__ import annotations

import asyncio
import math
import threading
import time
from collections.abc import Iterator
from typing import Any

import msgspec
import numpy as np
import pytest
import websockets
from hypothesis import given, settings
from hypothesis import strategies as st
from viser import _messages
from websockets.sync.client import connect

from vasim.viewer import isolation
from vasim.viewer.app import TrialOptions, ViewerApp, ViewerPace
from vasim.viewer.isolation import LoopSafeEvent, Strikes, camera_refusal, message_refusal
from vasim.viewer.views import CameraController, CameraPose

SUBPROTOCOL = "viser-v1.1.1"


def camera(**over: Any) -> dict[str, Any]:
    """A camera report as viser's browser client sends it (plain msgpack fields)."""
    m = {"type": "ViewerCameraMessage", "wxyz": [1.0, 0.0, 0.0, 0.0],
         "position": [0.0, -0.3, 0.1], "fov": 1.0, "near": 0.01, "far": 100.0,
         "image_height": 800, "image_width": 1280, "look_at": [0.0, 0.0, 0.0],
         "up_direction": [0.0, 0.0, 1.0]}
    m.update(over)
    return m


def _cam_message(**over: Any) -> _messages.ViewerCameraMessage:
    raw = msgspec.msgpack.encode(camera(**over))
    msg = _messages.Message.deserialize(raw)
    assert isinstance(msg, _messages.ViewerCameraMessage)
    return msg


# -- the checks (pure) --------------------------------------------------------------------


def test_an_honest_camera_passes_and_broken_ones_are_refused() -> None:
    assert camera_refusal(_cam_message()) is None
    inf = math.inf
    for over in ({"position": [inf, inf, inf]}, {"look_at": [math.nan, 0, 0]},
                 {"position": [2e6, 0, 0]}, {"wxyz": [0, 0, 0, 0]}, {"fov": 0.0},
                 {"fov": 4.0}, {"near": 1.0, "far": 0.5}, {"image_width": -1},
                 {"look_at": [0.0, -0.3, 0.1]}, {"up_direction": [0, 0, 0]},
                 {"position": [1, 2]}):
        assert camera_refusal(_cam_message(**over)) is not None, over


def test_gui_updates_may_change_only_a_value() -> None:
    assert message_refusal(_messages.GuiUpdateMessage("u", {"value": 3})) is None
    for updates in ({"visible": False}, {"label": "x", "value": 1}, {"options": ["a"]}):
        assert "other than value" in (message_refusal(
            _messages.GuiUpdateMessage("u", updates)) or "")
    assert message_refusal(_messages.GuiUpdateMessage("u", {"value": math.inf})) is not None
    assert "share" in (message_refusal(_messages.ShareUrlRequest()) or "")


@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=3, max_size=3))
@settings(max_examples=60, deadline=None)
def test_a_camera_is_refused_exactly_when_its_position_is_not_finite_and_near(
        pos: list[float]) -> None:
    ok = all(math.isfinite(p) and abs(p) <= isolation.MAX_COORD_M for p in pos) \
        and float(np.linalg.norm(np.array(pos))) > 1e-9
    assert (camera_refusal(_cam_message(position=pos)) is None) == ok


def test_strikes_count_in_a_sliding_window() -> None:
    s = Strikes(limit=3, window_s=10.0)
    assert not s.hit(0.0) and not s.hit(1.0)
    assert not s.hit(20.0)             # the first two have left the window
    assert not s.hit(21.0) and s.hit(22.0)


def test_a_loop_safe_event_set_from_another_thread_runs_on_the_loop() -> None:
    loop = asyncio.new_event_loop()
    try:
        ev = LoopSafeEvent(loop)
        ev.set()                    # no loop runs here: handed to the loop, not run
        assert not ev.is_set()
        loop.run_until_complete(asyncio.sleep(0))
        assert ev.is_set()

        async def on_loop() -> bool:
            ev.clear()
            ev.set()                # on the owning loop: immediate
            return ev.is_set()

        assert loop.run_until_complete(on_loop())
    finally:
        loop.close()
    ev.set()                        # a closed loop: nothing to wake, no error


class _FakeCamera:
    def __init__(self, bad: bool):
        object.__setattr__(self, "position", None)
        object.__setattr__(self, "bad", bad)

    def __setattr__(self, name: str, value: Any) -> None:
        if name in ("up_direction", "position", "look_at", "fov") and getattr(self, "bad", 0):
            raise ValueError("Camera position must be finite, got [inf inf inf].")
        object.__setattr__(self, name, value)


class _FakeClient:
    def __init__(self, cid: int, bad: bool):
        self.client_id = cid
        self.camera = _FakeCamera(bad)

    def atomic(self) -> Any:
        import contextlib

        return contextlib.nullcontext()


class _FakeServer:
    def __init__(self, clients: dict[int, _FakeClient]):
        self.clients = clients

    def get_clients(self) -> dict[int, _FakeClient]:
        return self.clients


def test_one_client_with_a_broken_camera_does_not_stop_the_others() -> None:
    clients = {0: _FakeClient(0, bad=True), 1: _FakeClient(1, bad=False),
               2: _FakeClient(2, bad=False)}
    pose = CameraPose(np.array([0.0, -0.3, 0.1]), np.zeros(3), np.array([0.0, 0, 1]), 1.0)
    cam = CameraController(_FakeServer(clients), pose)  # type: ignore[arg-type]
    cam.retarget(pose)               # forced push to every client
    assert cam.failures == 1
    assert clients[1].camera.position is pose.position
    assert clients[2].camera.position is pose.position


# -- a running server ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def app() -> Iterator[ViewerApp]:
    # Mag drives the camera: the view thread writes every client's camera all the time.
    a = ViewerApp(port=0, scene="none", trials=TrialOptions(schema="mag"),
                  pace=ViewerPace(view_hz=20.0)).start()
    try:
        yield a
    finally:
        a.stop()


def _recv_for(ws: Any, seconds: float) -> int:
    """Messages received within ``seconds`` (0 when the connection closed)."""
    n, t_end = 0, time.monotonic() + seconds
    while time.monotonic() < t_end:
        try:
            ws.recv(timeout=max(0.01, t_end - time.monotonic()))
            n += 1
        except TimeoutError:
            pass
    return n


def _wait(cond: Any, timeout: float = 30.0) -> bool:
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        if cond():
            return True
        time.sleep(0.05)
    return bool(cond())


def test_an_inf_camera_is_dropped_and_its_sender_disconnected(
        app: ViewerApp, caplog: pytest.LogCaptureFixture) -> None:
    url = f"ws://127.0.0.1:{app.port}/"
    before = isolation.refused_total
    with connect(url, subprotocols=[SUBPROTOCOL], open_timeout=30) as honest, \
            connect(url, subprotocols=[SUBPROTOCOL], open_timeout=30) as bad:
        honest.send(msgspec.msgpack.encode(camera()))
        bad.send(msgspec.msgpack.encode(camera()))
        assert _wait(lambda: len(app.server.get_clients()) >= 2)  # type: ignore[union-attr]
        bad.send(msgspec.msgpack.encode(camera(position=[math.inf] * 3)))
        assert _wait(lambda: isolation.refused_total > before)
        # The server never took the bad pose: every client's camera stays finite.
        for client in app.server.get_clients().values():  # type: ignore[union-attr]
            assert np.isfinite(client.camera.position).all()
        # One strike is in; STRIKES - 1 more reach the limit (a STRIKES-th more could meet a
        # socket the server has already closed: it did once, on a busy host).
        for _ in range(isolation.STRIKES - 1):
            bad.send(msgspec.msgpack.encode(camera(position=[math.inf] * 3)))
        with pytest.raises(websockets.exceptions.ConnectionClosed) as closed:
            while True:
                bad.recv(timeout=30)
        assert closed.value.rcvd is not None and closed.value.rcvd.code == 1008
        # The honest page keeps getting frames and the view thread never failed.
        assert _recv_for(honest, 2.0) > 0
    assert app.alive()
    assert not [e for e in app.errors if "viewer error" in e], app.errors
    assert app.camera.failures == 0
    assert any("dropped ViewerCameraMessage" in r.getMessage() for r in caplog.records)
    assert any("disconnected" in r.getMessage() for r in caplog.records)


def test_crafted_gui_updates_cannot_change_another_page(app: ViewerApp) -> None:
    """viser sets *any* attribute a GUI update names on the input's server-side state and
    broadcasts it: ``{"update_cb": []}`` would wipe an input's callbacks for every page,
    ``{"removed": true}`` kill it. A crafted connection tries both on an input of the
    trainee's page (a probe checkbox: the page's own inputs are per client): dropped."""
    url = f"ws://127.0.0.1:{app.port}/"
    s = app.server
    assert s is not None
    probe = s.gui.add_checkbox("probe", initial_value=False)
    calls: list[bool] = []
    probe.on_update(lambda e: calls.append(bool(probe.value)))
    uuid = probe._impl.uuid
    with connect(url, subprotocols=[SUBPROTOCOL], open_timeout=30) as ws:
        ws.send(msgspec.msgpack.encode(camera()))
        n0 = isolation.refused_total
        for updates in ({"update_cb": []}, {"removed": True}, {"value": True, "label": "x"}):
            ws.send(msgspec.msgpack.encode({"type": "GuiUpdateMessage", "uuid": uuid,
                                            "updates": updates}))
        assert _wait(lambda: isolation.refused_total >= n0 + 3)
        assert len(probe._impl.update_cb) == 1 and not probe._impl.removed
        assert probe.label == "probe" and calls == []
        # An honest value change still works (and reaches the callback).
        ws.send(msgspec.msgpack.encode({"type": "GuiUpdateMessage", "uuid": uuid,
                                        "updates": {"value": True}}))
        assert _wait(lambda: calls == [True])
    probe.remove()


def test_garbage_frames_are_refused_not_crashing(app: ViewerApp) -> None:
    url = f"ws://127.0.0.1:{app.port}/"
    n0 = isolation.refused_total
    with connect(url, subprotocols=[SUBPROTOCOL], open_timeout=30) as ws:
        ws.send(b"\xc1\xff garbage")
        ws.send("text frame")
        ws.send(msgspec.msgpack.encode({"type": "NoSuchMessage"}))
        assert _wait(lambda: isolation.refused_total >= n0 + 3)
    assert app.alive()


def test_150_simultaneous_connections_cause_no_loop_errors(
        app: ViewerApp, caplog: pytest.LogCaptureFixture) -> None:
    url = f"ws://127.0.0.1:{app.port}/"
    errors_before = len(app.errors)
    opened: list[int] = []

    async def one(i: int, hold: float) -> None:
        async with websockets.connect(url, subprotocols=[SUBPROTOCOL],  # type: ignore[list-item]
                                      open_timeout=60, max_size=None) as ws:
            await ws.send(msgspec.msgpack.encode(camera(position=[0.0, -0.3, 0.1 + i * 1e-4])))
            opened.append(i)
            t_end = time.monotonic() + hold
            while time.monotonic() < t_end:
                try:
                    await asyncio.wait_for(ws.recv(), timeout=0.5)
                except TimeoutError:
                    pass

    async def main() -> list[Any]:
        return await asyncio.gather(*(one(i, 4.0) for i in range(150)),
                                    return_exceptions=True)

    results: list[Any] = []
    t = threading.Thread(target=lambda: results.extend(asyncio.run(main())))
    t.start()
    t.join(timeout=180)
    assert not t.is_alive()
    failures = [r for r in results if isinstance(r, BaseException)]
    assert len(opened) == 150, failures[:3]
    assert app.alive()
    new_errors = app.errors[errors_before:]
    assert not [e for e in new_errors if "deque" in e or "viewer error" in e], new_errors
    assert not [r for r in caplog.records if "deque mutated" in r.getMessage()]
    assert isolation.installed()


def test_a_trainee_connection_cannot_reach_the_experimenter_s_controls(app: ViewerApp) -> None:
    """Every input of the experimenter's page, addressed by its id from the trainee's
    websocket with a plausible new value (and a Start click): nothing changes, nothing is
    queued for the controller."""
    e = app.exp_server
    assert e is not None
    inputs = list(e.gui._gui_input_handle_from_uuid.values())
    assert inputs
    before = {h._impl.uuid: h._impl.value for h in inputs}
    def choices() -> tuple[Any, ...]:
        p = app.controller.panel
        return (p.mode, p.input, p.schema, p.task, p.subject, p.label, p.protocol,
                p.condition, repr(p.f5pl))

    panel_before = choices()
    url = f"ws://127.0.0.1:{app.port}/"
    with connect(url, subprotocols=[SUBPROTOCOL], open_timeout=30) as ws:
        ws.send(msgspec.msgpack.encode(camera()))
        for uuid, value in before.items():
            new: Any = (not value if isinstance(value, bool) else
                        value + 1 if isinstance(value, int | float) else
                        "free" if isinstance(value, str) else value)
            ws.send(msgspec.msgpack.encode({"type": "GuiUpdateMessage", "uuid": uuid,
                                            "updates": {"value": new}}))
        _recv_for(ws, 1.5)
    assert {h._impl.uuid: h._impl.value for h in inputs} == before
    assert app.commands.empty()
    assert choices() == panel_before
