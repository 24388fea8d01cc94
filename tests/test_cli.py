"""The ``vasim`` command line (``vasim.cli``): bad arguments are one-line errors."""

from __future__ import annotations

from pathlib import Path

from vasim.study.store import TrialStore


def test_cli_one_line_errors_for_limits_paths_and_flags(tmp_path: Path, capsys) -> None:
    """A time limit beyond a day, an --out under a file, a real-time flag without
    --realtime: each a one-line error with exit status 2 (they were tracebacks, or ignored)."""
    from vasim.cli import main

    afile = tmp_path / "afile"
    afile.write_text("x")
    db = tmp_path / "s.sqlite"
    TrialStore(db).close()
    cases = [
        (["trial", "--scene", "none", "--max-time", "1e308"], "--max-time"),
        (["mrcp", "run", "faucet", "--duration", "1e308"], "--duration"),
        (["study", "export", "--db", str(db), "--out", str(afile / "x")], "afile"),
        (["report", "--db", str(db), "--out", str(afile / "x")], "afile"),
        (["trial", "--scene", "none", "--device", "emulator"], "only with --realtime"),
        (["trial", "--realtime", "--replay", "1", "--db", str(db)], "--replay"),
    ]
    for argv, needle in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert needle in err and err.count("\n") == 1 and "Traceback" not in err, (argv, err)
