"""vasim.mrcp.urdf's cache of generated URDFs and link hulls: concurrent writers (threads and
processes) do not collide, a partial cache is repaired, and the generator version is part of
the model key."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest

from vasim.mrcp import dh, urdf
from vasim.mrcp.backend import PybulletWorld

RX = dh.load_robot("rx60b")


def test_concurrent_writers_in_threads_do_not_collide(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("VASIM_CACHE", str(tmp_path))
    urdf.link_hulls(RX)
    text = urdf.urdf_text

    def slow_text(robot: dh.RobotModel) -> str:     # widens the race window
        time.sleep(0.02)
        return text(robot)

    monkeypatch.setattr(urdf, "urdf_text", slow_text)
    errors: list[BaseException] = []
    for trial in range(4):
        monkeypatch.setenv("VASIM_CACHE", str(tmp_path / str(trial)))
        barrier = threading.Barrier(4)

        def go(b: threading.Barrier = barrier) -> None:
            b.wait()
            try:
                urdf.write_urdf(RX)
            except BaseException as exc:       # collected, asserted below
                errors.append(exc)

        threads = [threading.Thread(target=go) for _ in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        folder = urdf.write_urdf(RX).parent
        names = sorted(p.name for p in folder.iterdir())
        assert names == [*(f"link{k}.obj" for k in range(7)), "rx60b.urdf"]   # no temps
    assert errors == []


def test_a_partial_cache_is_repaired(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                     ) -> None:
    monkeypatch.setenv("VASIM_CACHE", str(tmp_path))
    path = urdf.write_urdf(RX)
    (path.parent / "link2.obj").unlink()
    assert urdf.write_urdf(RX) == path
    assert (path.parent / "link2.obj").is_file()
    w = PybulletWorld(compiled_distances=False)
    w.add_robot("a", RX)
    w.add_sphere("ball", 0.03, np.array([0.0, 0.0, 0.15]))    # on the upper arm at home
    assert w.in_collision("a")


def test_the_generator_version_is_part_of_the_model_key(monkeypatch: pytest.MonkeyPatch
                                                        ) -> None:
    text = dh.robots_dir().joinpath("rx60b.toml").read_text()
    before = urdf.model_key(dh.parse_robot(text))
    monkeypatch.setattr(urdf, "GENERATOR_VERSION", urdf.GENERATOR_VERSION + 1)
    assert urdf.model_key(dh.parse_robot(text)) != before


