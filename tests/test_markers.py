"""tests/markers.py: every place given a marker still exists, the markers are the registered
ones, and a node id gets the markers of its folder, file or test."""

from __future__ import annotations

import re
import tomllib

import pytest

from tests.markers import MARKS, ROOT, SLOW, marks_for


def test_every_marked_place_exists() -> None:
    for mark, places in {**MARKS, "slow": SLOW}.items():
        for place in places:
            path, _, name = place.partition("::")
            assert (ROOT / path).exists(), f"{mark}: {path} does not exist"
            if name:
                assert re.search(rf"^\s*(async )?def {re.escape(name)}\(",
                                 (ROOT / path).read_text(encoding="utf-8"), re.M), \
                    f"{mark}: no test {name} in {path}"


def test_the_markers_are_registered_and_strict() -> None:
    ini = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    opts = ini["tool"]["pytest"]["ini_options"]
    registered = {m.split(":")[0] for m in opts["markers"]}
    assert registered == {"slow", "browser", "cluster"} == {*MARKS, "slow"}
    assert "--strict-markers" in opts["addopts"]


def test_a_node_gets_the_markers_of_its_folder_file_or_test() -> None:
    assert marks_for("tests/browser/test_x.py::test_y[1]") == ["browser"]
    assert marks_for("tests/study/power/test_driver.py::test_a") == ["cluster"]
    assert marks_for("tests/study/power/test_drivers.py::test_a") == []
    assert marks_for("tests/core/test_config.py::test_a") == []


def test_hypothesis_has_no_wall_clock_checks() -> None:
    """tests/conftest.py's profile: no per-example deadline, no too_slow health check."""
    from hypothesis import HealthCheck, settings

    assert settings.default.deadline is None
    assert HealthCheck.too_slow in settings.default.suppress_health_check



class _Item:
    """What conftest's collection hook reads and writes of a pytest item."""

    def __init__(self, nodeid: str, timeout: float | None = None) -> None:
        self.nodeid = nodeid
        self.marks = [] if timeout is None else [pytest.mark.timeout(timeout).mark]

    def add_marker(self, marker: pytest.MarkDecorator) -> None:
        self.marks.append(marker.mark)

    def get_closest_marker(self, name: str) -> pytest.Mark | None:
        return next((m for m in reversed(self.marks) if m.name == name), None)


def test_browser_ray_and_slow_tests_get_the_long_hang_guard() -> None:
    """tests/conftest.py gives them LONG_TIMEOUT_S unless they set their own (pyproject's
    300 s for the others): the slow null cohort outgrew 300 s at a load of 7."""
    from tests.conftest import LONG_TIMEOUT_S, pytest_collection_modifyitems

    items = [_Item("tests/browser/test_x.py::test_y"),
             _Item("tests/study/power/test_driver.py::t"),
             _Item("tests/study/test_null_full_engine.py::t"),
             _Item("tests/core/test_config.py::t"),
             _Item("tests/mrcp/test_eight_robots_minutes.py::t", timeout=3600)]
    pytest_collection_modifyitems(None, items)  # type: ignore[arg-type]  # unused by the hook
    limits = [(m.args[0] if (m := i.get_closest_marker("timeout")) else None) for i in items]
    assert limits == [LONG_TIMEOUT_S, LONG_TIMEOUT_S, LONG_TIMEOUT_S, None, 3600]
