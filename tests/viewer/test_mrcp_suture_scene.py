"""``vasim serve --scene mrcp:suture_combined`` server side (issue #28 item 1): the station
builds with the needle as the task body, the thread and the subtask label appear with the
first cycles, and the status names the subtask and the pairing mode."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from tests.polling import wait_for
from vasim.viewer.mrcp_panel import MrcpPace, MrcpViewerApp, status_text
from vasim.viewer.mrcp_view import SubtaskView, needle_mesh, subtask_text


@pytest.fixture(scope="module")
def app() -> Iterator[MrcpViewerApp]:
    a = MrcpViewerApp(port=0, scenario="mrcp:suture_combined", coarse=True,
                      pace=MrcpPace(speed=4.0, view_hz=20.0, plot_hz=4.0)).start()
    try:
        yield a
    finally:
        a.stop()


def test_scene_has_the_station_the_needle_the_thread_and_the_subtask(app: MrcpViewerApp
                                                                      ) -> None:
    nodes = app.scene_nodes()
    for r in ("R0", "R1", "C"):
        assert f"/mrcp/robots/{r}/link6" in nodes
    assert "/mrcp/obstacles/tissue_left" in nodes and "/mrcp/obstacles/tissue_right" in nodes
    assert "/mrcp/task/body" in nodes
    assert wait_for(lambda: app.subtasks is not None and app.subtasks.updates > 0)
    nodes = app.scene_nodes()
    for n in ("/mrcp/suture/thread", "/mrcp/suture/subtask", "/mrcp/suture/pinned"):
        assert n in nodes
    assert app.subtasks is not None
    assert app.subtasks.thread.points.shape[1:] == (2, 3)       # segments of the chain
    frame = app.live.latest()
    assert frame is not None and frame.sample.subtask is not None
    text = status_text("suture_combined", frame, app.speed)
    assert "subtask:" in text and frame.sample.mode in text


def test_status_shows_the_mrcp_pairing_once_stitching(app: MrcpViewerApp) -> None:
    def stitching() -> bool:
        f = app.live.latest()
        return f is not None and f.sample.mode == "MRCP"

    assert wait_for(stitching)
    assert app.subtasks is not None
    assert wait_for(lambda: "MRCP" in app.subtasks.label.text)
    assert app.stats()["failures"] == 0


def test_needle_mesh_follows_the_arc() -> None:
    from vasim.mrcp.scenarios.suture_geometry import NEEDLE_RADIUS

    m = needle_mesh()
    r = np.hypot(m.vertices[:, 0], m.vertices[:, 2])
    assert abs(float(np.median(r)) - NEEDLE_RADIUS) < 1e-3
    assert m.vertices[:, 2].max() < 1e-3                  # the half circle below its centre


def test_subtask_text_and_segments() -> None:
    class S:
        subtask, mode, scene = "knot_tying", "StdT", {"stitch": 3}

    assert subtask_text(S()) == "knot_tying · StdT"
    assert subtask_text(object()) is None
    seg = SubtaskView.segments([[0, 0, 0], [1, 0, 0], [1, 1, 0]])
    assert seg.shape == (2, 2, 3) and np.allclose(seg[1], [[1, 0, 0], [1, 1, 0]])
    assert SubtaskView.segments([[0, 0, 0]]).shape == (1, 2, 3)
