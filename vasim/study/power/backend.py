"""Where a power run's cohorts run: Ray (``vasim[cluster]``) or a local process pool.

:func:`choose_backend` picks one and :func:`open_backend` runs one task per cohort on it,
yielding the results as they finish (the driver sorts them afterwards, so the table does
not depend on which backend ran the tasks, nor on their order).

``ray``
    A local Ray on this machine, or the cluster ``--address`` names
    (:func:`vasim.study.power.ray_join.init_ray`). Needs the ``cluster`` extra.
``processes``
    A ``concurrent.futures.ProcessPoolExecutor`` of ``workers`` processes (default: the
    machine's cores) started with ``spawn`` (a fresh interpreter per worker, as a Ray worker
    is; forking a process that has started threads is unsafe). Nothing to install.

**Decisions** (issue #27 item 1):

* ``auto`` (the default) keeps the behaviour vasim had when Ray was a core dependency: a
  local Ray when Ray is installed, else the process pool. ``--address`` always means Ray;
  without the ``cluster`` extra it is a one-line error naming the extra.
* Both backends call the same task function with the same arguments, and a cohort is a pure
  function of its seed (``cohort_seed``), so the two give the same cohort rows for the same
  seed (tested in ``tests/study/power/test_backend.py``).
* On an error or Ctrl-C the pool's queued cohorts are cancelled and its workers
  terminated: a cohort takes minutes, and nobody would wait for its result.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Literal

from vasim.core.config import check_choice, expect
from vasim.core.extras import installed, require
from vasim.study.power.ray_join import init_ray

Backend = Literal["ray", "processes"]
BACKENDS: tuple[str, ...] = ("auto", "ray", "processes")
"""Values of ``--backend``."""


def choose_backend(backend: str = "auto", address: str | None = None) -> Backend:
    """The backend a run uses.

    Args:
        backend: ``"auto"``, ``"ray"`` or ``"processes"``. address: the Ray cluster to
            join (``--address``), if any.

    Raises:
        ConfigError: an unknown backend, or ``processes`` with an address.
        MissingExtraError: Ray is needed (``ray``, or an address) and not installed.

    >>> choose_backend("processes")
    'processes'
    """
    check_choice(backend, "--backend", BACKENDS)
    if address:
        expect(backend != "processes", backend, f"ray: --address {address} joins a Ray "
                "cluster; it cannot run on local processes (drop --backend processes)",
                field="--backend")
        require("ray", "--address (a Ray cluster)")
        return "ray"
    if backend == "ray":
        require("ray", "--backend ray")
        return "ray"
    if backend == "processes":
        return "processes"
    return "ray" if installed("ray") else "processes"


@dataclass
class Running:
    """A started backend: its name, the CPUs it offers, and :meth:`results`."""

    name: Backend
    cpus: int
    results: Callable[[Callable[..., Any], Sequence[tuple[Any, ...]]], Iterator[Any]]


def pool_workers(workers: int | None) -> int:
    """Worker processes of the pool: ``workers``, default the machine's cores.

    Raises:
        ConfigError: (field ``--workers``) fewer than 1.

    >>> pool_workers(3)
    3
    """
    if workers is not None:
        expect(workers >= 1, workers, "at least 1 worker process", field="--workers")
    return workers or (os.cpu_count() or 1)


@contextmanager
def open_backend(name: Backend, *, address: str | None = None,
                 workers: int | None = None) -> Iterator[Running]:
    """Starts ``name`` and yields it; stops it on leaving (errors and Ctrl-C included).

    ``Running.results(fn, args)`` submits ``fn(*a)`` for each ``a`` in ``args`` and yields
    the return values in order of completion.

    Raises:
        ConfigError: Ray could not start or join ``address``; bad ``workers``.
    """
    if name == "ray":
        yield from _ray(address, workers)
    else:
        yield from _processes(workers)


def _ray(address: str | None, workers: int | None) -> Iterator[Running]:
    ray = require("ray", "--backend ray")
    cpus = init_ray(address, workers)
    shared: dict[int, Any] = {}

    def put(v: Any) -> Any:
        # one object-store copy per distinct argument object (the protocol, the design)
        if id(v) not in shared:
            shared[id(v)] = ray.put(v)
        return shared[id(v)]

    def results(fn: Callable[..., Any], args: Sequence[tuple[Any, ...]]) -> Iterator[Any]:
        task = ray.remote(num_cpus=1)(fn)
        pending = [task.remote(*(put(v) if _large(v) else v for v in a)) for a in args]
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            yield ray.get(done[0])

    try:
        yield Running("ray", cpus, results)
    finally:
        ray.shutdown()


def _large(v: Any) -> bool:
    """Arguments handed through Ray's object store rather than with each task."""
    return not isinstance(v, int | float | str | type(None))


def _processes(workers: int | None) -> Iterator[Running]:
    n = pool_workers(workers)
    pool = ProcessPoolExecutor(max_workers=n, mp_context=multiprocessing.get_context("spawn"))

    def results(fn: Callable[..., Any], args: Sequence[tuple[Any, ...]]) -> Iterator[Any]:
        pending: set[Future[Any]] = {pool.submit(fn, *a) for a in args}
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                yield fut.result()

    try:
        yield Running("processes", n, results)
    except BaseException:
        _terminate(pool)
        raise
    pool.shutdown(wait=True)


def _terminate(pool: ProcessPoolExecutor) -> None:
    """Cancels the queued tasks and ends the running workers (minutes of work each)."""
    # the pool's worker processes (a CPython detail; ``terminate_workers`` is Python 3.14's)
    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        if proc.is_alive():
            proc.terminate()


__all__ = ["BACKENDS", "Backend", "Running", "choose_backend", "open_backend", "pool_workers"]
