"""Two tiny protocols for tests that run whole sessions in seconds (a 0.05 s trial time
limit): ``TINY`` (two VF-free trials in one block) and ``RETENTION`` (one FF trial, then
a VF-free retention probe a day later), and :func:`install` to make them shipped protocols
for a test (the viewer offers only shipped protocols)."""

from __future__ import annotations

from pathlib import Path

import pytest

TINY = """
name = "tiny"
description = "two short trials"
task = "trajectory"
reach_radius_m = 0.005
max_trial_time_s = 0.05

[[blocks]]
name = "b"
condition = "none"
variants = [0]
repetitions = 2
probe = true
counterbalance = false
"""

RETENTION = """
name = "tret"
description = "one trial, then a retention probe a day later"
task = "trajectory"
reach_radius_m = 0.005
max_trial_time_s = 0.05

[[blocks]]
name = "a"
condition = "ff"
variants = [0]
counterbalance = false

[[blocks]]
name = "r"
condition = "none"
phase = "retention"
delay_days = 1.0
variants = [0]
probe = true
counterbalance = false
"""


def install(monkeypatch: pytest.MonkeyPatch, folder: Path, **texts: str) -> Path:
    """Makes ``folder`` the shipped protocols' folder for the test, holding the shipped
    protocols and ``texts`` (file stem -> TOML text); returns the folder."""
    import shutil

    import vasim.study.protocol.loader as loader
    from vasim.core.resources import studies_dir

    folder.mkdir(parents=True, exist_ok=True)
    for f in studies_dir().glob("*.toml"):
        shutil.copy(f, folder / f.name)
    for stem, text in texts.items():
        (folder / f"{stem}.toml").write_text(text, encoding="utf-8")
    monkeypatch.setattr(loader, "studies_dir", lambda: folder)
    return folder
