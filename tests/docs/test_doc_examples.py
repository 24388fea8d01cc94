"""Every shell and Python example in README.md and docs/*.md runs (issue #27 item 2: docs
that cannot rot).

The convention (docs/developer.md, "Docs and their examples"): a ```` ```sh ```` block runs
as one bash script (``set -euo pipefail``) and a ```` ```python ```` block as a script in a
fresh interpreter, each in its own temporary folder, with ``vasim`` and ``python`` this
interpreter's (its ``bin/`` first on ``PATH``) and the checkout on ``PYTHONPATH``; each must
exit 0 within :data:`TIMEOUT_S`. ```` ```text ```` blocks are illustration and never run;
```` ```toml ```` and ```` ```json ```` blocks are parsed unless they show a fragment
(``...``). Marked ``slow``: the examples start ``vasim`` a dozen times (each start imports
numpy, pandas and numba: seconds on a loaded machine).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from tests.docs.doc_blocks import PARSE, ROOT, RUN, Block, all_blocks, run_block

pytestmark = pytest.mark.slow

TIMEOUT_S = 300.0
"""Per-example limit [s]: a hang guard for a loaded 2-core machine, not a speed check
(an example is meant to take seconds)."""

BLOCKS = all_blocks()
RUNNABLE = [b for b in BLOCKS if b.lang in RUN]
PARSED = [b for b in BLOCKS if b.lang in PARSE and "..." not in b.body]


def test_there_are_examples_to_run() -> None:
    """The docs show runnable examples of each kind (a broken extractor would find none)."""
    langs = {b.lang for b in RUNNABLE}
    assert {"sh", "python"} <= langs
    assert len(RUNNABLE) >= 10


def test_the_vasim_on_path_is_this_checkout(tmp_path: Path) -> None:
    """The examples' ``vasim`` and ``python`` run this checkout's code."""
    out = run_block(Block(tmp_path, 1, "sh", "python -c 'import vasim; print(vasim.__file__)'\n"),
                    tmp_path, TIMEOUT_S)
    assert out.returncode == 0, out.stderr
    assert Path(out.stdout.strip()).resolve().is_relative_to(ROOT)
    assert Path(sys.executable).parent.joinpath("vasim").exists()


@pytest.mark.parametrize("block", RUNNABLE, ids=[b.id for b in RUNNABLE])
def test_example_runs(block: Block, tmp_path: Path) -> None:
    try:
        out = run_block(block, tmp_path, TIMEOUT_S)
    except subprocess.TimeoutExpired:
        pytest.fail(f"{block.id}: the example did not end within {TIMEOUT_S:.0f} s "
                    "(make it quicker, or show it in a ```text block)")
    tail = "\n".join((out.stdout + out.stderr).splitlines()[-25:])
    assert out.returncode == 0, \
        f"{block.id}: the {block.lang} example exited {out.returncode}:\n{block.body}\n---\n{tail}"


@pytest.mark.parametrize("block", PARSED, ids=[b.id for b in PARSED])
def test_file_content_parses(block: Block) -> None:
    if block.lang == "toml":
        tomllib.loads(block.body)
    else:
        json.loads(block.body)
