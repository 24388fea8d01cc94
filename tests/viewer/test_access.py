"""The viewer accepts only its own page; an exposed viewer needs its token (issue #16 §6)."""

from __future__ import annotations

import urllib.error
import urllib.request
from collections.abc import Iterator

import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from vasim.core.errors import ConfigError
from vasim.viewer.access import (
    COOKIE,
    AccessPolicy,
    access_policy,
    cookie_name,
    is_loopback_name,
    new_token,
    viewer_url,
)
from vasim.viewer.app import PageAccess, TrialOptions, ViewerApp

# -- the policy (pure) -------------------------------------------------------------------

LOOP = AccessPolicy(loopback_only=True)


def test_same_origin_and_origin_less_clients_pass_on_loopback() -> None:
    for host in ("127.0.0.1:8080", "localhost:8080", "[::1]:8080"):
        assert LOOP.refusal("/", {"Host": host, "Origin": f"http://{host}"}) is None
    assert LOOP.refusal("/", {"Host": "127.0.0.1:8080"}) is None  # not a browser


@pytest.mark.parametrize("origin", [
    "https://evil.example", "http://127.0.0.1:9999", "http://localhost:8080", "null",
    "file://", "chrome-extension://abc"])
def test_foreign_origins_are_refused(origin: str) -> None:
    reason = LOOP.refusal("/", {"Host": "127.0.0.1:8080", "Origin": origin})
    assert reason is not None and "foreign origin" in reason


def test_dns_rebinding_host_is_refused_on_loopback() -> None:
    # evil.example resolves to 127.0.0.1: same origin by name, but not a loopback name.
    reason = LOOP.refusal("/", {"Host": "evil.example:8080",
                                "Origin": "http://evil.example:8080"})
    assert reason is not None and "loopback" in reason
    assert is_loopback_name("127.8.9.1:80") and not is_loopback_name("10.0.0.1:80")


def test_an_exposed_policy_needs_the_token_in_query_or_cookie() -> None:
    token = new_token()
    p = AccessPolicy(loopback_only=False, token=token)
    hdr = {"Host": "192.0.2.7:8080"}
    assert "token is required" in (p.refusal("/", hdr) or "")
    assert "token is required" in (p.refusal("/?token=wrong", hdr) or "")
    assert p.refusal(f"/?token={token}", hdr) is None
    assert p.grants_cookie(f"/?token={token}") and not p.grants_cookie("/?token=x")
    assert p.refusal("/", {**hdr, "Cookie": f"a=1; {COOKIE}={token}"}) is None
    assert p.refusal("/", {**hdr, "Cookie": f"{COOKIE}=nope"}) is not None
    # The token does not excuse a foreign origin.
    assert "foreign origin" in (p.refusal(f"/?token={token}", {
        **hdr, "Origin": "https://evil.example"}) or "")
    assert "SameSite=Strict" in p.cookie_header() and "HttpOnly" in p.cookie_header()


def test_a_public_bind_without_a_token_is_refused() -> None:
    with pytest.raises(ConfigError, match="needs an access token"):
        access_policy("0.0.0.0", None)
    with pytest.raises(ValueError):
        AccessPolicy(loopback_only=False)
    assert access_policy("127.0.0.1", None).token is None
    assert viewer_url("0.0.0.0", 81, "t") == "http://127.0.0.1:81/?token=t"
    assert viewer_url("::1", 81, None) == "http://[::1]:81/"


# -- a real server -----------------------------------------------------------------------


@pytest.fixture(scope="module")
def loop_app() -> Iterator[ViewerApp]:
    app = ViewerApp(port=0, scene="none", trials=TrialOptions(schema="none")).start()
    try:
        yield app
    finally:
        app.stop()


def _ws(port: int, **kw: object) -> None:
    with connect(f"ws://127.0.0.1:{port}/", subprotocols=["viser-v1.1.1"],
                 open_timeout=20, **kw):  # type: ignore[arg-type]
        pass


def test_the_server_refuses_a_foreign_origin_websocket(loop_app: ViewerApp) -> None:
    _ws(loop_app.port, origin=f"http://127.0.0.1:{loop_app.port}")  # its own page: fine
    _ws(loop_app.port)                                               # no Origin: fine
    with pytest.raises(InvalidStatus) as exc:
        _ws(loop_app.port, origin="https://evil.example")
    assert exc.value.response.status_code == 403
    assert b"foreign origin" in exc.value.response.body


def test_the_server_refuses_a_rebinding_host(loop_app: ViewerApp) -> None:
    req = urllib.request.Request(f"http://127.0.0.1:{loop_app.port}/",
                                 headers={"Host": f"evil.example:{loop_app.port}"})
    with pytest.raises(urllib.error.HTTPError) as exc:
        urllib.request.urlopen(req, timeout=20)
    assert exc.value.code == 403
    with urllib.request.urlopen(f"http://127.0.0.1:{loop_app.port}/", timeout=20) as r:
        assert r.status == 200


def test_an_exposed_server_needs_its_token() -> None:
    token = new_token()
    app = ViewerApp(host="0.0.0.0", port=0, scene="none", trials=TrialOptions(schema="none"),
                    access=PageAccess(token=token)).start()
    try:
        assert app.url.endswith(f"?token={token}")
        base = f"http://127.0.0.1:{app.port}/"
        with pytest.raises(urllib.error.HTTPError) as exc:
            urllib.request.urlopen(base, timeout=20)
        assert exc.value.code == 403
        with urllib.request.urlopen(app.url, timeout=20) as r:
            assert r.status == 200
            cookie = r.headers["Set-Cookie"]
        assert cookie.startswith(f"{cookie_name('trainee')}={token}")
        with pytest.raises(InvalidStatus):
            _ws(app.port, origin=f"http://127.0.0.1:{app.port}")
        _ws(app.port, origin=f"http://127.0.0.1:{app.port}",
            additional_headers={"Cookie": f"{cookie_name('trainee')}={token}"})
    finally:
        app.stop()
