"""The fenced blocks and relative links of README.md and docs/*.md (issue #27 item 2).

Shared by ``test_doc_examples.py`` (runs every ```` ```sh ```` and ```` ```python ```` block)
and ``test_links.py`` (every relative link resolves). The convention is in
docs/developer.md, "Docs and their examples".
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
import unicodedata
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"


def doc_files() -> list[Path]:
    """README.md and every docs/*.md, in a fixed order."""
    return [README, *sorted((ROOT / "docs").glob("*.md"))]


RUN = ("sh", "python")
"""Fence languages the examples test runs."""
PARSE = ("toml", "json")
"""Fence languages whose content is parsed (a file's content) unless it shows a fragment."""
ILLUSTRATION = ("text", "")
"""Fence languages never run: output, synopses, slow or server-starting commands. A bare
fence counts as ``text`` (pages written elsewhere may use one); ``text`` says it outright."""
KNOWN = RUN + PARSE + ILLUSTRATION


@dataclass(frozen=True)
class Block:
    """One fenced block: its file, the line of its opening fence, language and body."""

    path: Path
    line: int
    lang: str
    body: str

    @property
    def id(self) -> str:
        where = self.path.relative_to(ROOT) if self.path.is_relative_to(ROOT) else self.path
        return f"{where}:{self.line}"


_FENCE = re.compile(r"^( *)(`{3,}|~{3,})\s*([^\s`]*)")


def blocks(path: Path) -> list[Block]:
    """The fenced blocks of a Markdown file (indented ones inside list items too), bodies
    dedented by their fence's indentation.

    Raises:
        ValueError: for a fence that is never closed.
    """
    out: list[Block] = []
    lines = path.read_text(encoding="utf-8").splitlines()
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        indent, fence, lang = len(m[1]), m[2], m[3].lower()
        start = i
        body: list[str] = []
        i += 1
        while i < len(lines) and not (lines[i].strip().startswith(fence[0] * len(fence))
                                      and lines[i].strip().strip(fence[0]) == ""):
            body.append(lines[i])
            i += 1
        if i == len(lines):
            raise ValueError(f"{path}:{start + 1}: a fence that is never closed")
        i += 1
        text = "\n".join(ln[indent:] if ln[:indent].strip() == "" else ln for ln in body)
        out.append(Block(path, start + 1, lang, textwrap.dedent(text) + "\n"))
    return out


def all_blocks() -> list[Block]:
    return [b for path in doc_files() for b in blocks(path)]


# -- links ------------------------------------------------------------------------------

_LINK = re.compile(r"!?\[(?:[^\]\[]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")


def _prose(path: Path) -> str:
    """The file's text without its fenced blocks and inline code spans (links there are
    examples, not links)."""
    text = path.read_text(encoding="utf-8")
    kept: list[str] = []
    inside = ""
    for line in text.splitlines():
        m = _FENCE.match(line)
        if m and not inside:
            inside = m[2][0] * len(m[2])
            kept.append("")
            continue
        if inside:
            if line.strip().startswith(inside) and line.strip().strip(inside[0]) == "":
                inside = ""
            kept.append("")
            continue
        kept.append(re.sub(r"`[^`]*`", "``", line))
    return "\n".join(kept)


def links(path: Path) -> list[tuple[int, str]]:
    """(line, target) of every link and image in the file's prose."""
    out = []
    for n, line in enumerate(_prose(path).splitlines(), 1):
        out += [(n, m[1]) for m in _LINK.finditer(line)]
    return out


def is_relative(target: str) -> bool:
    return not re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", target) and not target.startswith("//")


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: its text without markup, lower case, every character
    that is not a letter, digit, space, hyphen or underscore dropped, spaces to hyphens."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)   # links: their text
    text = re.sub(r"<[^>]+>", "", text).strip().lower()
    kept = [c for c in text
            if c in " -_" or unicodedata.category(c)[0] in ("L", "N")]
    return "".join(kept).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """Every heading anchor of a Markdown file (repeats get -1, -2, ... as on GitHub)."""
    seen: dict[str, int] = {}
    out: set[str] = set()
    for line in _prose_with_code(path).splitlines():
        m = re.match(r"^ {0,3}#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        base = slug(m[1])
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.add(base if n == 0 else f"{base}-{n}")
    return out


def _prose_with_code(path: Path) -> str:
    """The file's text without fenced blocks (inline code kept: headings use it)."""
    kept: list[str] = []
    inside = ""
    for line in path.read_text(encoding="utf-8").splitlines():
        m = _FENCE.match(line)
        if m and not inside:
            inside = m[2][0] * len(m[2])
            continue
        if inside:
            if line.strip().startswith(inside) and line.strip().strip(inside[0]) == "":
                inside = ""
            continue
        kept.append(line.replace("`", ""))
    return "\n".join(kept)


# -- running an example -------------------------------------------------------------------


def example_env() -> dict[str, str]:
    """The examples' environment: this interpreter's ``bin/`` first on ``PATH`` (its
    ``vasim`` and ``python``), the checkout first on ``PYTHONPATH``."""
    env = dict(os.environ)
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    env["PYTHONPATH"] = str(ROOT) + (os.pathsep + env["PYTHONPATH"]
                                     if env.get("PYTHONPATH") else "")
    env.pop("VIRTUAL_ENV", None)
    return env


def run_block(block: Block, cwd: Path, timeout: float) -> subprocess.CompletedProcess[str]:
    """Runs a ``sh`` block as one bash script (``set -euo pipefail``) or a ``python`` block
    in a fresh interpreter, in ``cwd``.

    Raises:
        ValueError: for a block of another language.
        subprocess.TimeoutExpired: past ``timeout`` [s].
    """
    if block.lang == "sh":
        cmd = ["bash", "-c", "set -euo pipefail\n" + block.body]
    elif block.lang == "python":
        cmd = [sys.executable, "-c", block.body]
    else:
        raise ValueError(f"{block.id}: a {block.lang!r} block is not run")
    return subprocess.run(cmd, cwd=cwd, env=example_env(), capture_output=True, text=True,
                          timeout=timeout, stdin=subprocess.DEVNULL)
