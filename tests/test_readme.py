"""README.md's Python code blocks: every ``import`` of vasim they show still resolves (a
renamed module or symbol would otherwise leave the README silently wrong)."""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parent.parent / "README.md"
BLOCKS = re.findall(r"^```python\n(.*?)^```", README.read_text(encoding="utf-8"),
                    flags=re.M | re.S)


def _vasim_imports(code: str) -> list[tuple[str, str | None]]:
    """(module, name) pairs of the code's vasim imports (name None for ``import m``)."""
    out: list[tuple[str, str | None]] = []
    for node in ast.walk(ast.parse(code)):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "vasim":
            out += [(node.module or "", alias.name) for alias in node.names]
        elif isinstance(node, ast.Import):
            out += [(a.name, None) for a in node.names if a.name.split(".")[0] == "vasim"]
    return out


IMPORTS = sorted({pair for code in BLOCKS for pair in _vasim_imports(code)},
                 key=lambda p: (p[0], p[1] or ""))


def test_the_readme_shows_vasim_imports() -> None:
    assert len(BLOCKS) >= 2
    assert ("vasim.abdomen.world", "Abdomen") in IMPORTS


@pytest.mark.parametrize(("module", "name"), IMPORTS)
def test_readme_import_resolves(module: str, name: str | None) -> None:
    mod = importlib.import_module(module)
    if name is not None:
        assert hasattr(mod, name), f"README imports {name} from {module}, which has no {name}"
