"""Assembling the report: reads the store, builds every section, writes the files."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from vasim.core.atomic import atomic_folder
from vasim.core.config import check_dir_path
from vasim.core.errors import ConfigError
from vasim.core.progress import progress_bar
from vasim.study.recovery import recovery_summary
from vasim.study.report.analysis import analyse_vf
from vasim.study.report.data import load_study
from vasim.study.report.figures import label_png
from vasim.study.report.html_page import (
    Block,
    FigureBlock,
    ReportDoc,
    Section,
    TableBlock,
    render_html,
)
from vasim.study.report.sections.boxplots import box_plot_section
from vasim.study.report.sections.cohort import cohort_section
from vasim.study.report.sections.fixture import fixture_effect_section
from vasim.study.report.sections.groups import group_section
from vasim.study.report.sections.learning import learning_curve_section
from vasim.study.report.sections.mrcp import mrcp_section
from vasim.study.report.sections.proficiency import proficiency_section
from vasim.study.report.sections.questionnaires import questionnaire_section
from vasim.study.report.sections.retention import retention_section
from vasim.study.report.sections.traceability import traceability_section
from vasim.study.report.sections.transfer import measures_section, transfer_section
from vasim.study.report.summary import build_summary
from vasim.study.report.writing import page_meta, write_files


@dataclass(frozen=True)
class ReportResult:
    """What :func:`build_report` wrote.

    Attributes:
        out: the output folder. index: ``out/index.html``.
        tables: CSV stems written under ``out/tables/`` (``provenance`` included).
        n_figures: figures embedded in the page. seconds: wall time of the build [s].
        protocol: the protocol reported (None: the store has no session).
    """

    out: Path
    index: Path
    tables: tuple[str, ...]
    n_figures: int
    seconds: float
    protocol: str | None



# ------------------------------------------------------------------------------- assembly
STEPS: tuple[str, ...] = ("read store", "cohort", "measures", "transfer (primary)",
                          "learning curves", "fixture effect",
                          "box plots", "groups", "questionnaires", "MRCP",
                          "retention and transfer", "proficiency gates", "write")
"""The progress-bar steps of :func:`build_report`."""


def labelled(section: Section, label: str) -> Section:
    """The section with ``label`` on every figure (a band under the image) and table (its
    title and caption); unchanged when ``label`` is ``""`` (real data).

    The label (:attr:`StudyData.data_label`) is the report's only use of whether the
    cohort is synthetic: no analysis depends on it.
    """
    if not label:
        return section
    blocks: list[Block] = []
    for b in section.blocks:
        if isinstance(b, FigureBlock):
            b = replace(b, png=label_png(b.png, label), title=f"{b.title} [{label}]",
                        caption=f"{label}. {b.caption}")
        elif isinstance(b, TableBlock):
            b = replace(b, title=f"{b.title} [{label}]", caption=f"{label}. {b.caption}")
        blocks.append(b)
    return replace(section, blocks=tuple(blocks))


def report_files(out_dir: Path) -> Callable[[Path], bool]:
    """Which files of ``out_dir`` an earlier report wrote (relative paths): ``index.html``,
    ``summary.json`` and the ``tables/`` its ``tables/manifest.json`` lists; anything else
    (a user's own files) is kept when the report is replaced."""
    names: set[str] = {"manifest", "provenance"}
    try:
        old = json.loads((out_dir / "tables" / "manifest.json").read_text(encoding="utf-8"))
        names |= {n for n in old.get("tables", {}) if isinstance(n, str)}
    except (OSError, ValueError, AttributeError):
        pass

    def owned(rel: Path) -> bool:
        if len(rel.parts) == 1:
            return rel.name in ("index.html", "summary.json")
        return (len(rel.parts) == 2 and rel.parts[0] == "tables"
                and rel.suffix in (".csv", ".json") and rel.stem in names)

    return owned


def build_report(db: str | os.PathLike[str], out: str | os.PathLike[str], *,
                 protocol: str | None = None, progress: bool = False) -> ReportResult:
    """Writes the study report of ``db`` into the folder ``out``.

    Args:
        db: the SQLite study store (opened read-only).
        out: output folder, replaced as a whole and atomically (``index.html``,
            ``summary.json``, ``tables/``: ``vasim.core.atomic.atomic_folder``), so a killed
            report leaves the previous complete report or the new one; files in it that no
            report wrote are kept.
        protocol: the protocol to report, or None for the store's only protocol.
        progress: progress output over the report's steps on stderr (:mod:`vasim.core.progress`).

    Returns:
        :class:`ReportResult`.

    Raises:
        ConfigError: ``db`` missing, ``out`` is a file, protocol ambiguous or unknown.
        StoreError: ``db`` is not a vasim study store.
    """
    t0 = time.perf_counter()
    out_dir = Path(out)
    check_dir_path(out_dir, "--out", error=ConfigError)
    with progress_bar(len(STEPS), "vasim report", "step", enabled=progress,
                      leave=False) as bar:
        def step(name: str) -> None:
            bar.set_postfix_str(name)

        step(STEPS[0])
        data = load_study(db, protocol)
        bar.update()
        prov: list[dict[str, str]] = []
        sections: list[Section] = []

        def run(name: str, build: Callable[[], tuple[Section, list[dict[str, str]]]]
                ) -> None:
            step(name)  # shown while the section is built
            section, rows = build()
            sections.append(section)
            prov.extend(rows)
            bar.update()

        run(STEPS[1], lambda: cohort_section(data))
        vf = analyse_vf(data)
        run(STEPS[2], lambda: measures_section(vf))
        run(STEPS[3], lambda: transfer_section(vf))
        run(STEPS[4], lambda: learning_curve_section(data, vf))
        run(STEPS[5], lambda: fixture_effect_section(data, vf))
        run(STEPS[6], lambda: box_plot_section(vf))
        run(STEPS[7], lambda: group_section(data, vf))
        run(STEPS[8], lambda: questionnaire_section(data))
        run(STEPS[9], lambda: mrcp_section(data))
        if data.protocol is not None and any(b.phase != "acquisition"
                                             for b in data.protocol.blocks):
            run(STEPS[10], lambda: retention_section(data))
        else:
            bar.update()
        if data.protocol is not None and any(b.gate is not None for b in data.protocol.blocks):
            run(STEPS[11], lambda: proficiency_section(data))
        else:
            bar.update()
        step(STEPS[-1])
        sections.append(traceability_section(
            [b for s in sections for b in s.blocks if isinstance(b, TableBlock) and b.name]))
        sections = [labelled(s, data.data_label) for s in sections]
        tables = [b for s in sections for b in s.blocks
                  if isinstance(b, TableBlock) and b.name]
        n_fig = sum(isinstance(b, FigureBlock) for s in sections for b in s.blocks)
        doc = ReportDoc(title=f"vasim study report: {data.protocol_name or 'no sessions'}",
                        meta=page_meta(data), sections=tuple(sections))
        # assumed vs recovered effects of a simulated cohort (vasim.study.recovery)
        summary = build_summary({t.name: t.data for t in tables}, synthetic=data.synthetic,
                                n_subjects=int(data.sessions["subject"].nunique()),
                                simulation=recovery_summary(data) if data.synthetic else None)
        with atomic_folder(out_dir, owned=report_files(out_dir), what="report") as tmp:
            names = write_files(tmp, data, tables, prov, render_html(doc), summary)
        bar.update()
    return ReportResult(out=out_dir, index=out_dir / "index.html", tables=names,
                        n_figures=n_fig, seconds=time.perf_counter() - t0,
                        protocol=data.protocol_name)


