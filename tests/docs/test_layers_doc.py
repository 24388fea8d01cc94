"""docs/developer.md's layer diagram is the import-linter layers contract of pyproject.toml
(the same packages, top to bottom), and README.md's one-line layer order says the same."""

from __future__ import annotations

import re
import tomllib

from tests.docs.doc_blocks import README, ROOT


def _contract_layers() -> list[set[str]]:
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    contracts = cfg["tool"]["importlinter"]["contracts"]
    layers = next(c["layers"] for c in contracts if c["type"] == "layers")
    return [{p.strip().removeprefix("vasim.") for p in layer.split("|")} for layer in layers]


def _diagram_layers() -> list[set[str]]:
    text = (ROOT / "docs" / "developer.md").read_text(encoding="utf-8")
    out = []
    for line in text.splitlines():
        m = re.match(r"^ ?\d  (vasim/\S+(?: \| \S+)*)", line)
        if m:
            out.append({p.strip().removeprefix("vasim/").rstrip("/") for p in m[1].split("|")})
    return out


def test_the_diagram_is_the_layers_contract() -> None:
    assert _diagram_layers() == _contract_layers()


def test_the_readme_layer_order_is_the_contract() -> None:
    flat = " ".join(README.read_text(encoding="utf-8").split())
    m = re.search(r"the package: (core < .*?) \(", flat)
    assert m, "README.md has no line 'the package: core < ... ('"
    order = [set(step.strip().split("|")) for step in m[1].split("<")]
    assert order == _contract_layers()[::-1]
