"""Writing the report: the page's metadata, ``tables/*.csv``, ``provenance.csv``,
``manifest.json`` and ``index.html``."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pandas as pd

from vasim import __version__
from vasim.study.report.common import (
    PROVENANCE_COLUMNS,
)
from vasim.study.report.data import StudyData
from vasim.study.report.html_page import (
    TableBlock,
)
from vasim.study.report.summary import write_summary


def page_meta(data: StudyData) -> tuple[tuple[str, str], ...]:
    s = data.sessions
    shas = sorted(set(s["protocol_sha256"])) if len(s) else []
    return (
        ("database", str(data.db)),
        ("store schema version", "–" if data.schema_version is None
         else str(data.schema_version)),
        ("protocol", data.protocol_name or "– (no sessions)"),
        ("protocol text sha256", ", ".join(x[:16] for x in shas) or "–"),
        ("subjects / sessions", f"{s['subject'].nunique() if len(s) else 0} / {len(s)}"),
        ("generated", datetime.now(UTC).isoformat(timespec="seconds")),
        ("vasim", __version__),
        ("data", data.data_label or "recorded sessions (no scripted operator)"),
        ("tables", "tables/*.csv beside this file; tables/provenance.csv traces the tests"),
    )


def write_files(out_dir: Path, data: StudyData, tables: Sequence[TableBlock],
           prov: Sequence[dict[str, str]], page: str,
           summary: Mapping[str, Any] | None = None) -> tuple[str, ...]:
    tdir = out_dir / "tables"
    tdir.mkdir(parents=True, exist_ok=True)
    manifest = tdir / "manifest.json"  # out_dir is a fresh folder (atomic_folder)
    seen: set[str] = set()
    info: dict[str, Any] = {}
    for t in tables:
        if t.name in seen:
            raise RuntimeError(f"report table {t.name!r} written twice")  # a programming error
        seen.add(t.name)
        t.data.to_csv(tdir / f"{t.name}.csv", index=False)
        info[t.name] = {"title": t.title, "rows": len(t.data),
                        "columns": [str(c) for c in t.data.columns]}
    pv = pd.DataFrame(list(prov), columns=list(PROVENANCE_COLUMNS))
    pv.to_csv(tdir / "provenance.csv", index=False)
    info["provenance"] = {"title": "provenance", "rows": len(pv),
                          "columns": list(PROVENANCE_COLUMNS)}
    manifest.write_text(json.dumps({
        "vasim_version": __version__, "database": str(data.db),
        "protocol": data.protocol_name, "synthetic": data.synthetic,
        "data_label": data.data_label, "tables": info}, indent=1), encoding="utf-8")
    if summary is not None:
        write_summary(out_dir / "summary.json", summary)
    (out_dir / "index.html").write_text(page, encoding="utf-8")
    return tuple(info)


