"""The driver of a power run (the stateful shell): one task per cohort, on Ray or, without
the ``cluster`` extra (or with ``backend="processes"``), on a local process pool
(:mod:`vasim.study.power.backend`, issue #27 item 1; what follows describes Ray).

:func:`run_power` starts a local Ray on this machine (``ray.init(num_cpus=workers,
include_dashboard=False)``, its processes on 127.0.0.1) or joins the cluster ``address``
names: ``host:port`` (the head's GCS port; the driver must run on a node of the
cluster, tested in ``tests/study/power/test_cluster.py``), ``auto`` (the cluster started on
this node) or ``ray://head:10001`` (Ray Client, from anywhere; the ``ray[client]`` extra,
a dependency of vasim; tested against a client server in the same file). It submits one
task per design point and cohort (:func:`~vasim.study.power.cohort.cohort_tests`),
collects them as they finish with a progress bar over cohorts (:mod:`vasim.core.progress`)
and always shuts Ray down (``ray.shutdown()`` in a ``finally``: Ctrl-C and errors
included; a local Ray's processes end with it).

**Decisions**:

* One task = one cohort (``num_cpus=1``): a cohort at the VF protocol's 38 trials per
  subject is minutes of CPU, so Ray's per-task overhead (milliseconds) is negligible, and
  a cohort's analysis needs all of its trials together. The result is a few rows.
* The protocol is parsed once on the driver and handed to the tasks through the object
  store (``ray.put``); fixture schemas and scenes are read by each worker from its own
  vasim installation. On a cluster every node must therefore run the same vasim (same
  commit, its ``protocols/`` included), which the driver checks: every task returns its
  node's vasim version, and a mismatch is an error.
* On a local Ray, ``workers`` (``--workers``) sets Ray's CPUs (default: the machine's
  cores); with ``--address`` the cluster's own resources decide and ``workers`` is ignored.
* Results are returned in order of completion and sorted afterwards, so the table does not
  depend on scheduling.
* ``--address`` is checked before Ray sees it (issue #30 item 4: ``127.0.0.1:1``, port
  99999, a 10,000-character host ran for minutes, deaf to Ctrl-C, and ``''`` silently
  started a local Ray): :func:`parse_ray_address` checks the syntax (``auto``,
  ``HOST:PORT`` or ``ray://HOST:PORT``; an IPv4/IPv6 address or an RFC 1123 name, IPv6
  in brackets; port 1-65535) and :func:`probe_ray_address` that something answers there
  within :data:`ADDRESS_CHECK_S` seconds and speaks gRPC (HTTP/2, as a Ray head's GCS port
  and a Ray Client server do): a refused connection, an unresolvable name, a timeout or a
  server that is not HTTP/2 is one clear error, not minutes of Ray retrying. Ray's own
  start or join then runs in a helper thread the main thread waits on, so Ctrl-C and
  SIGTERM (turned into ``KeyboardInterrupt`` by the command line) end the command at once
  even while Ray's C++ client retries, and a join that takes longer than
  :data:`JOIN_TIMEOUT_S` is an error. A local Ray starts in the main thread, as before.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import pandas as pd

from vasim.core.errors import ConfigError
from vasim.core.progress import progress_bar
from vasim.study.power.backend import choose_backend, open_backend
from vasim.study.power.cohort import CohortOutcome, cohort_tests
from vasim.study.power.design import PowerDesign, check_power_protocol
from vasim.study.power.estimate import power_table
from vasim.study.protocol import Protocol


@dataclass(frozen=True)
class PowerResult:
    """A finished power run.

    Attributes:
        cohorts: one row per cohort and primary test (``COHORT_COLUMNS``).
        power: :func:`~vasim.study.power.estimate.power_table` of it.
        wall_seconds: the run's wall-clock time [s]. task_seconds: the tasks' summed wall
            time [s]. cpu_seconds: the tasks' summed process CPU time [s] (below
            ``task_seconds`` when they waited for cores). sim_seconds: simulated trial
            time [s]. n_trials: trials run.
        workers: CPUs Ray offered. address: the cluster joined (None: a local Ray).
        ray_seconds: time to start or join Ray, or to start the process pool [s] (part of
            ``wall_seconds``).
        backend: where the cohorts ran, ``"ray"`` or ``"processes"``.
    """

    cohorts: pd.DataFrame
    power: pd.DataFrame
    wall_seconds: float
    task_seconds: float
    cpu_seconds: float
    sim_seconds: float
    n_trials: int
    workers: int
    address: str | None
    ray_seconds: float = 0.0
    backend: str = "ray"

    @property
    def cohorts_per_second(self) -> float:
        """Cohorts finished per wall-clock second."""
        n = int(self.cohorts[["n_subjects", "cohort"]].drop_duplicates().shape[0])
        return n / self.wall_seconds if self.wall_seconds > 0 else float("nan")


def _vasim_version() -> str:
    from vasim import __version__

    return str(__version__)


def _task(protocol: Protocol, design: PowerDesign, n: int, k: int,
          keep_dir: str | None) -> tuple[CohortOutcome, str]:
    return cohort_tests(protocol, design, n, k, keep_dir), _vasim_version()


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
        ConfigError: (field ``--address``) an empty or malformed address, a bad host or port.

    Examples:
        >>> parse_ray_address("ray://10.0.0.5:10001"), parse_ray_address("[::1]:6379")
        (('10.0.0.5', 10001), ('::1', 6379))
        >>> parse_ray_address("auto") is None
        True
        >>> parse_ray_address("127.0.0.1:99999")
        Traceback (most recent call last):
        ...
        vasim.core.errors.ConfigError: field '--address': got '127.0.0.1:99999', expected a \
port in 1-65535 (ray://HOST:PORT, HOST:PORT or auto)
    """
    import ipaddress
    import re

    from vasim.core.config import show

    form = "(ray://HOST:PORT, HOST:PORT or auto)"
    if not isinstance(address, str) or not address.strip():
        raise ConfigError(f"got {show(address)}, expected a Ray address {form}; leave "
                          "--address out for a local Ray", field="--address")
    if address == "auto":
        return None
    rest = address[len("ray://"):] if address.startswith("ray://") else address
    m = re.fullmatch(r"\[([0-9A-Fa-f:.]+)\]:(\d{1,5})|([^:\[\]/]+):(\d{1,5})", rest)
    if m is None:
        raise ConfigError(f"got {show(address)}, expected a Ray address {form} (an IPv6 host "
                          "in brackets: [::1]:6379)", field="--address")
    host, port = (m.group(1), int(m.group(2))) if m.group(1) else (m.group(3), int(m.group(4)))
    if not 1 <= port <= 65535:
        raise ConfigError(f"got {show(address)}, expected a port in 1-65535 {form}",
                          field="--address")
    try:
        ipaddress.ip_address(host)
    except ValueError:
        labels = host.rstrip(".").split(".")
        ok = (len(host) <= 253 and all(re.fullmatch(
            r"[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?", lb) for lb in labels)
            and not all(lb.isdigit() for lb in labels))
        if not ok:
            raise ConfigError(f"got {show(address)}, expected an IP address or a host name "
                              f"(RFC 1123) before the port {form}", field="--address") from None
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


