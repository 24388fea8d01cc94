"""The house facts of issue #29, measured from the source tree (not a timing benchmark).

Prints, for ``vasim/``:

* modules longer than 800 lines, functions longer than 100 lines (outside the compiled
  kernels, ``_*kernels.py``),
* functions with more than 10 parameters,
* ``raise ConfigError`` outside ``vasim/core/config.py`` and ``tomllib`` imports outside it,
* private names (``_x``) imported from another package of vasim (a module may use its own
  package's private names, and a sub-package its parent's: ``private_imports_inside`` lists
  those),
* module import cycles, counting imports inside functions too (grimp's graph).

Usage::

    python -m bench.house            # the figures, one line each, then the lists
    python -m bench.house --smoke    # the same (it takes a second; VASIM_BENCH_SMOKE=1, which
                                     # make test's smoke run sets, changes nothing either)
    python -m bench.house --json     # machine-readable
"""

from __future__ import annotations

import argparse
import ast
import json
import sys
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "vasim"
LONG_MODULE = 800
LONG_LINES = 100
MANY_PARAMS = 10


@dataclass
class Facts:
    long_modules: list[str] = field(default_factory=list)
    long_functions: list[str] = field(default_factory=list)
    many_params: list[str] = field(default_factory=list)
    config_raises_outside: list[str] = field(default_factory=list)
    tomllib_outside: list[str] = field(default_factory=list)
    private_imports: list[str] = field(default_factory=list)
    private_imports_inside: list[str] = field(default_factory=list)
    cycles: list[str] = field(default_factory=list)


def _modules() -> Iterator[tuple[str, Path, ast.Module]]:
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT.parent)
        if "protocols" in rel.parts:
            continue
        name = ".".join(rel.with_suffix("").parts).removesuffix(".__init__")
        yield name, path, ast.parse(path.read_text(), str(path))


def _params(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    a = fn.args
    names = [*a.posonlyargs, *a.args, *a.kwonlyargs]
    n = len([x for x in names if x.arg not in ("self", "cls")])
    return n + (a.vararg is not None) + (a.kwarg is not None)


def _resolve(module: str, node: ast.ImportFrom, is_package: bool) -> str:
    if not node.level:
        return node.module or ""
    base = module.split(".")
    base = base if is_package else base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join([*base, *([node.module] if node.module else [])])


def measure() -> Facts:
    facts = Facts()
    for name, path, tree in _modules():
        where = str(path.relative_to(ROOT.parent))
        kernel = path.name.endswith("kernels.py")
        n_lines = len(path.read_text().splitlines())
        if n_lines > LONG_MODULE:
            facts.long_modules.append(f"{where} {n_lines}")
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                length = (node.end_lineno or node.lineno) - node.lineno + 1
                if length > LONG_LINES and not kernel:
                    facts.long_functions.append(f"{where}:{node.lineno} {node.name} {length}")
                if _params(node) > MANY_PARAMS and not kernel:
                    facts.many_params.append(f"{where}:{node.lineno} {node.name} "
                                             f"{_params(node)}")
            elif isinstance(node, ast.Raise) and where != "vasim/core/config.py":
                exc = node.exc
                call = exc.func if isinstance(exc, ast.Call) else exc
                if (isinstance(call, ast.Name) and call.id == "ConfigError") or (
                        isinstance(call, ast.Attribute) and call.attr == "ConfigError"):
                    facts.config_raises_outside.append(f"{where}:{node.lineno}")
            elif isinstance(node, ast.Import | ast.ImportFrom):
                mods = ([a.name for a in node.names] if isinstance(node, ast.Import)
                        else [_resolve(name, node, path.name == "__init__.py")])
                if "tomllib" in mods and where != "vasim/core/config.py":
                    facts.tomllib_outside.append(f"{where}:{node.lineno}")
                if isinstance(node, ast.ImportFrom):
                    src = mods[0]
                    own = name if path.name == "__init__.py" else name.rpartition(".")[0]
                    for alias in node.names:
                        if (src.startswith("vasim") and alias.name.startswith("_")
                                and not alias.name.startswith("__")):
                            # the package that holds the name: src itself when the name is
                            # a module of it (``from vasim.abdomen import _kernels``)
                            holder = (src if (ROOT.parent / src.replace(".", "/")
                                              / "__init__.py").exists()
                                      else src.rpartition(".")[0])
                            inside = own == holder or own.startswith(holder + ".")
                            (facts.private_imports_inside if inside
                             else facts.private_imports).append(
                                f"{where}:{node.lineno} {alias.name} from {src}")
    facts.cycles = _cycles()
    return facts


def _cycles() -> list[str]:
    """Strongly connected groups of modules (size > 1) in grimp's import graph."""
    import grimp

    graph = grimp.build_graph("vasim", include_external_packages=False)
    edges = {m: graph.find_modules_directly_imported_by(m) for m in graph.modules}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[str] = []
    counter = [0]

    def strong(v: str) -> None:   # Tarjan's algorithm, recursive (a few hundred modules)
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                out.append(" <-> ".join(sorted(group)))

    sys.setrecursionlimit(10_000)
    for v in sorted(edges):
        if v not in index:
            strong(v)
    return sorted(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench.house", description=__doc__)
    ap.add_argument("--smoke", action="store_true", help="the same measurement")
    ap.add_argument("--json", action="store_true", help="print JSON")
    args = ap.parse_args(argv)
    facts = measure()
    if args.json:
        print(json.dumps(asdict(facts), indent=1))
        return 0
    for key, items in asdict(facts).items():
        print(f"{key}: {len(items)}")
    for key, items in asdict(facts).items():
        if items:
            print(f"\n# {key}")
            print("\n".join(f"  {x}" for x in items))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
