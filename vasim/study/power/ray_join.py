"""Starting or joining Ray for a power run: the ``--address`` checks and ``ray.init`` in
a thread the command can interrupt (see :mod:`vasim.study.power.driver`'s decisions, which
describe them).

**Decision** (issue #29 item 4): these live in their own module, below both the driver and
the backends (:mod:`vasim.study.power.backend` starts Ray through :func:`init_ray`), so that
``backend`` no longer imports ``driver`` (the former ``backend`` <-> ``driver`` module
cycle, hidden by a function-level import). The driver re-exports the names it always had.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from typing import Any

from vasim.core.config import expect, fail
from vasim.core.errors import ConfigError, FieldError, InputError

ADDRESS_CHECK_S = 15.0
"""Seconds the address check waits for the name lookup, the connection and the answer. A
refused or unresolvable address fails at once; this bounds a silent one. 3 s was too short
for a Ray Client server on a loaded machine (a ray:// run of the cluster test failed at load
11 while the same cluster's GCS address worked)."""
JOIN_TIMEOUT_S = 120.0
"""Seconds ``ray.init`` may take to join a cluster (a local Ray start is not limited)."""
_HTTP2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])
"""The HTTP/2 client connection preface and an empty SETTINGS frame."""


def parse_ray_address(address: str) -> tuple[str, int] | None:
    """The (host, port) of a Ray address, or None for ``auto`` (the cluster on this node).

    Raises:
        InputError: (field ``--address``, a command-line argument) an empty or malformed
            address, a bad host or port.

    Examples:
        >>> parse_ray_address("ray://10.0.0.5:10001"), parse_ray_address("[::1]:6379")
        (('10.0.0.5', 10001), ('::1', 6379))
        >>> parse_ray_address("auto") is None
        True
        >>> parse_ray_address("127.0.0.1:99999")
        Traceback (most recent call last):
        ...
        vasim.core.errors.InputError: field '--address': got '127.0.0.1:99999', expected a \
port in 1-65535 (ray://HOST:PORT, HOST:PORT or auto)
    """
    import ipaddress
    import re

    form = "(ray://HOST:PORT, HOST:PORT or auto)"
    arg: dict[str, Any] = {"field": "--address", "error": InputError}   # an argument
    expect(isinstance(address, str) and address.strip(), address,
            f"a Ray address {form}; leave --address out for a local Ray", **arg)
    if address == "auto":
        return None
    rest = address[len("ray://"):] if address.startswith("ray://") else address
    m = re.fullmatch(r"\[([0-9A-Fa-f:.]+)\]:(\d{1,5})|([^:\[\]/]+):(\d{1,5})", rest)
    if m is None:
        raise fail(address, f"a Ray address {form} (an IPv6 host in brackets: [::1]:6379)",
                   **arg)
    host, port = (m.group(1), int(m.group(2))) if m.group(1) else (m.group(3), int(m.group(4)))
    expect(1 <= port <= 65535, address, f"a port in 1-65535 {form}", **arg)
    try:
        ipaddress.ip_address(host)
    except ValueError:
        labels = host.rstrip(".").split(".")
        ok = (len(host) <= 253 and all(re.fullmatch(
            r"[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?", lb) for lb in labels)
            and not all(lb.isdigit() for lb in labels))
        expect(ok, address, f"an IP address or a host name (RFC 1123) before the port {form}",
                **arg)
    return host, port


def probe_ray_address(host: str, port: int, timeout: float = ADDRESS_CHECK_S) -> None:
    """Checks that ``host:port`` answers within ``timeout`` seconds (name lookup, TCP
    connection, and an HTTP/2 SETTINGS frame in reply to the HTTP/2 preface: the gRPC of a
    Ray head's GCS port and of a Ray Client server).

    Raises:
        ConfigError: (field ``--address``) naming the address, what failed and what to check.
    """
    import socket
    import threading

    where = f"{host}:{port}" if ":" not in host else f"[{host}]:{port}"
    hint = ("; check the address and that the head runs (`ray start --head` prints it)")
    found: list[Any] = []

    def lookup() -> None:
        try:
            found.append(socket.getaddrinfo(host, port, type=socket.SOCK_STREAM))
        except OSError as exc:
            found.append(exc)

    t = threading.Thread(target=lookup, name="vasim-ray-address-lookup", daemon=True)
    t.start()
    t.join(timeout)
    if not found:
        raise ConfigError(f"cannot reach the Ray cluster {where}: the name {host!r} did not "
                          f"resolve within {timeout:g} s{hint}", field="--address")
    if isinstance(found[0], OSError):
        raise ConfigError(f"cannot reach the Ray cluster {where}: {found[0]}{hint}",
                          field="--address")
    family, kind, proto, _, sockaddr = found[0][0]
    try:
        with socket.socket(family, kind, proto) as sock:
            sock.settimeout(timeout)
            sock.connect(sockaddr)
            sock.sendall(_HTTP2_PREFACE)
            head = b""
            while len(head) < 9:
                chunk = sock.recv(9 - len(head))
                if not chunk:
                    break
                head += chunk
    except TimeoutError:
        raise ConfigError(f"cannot reach the Ray cluster {where}: no answer within "
                          f"{timeout:g} s{hint}", field="--address") from None
    except OSError as exc:
        raise ConfigError(f"cannot reach the Ray cluster {where}: "
                          f"{exc.strerror or exc}{hint}", field="--address") from None
    if len(head) < 9 or head[3] != 4:   # frame type 4: SETTINGS
        raise ConfigError(f"{where} answers but is not a Ray head: it does not speak gRPC "
                          f"(HTTP/2){hint} (the GCS port, 6379 by default, or ray://HOST:10001)",
                          field="--address")


