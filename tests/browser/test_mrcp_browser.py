"""The MRCP panel in a real headless Chromium (issue 6, MRCP bullet): the page of
``vasim serve --scene mrcp:cube_rotation`` loads, every robot link is a scene node that
moves in the browser, the MRCP tab draws its three uPlot charts, and the 3-D view is not
blank. Launch flags and readiness waits: tests/browser/conftest.py (guides/viewer.md).
"""

from __future__ import annotations

from collections.abc import Iterator
from io import BytesIO
from typing import Any

import numpy as np
import pytest

from tests.browser.conftest import VIEWPORT, wait_ready
from tests.polling import wait_for
from vasim.viewer.mrcp_panel import MrcpPace, MrcpViewerApp

ROBOT_NODES = [f"/mrcp/robots/{r}/link{k}" for r in ("R0", "R1") for k in range(7)]


@pytest.fixture(scope="module")
def app(browser: Any) -> Iterator[MrcpViewerApp]:
    # The coarse 36 ms cycle in real time; 15 pose updates/s keep software WebGL responsive.
    a = MrcpViewerApp(port=0, scenario="cube_rotation", coarse=True,
                      pace=MrcpPace(view_hz=15.0, plot_hz=2.0)).start()
    try:
        yield a
    finally:
        a.stop()


@pytest.fixture(scope="module")
def page(browser: Any, app: MrcpViewerApp) -> Iterator[Any]:
    pg = browser.new_page(viewport=VIEWPORT)
    pg.goto(app.url)
    wait_ready(pg, "/mrcp/robots/R1/link6")
    yield pg
    pg.close()


def node_pose(page: Any, name: str) -> list[float] | None:
    return page.evaluate("""(n) => {
        const o = window.__viserMutable.nodeRefFromName[n];
        return o ? [...o.position.toArray(), ...o.quaternion.toArray()] : null;
    }""", name)


def test_robot_nodes_exist_and_move_in_the_browser(app: MrcpViewerApp, page: Any) -> None:
    for name in [*ROBOT_NODES, "/mrcp/task/body", "/mrcp/obstacles/view_cone"]:
        assert wait_for(lambda n=name: node_pose(page, n) is not None), name
    # The poses the server sent arrive: R1's wrist turns with the cube it holds.
    first = node_pose(page, "/mrcp/robots/R1/link6")
    # (WAIT_S: a wait, not a timing goal; on a loaded 2-core host the kernel, the server and
    # software WebGL share the cores and the first wrist turn took over 20 s once.)
    assert wait_for(lambda: not np.allclose(node_pose(page, "/mrcp/robots/R1/link6"), first,
                                            atol=1e-4))
    server_pos = np.asarray(app.station.links["R0"][0].position)  # type: ignore[union-attr]
    assert np.allclose(node_pose(page, "/mrcp/robots/R0/link0")[:3], server_pos, atol=1e-6)


def test_mrcp_tab_draws_its_plots(page: Any) -> None:
    # uPlot charts: NTT, texec and tus per robot.
    assert wait_for(lambda: page.evaluate(
        "() => document.querySelectorAll('.uplot canvas').length") >= 3)
    text = page.evaluate("() => document.body.innerText")
    assert "holds the task" in text and "NTT" in text


def test_screenshot_is_not_blank(page: Any) -> None:
    from PIL import Image

    seen: list[float] = []

    def drawn() -> bool:
        img = np.asarray(Image.open(BytesIO(page.screenshot())).convert("RGB")).astype(int)
        h, w, _ = img.shape
        view = img[h // 3: h - 40, w // 10: int(w * 0.45)]  # below the WebGL notice
        seen.append(float((view.min(axis=2) < 235).mean()))
        return seen[-1] > 0.03  # robots, cube and floor grid on a white background

    assert wait_for(drawn, step=0.5), seen[-3:]
