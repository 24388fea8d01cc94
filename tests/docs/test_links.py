"""README.md stays short, and every relative link in README.md and docs/*.md resolves to an
existing file and, with ``#anchor``, to a heading of it (issue #27 item 2)."""

from __future__ import annotations

import re
from pathlib import Path
from urllib.parse import unquote

import pytest

from tests.docs.doc_blocks import (
    KNOWN,
    README,
    ROOT,
    all_blocks,
    anchors,
    blocks,
    doc_files,
    is_relative,
    links,
    slug,
)

README_MAX_LINES = 250

PENDING: dict[str, str] = {
}
"""Pages other branches add in parallel (file -> branch). A link to one of them that is
missing here is an expected failure naming the branch, until the merge brings it; once the
file exists its links and anchors are checked like any other. Empty this after the merge."""


def test_readme_is_short() -> None:
    n = len(README.read_text(encoding="utf-8").splitlines())
    assert n <= README_MAX_LINES, f"README.md has {n} lines; at most {README_MAX_LINES}"


def test_the_readme_links_every_role_page() -> None:
    targets = {t for _, t in links(README)}
    for page in ("trainee", "experimenter", "researcher", "developer", "seed-comparison"):
        assert f"docs/{page}.md" in targets, f"README.md does not link docs/{page}.md"


def test_the_readme_keeps_the_two_commands() -> None:
    """.ci/run runs `make test`, the README's test command; `make run` is the other."""
    text = README.read_text(encoding="utf-8")
    assert "make run" in text and "make test" in text
    assert "make test" in (ROOT / ".ci" / "run").read_text(encoding="utf-8")


LINKS = [(path, line, target) for path in doc_files() for line, target in links(path)
         if is_relative(target)]


@pytest.mark.parametrize(("path", "line", "target"), LINKS,
                         ids=[f"{p.relative_to(ROOT)}:{n}:{t}" for p, n, t in LINKS])
def test_relative_link_resolves(path: Path, line: int, target: str) -> None:
    file_part, _, anchor = target.partition("#")
    dest = (path.parent / unquote(file_part)).resolve() if file_part else path
    where = f"{path.relative_to(ROOT)}:{line}: link {target!r}"
    if not dest.exists():
        rel = dest.relative_to(ROOT).as_posix() if dest.is_relative_to(ROOT) else str(dest)
        if rel in PENDING:
            pytest.xfail(f"{rel} comes with the branch {PENDING[rel]!r}")
        pytest.fail(f"{where}: no such file {rel}")
    assert dest.is_relative_to(ROOT), f"{where}: points outside the repository"
    if anchor:
        assert dest.suffix == ".md", f"{where}: an anchor into a file that is not Markdown"
        assert unquote(anchor) in anchors(dest), \
            f"{where}: {dest.name} has no heading with the anchor #{anchor}"


def test_links_are_found() -> None:
    """The link finder sees the README's links (a broken pattern would pass everything)."""
    assert len([t for _, t in links(README) if t.startswith("docs/")]) >= 10
    assert len(LINKS) >= 60


def test_fences_name_a_known_language() -> None:
    unknown = [f"{b.id}: ```{b.lang}" for b in all_blocks() if b.lang not in KNOWN]
    assert not unknown, "fences of unknown language (see docs/developer.md): " + ", ".join(unknown)


def test_slug_follows_github() -> None:
    assert slug("The viewer (`vasim serve`)".replace("`", "")) == "the-viewer-vasim-serve"
    assert slug('The f5PL editor (experimenter\'s page, "Fixture schema")') == \
        "the-f5pl-editor-experimenters-page-fixture-schema"
    assert slug("Retention and transfer probes, proficiency gates") == \
        "retention-and-transfer-probes-proficiency-gates"
    assert slug("Performance: the 18 ms cycle with more robots") == \
        "performance-the-18-ms-cycle-with-more-robots"


def test_anchor_and_block_parsing(tmp_path: Path) -> None:
    page = tmp_path / "p.md"
    page.write_text("# Title\n\n## A `code` heading\n\n## Title\n\n```sh\n# not a heading\n"
                    "echo [x](nowhere.md)\n```\n\n* item\n\n  ```python\n  print(1)\n  ```\n"
                    "[ok](p.md#a-code-heading)\n", encoding="utf-8")
    assert anchors(page) == {"title", "a-code-heading", "title-1"}
    assert [(b.lang, b.body) for b in blocks(page)] == [
        ("sh", "# not a heading\necho [x](nowhere.md)\n"), ("python", "print(1)\n")]
    assert links(page) == [(17, "p.md#a-code-heading")]


_PATH = re.compile(r"`((?:vasim|tests|bench|protocols|docs)/[A-Za-z0-9_./*-]+)`")

PATHS = [(path, m[1]) for path in doc_files()
         for m in _PATH.finditer(path.read_text(encoding="utf-8"))]


def test_named_repository_paths_exist() -> None:
    """A module, test or data file a page names in code (`vasim/...py`) exists: a renamed
    file would otherwise leave the docs pointing nowhere."""
    assert len(PATHS) >= 50
    missing = [f"{p.relative_to(ROOT)}: {name}" for p, name in PATHS
               if not (list(ROOT.glob(name.rstrip("/."))) if "*" in name
                       else (ROOT / name.rstrip("/.")).exists())]
    assert not missing, "paths named in the docs that do not exist: " + "; ".join(missing)
