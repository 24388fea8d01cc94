"""`vasim study power` end to end on a local Ray with tiny numbers, and Ray always shut
down (vasim/study/power/driver.py, vasim/cli/study.py)."""

from __future__ import annotations

import math
import os
import time
from pathlib import Path

import pandas as pd
import psutil
import pytest

from vasim.cli import main
from vasim.study.power.design import COARSE_DT, PowerDesign
from vasim.study.power.driver import run_power
from vasim.study.power.estimate import POWER_COLUMNS
from vasim.study.power.ray_join import init_ray
from vasim.study.protocol import Protocol

RAY_DAEMONS = ("raylet", "gcs_server")


def _ray_daemons() -> set[int]:
    """Pids of Ray daemons started by this test process (its descendants)."""
    me = psutil.Process()
    out = set()
    for p in me.children(recursive=True):
        try:
            if any(d in p.name() for d in RAY_DAEMONS):
                out.add(p.pid)
        except psutil.Error:
            continue
    return out


def _no_ray_left(timeout: float = 15.0) -> bool:
    import ray

    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if not ray.is_initialized() and not _ray_daemons():
            return True
        time.sleep(0.25)
    return False


def test_power_end_to_end_on_a_local_ray(tiny_protocol_path: Path, tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "power"
    # ~40 s on an idle 2-core machine (no wall-clock assert: bench/power.py measures speed)
    code = main(["study", "power", "--protocol", str(tiny_protocol_path), "--subjects", "4",
                 "--cohorts", "2", "--coarse", "--max-time", "1.5", "--workers", "2",
                 "--out", str(out), "--no-progress"])
    text = capsys.readouterr().out
    assert code == 0, text
    assert _no_ray_left()
    assert not list(tmp_path.glob("**/*.sqlite"))       # no study database without asking
    power = pd.read_csv(out / "power.csv")
    cohorts = pd.read_csv(out / "power_cohorts.csv")
    assert list(power.columns) == list(POWER_COLUMNS)
    # 3 outcomes x (PRIMARY probe model, seed's fixture RM-ANOVA, seed's practice RM-ANOVA)
    assert len(power) == 9 and set(power["n_subjects"]) == {4}
    assert set(power["cohorts"]) == {2}
    assert len(cohorts) == 2 * 9 and set(cohorts["cohort"]) == {0, 1}
    assert (out / "power.png").stat().st_size > 10_000
    for r in power.itertuples():
        got = cohorts[(cohorts["dv"] == r.dv) & (cohorts["factor"] == r.factor)]
        rej = int((got["p_gg"] < 0.05).sum())
        assert r.rejections == rej and math.isclose(r.power, rej / 2)
        assert math.isclose(r.mc_se, math.sqrt(r.power * (1 - r.power) / 2))
    assert "seed RM-ANOVA: fixture effect on path deviation" in text and "cohorts/s" in text
    assert "PRIMARY probe model: fixture practised, path deviation" in text
    assert "the PRIMARY post-block probe model" in text
    assert "N=4" in text and "±" in text
    assert "warning: coarse 2 ms step" in text and "underestimated" in text


def test_ray_is_shut_down_when_a_run_fails(tiny_protocol: Protocol) -> None:
    design = PowerDesign(subjects=(2,), cohorts=2, dt=COARSE_DT, max_trial_time=0.5)

    def stop(_outcome: object) -> None:
        raise RuntimeError("stop after the first cohort")

    with pytest.raises(RuntimeError, match="stop after"):
        run_power(tiny_protocol, design, workers=1, progress=False, on_cohort=stop)
    assert _no_ray_left()


def test_bad_subject_spec_fails_before_ray_starts(tiny_protocol_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["study", "power", "--protocol", str(tiny_protocol_path), "--subjects",
                 "60:10:5", "--cohorts", "2"])
    assert code == 2
    err = capsys.readouterr().err
    assert "--subjects" in err and "START 60 > STOP 10" in err
    assert not _ray_daemons()


@pytest.mark.parametrize(("args", "needle"), [
    (["--cohorts", "0"], "got 0, expected an integer in [1, 100000]"),
    (["--cohorts", "1e308"], "expected an integer"),
    (["--effect-scale", "nan"], "expected a finite number in [0, 5]"),
    (["--effect-scale", "-1"], "expected a finite number in [0, 5]"),
    (["--alpha", "0.9"], "got 0.9, expected a finite number in [1e-06, 0.5]"),
    (["--workers", "1000"], "got 1000, expected an integer in [0, "),
    (["--workers", "0"], "got 0, expected at least 1 Ray worker"),
    (["--subjects", "1:5"], "got 1, expected an integer"),
    (["--subjects", "10:60:0"], "got '10:60:0', expected a STEP >= 1 (STEP 0)"),
    (["--effect-scale", "4"], "fixture 'ff' would get an invalid effect"),
])
def test_bad_power_arguments_are_one_line_errors(tiny_protocol_path: Path, args: list[str],
                                                 needle: str,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    base = {"--subjects": "4", "--cohorts": "2"}
    for k, v in zip(args[::2], args[1::2], strict=True):
        base[k] = v
    argv = ["study", "power", "--protocol", str(tiny_protocol_path)]
    for k, v in base.items():
        argv += [k, v]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err, err
    assert not _ray_daemons()


def test_an_out_folder_under_a_file_fails_before_ray_starts(
        tiny_protocol_path: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    afile = tmp_path / "afile"
    afile.write_text("x")
    for flag in ("--out", "--keep-cohorts"):
        code = main(["study", "power", "--protocol", str(tiny_protocol_path), "--subjects",
                     "4", "--cohorts", "1", flag, str(afile / "x")])
        err = capsys.readouterr().err
        assert code == 2 and "afile" in err and err.count("\n") == 1, (flag, err)
        assert not _ray_daemons()


def test_a_local_ray_s_workers_run_at_the_command_s_niceness() -> None:
    # Ray's default puts its workers 15 niceness steps below the command (issue #31)
    import ray

    try:
        assert init_ray(None, 1) == 1
        niceness = ray.get(ray.remote(lambda: os.nice(0)).remote())
    finally:
        ray.shutdown()
    assert niceness == os.nice(0)
    assert _no_ray_left()
