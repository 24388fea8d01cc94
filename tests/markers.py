"""Which tests carry the ``browser``, ``cluster`` and ``slow`` markers, by location (applied
in tests/conftest.py; registered in pyproject.toml with ``--strict-markers``).

``make check`` runs ``-m "not slow and not browser and not cluster"`` (a developer's quick
loop, in parallel); ``make test`` runs everything. A place is a folder (``path/``), a file
(``path.py``) or a test (``path.py::name``, every parametrisation of it), relative to the
repository root; ``tests/test_markers.py`` checks every place still exists.
"""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

MARKS: dict[str, tuple[str, ...]] = {
    "browser": ("tests/browser/",),
    "cluster": (
        "tests/study/power/test_cluster.py",   # a `ray start --head` cluster + local Ray
        "tests/study/power/test_driver.py",    # `vasim study power` on a local Ray
    ),
}
"""Marker -> the files (``path.py``), folders (``path/``) or tests (``path.py::name``) it
applies to, relative to the repository root."""

SLOW: tuple[str, ...] = (
    "tests/study/test_null_full_engine.py",   # 380 full-engine trials of 4 s (issue #25)
    "tests/study/test_seed_chapter6.py",      # the outcome-engine comparison, a subprocess
)
"""Places marked ``slow``: longer than ~10 s on an idle 2-core machine (``--durations``; the
measured figure beside each)."""


def marks_for(nodeid: str) -> list[str]:
    """The markers of the test ``nodeid`` (relative to the repository root)."""
    path = nodeid.split("::", 1)[0]
    out = []
    for mark, places in {**MARKS, "slow": SLOW}.items():
        for place in places:
            if (path.startswith(place) if place.endswith("/")
                    else nodeid == place or path == place or nodeid.startswith(place + "[")):
                out.append(mark)
                break
    return out
