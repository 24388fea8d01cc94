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
        # the process pool against a local Ray, same seed
        "tests/study/power/test_backend.py::test_process_pool_and_ray_give_the_same_cohorts",
    ),
}
"""Marker -> the files (``path.py``), folders (``path/``) or tests (``path.py::name``) it
applies to, relative to the repository root."""

SLOW: tuple[str, ...] = (
    # figures: CI's --durations on 2 xdist workers, 2026-11-28 (setup = a module fixture)
    "tests/mrcp/test_study_e2e.py",                       # 108 s setup: a teleop study + report
    "tests/trials/test_teleop.py",                        # 60 s setup: every mode run and stored
    # 31 s
    "tests/trials/test_chapter5.py::test_the_bench_runs_a_tiny_cohort_and_prints_it_beside_table_5_1",
    "tests/study/power/test_coarse.py::test_coarse_step_keeps_the_per_trial_means",  # 17 s
    # 15 s
    "tests/viewer/test_sitting.py::test_the_browser_records_the_sitting_that_begins_the_retention_block",
    "tests/study/test_fading_schemas_e2e.py",             # 14 s + 11 s: two simulated protocols
    "tests/mrcp/test_kernel_edges.py::test_cli_json_is_strict",  # 11 s
    "tests/study/test_export_atomic.py::test_a_sigkilled_re_export_leaves_a_complete_set",  # 11 s
    # a full non-browser run at load 5-7 (2026-11-28), to bring `make check` under 3 min
    "tests/study/test_harden.py::test_a_second_session_of_a_completed_protocol_needs_again",  # 46 s
    "tests/study/test_cohort.py::test_cohort_end_to_end_in_process_and_with_workers",  # 22 s
    "tests/mrcp/test_kernel_theta.py::test_compiled_theta_equals_numpy",  # 21 s (first case)
    "tests/study/test_report_science.py::test_path_deviation_is_analysed_when_stored",  # 18 s
    "tests/study/test_harden.py::test_unreachable_addresses_fail_within_seconds",  # 16 s
    # 16 s
    "tests/mrcp/test_world_distances_all_robots.py::test_kernel_cycles_are_the_same_with_one_call_or_one_per_robot",
    "tests/viewer/test_flow.py::test_both_pages_are_told_when_the_loop_cannot_keep_up",  # 14 s
    "tests/study/test_null_full_engine.py",   # 380 full-engine trials of 4 s (issue #25)
    "tests/study/test_seed_chapter6.py",      # the outcome-engine comparison, a subprocess
    # a check run at load 10-20 (2026-11-28; idle figures are ~1/5 to 1/8 of these), for
    # make check's 3 min: each over 40 s there
    "tests/study/power/test_cohort.py::test_in_memory_cohort_equals_the_stored_one",  # 101 s
    # 81 s
    "tests/mrcp/test_scen_eight_robots.py::test_eight_robots_hand_the_cube_over_once_with_the_invariants_held",
    "tests/viewer/test_trainee_gate.py::test_a_browser_session_decides_the_gate_and_shows_it",  # 58
    "tests/trials/test_realtime_process.py::test_process_trial_viewer_surface",  # 58 s
    "tests/study/power/test_backend.py::test_a_failed_pool_run_ends_its_workers",  # 57 s
    "tests/study/power/test_backend.py::test_a_power_run_without_ray_runs_on_the_pool",  # 48 s
    "tests/study/test_mrcp_suture_dynamic.py",   # 53 s module setup: a simulated experiment 3
    "tests/study/test_report_mrcp.py",           # 46 s module setup: an MRCP cohort + report
    "tests/study/power/test_primary.py::test_primary_tests_are_the_reports_rm_anova_rows",  # 3x45
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
