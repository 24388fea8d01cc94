"""Writes ``store_v5.sqlite``: a study store as vasim wrote it at schema version 5, before
the packed samples of version 6 (the fixture of ``tests/study/test_store_v6.py``).

Run with the vasim of a schema-5 commit (it was made from main at 66e4d98, 2026-11-28):
``PYTHONPATH=<that checkout> python tests/study/data/make_store_v5.py OUT.sqlite``. Three
short headless trials (FF with gain 0.75, VG, VF-free) of subject S01, then VACUUM, so
the file stays small.
"""

from __future__ import annotations

import sqlite3
import sys


def main(out: str) -> None:
    from vasim.study.store import SCHEMA_VERSION, TrialStore
    from vasim.trials.registry import run_trial
    from vasim.trials.vf import TrialConfig

    assert SCHEMA_VERSION == 5, f"needs a schema-5 vasim, this one writes {SCHEMA_VERSION}"
    with TrialStore(out) as st:
        for schema, gain, seed in (("ff", 0.75, 1), ("vg", 1.0, 2), ("none", 1.0, 3)):
            run_trial(TrialConfig(schema=schema, seed=seed, max_time=0.25, scene="none",
                                  subject="S01", gain=gain), st)
    con = sqlite3.connect(out)
    con.execute("PRAGMA journal_mode = DELETE")
    con.execute("VACUUM")
    con.close()


if __name__ == "__main__":
    main(sys.argv[1])
