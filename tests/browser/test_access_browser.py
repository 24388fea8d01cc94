"""In a real browser: a page from another site cannot use the viewer; an exposed viewer
opens only with its token (issue #16 §6)."""

from __future__ import annotations

import http.server
import threading
from collections.abc import Iterator
from typing import Any

import pytest

from tests.browser.conftest import VIEWPORT, WAIT_MS, wait_ready
from vasim.viewer.access import new_token
from vasim.viewer.app import PageAccess, TrialOptions, ViewerApp, ViewerPace

_PROBE = """<!doctype html><title>another site</title><body><pre id="out">pending</pre>
<script>
const out = document.getElementById('out');
const ws = new WebSocket('ws://127.0.0.1:%d/', ['viser-v1.1.1']);
ws.onopen = () => { out.textContent = 'OPEN'; };
ws.onerror = () => { out.textContent = 'REFUSED'; };
ws.onclose = (e) => { if (out.textContent !== 'OPEN') out.textContent = 'REFUSED'; };
</script></body>"""


class _Foreign(http.server.BaseHTTPRequestHandler):
    """Serves the probe page from another origin (another port of this machine)."""

    viewer_port = 0

    def do_GET(self) -> None:
        body = (_PROBE % self.viewer_port).encode()
        self.send_response(200)
        self.send_header("Content-Type", "text/html; charset=utf-8")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args: Any) -> None:
        pass


@pytest.fixture(scope="module")
def viewer(browser: Any) -> Iterator[ViewerApp]:
    app = ViewerApp(port=0, scene="none", trials=TrialOptions(schema="none"),
                    pace=ViewerPace(view_hz=10.0)).start()
    try:
        yield app
    finally:
        app.stop()


@pytest.fixture()
def foreign_site(viewer: ViewerApp) -> Iterator[str]:
    handler = type("Handler", (_Foreign,), {"viewer_port": viewer.port})
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()


def test_a_foreign_page_cannot_open_the_viewer_websocket(browser: Any, viewer: ViewerApp,
                                                         foreign_site: str) -> None:
    # The viewer's own page connects (the control) ...
    own = browser.new_page(viewport=VIEWPORT)
    try:
        own.goto(viewer.url)
        wait_ready(own)
    finally:
        own.close()
    # ... a page of another origin open in the same browser is refused at the handshake.
    page = browser.new_page(viewport=VIEWPORT)
    try:
        page.goto(foreign_site)
        page.wait_for_function(
            "() => document.getElementById('out').textContent !== 'pending'", timeout=WAIT_MS)
        assert page.inner_text("#out") == "REFUSED"
    finally:
        page.close()


def test_an_exposed_viewer_opens_only_with_its_token(browser: Any) -> None:
    token = new_token()
    app = ViewerApp(host="0.0.0.0", port=0, scene="none", trials=TrialOptions(schema="none"),
                    pace=ViewerPace(view_hz=10.0), access=PageAccess(token=token)).start()
    page = browser.new_page(viewport=VIEWPORT)
    try:
        response = page.goto(f"http://127.0.0.1:{app.port}/")
        assert response is not None and response.status == 403
        assert "token is required" in page.inner_text("body")
        response = page.goto(app.url)                   # the printed URL, with the token
        assert response is not None and response.status == 200
        wait_ready(page)                                # assets and websocket via the cookie
    finally:
        page.close()
        app.stop()