def init_ray(address: str | None, workers: int | None) -> int:
    """Starts (or joins) Ray and returns the CPUs it offers.

    Raises:
        ConfigError: (field ``--address``) Ray could not start or reach the cluster.
    """
    import ray

    if workers is not None and workers < 1:
        raise ConfigError(f"got {workers!r}, expected at least 1 Ray worker (a power run "
                          "always runs on Ray)", field="--workers")
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
                     log_to_driver=False, _node_ip_address="127.0.0.1")
    except KeyboardInterrupt:
        raise
    except ConfigError:
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


def run_power(protocol: Protocol, design: PowerDesign, *, address: str | None = None,
              workers: int | None = None, keep_dir: str | os.PathLike[str] | None = None,
              progress: bool = True,
              on_cohort: Callable[[CohortOutcome], None] | None = None,
              backend: str = "auto") -> PowerResult:
    """Simulates and analyses every cohort of ``design`` on Ray; returns the power table.

    Args:
        protocol: the protocol (``check_runnable``). design: the run.
        address: a Ray cluster to join (None: a local Ray on this machine).
        workers: CPUs of the local Ray (None: the machine's cores).
        keep_dir: write each cohort's study database there (None: nothing written).
        progress: the progress bar over cohorts. on_cohort: called with each finished
            cohort (e.g. by the benchmark).
        backend: ``"auto"``, ``"ray"`` or ``"processes"``
            (:mod:`vasim.study.power.backend`; ``auto``: Ray when installed).

    Raises:
        ConfigError: a protocol that cannot run, Ray that does not start, nodes that run
            another vasim.
    """
    protocol.check_runnable()
    check_power_protocol(protocol)
    name = choose_backend(backend, address)
    keep = None
    if keep_dir is not None:
        kd = os.fspath(keep_dir)
        if os.path.exists(kd) and not os.path.isdir(kd):
            raise ConfigError("is not a folder", file=kd, field="--keep-cohorts")
        os.makedirs(kd, exist_ok=True)
        keep = os.path.abspath(kd)
    t0 = time.perf_counter()
    frames: list[pd.DataFrame] = []
    waited = cpu = sim = 0.0
    trials = 0
    mine = _vasim_version()
    with open_backend(name, address=address, workers=workers) as running:
        t_ray = time.perf_counter() - t0
        bar = progress_bar(design.n_cohorts, f"power {protocol.name}", "cohort",
                           enabled=progress)
        try:
            args = [(protocol, design, n, k, keep)
                    for n in design.subjects for k in range(design.cohorts)]
            for outcome, version in running.results(_task, args):
                if version != mine:
                    raise ConfigError(f"a Ray node runs vasim {version}, this driver {mine}: "
                                      "install the same vasim on every node",
                                      field="--address")
                frames.append(outcome.tests)
                waited += outcome.wall_seconds
                cpu += outcome.cpu_seconds
                sim += outcome.sim_seconds
                trials += outcome.n_trials
                if on_cohort is not None:
                    on_cohort(outcome)
                bar.update(1)
                t = outcome.tests.iloc[0] if len(outcome.tests) else None
                if t is not None:
                    bar.set_postfix_str(
                        f"N={int(t['n_subjects'])} cohort {int(t['cohort']) + 1}")
        finally:
            bar.close()
    cohorts = pd.concat(frames, ignore_index=True).sort_values(
        ["n_subjects", "cohort", "factor", "dv"]).reset_index(drop=True)
    table = power_table(cohorts, alpha=design.alpha, p_column=design.p_column)
    return PowerResult(cohorts=cohorts, power=table, wall_seconds=time.perf_counter() - t0,
                       task_seconds=waited, cpu_seconds=cpu, sim_seconds=sim,
                       n_trials=trials, workers=running.cpus, address=address,
                       ray_seconds=t_ray, backend=name)


__all__ = ["ADDRESS_CHECK_S", "JOIN_TIMEOUT_S", "PowerResult", "init_ray",
           "parse_ray_address", "probe_ray_address", "run_power"]
