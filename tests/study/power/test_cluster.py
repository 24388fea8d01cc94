"""`vasim study power --address` against a real Ray cluster started on this machine
(`ray start --head --block` on 127.0.0.1, 1 CPU), compared with the local-Ray run of the
same seed (vasim/study/power/driver.py).

The cluster is this test's own: `ray start --block` runs as a child process in its own
session with its own `--temp-dir` (where it records `ray_current_cluster`, so a concurrent
`ray.init()` on the machine, which looks in /tmp/ray, never finds and joins it), and
teardown ends it and its descendants by pid (never `ray stop`, which would stop every Ray
of the user on the machine) and removes its temp dir. Starting it takes
~10 s here (2026-11-27), so the test stays in the suite. The cluster uses token
authentication (Ray 2.60) with a token of the test's own, given to the driver as
``RAY_AUTH_MODE=token`` and ``RAY_AUTH_TOKEN``: what a user joining such a cluster exports.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import time
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pandas as pd
import psutil
import pytest

import vasim
from vasim.cli import main

RAY = Path(sys.executable).with_name("ray")
START_TIMEOUT_S = 180.0   # a condition-based wait: the head started in 37 s at load 25 and
# had not in 60 s at load 41 (2026-11-28, the shared 2-core machine)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait_for_gcs(port: int, proc: subprocess.Popen[bytes], log: Path) -> None:
    """Until the cluster's GCS accepts connections and `ray start` reports it started."""
    end = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < end:
        if proc.poll() is not None:
            pytest.fail(f"ray start exited {proc.returncode}: {log.read_text()[-2000:]}")
        if "Ray runtime started" in log.read_text(errors="replace"):
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", port)) == 0:
                    return
        time.sleep(0.25)
    pytest.fail(f"the Ray head did not start in {START_TIMEOUT_S} s: "
                f"{log.read_text()[-2000:]}")


AUTH_VARS = ("RAY_AUTH_MODE", "RAY_AUTH_TOKEN", "RAY_AUTH_TOKEN_PATH")


def _reset_ray_auth() -> None:
    """Makes this process's Ray re-read the authentication variables (Ray caches them)."""
    from ray._raylet import AuthenticationTokenLoader, Config

    Config.initialize("")
    AuthenticationTokenLoader.instance().reset_cache()


