"""Who may open the viewer: its own page only, and with a token when it is exposed.

A viewer bound to 127.0.0.1 is still reachable from *every web page* open in the
experimenter's browser: a page from another site can open a websocket to
``ws://127.0.0.1:8080`` (browsers do not apply the same-origin policy to websockets) and
receive the scene and panel state, or press the experimenter's buttons. The checks here run
on every HTTP request and websocket handshake, before viser sees it:

* **Same origin.** A browser always sends ``Origin`` on a websocket handshake; it must name
  the host the request was sent to (``Origin`` netloc == ``Host``). A foreign page, a
  sandboxed frame or a ``file://`` page (``Origin: null``) is refused with HTTP 403.
  Clients that are not browsers send no ``Origin`` and are allowed on loopback (a local
  process can read the study database anyway).
* **Loopback means loopback.** On a loopback bind the ``Host`` header must be a loopback
  name (``127.0.0.1``, ``localhost``, ``[::1]``): a DNS-rebinding page whose name resolves
  to 127.0.0.1 sends its own name and is refused.
* **Exposed means a token -- one per page.** Binding beyond loopback needs an explicit
  ``--expose`` (the CLI) and then random tokens, printed with the URLs at start
  (``?token=...``). The trainee's page and the experimenter's page each have their own
  token (issue #30.1): the trainee's token never opens the experimenter's page. The page
  request carrying a token gets a ``SameSite=Strict`` cookie named after the page's role
  (``vasim_token_trainee``, ``vasim_token_experimenter``); every later request (scripts,
  the websocket) must carry that cookie or the token. **Decisions**: a cookie rather than
  a token in every URL, because viser's client opens its websocket and loads its assets
  without the page's query string; one cookie *name per role* because browsers do not
  separate cookies by port, so both pages open in one browser would otherwise overwrite
  each other's cookie (and each page reads only its own).
* **Compared as bytes, in constant time.** Tokens are compared with
  ``hmac.compare_digest`` on their UTF-8 bytes, so any text a client sends (``%C3%A9``,
  an unpaired surrogate) is a plain mismatch: HTTP 403, logged, never a 500.

Every refusal is logged (logger ``vasim.viewer.access``, WARNING) with the page's role, the
client's address, the path without its query (a token is never logged) and the reason.

The websocket server belongs to viser; :func:`guarded_server` installs the check as the
server's ``process_request`` hook while viser binds it (viser 1.1 calls
``websockets.asyncio.server.serve`` once, from its start-up, which ``ViserServer()`` waits
for).
"""

from __future__ import annotations

import hmac
import http
import http.cookies
import ipaddress
import logging
import secrets
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any
from urllib.parse import parse_qs, urlsplit

import viser
import websockets.asyncio.server

from vasim.core.config import expect

log = logging.getLogger(__name__)

COOKIE = "vasim_token"
"""Name of the cookie that carries the token of an exposed single-page viewer (the MRCP
station); a role's page uses :func:`cookie_name` of its role."""


def cookie_name(role: str | None) -> str:
    """The cookie carrying the token of the page of ``role`` (None: a single-page viewer).

    Example:
        >>> cookie_name("trainee"), cookie_name(None)
        ('vasim_token_trainee', 'vasim_token')
    """
    return COOKIE if not role else f"{COOKIE}_{role}"


def same_token(given: str | bytes | None, token: str) -> bool:
    """True when ``given`` equals ``token``: a constant-time comparison of UTF-8 bytes
    (any text, even non-ASCII or an unpaired surrogate, compares without raising).

    Example:
        >>> same_token("\u00e9", "abc"), same_token("abc", "abc"), same_token(None, "abc")
        (False, True, False)
    """
    if given is None:
        return False
    a = given if isinstance(given, bytes) else given.encode("utf-8", "surrogatepass")
    return hmac.compare_digest(a, token.encode("utf-8"))

_LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "::1"})


def new_token() -> str:
    """A fresh random token (128 bits, URL-safe)."""
    return secrets.token_urlsafe(16)


def _host_name(netloc: str) -> str:
    """The host part of ``host[:port]`` / ``[v6]:port``, lower case."""
    netloc = netloc.strip().lower()
    if netloc.startswith("["):
        return netloc[1:].split("]", 1)[0]
    return netloc.rsplit(":", 1)[0] if netloc.count(":") == 1 else netloc


def is_loopback_name(netloc: str) -> bool:
    """True when a ``Host`` header names this machine's loopback interface.

    Example:
        >>> is_loopback_name("127.0.0.1:8080"), is_loopback_name("evil.example:8080")
        (True, False)
    """
    name = _host_name(netloc)
    if name in _LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False


