"""A catalogue of bad inputs for every loader, and how each one ends.

Every numeric field of every shipped file (schemas, protocols, scenes, robots) is set, one
at a time, to each extreme value (±1e308, ±1e-308, NaN, ±inf, huge integers, -0.0, ...);
meshes get non-finite, huge and oversized vertices; the command line gets huge counts,
long subject codes and impossible addresses; the issue's named cases are run as such. Each
input ends in one of:

* ``clean error``: a :class:`vasim.core.errors.ConfigError` naming the file (or an argparse
  error, exit 2, for the command line);
* ``finite result``: the loader returned an object whose numbers are all finite;
* ``other``: any other exception, or a result holding a non-finite number (a crash
  waiting to happen downstream).

``python -m bench bad_inputs`` (or ``python bench/bad_inputs.py``) prints the table
``category, tried, clean error, finite result, other``; ``tests/test_bad_inputs.py`` runs a
subset and asserts that ``other`` is 0.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import io
import math
import os
import sys
import tempfile
import tomllib
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

EXTREMES: tuple[Any, ...] = (1e308, -1e308, 1e-308, -1e-308, math.nan, math.inf, -math.inf,
                             10**30, -(10**30), 2**63, -0.0, 0, -1, 1e20)
"""The values every numeric field is set to."""

SMOKE = os.environ.get("VASIM_BENCH_SMOKE") == "1"
"""``python -m bench --smoke``: every run cut to seconds (it checks the bench runs; its
figures mean nothing)."""

Outcome = str  # "clean error" | "finite result" | "other"
Case = tuple[str, str, Callable[[], Any]]
"""(category, description, thunk running the loader)."""


# -- TOML writing (a minimal dumper for the shipped layouts) --------------------------------
def _scalar(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_scalar(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {_scalar(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def _key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() else _scalar(k)


def _is_aot(v: Any) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def dumps(data: dict[str, Any], prefix: str = "") -> str:
    """TOML text of ``data`` (tables and arrays of tables as headers)."""
    lines = [f"{_key(k)} = {_scalar(v)}" for k, v in data.items()
             if not isinstance(v, dict) and not _is_aot(v)]
    out = "\n".join(lines) + ("\n" if lines else "")
    for k, v in data.items():
        path = f"{prefix}.{_key(k)}" if prefix else _key(k)
        if isinstance(v, dict):
            out += f"\n[{path}]\n" + dumps(v, path)
        elif _is_aot(v):
            for item in v:
                out += f"\n[[{path}]]\n" + dumps(item, path)
    return out


# -- numeric leaves ---------------------------------------------------------------------
def numeric_paths(data: Any, path: tuple[Any, ...] = ()) -> Iterator[tuple[Any, ...]]:
    """Paths (keys and indices) of every number (not bool) in parsed TOML."""
    if isinstance(data, dict):
        for k, v in data.items():
            yield from numeric_paths(v, (*path, k))
    elif isinstance(data, list):
        for i, v in enumerate(data):
            yield from numeric_paths(v, (*path, i))
    elif isinstance(data, int | float) and not isinstance(data, bool):
        yield path


def with_value(data: dict[str, Any], path: tuple[Any, ...], value: Any) -> dict[str, Any]:
    """A deep copy of ``data`` with the leaf at ``path`` set to ``value``."""
    out = copy.deepcopy(data)
    node: Any = out
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    return out


def all_finite(obj: Any, _depth: int = 0) -> bool:
    """Whether every number reachable in ``obj`` (dataclasses, tuples, arrays) is finite."""
    if _depth > 12:
        return True
    if isinstance(obj, bool) or obj is None or isinstance(obj, str):
        return True
    if isinstance(obj, int):
        return abs(obj) < 2**63
    if isinstance(obj, float):
        return math.isfinite(obj)
    if isinstance(obj, np.ndarray):
        return obj.dtype.kind not in "fc" or bool(np.all(np.isfinite(obj)))
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return all(all_finite(getattr(obj, f.name), _depth + 1) for f in dataclasses.fields(obj))
    if isinstance(obj, tuple | list):
        return all(all_finite(x, _depth + 1) for x in obj)
    if isinstance(obj, dict):
        return all(all_finite(x, _depth + 1) for x in obj.values())
    return True


def classify(thunk: Callable[[], Any], source: str | None = None) -> Outcome:
    """Runs ``thunk``: a ConfigError (naming ``source``, if given) is a clean error."""
    from vasim.core.errors import ConfigError

    try:
        result = thunk()
    except ConfigError as exc:
        return "clean error" if source is None or source in str(exc) else "other"
    except SystemExit as exc:  # argparse
        return "clean error" if exc.code == 2 else "other"
    except Exception:
        return "other"
    return "finite result" if all_finite(result) else "other"


# -- the catalogue ----------------------------------------------------------------------
def _shipped() -> list[tuple[str, Path, Callable[[str, str], Any]]]:
    from vasim.abdomen.scene import parse_scene
    from vasim.core.resources import protocols_dir
    from vasim.fixtures.schema import parse_schema
    from vasim.mrcp.dh import parse_robot
    from vasim.study.protocol import parse_protocol

    root = protocols_dir()
    loaders: dict[str, Callable[[str, str], Any]] = {
        "schemas": lambda text, src: parse_schema(text, source=src),
        "studies": lambda text, src: parse_protocol(text, source=src),
        "scenes": lambda text, src: parse_scene(text, source=src),
        "robots": lambda text, src: parse_robot(text, file=src),
    }
    out = []
    for folder, load in loaders.items():
        for p in sorted((root / folder).glob("*.toml")):
            out.append((folder, p, load))
    return out


def field_cases(stride: int = 1, extremes: tuple[Any, ...] = EXTREMES) -> Iterator[Case]:
    """Every ``stride``-th numeric field of every shipped file, set to each extreme."""
    for folder, path, load in _shipped():
        data = tomllib.loads(path.read_text(encoding="utf-8"))
        src = str(path)
        for k, leaf in enumerate(numeric_paths(data)):
            if k % stride:
                continue
            for value in extremes:
                text = dumps(with_value(data, leaf, value))
                yield (folder, f"{path.name}:{'.'.join(map(str, leaf))}={value!r}",
                       lambda text=text, src=src, load=load: load(text, src))
        # a BOM at the start is accepted
        text = "\ufeff" + path.read_text(encoding="utf-8")
        yield (folder, f"{path.name} with a UTF-8 BOM",
               lambda text=text, src=src, load=load: load(text, src))


def _obj(vertices: np.ndarray, faces: np.ndarray) -> str:
    v = "\n".join("v " + " ".join(repr(float(c)) for c in row) for row in vertices)
    f = "\n".join("f " + " ".join(str(int(i) + 1) for i in row) for row in faces)
    return v + "\n" + f + "\n"


def mesh_cases(tmp: Path) -> Iterator[Case]:
    """User meshes: non-finite, huge, oversized and out-of-unit vertices."""
    import trimesh

    from vasim.abdomen.meshes import load_user_mesh

    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.03)
    variants: dict[str, np.ndarray] = {}
    for value in (math.nan, math.inf, 1e200, 1e20, 1e308, -1e308):
        v = ball.vertices.copy()
        v[0, 0] = value
        variants[f"vertex0.x={value!r}"] = v
    variants["0.9 m organ"] = ball.vertices * 15.0
    variants["1e20 m organ"] = ball.vertices * 1e20 / 0.06
    variants["1e-308 m organ"] = ball.vertices * 1e-308
    variants["organ at 1 m"] = ball.vertices + 1.0
    variants["a 6 cm ball (fine)"] = ball.vertices
    for name, v in variants.items():
        p = tmp / f"mesh_{len(list(tmp.iterdir()))}.obj"
        p.write_text(_obj(v, ball.faces))
        yield ("meshes", name, lambda p=p: load_user_mesh(p, field="organs.x.mesh"))


def cli_cases() -> Iterator[Case]:
    """Command-line numbers, codes and addresses, parsed only (nothing runs)."""
    from vasim.cli import build_parser

    bad = ["1000000000", "-1", "1e308", "nan", "inf", str(10**30), "-0.0", "0"]
    argvs: list[list[str]] = []
    for v in bad:
        argvs += [["study", "simulate", "--protocol", "p", "--db", "x", "--subjects", v],
                  ["study", "simulate", "--protocol", "p", "--db", "x", "--workers", v],
                  ["study", "simulate", "--protocol", "p", "--db", "x", "--seed", v],
                  ["study", "run", "--protocol", "p", "--db", "x", "--subject", "S1",
                   "--max-time", v],
                  ["trial", "--variant", v], ["serve", "--port", v], ["serve", "--duration", v]]
    for code in ("A" * 100_000, "Jane Doe", "", "S\n1"):
        argvs.append(["study", "run", "--protocol", "p", "--db", "x", "--subject", code])
    for host in ("999.1.1.1", "1.2.3", "bad_host!", "x" * 300, "::1", "localhost"):
        argvs.append(["serve", "--host", host])
    for argv in argvs:
        def run(argv: list[str] = argv) -> Any:
            with contextlib.redirect_stderr(io.StringIO()):
                ns = build_parser().parse_args(argv)
            return {k: v for k, v in vars(ns).items() if not callable(v)}

        yield ("cli", " ".join(a[:40] for a in argv), run)


def issue_cases() -> Iterator[Case]:
    """The cases issue #16 lists, by name."""
    from vasim.abdomen.scene import parse_scene
    from vasim.fixtures.schema import parse_schema
    from vasim.study.protocol import parse_protocol

    head = 'name = "x"\ndescription = "d"\n'
    for body in ("max_force_n = 1000", "[fixtures.ff]\nmax_force_n = 1000",
                 "[fixtures.ff]\nk = 1e6", "max_force_n = 1e300"):
        yield ("issue", f"schema {body!r}",
               lambda b=body: parse_schema(head + b, source="protocols/schemas/ff.toml"))
    proto = ('name = "p"\ndescription = "d"\ntask = "trajectory"\nreach_radius_m = {r}\n'
             '[[blocks]]\nname = "b"\ncondition = "none"\n')
    for r in ("0.5", "1e300"):
        yield ("issue", f"protocol reach_radius_m = {r}",
               lambda r=r: parse_protocol(proto.format(r=r), source="p.toml"))
    yield ("issue", "scene mass = 1e-300",
           lambda: parse_scene('name = "s"\n[organs.liver]\nmass = 1e-300\n', source="s.toml"))


