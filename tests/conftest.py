"""Suite-wide test infrastructure: the markers, by location, and a guard that every test
leaves the pytest process as it found it.

Markers (registered in pyproject.toml, ``--strict-markers``):

* ``browser``: drives a real headless Chromium (``tests/browser``);
* ``cluster``: starts Ray in or beside the pytest process (a local Ray, a ``ray start`` head);
* ``slow``: longer than ~10 s on an idle 2-core machine.

They are given by location in one table (tests/markers.py) rather than in each module, so
that one place says what a quick run leaves out; ``tests/test_markers.py`` checks every
entry still names a file or a test. ``make check`` runs ``-m "not slow and not browser and
not cluster"`` in parallel; ``make test`` runs everything.

The guard (autouse; tests/process_state.py): after each test (its fixtures torn down) the
process must have the signal handlers, the environment and the working directory it had
before (:func:`_leaves_no_trace`), and after each module no thread its tests started may
still run (:func:`_module_leaves_no_threads`: a module-scoped fixture such as a shared
viewer app starts threads lazily and stops them at the module's end). Ray's ``ray.init``
installs a SIGTERM handler (``sys.exit(signum)``) and sets ``RAY_*`` variables in the
process that calls it; left in the pytest process, that handler once turned a SIGTERM meant
for the whole run into the failure of whatever test was running minutes later (issue #31).
A test that leaves such state fails, and the guard puts it back so one leak cannot cascade
into later tests. Threads get :data:`THREAD_GRACE_S` to end (a stopped server's threads
wind down asynchronously); the few process-wide threads a library keeps by design are
listed in tests/process_state.py. Session-scoped fixtures (the browser) are set up before
the first module that uses them and torn down at the end of the session.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from hypothesis import HealthCheck, settings

from tests.markers import marks_for
from tests.process_state import leftover_threads, snapshot, undo_changes

# Hypothesis's own wall-clock checks fail a property test on a loaded machine: the 200 ms
# per-example deadline (20 @given tests had it) and the too_slow health check (data
# generation timed). Both off for the whole suite; what is tested is the property.
settings.register_profile("vasim", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("vasim")

LONG_TIMEOUT_S = 900
"""pytest-timeout's limit for browser, Ray and slow tests (pyproject: 300 s for the others):
a hang guard, not a speed check; a real-time page or a Ray cluster on a 2-core machine at a
load of 30-40 has needed more than 300 s, and the full-engine null cohort (66-75 s in CI)
more than 300 s at a load of 7 (issue #31's stress run)."""

THREAD_GRACE_S = 10.0
"""How long threads a test started may take to end after its teardown [s]."""


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:  # node ids are relative to the rootdir, the repository root
        marks = marks_for(item.nodeid)
        for mark in marks:
            item.add_marker(getattr(pytest.mark, mark))
        if ({"browser", "cluster", "slow"} & set(marks)
                and item.get_closest_marker("timeout") is None):
            item.add_marker(pytest.mark.timeout(LONG_TIMEOUT_S))


# -- the guard ------------------------------------------------------------------------


@pytest.fixture(autouse=True)
def _leaves_no_trace(request: pytest.FixtureRequest) -> Iterator[None]:
    """Signal handlers, environment and working directory, after each test."""
    before = snapshot()
    yield
    problems = undo_changes(before, threads=False)
    if problems:
        pytest.fail(f"{request.node.nodeid} left state in the pytest process: "
                    + "; ".join(problems), pytrace=False)


@pytest.fixture(autouse=True, scope="module")
def _module_leaves_no_threads(request: pytest.FixtureRequest) -> Iterator[None]:
    """Threads, after each module (its module-scoped fixtures torn down: an autouse fixture
    is set up before, so torn down after, the other fixtures of its scope)."""
    before = snapshot()
    yield
    problems = leftover_threads(before, THREAD_GRACE_S)
    if problems:
        pytest.fail(f"{request.node.nodeid} left state in the pytest process: "
                    + "; ".join(problems), pytrace=False)
