"""docs/researcher.md's table of trial metrics is TRIAL_METRICS (name, unit and meaning, in
order), so the documented units cannot drift from the code's."""

from __future__ import annotations

import re

from tests.docs.doc_blocks import ROOT
from vasim.records.trial_metrics import TRIAL_METRICS


def _documented() -> list[tuple[str, str, str]]:
    """(name, unit, meaning) of the rows of the table after "**Trial metrics**"."""
    lines = (ROOT / "docs" / "researcher.md").read_text(encoding="utf-8").splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("**Trial metrics**"))
    rows = []
    for line in lines[start + 1:]:
        if not line.strip() and not rows:
            continue
        if not line.startswith("|"):
            break
        m = re.match(r"^\| `(\w+)` \| (.*?) \| (.*) \|$", line.replace(r"\|", "\x00"))
        if m:
            rows.append((m[1], m[2].replace("\x00", "|"), m[3].replace("\x00", "|")))
    return rows


def test_the_documented_trial_metrics_are_the_codes() -> None:
    documented = _documented()
    assert [r[0] for r in documented] == list(TRIAL_METRICS), \
        "docs/researcher.md's trial-metric table lists other metrics than TRIAL_METRICS"
    for name, unit, meaning in documented:
        assert (unit, meaning) == TRIAL_METRICS[name], f"docs/researcher.md: {name}"
