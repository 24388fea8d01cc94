"""One token per page (issue #30.1): under ``--expose`` the trainee's token never opens the
experimenter's page; tokens are compared in constant time as bytes (a non-ASCII token is a
logged 403, not a 500)."""

from __future__ import annotations

import logging
import os
import re
import subprocess
import sys
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from vasim.core.errors import ConfigError
from vasim.viewer.access import AccessPolicy, cookie_name, new_token, same_token
from vasim.viewer.app import PageAccess, TrialOptions, ViewerApp, ViewerPace

ROOT = Path(__file__).resolve().parents[2]


def _status(url: str, headers: dict[str, str] | None = None) -> int:
    req = urllib.request.Request(url, headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return int(r.status)
    except urllib.error.HTTPError as exc:
        return int(exc.code)


def _ws_status(port: int, path: str = "/", cookie: str | None = None) -> int:
    headers = {"Cookie": cookie} if cookie else {}
    try:
        with connect(f"ws://127.0.0.1:{port}{path}", subprotocols=["viser-v1.1.1"],  # type: ignore[list-item]
                     origin=f"http://127.0.0.1:{port}",  # type: ignore[arg-type]
                     additional_headers=headers, open_timeout=30):
            return 101
    except InvalidStatus as exc:
        return int(exc.response.status_code)


def test_same_token_compares_bytes_and_never_raises() -> None:
    t = new_token()
    assert same_token(t, t) and same_token(t.encode(), t)
    for given in ("\u00e9", "\ud800", t[:-1], t + "x", "", b"\xff"):
        assert not same_token(given, t)
    p = AccessPolicy(loopback_only=False, token=t, role="trainee")
    assert "token is required" in (p.refusal("/?token=%C3%A9", {"Host": "h:1"}) or "")
    assert "token is required" in (p.refusal("/", {"Host": "h:1",
                                                   "Cookie": f"{p.cookie}=\u00e9"}) or "")
    assert p.cookie == "vasim_token_trainee" != cookie_name("experimenter")


def test_the_two_pages_may_not_share_a_token() -> None:
    t = new_token()
    with pytest.raises(ConfigError, match="must differ"):
        ViewerApp(host="0.0.0.0", port=0, scene="none", trials=TrialOptions(schema="none"),
                  access=PageAccess(token=t, experimenter_token=t))


@pytest.fixture(scope="module")
def exposed() -> Iterator[ViewerApp]:
    app = ViewerApp(host="0.0.0.0", port=0, scene="none", trials=TrialOptions(schema="none"),
                    pace=ViewerPace(view_hz=10.0), access=PageAccess(token=new_token())).start()
    try:
        yield app
    finally:
        app.stop()


def test_each_page_opens_only_with_its_own_token(exposed: ViewerApp) -> None:
    trainee, experimenter = exposed.access.token, exposed.exp_access.token
    assert trainee and experimenter and trainee != experimenter
    assert exposed.url.endswith(f"?token={trainee}")
    assert exposed.experimenter_url.endswith(f"?token={experimenter}")
    t_port, e_port = exposed.port, exposed.experimenter_port
    assert _status(f"http://127.0.0.1:{t_port}/?token={trainee}") == 200
    assert _status(f"http://127.0.0.1:{e_port}/?token={experimenter}") == 200
    # The trainee's token, in the query or in either cookie, never opens the experimenter's
    # page nor its websocket (where the controller's commands arrive).
    assert _status(f"http://127.0.0.1:{e_port}/?token={trainee}") == 403
    for name in (cookie_name("trainee"), cookie_name("experimenter"), "vasim_token"):
        assert _status(f"http://127.0.0.1:{e_port}/",
                       {"Cookie": f"{name}={trainee}"}) == 403
        assert _ws_status(e_port, cookie=f"{name}={trainee}") == 403
    assert _ws_status(e_port, path=f"/?token={trainee}") == 403
    # ... and the experimenter's token is no key to the trainee's page either.
    assert _status(f"http://127.0.0.1:{t_port}/?token={experimenter}") == 403
    # Each page's own cookie lets its websocket through.
    assert _ws_status(e_port, cookie=f"{cookie_name('experimenter')}={experimenter}") == 101
    assert _ws_status(t_port, cookie=f"{cookie_name('trainee')}={trainee}") == 101


def test_a_non_ascii_token_is_a_logged_403(exposed: ViewerApp,
                                           caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING, logger="vasim.viewer.access")
    for port in (exposed.port, exposed.experimenter_port):
        assert _status(f"http://127.0.0.1:{port}/?token=%C3%A9") == 403
        assert _status(f"http://127.0.0.1:{port}/?token=%ED%A0%80") == 403
        assert _ws_status(port, path="/?token=%C3%A9") == 403
        assert _status(f"http://127.0.0.1:{port}/", {"Cookie": "vasim_token_trainee=\u00e9"
                                                     .encode().decode("latin-1")}) == 403
    lines = [r.getMessage() for r in caplog.records if "refused" in r.getMessage()]
    assert len(lines) >= 8 and all("token is required" in m for m in lines)
    assert not any(exposed.access.token in m or exposed.exp_access.token in m  # type: ignore[operator]
                   for m in lines)
    assert exposed.alive()


def test_vasim_serve_expose_prints_two_tokens_that_do_not_cross() -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "vasim", "serve", "--host", "0.0.0.0", "--expose", "--port", "0",
         "--scene", "none", "--schema", "none", "--duration", "60"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT)
    try:
        assert proc.stdout is not None
        line = ""
        for line in proc.stdout:  # viser's banner first, then vasim's line with the URLs
            if line.startswith("vasim viewer:"):
                break
        m = re.search(r"trainee (http://\S+:(\d+)/\?token=(\S+)), experimenter "
                      r"(http://\S+:(\d+)/\?token=(\S+?))\s", line)
        assert m, line
        t_port, trainee, e_port, experimenter = m.group(2), m.group(3), m.group(5), m.group(6)
        assert trainee != experimenter
        assert _status(f"http://127.0.0.1:{e_port}/?token={trainee}") == 403
        assert _status(f"http://127.0.0.1:{e_port}/?token={experimenter}") == 200
        assert _status(f"http://127.0.0.1:{t_port}/?token={trainee}") == 200
    finally:
        proc.terminate()
        proc.wait(timeout=30)
