"""``vasim report``: the study report (HTML page + CSV tables) of a study database.

``register(subparsers)`` adds ``vasim report --db study.sqlite --out report/
[--protocol NAME] [--no-progress]``. A missing database, an ambiguous or unknown protocol
or a file that is not a vasim store raise a ``VasimError``, which ``vasim.cli`` prints as
one line with exit code 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from vasim.cli.args import output_folder

_EPILOG = """\
writes:
  OUT/index.html          one self-contained page (figures embedded, no script)
  OUT/tables/*.csv        every table at full precision, with trial ids or provenance
  OUT/tables/provenance.csv   per table cell: the stored trial ids it was computed from

examples:
  vasim report --db study.sqlite --out report/
  vasim report --db study.sqlite --out report-mrcp/ --protocol mrcp_vs_stdt
"""


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds ``vasim report`` to the ``vasim`` parser."""
    p = subparsers.add_parser(
        "report",
        help="study report: HTML page with plots and CSV tables of a study database",
        description="Writes the report of a study database: cohort, learning curves, "
                    "effect of fixture (subject-level RM-ANOVA, post hoc tests, the seed's "
                    "per-sample ANOVA as a labelled replication), box plots, questionnaires "
                    "and the MRCP vs standard-teleoperation comparison.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--db", type=Path, required=True, help="SQLite study database (read only)")
    p.add_argument("--out", type=output_folder, required=True, help="output folder")
    p.add_argument("--protocol", default=None, metavar="NAME",
                   help="protocol to report (needed when the database holds several)")
    p.add_argument("--no-progress", action="store_true",
                   help="no progress output (default: a bar on a terminal, a line every 15 s "
                        "in a log file)")
    p.set_defaults(func=cmd_report)


def cmd_report(args: argparse.Namespace) -> int:
    """Runs ``vasim report``; prints where the report went."""
    from vasim.study.report import build_report

    res = build_report(args.db, args.out, protocol=args.protocol,
                       progress=not args.no_progress)
    print(f"wrote {res.index} ({len(res.tables)} tables in {res.out / 'tables'}, "
          f"{res.n_figures} figures, {res.out / 'summary.json'}) in {res.seconds:.1f} s")
    return 0


__all__ = ["cmd_report", "register"]