@contextmanager
def _cluster_token() -> Iterator[dict[str, str]]:
    """Token authentication with a token of this test's own, in this process (the driver)
    and for the head: the shared ``~/.ray/auth_token`` (which any local Ray creates) is then
    neither needed nor read, whatever ran before."""
    from ray._private.authentication.authentication_token_generator import (
        generate_new_authentication_token,
    )

    saved = {k: os.environ.get(k) for k in AUTH_VARS}
    auth = {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": generate_new_authentication_token()}
    os.environ.pop("RAY_AUTH_TOKEN_PATH", None)
    os.environ.update(auth)
    _reset_ray_auth()
    try:
        yield auth
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        _reset_ray_auth()


@pytest.fixture
def ray_cluster(tmp_path: Path) -> Iterator[tuple[int, int]]:
    """A 1-CPU Ray head on 127.0.0.1: (its GCS port, its Ray Client server port), ended by
    pid in teardown."""
    assert RAY.exists(), f"no ray executable beside {sys.executable}"
    with _cluster_token():
        yield from _head(tmp_path)


def _head(tmp_path: Path) -> Iterator[tuple[int, int]]:
    port, client_port = _free_port(), _free_port()
    log = tmp_path / "ray_head.log"
    env = dict(os.environ)
    root = str(Path(vasim.__file__).resolve().parents[1])   # the workers import this vasim
    env["PYTHONPATH"] = os.pathsep.join([root, *filter(None, [env.get("PYTHONPATH")])])
    # The head's Ray Client server starts a server process per client and waits 30 s (Ray's
    # default) for it: on this loaded 2-core machine that start took longer and the ray://
    # run failed with "Initialization failure from server" (2 of 4 stress runs at load 4-11).
    env["RAY_CLIENT_SERVER_CHECK_CHANNEL_TIMEOUT_S"] = "180"
    # ... and a specific server (one per client) that sees no client for 30 s (Ray's
    # default) ends itself: under load its start and the client's arrival drift apart.
    env["TIMEOUT_FOR_SPECIFIC_SERVER_S"] = "180"
    # Its workers at the niceness of the test, as a local power run's (ray_join.py
    # LOCAL_SYSTEM_CONFIG): at Ray's default of 15 any busy process took their cores
    env["RAY_worker_niceness"] = "0"
    temp = Path("/tmp") / f"vasim_ray_{os.getpid()}_{port}"   # short: unix socket paths
    with log.open("wb") as out:
        proc = subprocess.Popen(
            [str(RAY), "start", "--head", "--block", "--node-ip-address", "127.0.0.1",
             "--port", str(port), "--ray-client-server-port", str(client_port),
             "--num-cpus", "1", "--include-dashboard", "false",
             "--disable-usage-stats", "--temp-dir", str(temp)],
            stdout=out, stderr=subprocess.STDOUT, env=env, start_new_session=True)
    try:
        _wait_for_gcs(port, proc, log)
        yield port, client_port
    finally:
        try:
            family = psutil.Process(proc.pid).children(recursive=True)
        except psutil.Error:
            family = []
        proc.terminate()                  # ray start --block drains and ends its children
        try:
            proc.wait(timeout=45)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)
        _, alive = psutil.wait_procs(family, timeout=15)
        for p in alive:
            p.kill()
        shutil.rmtree(temp, ignore_errors=True)      # the head's session logs and sockets
        assert not alive, f"Ray processes outlived their head: {alive}"


def _head_logs() -> str:
    """The tails of the running test heads' Ray Client server logs (why a ray:// join
    failed: the proxier's and each specific server's)."""
    out = []
    for path in sorted(Path("/tmp").glob(f"vasim_ray_{os.getpid()}_*/session_latest/logs/"
                                         "ray_client_server*")):
        text = path.read_text(errors="replace").strip()
        if text:
            out.append(f"--- {path.name}:\n{text[-3000:]}")
    return "\n".join(out)


RAY_SPAWN_FAILURE = "SpecificServer startup failed"
"""What the head's Ray Client server logs when the server process it starts for a ray://
client dies while starting: the new process prints gRPC's "epoll_wait error: Bad file
descriptor" and ends at once, after the proxy logged "Other threads are currently calling
into gRPC, skipping fork() handlers" (Ray 2.60's own fork of a gRPC process). The client
then waits out vasim's 120 s join limit. Seen in 2 of 3 runs of this test on 2026-12-01
(one beside an apt-get install, one in a clean-clone `make test`), never in the 5 stress
runs of 2026-11-28. Not vasim's code: the test ends that driver as soon as the head logs
it and starts it again, once, with a warning."""


def _spawn_failures() -> int:
    return _head_logs().count(RAY_SPAWN_FAILURE)


def _run_watching_the_head(cmd: list[str], env: dict[str, str]) -> tuple[int, str, str, bool]:
    """Runs ``cmd`` to its end: (exit status, stdout, stderr, whether the head logged a new
    :data:`RAY_SPAWN_FAILURE` meanwhile, in which case ``cmd`` was ended with SIGTERM at
    once). A run over 900 s is ended the same way."""
    before = _spawn_failures()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env)
    end = time.monotonic() + 900
    while True:
        try:   # (a timed-out communicate keeps what it read: it is called again)
            stdout, stderr = proc.communicate(timeout=2.0)
            return proc.returncode, stdout, stderr, _spawn_failures() > before
        except subprocess.TimeoutExpired:
            failed = _spawn_failures() > before
            if failed or time.monotonic() > end:
                proc.terminate()
                stdout, stderr = proc.communicate(timeout=60)
                return proc.returncode, stdout, stderr, failed


