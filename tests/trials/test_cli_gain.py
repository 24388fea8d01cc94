"""`vasim trial --gain G` (vasim/cli/study.py): a constant fixture gain scaling every
fixture's f5PL output, validated, logged per sample and stored with the trial."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from vasim.cli import main
from vasim.study.store import TrialStore

BASE = ["trial", "--scene", "none", "--max-time", "0.4", "--seed", "3"]


def _run(db: Path, *extra: str) -> int:
    assert main([*BASE, "--db", str(db), *extra]) == 0
    with TrialStore(db, readonly=True) as st:
        return int(st.trials()["id"].max())


def test_gain_is_stored_logged_and_scales_the_fixture_force(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = tmp_path / "g.sqlite"
    full = _run(db, "--schema", "ff")
    half = _run(db, "--schema", "ff", "--gain", "0.5")
    out = capsys.readouterr().out
    assert "ff [ff], gain 0.5 (constant)" in out
    with TrialStore(db, readonly=True) as st:
        t_full, t_half = st.trial(full), st.trial(half)
        s_full, s_half = st.samples(full), st.samples(half)
    # stored with the trial as a schedule's gain is: the config and the summary's mean
    assert t_half["config"]["gain"] == 0.5 and "gain" not in t_full["config"]  # 1: as before
    assert t_half["summary"]["gain_mean"] == 0.5 and "gain_mean" not in t_full["summary"]
    assert np.all(s_half["gain"] == 0.5) and np.all(s_full["gain"] == 1.0)
    # same seed, same first state: the first step's fixture force is exactly halved
    # (the gain multiplies the f5PL output; the trajectories diverge afterwards)
    f = ["f_x", "f_y", "f_z"]
    first_full = s_full[f].iloc[0].to_numpy()
    first_half = s_half[f].iloc[0].to_numpy()
    assert np.linalg.norm(first_full) > 0
    np.testing.assert_allclose(first_half, 0.5 * first_full, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize(("argv", "needle"), [
    (["--schema", "ff", "--gain", "1.5"], "got 1.5, expected a finite number in [0, 1]"),
    (["--schema", "ff", "--gain", "-0.1"], "expected a finite number in [0, 1]"),
    (["--schema", "ff", "--gain", "nan"], "expected a finite number in [0, 1]"),
    (["--schema", "ff", "--gain", "half"], "got 'half', expected a number"),
    (["--gain", "0.5"], "got 0.5, expected 1 for schema 'none', which has no fixtures"),
])
def test_bad_gains_are_one_line_errors(argv: list[str], needle: str,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*BASE, *argv]) == 2
    err = capsys.readouterr().err
    assert "--gain" in err and needle in err and err.count("\n") == 1, err
