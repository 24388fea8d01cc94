"""The ``vasim`` command line: one entry point, one subcommand per activity.

Each subsystem contributes its subcommands through a ``register(subparsers)`` function so
that this module only wires them together. Errors vasim raises on purpose (``VasimError``)
print as one line on stderr and exit with code 2; argparse usage errors exit 2 as well.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Sequence
from typing import NoReturn

from vasim import __version__
from vasim.core.errors import VasimError

Registrar = Callable[["argparse._SubParsersAction[argparse.ArgumentParser]"], None]


def _registrars() -> list[Registrar]:
    from vasim.cli import fixtures as fixtures_cli
    from vasim.cli import haptics as haptics_cli
    from vasim.cli import mrcp as mrcp_cli
    from vasim.cli import report as report_cli
    from vasim.cli import stats as stats_cli
    from vasim.cli import study as study_cli
    from vasim.cli import viewer as viewer_cli

    return [study_cli.register, viewer_cli.register, fixtures_cli.register, stats_cli.register,
            haptics_cli.register, report_cli.register, mrcp_cli.register]


class _Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose usage errors are one line, like vasim's own errors.

    **Decision**: argparse prints the whole usage before a bad argument (several lines); a
    refused value (``--subjects 1000000000``) reads better as the one line
    ``vasim study simulate: error: argument --subjects: got ..., expected ...``; the usage
    is one ``--help`` away. Subparsers inherit the class.
    """

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser: argparse.ArgumentParser = _Parser(
        prog="vasim",
        description="Haptic surgical training simulator with task-oriented virtual fixtures.",
    )
    parser.add_argument("--version", action="version", version=f"vasim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for register in _registrars():
        register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # a usage error (printed, one line) returns 2; --help exits
        if exc.code == 2:
            return 2
        raise
    try:
        code = args.func(args)
    except VasimError as exc:
        print(f"vasim {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"vasim {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader went away (e.g. `vasim ... | head`): not an error; silence the flush
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as exc:
        # The file system refused (an --out under a file, no permission, a full disk): one
        # line naming the path, like any other bad input. Stored trials are transactional,
        # so nothing half-written is left in a study database.
        where = f" {exc.filename}" if exc.filename else ""
        print(f"vasim {args.command}: error:{where}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    return int(code or 0)


if __name__ == "__main__":
    sys.exit(main())
