"""Bad inputs end in a clean ConfigError or a finite result, never another exception.

Runs a subset of ``bench/bad_inputs.py``'s catalogue and, with hypothesis, feeds every
loader (schema, protocol, scene, robot) an extreme value in a random numeric field.
"""

from __future__ import annotations

import importlib.util
import math
import sys
import tomllib
from pathlib import Path
from types import ModuleType

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vasim.core.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]


def _bench() -> ModuleType:
    name = "_vasim_bench_bad_inputs"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, ROOT / "bench" / "bad_inputs.py")
        assert spec is not None and spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
    return sys.modules[name]


def test_catalogue_subset_has_no_other_outcome() -> None:
    b = _bench()
    counts, others = b.run_catalogue(stride=9, extremes=(1e308, math.nan, -math.inf, 10**30,
                                                         -0.0, 1e-308))
    assert others == []
    for category in ("schemas", "studies", "scenes", "robots", "meshes", "cli", "issue"):
        c = counts[category]
        assert c["other"] == 0
        assert c["clean error"] > 0, category  # the catalogue really refuses something
    # every named case of the issue is refused
    assert counts["issue"]["finite result"] == 0
    table = b.table(counts)
    assert table.splitlines()[0].split()[:2] == ["category", "tried"]


def test_classify_tells_the_outcomes_apart() -> None:
    b = _bench()
    assert b.classify(lambda: (1.0, 2)) == "finite result"
    assert b.classify(lambda: (1.0, math.nan)) == "other"
    assert b.classify(lambda: [][1]) == "other"

    def refuse() -> None:
        raise ConfigError("x", file="a.toml")

    assert b.classify(refuse, "a.toml") == "clean error"
    assert b.classify(refuse, "b.toml") == "other"  # must name the file


def test_dumps_round_trips_every_shipped_file() -> None:
    b = _bench()
    for _folder, path, _load in b._shipped():
        data = tomllib.loads(path.read_text(encoding="utf-8"))
        assert tomllib.loads(b.dumps(data)) == data, path.name


# -- property: every loader, every numeric field, any extreme ----------------------------
_SHIPPED = None


def _files() -> list[tuple[str, Path, object, dict, list]]:
    global _SHIPPED
    if _SHIPPED is None:
        b = _bench()
        _SHIPPED = []
        for folder, path, load in b._shipped():
            data = tomllib.loads(path.read_text(encoding="utf-8"))
            leaves = list(b.numeric_paths(data))
            if leaves:  # (a schema without fixtures has no number)
                _SHIPPED.append((folder, path, load, data, leaves))
    return _SHIPPED


extreme = st.one_of(
    st.sampled_from([1e308, -1e308, 1e-308, -1e-308, 5e-324, math.nan, math.inf, -math.inf,
                     -0.0, 0, 2**63, -(2**63) - 1, 10**400]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(10**40), max_value=10**40),
)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(pick=st.integers(min_value=0, max_value=10**9), field=st.integers(min_value=0),
       value=extreme)
def test_every_loader_gives_a_clean_error_or_a_finite_result(pick: int, field: int,
                                                             value: object) -> None:
    b = _bench()
    files = _files()
    folder, path, load, data, leaves = files[pick % len(files)]
    leaf = leaves[field % len(leaves)]
    text = b.dumps(b.with_value(data, leaf, value))
    try:
        result = load(text, str(path))  # type: ignore[operator]
    except ConfigError as exc:
        assert str(path) in str(exc) and exc.field  # names the file and the field ...
        assert "got " in exc.reason  # ... and the value, in the toolkit's words
        return
    assert b.all_finite(result), (folder, leaf, value)


@pytest.mark.parametrize("value", [1e308, math.nan, math.inf, 10**30, -0.0])
def test_every_numeric_field_of_ff_schema_is_checked(value: object) -> None:
    """Each of the ff schema's numbers, set to an extreme, is refused naming its field (or
    is a finite, harmless value: -0.0 where 0 is allowed)."""
    b = _bench()
    (_folder, path, load, data, leaves), = [f for f in _files() if f[1].name == "ff.toml"]
    for leaf in leaves:
        text = b.dumps(b.with_value(data, leaf, value))
        try:
            load(text, str(path))  # type: ignore[operator]
        except ConfigError as exc:
            assert exc.field == ".".join(map(str, leaf)), (exc.field, leaf)
            continue
        assert value == 0.0, leaf
