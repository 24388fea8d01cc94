"""Where power cohorts run (vasim/study/power/backend.py, issue #27 item 1): the local process
pool gives the same cohort rows as Ray for the same seed; without the ``cluster`` extra a
power run falls back to the pool and ``--address`` is a one-line error naming the extra; a
failed pool run leaves no worker behind."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import pandas as pd
import psutil
import pytest

from vasim.cli import main
from vasim.core.extras import MissingExtraError
from vasim.study.power.backend import choose_backend, pool_workers
from vasim.study.power.design import COARSE_DT, PowerDesign
from vasim.study.power.driver import run_power
from vasim.study.power.estimate import COHORT_COLUMNS
from vasim.study.protocol import Protocol


def _no_ray(monkeypatch: pytest.MonkeyPatch) -> None:
    """Ray as if not installed: ``import ray`` raises ImportError (None in sys.modules)."""
    for name in [m for m in sys.modules if m == "ray" or m.startswith("ray.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "ray", None)


def _workers(p: psutil.Process) -> bool:
    """A pool worker (multiprocessing's spawn entry point), not its resource tracker."""
    try:
        cmd = " ".join(p.cmdline())
        return (p.status() != psutil.STATUS_ZOMBIE and "spawn_main" in cmd
                and "resource_tracker" not in cmd)
    except psutil.Error:
        return False


def _children_left(timeout: float = 20.0) -> list[psutil.Process]:
    """This process's pool workers still alive after ``timeout`` seconds."""
    end = time.monotonic() + timeout
    while True:
        kids = [p for p in psutil.Process().children(recursive=True) if _workers(p)]
        if not kids or time.monotonic() > end:
            return kids
        time.sleep(0.25)


@pytest.mark.timeout(900)   # a local Ray's start alone took 36 s on the loaded machine
def test_process_pool_and_ray_give_the_same_cohorts(tiny_protocol: Protocol) -> None:
    design = PowerDesign(subjects=(2,), cohorts=2, dt=COARSE_DT, max_trial_time=0.4, seed=5)
    pool = run_power(tiny_protocol, design, workers=2, progress=False, backend="processes")
    ray = run_power(tiny_protocol, design, workers=2, progress=False, backend="ray")
    assert (pool.backend, ray.backend) == ("processes", "ray")
    assert list(pool.cohorts.columns) == list(COHORT_COLUMNS)
    assert set(pool.cohorts["cohort"]) == {0, 1} and set(pool.cohorts["n_subjects"]) == {2}
    assert pool.n_trials == ray.n_trials == 2 * 2 * 8
    # a cohort is a pure function of its seed: the same numbers, bit for bit
    pd.testing.assert_frame_equal(pool.cohorts, ray.cohorts, check_exact=True)
    pd.testing.assert_frame_equal(pool.power, ray.power, check_exact=True)
    assert pool.sim_seconds == ray.sim_seconds


def test_without_ray_auto_is_the_process_pool(monkeypatch: pytest.MonkeyPatch) -> None:
    _no_ray(monkeypatch)
    assert choose_backend("auto") == "processes"
    assert choose_backend("processes") == "processes"
    for backend, address in (("auto", "ray://head:10001"), ("ray", None)):
        with pytest.raises(MissingExtraError) as err:
            choose_backend(backend, address)
        msg = str(err.value)
        assert "\n" not in msg and "pip install 'vasim[cluster]'" in msg, msg


def test_with_ray_auto_keeps_the_local_ray(monkeypatch: pytest.MonkeyPatch) -> None:
    # Ray is installed with the test dependencies (`make test`: the cluster extra);
    # importing it (for an address) sets RAY_CLIENT_MODE: undone after the test
    monkeypatch.setenv("RAY_CLIENT_MODE", "")
    monkeypatch.delenv("RAY_CLIENT_MODE")
    assert choose_backend("auto") == "ray"
    assert choose_backend("auto", "auto") == "ray"


def test_bad_backend_choices_are_config_errors() -> None:
    with pytest.raises(ValueError, match="field '--backend': got 'dask', expected one of "
                                         "'auto', 'ray', 'processes'"):
        choose_backend("dask")
    with pytest.raises(ValueError, match="cannot run on local processes"):
        choose_backend("processes", "ray://head:10001")
    with pytest.raises(ValueError, match="at least 1 worker process"):
        pool_workers(0)


def test_address_without_the_cluster_extra_is_one_line(
        monkeypatch: pytest.MonkeyPatch, tiny_protocol_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    _no_ray(monkeypatch)
    code = main(["study", "power", "--protocol", str(tiny_protocol_path), "--subjects", "2",
                 "--cohorts", "1", "--address", "ray://127.0.0.1:1", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "'cluster' extra" in err and "vasim[cluster]" in err, err
    assert not _children_left(0.0)


def test_a_power_run_without_ray_runs_on_the_pool(
        monkeypatch: pytest.MonkeyPatch, tiny_protocol_path: Path, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    _no_ray(monkeypatch)
    code = main(["study", "power", "--protocol", str(tiny_protocol_path), "--subjects", "2",
                 "--cohorts", "2", "--coarse", "--max-time", "0.5", "--workers", "2",
                 "--no-progress", "--out", str(tmp_path / "out")])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "on 2 CPU(s) (local processes)" in text
    power = pd.read_csv(tmp_path / "out" / "power.csv")
    assert set(power["n_subjects"]) == {2} and set(power["cohorts"]) == {2}
    assert "ray" not in sys.modules or sys.modules["ray"] is None   # never imported
    assert not _children_left()


def test_a_failed_pool_run_ends_its_workers(tiny_protocol: Protocol) -> None:
    design = PowerDesign(subjects=(2,), cohorts=4, dt=COARSE_DT, max_trial_time=0.5)

    def stop(_outcome: object) -> None:
        raise RuntimeError("stop after the first cohort")

    with pytest.raises(RuntimeError, match="stop after"):
        run_power(tiny_protocol, design, workers=2, progress=False, on_cohort=stop,
                  backend="processes")
    assert not _children_left()