def run_catalogue(stride: int = 1, extremes: tuple[Any, ...] = EXTREMES,
                  ) -> tuple[dict[str, Counter[str]], list[str]]:
    """Runs every case; returns outcome counts per category and the 'other' cases."""
    counts: dict[str, Counter[str]] = {}
    others: list[str] = []
    with tempfile.TemporaryDirectory() as d:
        groups = [field_cases(stride, extremes), mesh_cases(Path(d)), cli_cases(),
                  issue_cases()]
        for group in groups:
            for category, what, thunk in group:
                src = None if category in ("cli", "issue", "meshes") else what.split(":")[0]
                outcome = classify(thunk, src.split(" ")[0] if src else None)
                counts.setdefault(category, Counter())[outcome] += 1
                if outcome == "other":
                    others.append(f"{category}: {what}")
    return counts, others


def table(counts: dict[str, Counter[str]]) -> str:
    """The printed table."""
    rows = [f"{'category':<10} {'tried':>6} {'clean error':>12} {'finite result':>14} "
            f"{'other (crash)':>14}"]
    total: Counter[str] = Counter()
    for cat, c in counts.items():
        total.update(c)
        rows.append(f"{cat:<10} {sum(c.values()):>6} {c['clean error']:>12} "
                    f"{c['finite result']:>14} {c['other']:>14}")
    rows.append(f"{'total':<10} {sum(total.values()):>6} {total['clean error']:>12} "
                f"{total['finite result']:>14} {total['other']:>14}")
    return "\n".join(rows)


def main() -> None:
    import time

    t0 = time.perf_counter()
    counts, others = run_catalogue(40, EXTREMES[:3]) if SMOKE else run_catalogue()
    print(table(counts))
    print(f"({time.perf_counter() - t0:.1f} s)")
    for o in others[:50]:
        print("other:", o)


if __name__ == "__main__":
    main()
    sys.exit(0)
