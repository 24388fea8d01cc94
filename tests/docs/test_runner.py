"""The examples' runner itself (tests/docs/doc_blocks.py): a failing command anywhere in a
``sh`` block, or an exception in a ``python`` block, fails the example; each block starts
afresh (no state carried from one block to the next)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.docs.doc_blocks import Block, run_block


def _run(tmp_path: Path, lang: str, body: str) -> int:
    return run_block(Block(tmp_path / "x.md", 1, lang, body), tmp_path, 60.0).returncode


def test_a_failing_command_mid_block_fails_it(tmp_path: Path) -> None:
    assert _run(tmp_path, "sh", "echo one\n") == 0
    assert _run(tmp_path, "sh", "false\necho after\n") != 0
    assert _run(tmp_path, "sh", "false | cat\necho after\n") != 0     # pipefail
    assert _run(tmp_path, "sh", "echo $UNSET_VARIABLE_OF_NO_ONE\n") != 0  # nounset


def test_a_python_exception_fails_the_block(tmp_path: Path) -> None:
    assert _run(tmp_path, "python", "x = 1\nassert x == 1\n") == 0
    assert _run(tmp_path, "python", "raise RuntimeError('docs rot')\n") != 0


def test_blocks_run_in_their_folder_with_a_fresh_namespace(tmp_path: Path) -> None:
    assert _run(tmp_path, "python", "open('made_here', 'w').write('1')\n") == 0
    assert (tmp_path / "made_here").exists()
    assert _run(tmp_path, "python", "print(x)\n") != 0     # nothing from another block


def test_other_languages_are_not_run(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="not run"):
        _run(tmp_path, "text", "rm -rf /\n")
