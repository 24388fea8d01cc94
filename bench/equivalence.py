"""Behaviour-equivalence check across a refactoring: same commands, same stored rows.

Runs, in the current tree and in a git revision (checked out into a temporary worktree and
imported through ``PYTHONPATH``), the same fixed-seed commands:

* one headless trial (``vasim trial --schema ff --seed 1``),
* a 3-subject simulated cohort of ``vf_learning_curve`` (seed 7) and its report tables,
* one teleoperation session (``vasim study run`` of ``mrcp_vs_stdt`` cut to one trial per
  mode: StdT, MRCP, MRCP+Cam; subject S01, seed 3), the scripted operator through the MRCP
  slave station,
* ``vasim mrcp run cube_rotation --json``,

then compares every stored row of both databases (all tables; columns that hold wall-clock
times, process ids, host names or the package version are left out), every CSV table of
both reports, and the MRCP JSON. Exit status 0 when everything is identical, 1 otherwise
with the first differences printed.

Usage::

    python -m bench.equivalence --ref <git revision>            # current tree vs revision
    python -m bench.equivalence --capture DIR                   # only write this tree's outputs

It is a script (minutes of simulation), not a unit test: the refactoring commit runs it
against its parent and quotes the result.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sqlite3
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

#: Columns whose value depends on when/where a command ran, not on what it computed.
VOLATILE_COLUMNS = frozenset(
    {"pid", "host", "proc_token", "timing_json", "vasim_version", "applied_at"}
)

RUN_CLI = "import sys; from vasim.cli import main; sys.exit(main(sys.argv[1:]))"


def _vasim(args: list[str], src: Path, cwd: Path) -> str:
    env = dict(os.environ, PYTHONPATH=str(src), VASIM_PROTOCOLS=str(src / "protocols"))
    proc = subprocess.run(
        [sys.executable, "-c", RUN_CLI, *args, "--no-progress"]
        if args[0] in {"study", "report"}
        else [sys.executable, "-c", RUN_CLI, *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    if proc.returncode != 0:
        raise SystemExit(f"vasim {' '.join(args)} failed in {src}:\n{proc.stderr[-2000:]}")
    return proc.stdout


def _teleop_protocol(src: Path, out: Path) -> Path:
    """``src``'s ``mrcp_vs_stdt`` protocol with one trial per mode (same questionnaires)."""
    text = (src / "protocols" / "studies" / "mrcp_vs_stdt.toml").read_text(encoding="utf-8")
    if "repetitions = 6" not in text:
        raise SystemExit(f"{src}: mrcp_vs_stdt.toml no longer has 'repetitions = 6'; update "
                         "bench/equivalence.py's teleoperation session")
    path = out / "mrcp_short.toml"
    path.write_text(text.replace("repetitions = 6", "repetitions = 1")
                    .replace('name = "mrcp_vs_stdt"', 'name = "mrcp_short"'), encoding="utf-8")
    return path


def capture(src: Path, out: Path) -> None:
    """Run the fixed-seed commands with the code of ``src``; write outputs under ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    print(f"[equivalence] {src}: one trial", file=sys.stderr)
    _vasim(["trial", "--schema", "ff", "--seed", "1", "--subject", "S00",
            "--db", str(out / "trial.sqlite")], src, out)
    print(f"[equivalence] {src}: 3-subject cohort", file=sys.stderr)
    _vasim(
        ["study", "simulate", "--protocol", "vf_learning_curve", "--subjects", "3",
         "--seed", "7", "--db", str(out / "cohort.sqlite")],
        src, out,
    )
    print(f"[equivalence] {src}: teleoperation session (StdT, MRCP, MRCP+Cam)", file=sys.stderr)
    _vasim(["study", "run", "--protocol", str(_teleop_protocol(src, out)), "--subject", "S01",
            "--seed", "3", "--db", str(out / "teleop.sqlite")], src, out)
    print(f"[equivalence] {src}: report", file=sys.stderr)
    _vasim(["report", "--db", str(out / "cohort.sqlite"), "--out", str(out / "report")], src, out)
    print(f"[equivalence] {src}: mrcp cube_rotation", file=sys.stderr)
    text = _vasim(["mrcp", "run", "cube_rotation", "--json"], src, out)
    (out / "mrcp_cube_rotation.json").write_text(text)


def _columns(db: Path) -> dict[str, list[str]]:
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        tables = [r[0] for r in con.execute(
            "SELECT name FROM sqlite_master WHERE type='table' ORDER BY name")]
        return {t: [r[1] for r in con.execute(f"PRAGMA table_info({t})")
                    if r[1] not in VOLATILE_COLUMNS and not r[1].endswith("_at")]
                for t in tables}
    finally:
        con.close()


def _json_cell(value: object, keys: set[str] | None) -> object:
    """A JSON text cell with only ``keys`` kept (None: all), for comparison."""
    if not isinstance(value, str) or not value.startswith("{"):
        return value
    try:
        d = json.loads(value)
    except ValueError:
        return value
    if keys is not None:
        d = {k: v for k, v in d.items() if k in keys}
    return json.dumps(d, sort_keys=True)


def _rows(db: Path, columns: dict[str, list[str]],
          json_keys: dict[str, set[str]] | None = None) -> dict[str, list[tuple[object, ...]]]:
    """Every row of ``columns``' tables, those columns only (JSON cells: ``json_keys``)."""
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        result: dict[str, list[tuple[object, ...]]] = {}
        for table, keep in columns.items():
            if not keep:
                continue
            sel = ", ".join(f'"{c}"' for c in keep)
            rows = con.execute(f'SELECT {sel} FROM "{table}"').fetchall()
            rows = [tuple(_json_cell(v, (json_keys or {}).get(c)) for c, v in zip(keep, r,
                                                                               strict=True))
                    for r in rows]
            result[table] = [tuple(keep), *sorted(rows, key=repr)]
        return result
    finally:
        con.close()


