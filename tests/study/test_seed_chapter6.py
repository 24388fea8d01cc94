"""The chapter-6 seed comparison of docs/seed-chapter6.md (issue #25 items 4 and 7):
`python -m bench.calibration --markdown` prints a table whose every row has the three
columns seed / assumed / out beside its label, and whose rows of an input say so."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _table(*args: str) -> list[list[str]]:
    out = subprocess.run([sys.executable, "-m", "bench.calibration", "--smoke", "--markdown",
                          *args], cwd=ROOT, capture_output=True, text=True, timeout=600,
                         check=True).stdout
    rows = [line for line in out.splitlines() if line.startswith("|")]
    return [[c.strip() for c in r.strip().strip("|").split(" | ")] for r in rows]


def test_the_comparison_has_seed_assumed_and_out_columns() -> None:
    t = _table()
    assert t[0] == ["quantity", "seed (published result)", "assumed (scenario input)",
                    "out (synthetic cohort)"]
    assert t[1] == ["---|---|---|---"]   # the separator row
    body = t[2:]
    assert len(body) >= 13 and all(len(r) == 4 and all(r) for r in body)
    # the fixture ratios of the outcome engine are inputs realised by construction
    ratios = [r for r in body if r[0].endswith("path-deviation ratio")]
    assert len(ratios) == 5 and all("INPUT" in r[3] for r in ratios)
    # the questionnaire rows come from the subjects' own benefits, never the seed's shares
    q = [r for r in body if "best / worst / rating" in r[0]]
    assert len(q) == 5 and all("own benefit" in r[2] for r in q)


def test_the_page_shows_the_three_columns_and_the_command() -> None:
    page = (ROOT / "docs" / "seed-chapter6.md").read_text(encoding="utf-8")
    assert "python -m bench.calibration" in page and "--markdown" in page
    assert "| quantity | seed (published result) | assumed (scenario input) | out " in page
