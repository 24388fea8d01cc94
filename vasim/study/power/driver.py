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

import pandas as pd

from vasim.core.config import check_dir_path
from vasim.core.errors import ConfigError
from vasim.core.progress import progress_bar
from vasim.study.power.backend import choose_backend, open_backend
from vasim.study.power.cohort import CohortOutcome, cohort_tests
from vasim.study.power.design import PowerDesign, check_power_protocol
from vasim.study.power.estimate import power_table
from vasim.study.power.ray_join import (
    ADDRESS_CHECK_S,
    JOIN_TIMEOUT_S,
    init_ray,
    parse_ray_address,
    probe_ray_address,
)
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
        check_dir_path(kd, "--keep-cohorts", error=ConfigError)
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