@dataclass(frozen=True)
class AccessPolicy:
    """What a request must show to reach the viewer.

    Attributes:
        loopback_only: the server is bound to a loopback address (Host must be loopback).
        token: the token an exposed viewer requires, or None (loopback binds only).
        role: the page's role (``"trainee"``, ``"experimenter"``; None: a single-page
            viewer): names the cookie and the log lines.
    """

    loopback_only: bool
    token: str | None = None
    role: str | None = None

    def __post_init__(self) -> None:
        if not self.loopback_only and not self.token:
            raise ValueError("a viewer bound beyond loopback needs a token")

    def refusal(self, path: str, headers: Any) -> str | None:
        """Why a request is refused, or None to let it through.

        Args:
            path: the request target (path and query string).
            headers: the request headers (``.get(name)``, case-insensitive).

        Example:
            >>> p = AccessPolicy(loopback_only=True)
            >>> p.refusal("/", {"Host": "127.0.0.1:8080", "Origin": "http://127.0.0.1:8080"})
            >>> p.refusal("/", {"Host": "127.0.0.1:8080", "Origin": "https://evil.example"})
            "foreign origin 'https://evil.example'"
        """
        host = headers.get("Host") or ""
        if self.loopback_only and not is_loopback_name(host):
            return f"host {host[:80]!r} is not this machine's loopback name"
        origin = headers.get("Origin")
        if origin is not None:
            parts = urlsplit(origin)
            if parts.scheme not in ("http", "https") or parts.netloc.lower() != host.lower():
                return f"foreign origin {origin[:80]!r}"
        if self.token is not None and not self._has_token(path, headers):
            return "a token is required (open the URL the server printed)"
        return None

    def grants_cookie(self, path: str) -> bool:
        """True when the request carries the token in its query (set the cookie)."""
        return self.token is not None and same_token(self._query_token(path), self.token)

    @property
    def cookie(self) -> str:
        """Name of this page's cookie."""
        return cookie_name(self.role)

    def cookie_header(self) -> str:
        """The ``Set-Cookie`` value that lets the browser's later requests through."""
        return f"{self.cookie}={self.token}; Path=/; HttpOnly; SameSite=Strict"

    @staticmethod
    def _query_token(path: str) -> str | None:
        values = parse_qs(urlsplit(path).query).get("token")
        return values[0] if values else None

    def _has_token(self, path: str, headers: Any) -> bool:
        assert self.token is not None
        if same_token(self._query_token(path), self.token):
            return True
        cookie = http.cookies.SimpleCookie()
        try:
            cookie.load(headers.get("Cookie") or "")
        except http.cookies.CookieError:
            return False
        morsel = cookie.get(self.cookie)
        return morsel is not None and same_token(morsel.value, self.token)


def is_loopback(host: str) -> bool:
    """True when a bind address only accepts connections from this machine."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def access_policy(host: str, token: str | None, role: str | None = None) -> AccessPolicy:
    """The policy of a viewer (page of ``role``) bound to ``host``.

    Raises:
        ConfigError: ``host`` is beyond loopback and no token was given (the CLI makes one
            only with ``--expose``).
    """
    expect(is_loopback(host) or token, host, "a loopback host, or a token with this one "
           "(it exposes the viewer beyond this machine: it needs an access token; vasim "
           "serve --expose makes one)", field="host")
    return AccessPolicy(loopback_only=is_loopback(host), token=token or None, role=role)


def viewer_url(host: str, port: int, token: str | None) -> str:
    """The address to open in a browser (wildcard hosts shown as 127.0.0.1), with the token.

    Example:
        >>> viewer_url("0.0.0.0", 8080, "abc")
        'http://127.0.0.1:8080/?token=abc'
    """
    if host in ("0.0.0.0", "::", ""):
        host = "127.0.0.1"
    elif ":" in host and not host.startswith("["):
        host = f"[{host}]"
    return f"http://{host}:{port}/" + (f"?token={token}" if token else "")


def _peer(connection: Any) -> str:
    """``host:port`` of a connection's client (best effort, for the log)."""
    try:
        addr = connection.remote_address
        return f"{addr[0]}:{addr[1]}"
    except Exception:
        return "?"


_serve_lock = threading.Lock()


@contextmanager
def _guarded_serve(policy: AccessPolicy) -> Iterator[None]:
    """Wraps ``websockets.asyncio.server.serve`` so the next server bound gets the check."""
    original = websockets.asyncio.server.serve

    def serve(handler: Any, *args: Any, process_request: Callable[..., Any] | None = None,
              **kwargs: Any) -> Any:
        def check(connection: Any, request: Any) -> Any:
            try:
                reason = policy.refusal(request.path, request.headers)
            except Exception as exc:  # a request the policy cannot read is refused
                reason = f"unreadable request ({type(exc).__name__})"
            if reason is not None:
                log.warning("vasim viewer (%s page): refused %s %s from %s: %s",
                            policy.role or "single", "websocket" if
                            request.headers.get("Upgrade") else "request",
                            urlsplit(request.path).path[:80],
                            _peer(connection), reason)
                return connection.respond(http.HTTPStatus.FORBIDDEN,
                                          f"vasim viewer: refused: {reason}\n")
            response = process_request(connection, request) if process_request else None
            if response is not None and policy.grants_cookie(request.path):
                response.headers["Set-Cookie"] = policy.cookie_header()
            return response

        return original(handler, *args, process_request=check, **kwargs)

    with _serve_lock:
        setattr(websockets.asyncio.server, "serve", serve)  # noqa: B010 (see module doc)
        try:
            yield
        finally:
            setattr(websockets.asyncio.server, "serve", original)  # noqa: B010


def guarded_server(host: str, port: int, policy: AccessPolicy) -> viser.ViserServer:
    """A ``viser.ViserServer`` bound to ``host:port`` whose every request passes ``policy``
    and whose every client message is validated (:mod:`vasim.viewer.isolation`)."""
    from vasim.viewer import isolation

    isolation.install()
    with _guarded_serve(policy):
        return viser.ViserServer(host=host, port=port, verbose=False)


__all__ = ["COOKIE", "AccessPolicy", "access_policy", "cookie_name", "guarded_server",
           "is_loopback", "is_loopback_name", "new_token", "same_token", "viewer_url"]