def _init_in_thread(init: Callable[[], object], timeout: float | None, what: str) -> None:
    """Runs ``init`` (``ray.init``) in a helper thread while this thread waits, so that
    Ctrl-C / SIGTERM reach the command at once; ``timeout`` [s] (None: none) bounds it.

    Raises:
        ConfigError: ``init`` did not return within ``timeout``. What ``init`` raised.
        KeyboardInterrupt: while waiting (the helper thread is a daemon: it ends with the
            process).
    """
    import threading

    box: list[BaseException | None] = []

    def run() -> None:
        try:
            init()
            box.append(None)
        except BaseException as exc:  # handed to the waiting thread
            box.append(exc)

    import logging

    # Ray warns that it sets no SIGTERM handler outside the main thread: the command line
    # sets its own (vasim.cli.power), so the warning would only mislead.
    logging.getLogger("ray._private.worker").addFilter(
        lambda r: "SIGTERM handler is not set" not in r.getMessage())
    t = threading.Thread(target=run, name="vasim-ray-init", daemon=True)
    t.start()
    end = None if timeout is None else time.monotonic() + timeout
    while t.is_alive():
        t.join(0.2)
        if end is not None and time.monotonic() > end and t.is_alive():
            raise ConfigError(f"{what} did not answer within {timeout:g} s; check that it is "
                              "a running Ray cluster of the same Ray version", field="--address")
    if box and box[0] is not None:
        raise box[0]


LOCAL_SYSTEM_CONFIG = {"worker_niceness": 0}
"""Ray settings of a local start.

**Decision** (issue #31): a local Ray's workers run at the niceness of the command that
starts them, not Ray's default of 15 more. The workers do all of a power run's work while
the command waits for them; at niceness 15 any other busy process on the machine took their
cores (a power run that took 100 s beside two busy loops at niceness 15 took 310 s beside
two at niceness 0). Who wants a power run to yield runs it as ``nice -n 15 vasim study
power ...``: the workers then run at that niceness too. A cluster joined by ``--address``
keeps its own setting."""


def init_ray(address: str | None, workers: int | None) -> int:
    """Starts (or joins) Ray and returns the CPUs it offers.

    Raises:
        ConfigError: (field ``--address``) Ray could not start or reach the cluster.
    """
    import ray

    if workers is not None:
        expect(workers >= 1, workers, "at least 1 Ray worker (a power run always runs on "
                "Ray)", field="--workers")
    if address is not None:
        target = parse_ray_address(address)
        if address.startswith("ray://"):   # Ray Client needs grpcio (the ray[client] extra)
            from ray.client_builder import get_ray_client_dependency_error

            missing = get_ray_client_dependency_error()
            if missing is not None:
                raise ConfigError(f"could not join the Ray cluster {address!r}: {missing}"
                                  f"{_join_hint(address)}", field="--address")
        if target is not None:
            probe_ray_address(*target)
    try:
        if address:
            _init_in_thread(lambda: ray.init(address=address, log_to_driver=False),
                            JOIN_TIMEOUT_S, f"the Ray cluster {address!r}")
        else:   # a local start: in this thread, as before (it does not hang)
            ray.init(num_cpus=workers or (os.cpu_count() or 1), include_dashboard=False,
                     log_to_driver=False, _node_ip_address="127.0.0.1",
                     _system_config=LOCAL_SYSTEM_CONFIG)
    except KeyboardInterrupt:
        raise
    except FieldError:
        raise
    except (ConnectionError, RuntimeError, ValueError) as exc:
        ray.shutdown()
        where = f"the Ray cluster {address!r}" if address else "a local Ray"
        raise ConfigError(f"could not start or join {where}: {exc}{_join_hint(address)}",
                          field="--address") from None
    return int(ray.cluster_resources().get("CPU", 0))


def _join_hint(address: str | None) -> str:
    """What to check when joining ``address`` failed (nothing for a local Ray).

    **Decision**: Ray 2.60 enables token authentication on a cluster whose head finds a
    token (``~/.ray/auth_token``), but a driver given an explicit address never enables it
    by itself; such a join fails with "Authentication token is missing or incorrect"
    repeated until Ray's timeout. vasim does not set the mode for the user (it would send
    a token to any address named); the error says what to export instead.

    >>> _join_hint(None)
    ''
    >>> "RAY_AUTH_MODE=token" in _join_hint("10.0.0.5:6379")
    True
    """
    if not address:
        return ""
    hint = ("; a cluster with token authentication needs RAY_AUTH_MODE=token and its token "
            "(RAY_AUTH_TOKEN, RAY_AUTH_TOKEN_PATH or ~/.ray/auth_token) in this shell")
    if address.startswith("ray://"):
        hint += "; a ray:// address needs the ray[client] extra installed"
    return hint