def _json_keys(a: Path, b: Path, table: str, column: str) -> set[str]:
    """Keys present in every JSON cell of ``table.column`` of both databases."""
    keys: set[str] | None = None
    for db in (a, b):
        con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
        try:
            for (v,) in con.execute(f'SELECT "{column}" FROM "{table}"'):
                if isinstance(v, str) and v.startswith("{"):
                    k = set(json.loads(v))
                    keys = k if keys is None else keys & k
        finally:
            con.close()
    return keys or set()


def _table(path: Path) -> list[list[str]]:
    """A CSV table's cells as text, without the wall-clock columns (``*_at``)."""
    with path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        return rows
    keep = [i for i, name in enumerate(rows[0]) if not name.endswith("_at")]
    return [[row[i] for i in keep if i < len(row)] for row in rows]


def compare(a: Path, b: Path) -> list[str]:
    """Differences between two captured output folders (empty when identical)."""
    diffs: list[str] = []
    for name in ("trial.sqlite", "cohort.sqlite", "teleop.sqlite"):
        ca, cb = _columns(a / name), _columns(b / name)
        if sorted(ca) != sorted(cb):
            diffs.append(f"{name}: tables differ {sorted(ca)} vs {sorted(cb)}")
            continue
        shared = {t: [c for c in ca[t] if c in cb[t]] for t in ca}
        for t in ca:
            extra = sorted(set(ca[t]) ^ set(cb[t]))
            if extra:
                print(f"  {name}:{t}: compared without the columns only one side has: "
                      f"{extra}")
        keys = {c: _json_keys(a / name, b / name, "trials", c)
                for c in ("summary_json", "config_json") if c in shared.get("trials", [])}
        ra, rb = _rows(a / name, shared, keys), _rows(b / name, shared, keys)
        for table in ra:
            if ra[table] != rb[table]:
                n = sum(x != y for x, y in zip(ra[table], rb[table], strict=False))
                diffs.append(f"{name}:{table}: {n} rows differ "
                             f"({len(ra[table]) - 1} vs {len(rb[table]) - 1} rows)")
            else:
                print(f"  {name}:{table}: {len(ra[table]) - 1} rows identical")
    ta = sorted(p.relative_to(a) for p in (a / "report").rglob("*.csv"))
    tb = sorted(p.relative_to(b) for p in (b / "report").rglob("*.csv"))
    if ta != tb:
        diffs.append(f"report tables differ: {ta} vs {tb}")
    for rel in ta:
        if rel in tb and _table(a / rel) != _table(b / rel):
            diffs.append(f"{rel}: contents differ")
    print(f"  report: {len(ta)} CSV tables compared")
    ja = json.loads((a / "mrcp_cube_rotation.json").read_text())
    jb = json.loads((b / "mrcp_cube_rotation.json").read_text())
    for volatile in ("elapsed_s", "wall_s", "cycle_ms"):
        ja.pop(volatile, None)
        jb.pop(volatile, None)
    if ja != jb:
        diffs.append("mrcp_cube_rotation.json differs")
    else:
        print("  mrcp cube_rotation JSON identical")
    return diffs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ref", help="git revision to compare the current tree against")
    parser.add_argument("--capture", type=Path, help="only capture this tree's outputs here")
    parser.add_argument("--keep", type=Path, help="keep both captures under this folder")
    args = parser.parse_args(argv)
    if args.capture:
        capture(REPO, args.capture)
        return 0
    if not args.ref:
        parser.error("--ref or --capture is required")
    with tempfile.TemporaryDirectory(prefix="vasim-equiv-") as tmp:
        root = args.keep or Path(tmp)
        # not root / "ref": that is where the reference's outputs go, and removing the
        # worktree would delete them before the comparison
        worktree = Path(tmp) / "src"
        subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", str(worktree),
                        args.ref], check=True, capture_output=True)
        try:
            capture(worktree, root / "ref")
            capture(REPO, root / "head")
        finally:
            subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force",
                            str(worktree)], check=False)
        diffs = compare(root / "ref", root / "head")
    if diffs:
        print("NOT equivalent:")
        for d in diffs[:40]:
            print("  " + d)
        return 1
    print(f"equivalent: the current tree reproduces {args.ref} exactly")
    return 0


if __name__ == "__main__":
    sys.exit(main())
