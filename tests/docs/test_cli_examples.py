"""The ``vasim`` commands the docs show but do not run (```` ```text ```` blocks: sessions,
cohorts, power runs, servers) still parse: every option they use exists and takes the value
shown. Parsing only, nothing runs (argparse's ``type`` checks of values do run)."""

from __future__ import annotations

import re
import shlex

import pytest

from tests.docs.doc_blocks import ILLUSTRATION, Block, all_blocks
from vasim.cli import build_parser


def _commands(block: Block) -> list[str]:
    """The block's ``vasim ...`` command lines: continuations joined, a ``$ `` prompt, a
    ``.venv/bin/`` prefix, environment assignments and trailing comments dropped. Usage
    synopses (``[--opt]``), elisions (``...``) and output (lines after a prompt that have
    none; ``vasim report, 46 subjects``) are not commands."""
    joined = re.sub(r"\\\n\s*", " ", block.body)
    prompted = any(line.startswith("$ ") for line in joined.splitlines())
    out = []
    for line in joined.splitlines():
        if prompted and not line.startswith("$ "):
            continue    # output shown after a prompt
        line = line.strip().removeprefix("$ ")
        line = re.sub(r"^(?:[A-Z_][A-Z0-9_]*=\S+\s+)+", "", line)
        line = line.removeprefix(".venv/bin/")
        if (not re.match(r"^vasim [a-z]+( |$)", line)   # a subcommand, not output
                or "[" in line or "..." in line or "|" in line):
            continue
        out.append(shlex.split(line, comments=True)[1:])
    return [shlex.join(c) for c in out]


CASES = [(b, c) for b in all_blocks() if b.lang in ILLUSTRATION for c in _commands(b)]


def test_there_are_illustrated_commands() -> None:
    assert len(CASES) >= 30


@pytest.mark.parametrize(("block", "command"), CASES,
                         ids=[f"{b.id}:{c[:60]}" for b, c in CASES])
def test_illustrated_command_parses(block: Block, command: str,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    try:
        build_parser().parse_args(shlex.split(command))
    except SystemExit as exc:
        pytest.fail(f"{block.id}: `vasim {command}` does not parse (exit {exc.code}): "
                    f"{capsys.readouterr().err.strip()}")
