"""Shared fixtures of the power-planning tests: a tiny protocol (8 trials per subject)."""

from __future__ import annotations

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
