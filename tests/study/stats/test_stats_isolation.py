"""``vasim.study.stats`` is a leaf: importing it loads neither the store nor tqdm (issue #14).

The import-linter contract in pyproject.toml forbids the static imports; this test checks
what a fresh interpreter really loads.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from vasim.study.export import CSV_NA as EXPORT_NA
from vasim.study.stats._data import CSV_NA

ROOT = Path(__file__).resolve().parents[3]

_PROBE = """
import json, sys
import vasim.study.stats
print(json.dumps(sorted(m for m in sys.modules if m == "tqdm" or m.startswith("vasim"))))
"""


def test_import_loads_no_store_export_tqdm_or_fixtures() -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True,
                         env=env, cwd=ROOT, timeout=120, check=True)
    loaded = set(json.loads(out.stdout.strip().splitlines()[-1]))
    assert "vasim.study.stats" in loaded  # the probe did import it
    for forbidden in ("tqdm", "vasim.study.store", "vasim.study.export", "vasim.study.report",
                      "vasim.fixtures", "vasim.trials", "vasim.records", "vasim.tasks"):
        assert forbidden not in loaded, forbidden
    assert {m for m in loaded if m.startswith("vasim.")} <= (
        {"vasim.core", "vasim.core.errors", "vasim.study"}
        | {m for m in loaded if m.startswith("vasim.study.stats")})


def test_missing_value_marker_matches_export() -> None:
    assert CSV_NA == EXPORT_NA == "\\N"