def _power(argv: list[str], out: Path) -> str:
    """``vasim study power`` in a child process (its output): a join that fails or times
    out leaves Ray's client state in the process that tried it (a ray:// connection still
    being made by Ray's thread), which must not be this pytest process (issue #31).

    A run whose ray:// join fails because the head's Ray Client server could not start its
    server process (:data:`RAY_SPAWN_FAILURE`, in the head's log) is ended (SIGTERM) and run
    once more, with a warning; any other failure, or that one twice, fails the test."""
    root = str(Path(vasim.__file__).resolve().parents[1])
    env = dict(os.environ)   # with the cluster's token (the fixture exported it)
    env["PYTHONPATH"] = os.pathsep.join([root, *filter(None, [env.get("PYTHONPATH")])])
    cmd = [sys.executable, "-m", "vasim", "study", "power", *argv, "--out", str(out),
           "--no-progress"]
    code, stdout, stderr, spawn_failed = _run_watching_the_head(cmd, env)
    if spawn_failed:
        where = argv[argv.index("--address") + 1] if "--address" in argv else "a local Ray"
        warnings.warn(f"Ray's client server could not start a server process for {where!r} "
                      f"({RAY_SPAWN_FAILURE!r}); joining once more", stacklevel=2)
        shutil.rmtree(out, ignore_errors=True)
        code, stdout, stderr, spawn_failed = _run_watching_the_head(cmd, env)
    if code != 0 or spawn_failed:   # the whole message, and the head's side of a failed join
        pytest.fail(f"vasim study power exited {code}:\n{stderr[-4000:]}\n{_head_logs()}",
                    pytrace=False)
    return stdout


def test_addresses_of_a_running_cluster_give_the_local_result(
        ray_cluster: tuple[int, int], tiny_protocol_path: Path, tmp_path: Path) -> None:
    common = ["--protocol", str(tiny_protocol_path), "--subjects", "2,3", "--cohorts", "2",
              "--coarse", "--max-time", "1.0", "--seed", "11"]
    port, client_port = ray_cluster
    runs = {"gcs": f"127.0.0.1:{port}", "client": f"ray://127.0.0.1:{client_port}"}
    text = {k: _power([*common, "--address", a], tmp_path / k) for k, a in runs.items()}
    local = _power([*common, "--workers", "1"], tmp_path / "local")
    assert "(local Ray)" in local
    b = pd.read_csv(tmp_path / "local" / "power_cohorts.csv")
    assert set(b["n_subjects"]) == {2, 3} and set(b["cohort"]) == {0, 1}
    assert b["F"].notna().sum() >= 4, b          # real tests were computed and compared
    for k, address in runs.items():
        assert f"(cluster {address})" in text[k] and "on 1 CPU(s)" in text[k], text[k]
        # same seeds -> the same cohorts -> the same F, p and power, whatever ran them
        pd.testing.assert_frame_equal(pd.read_csv(tmp_path / k / "power_cohorts.csv"), b)
        pd.testing.assert_frame_equal(pd.read_csv(tmp_path / k / "power.csv"),
                                      pd.read_csv(tmp_path / "local" / "power.csv"))
        table = [ln for ln in text[k].splitlines() if "±" in ln]
        assert table and table == [ln for ln in local.splitlines() if "±" in ln]


def test_a_ray_client_address_without_ray_client_is_a_clear_error(
        tiny_protocol_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    # an installation without the ray[client] extra (vasim requires it; a user's own Ray
    # may lack it): Ray's own check reports the missing grpcio
    import ray.client_builder

    monkeypatch.setattr(ray.client_builder, "get_ray_client_dependency_error",
                        lambda: ImportError("No module named 'grpc'"))
    code = main(["study", "power", "--protocol", str(tiny_protocol_path), "--subjects", "2",
                 "--cohorts", "1", "--address", "ray://127.0.0.1:10001", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and "--address" in err and "ray[client]" in err, err
    assert err.count("\n") == 1
