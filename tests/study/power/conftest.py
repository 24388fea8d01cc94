"""Shared fixtures of the power-planning tests: a tiny protocol (8 trials per subject), and
Ray's traces undone after each test that runs it in the pytest process."""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from vasim.study.protocol import Protocol, load_protocol

TINY_POWER = """
name = "tiny_power"
description = "2 VF-free baseline probes, then Mag and FF blocks of 2 trials + 1 probe"
task = "trajectory"
reach_radius_m = 0.005
max_trial_time_s = 2.0
excessive_force_n = 2.0

[randomisation]
block_order = "random"
variant_order = "random"

[probe]
condition = "none"
variant = 0

[[blocks]]
name = "baseline"
condition = "none"
variants = [0]
repetitions = 2
probe = true
counterbalance = false

[[blocks]]
name = "mag"
condition = "mag"
variants = [1, 2]
probes_after = 1

[[blocks]]
name = "ff"
condition = "ff"
variants = [1, 2]
probes_after = 1
"""


@pytest.fixture
def tiny_protocol_path(tmp_path: Path) -> Path:
    path = tmp_path / "tiny_power.toml"
    path.write_text(TINY_POWER, encoding="utf-8")
    return path


@pytest.fixture
def tiny_protocol(tiny_protocol_path: Path) -> Protocol:
    return load_protocol(tiny_protocol_path)


RAY_SIGNALS = (signal.SIGTERM, signal.SIGINT)


@pytest.fixture(autouse=True)
def _ray_is_undone(request: pytest.FixtureRequest) -> Iterator[None]:
    """For the tests marked ``cluster`` (tests/conftest.py): ``ray.init`` in the pytest
    process, as ``vasim study power`` does it, installs Ray's SIGTERM handler
    (``sys.exit(signum)``) and sets ``RAY_CLIENT_MODE``, ``RAY_AUTH_MODE``,
    ``RAY_USAGE_STATS_ENABLED`` and ``PYTHONBREAKPOINT``, and ``ray.shutdown`` leaves them
    (Ray 2.60). They are put back here, after the test checked Ray is down; anything else
    a test leaves is the suite-wide guard's to report (tests/conftest.py)."""
    if request.node.get_closest_marker("cluster") is None:
        yield
        return
    handlers = {s: signal.getsignal(s) for s in RAY_SIGNALS}
    env = dict(os.environ)
    yield
    ray = sys.modules.get("ray")
    if ray is not None and ray.is_initialized():   # the test failed before its own check
        ray.shutdown()
    for s, h in handlers.items():
        if h is not None:
            signal.signal(s, h)  # type: ignore[arg-type]
    for k in {k for k in (*env, *os.environ) if k.startswith("RAY_") or k == "PYTHONBREAKPOINT"}:
        if k in env:
            os.environ[k] = env[k]
        else:
            os.environ.pop(k, None)
