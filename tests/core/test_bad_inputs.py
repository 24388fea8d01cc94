"""Bad inputs end in a clean ConfigError or a finite result, never another exception.

Runs a subset of ``bench/bad_inputs.py``'s catalogue and, with hypothesis, feeds every
loader (schema, protocol, scene, robot) an extreme value in a random numeric field.
"""

from __future__ import annotations

import importlib.util
import math
import sys
import tomllib
from collections import Counter
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


# -- issue #30 item 5: tracebacks -------------------------------------------------------
def _deep_texts() -> list[tuple[str, str]]:
    n = 50_000
    return [("brackets", "x = " + "[" * n + "]" * n + "\n"),
            ("inline tables", "x = " + "{a = " * n + "1" + "}" * n + "\n"),
            ("mixed", "x = " + "[{a = " * (n // 2) + "1" + "}]" * (n // 2) + "\n")]


def _loaders(tmp: Path) -> list[tuple[str, object]]:
    from vasim.abdomen.scene import parse_scene
    from vasim.fixtures.schema import parse_schema
    from vasim.mrcp.dh import parse_robot
    from vasim.study.power.design import parse_effects
    from vasim.study.protocol import parse_protocol
    from vasim.study.session import load_answers_file

    def answers(text: str, src: str) -> object:
        p = tmp / "answers.toml"
        p.write_text(text, encoding="utf-8")
        return load_answers_file(p)

    return [("schema", lambda t, s: parse_schema(t, source=s)),
            ("protocol", lambda t, s: parse_protocol(t, source=s)),
            ("scene", lambda t, s: parse_scene(t, source=s)),
            ("robot", lambda t, s: parse_robot(t, file=s)),
            ("effects", lambda t, s: parse_effects(t, file=s)),
            ("answers", answers)]


@pytest.mark.parametrize("shape", ["brackets", "inline tables", "mixed"])
def test_deeply_nested_toml_is_refused_by_every_loader(tmp_path: Path, shape: str) -> None:
    """50,000 nested brackets: a RecursionError in every loader before; now the one TOML
    reader (vasim.core.config.parse_toml) refuses them, naming the file."""
    text = dict(_deep_texts())[shape]
    for kind, load in _loaders(tmp_path):
        src = str(tmp_path / "answers.toml") if kind == "answers" else f"{kind}.toml"
        with pytest.raises(ConfigError) as info:
            load(text, src)  # type: ignore[operator]
        assert info.value.file == src, kind
        assert "nested 50000 levels deep at line 1, expected at most 64" in str(info.value)


def test_nesting_up_to_the_limit_parses() -> None:
    from vasim.core.config import MAX_TOML_NESTING, parse_toml

    n = MAX_TOML_NESTING
    data = parse_toml("x = " + "[" * n + "1" + "]" * n)
    depth, node = 0, data["x"]
    while isinstance(node, list):
        depth, node = depth + 1, node[0]
    assert depth == n and node == 1
    with pytest.raises(ConfigError, match=f"nested {n + 1} levels"):
        parse_toml("x = " + "[" * (n + 1) + "1" + "]" * (n + 1), file="f.toml")


def _depth(v: object) -> int:
    if isinstance(v, list):
        return 1 + max((_depth(x) for x in v), default=0)
    if isinstance(v, dict):
        return 1 + max((_depth(x) for x in v.values()), default=0)
    return 0


_leaf = st.one_of(st.integers(-5, 5), st.text(alphabet="[]{}#\"' ab\\", max_size=6),
                  st.booleans())
_value = st.recursive(_leaf, lambda c: st.one_of(
    st.lists(c, max_size=3),
    st.dictionaries(st.sampled_from(["a", "b", "c d", "[x]"]), c, max_size=3)),
    max_leaves=12)


@settings(max_examples=300, deadline=None)
@given(doc=st.dictionaries(st.sampled_from(["k", "m", "n"]), _value, min_size=1, max_size=3))
def test_toml_nesting_equals_the_parsed_depth(doc: dict) -> None:
    """toml_nesting of a document written as inline values (strings with brackets, quotes
    and '#' included) equals the nesting depth of the parsed document: an independent
    count."""
    from vasim.core.config import toml_nesting

    b = _bench()
    text = "\n".join(f"{k} = {b._scalar(v)}" for k, v in doc.items()) + "\n"
    assert tomllib.loads(text) == doc
    depth, _line = toml_nesting(text)
    assert depth == max(_depth(v) for v in doc.values())


def test_replay_of_a_huge_trial_id_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    from vasim.cli import main

    assert main(["trial", "--replay", "99999999999999999999999", "--db", "x.db"]) == 2
    err = capsys.readouterr().err
    assert "argument --replay: got 99999999999999999999999, expected an integer in " \
           "[1, 9223372036854775807]" in err and "Traceback" not in err


def test_parse_batch_drops_a_400_digit_integer() -> None:
    from vasim.viewer.instrument_input import parse_batch

    for key in ("dx", "dy", "wheel", "sx", "sy", "ins", "roll"):
        assert parse_batch(f'{{"{key}": {"9" * 400}}}') is None
        assert parse_batch(f'{{"{key}": -{"9" * 400}}}') is None
    assert parse_batch(f'{{"dx": {"9" * 300}}}') is not None  # 1e300 is a finite float
    assert parse_batch(f'{{"dx": {"9" * 5000}}}') is None      # beyond int parsing limits


def test_the_round_tells_its_outcomes_apart() -> None:
    """bench/bad_inputs.py's issue #30 round: each outcome of a case is recognised (the
    case runs in a forked process; a hang is killed at its time limit)."""
    import time

    b = _bench()

    def refuse() -> None:
        raise ConfigError("got 1, expected 2", file="f.toml", field="x")

    def crash() -> None:
        raise ValueError("boom")

    cases = [
        (b.RoundCase("t", "refused", call=refuse, words=("f.toml", "field 'x'")), "refused"),
        (b.RoundCase("t", "unclear", call=refuse, words=("field 'y'",)), "wrong"),
        (b.RoundCase("t", "silent", call=lambda: None), "wrong"),      # refusal was due
        (b.RoundCase("t", "handled", call=lambda: True, expect="handled"), "handled"),
        (b.RoundCase("t", "check", call=lambda: False, expect="handled"), "wrong"),
        (b.RoundCase("t", "crash", call=crash), "traceback"),
        (b.RoundCase("t", "hang", call=lambda: time.sleep(60), timeout=1.0), "hang"),
        (b.RoundCase("t", "cli", ["trial", "--replay", "1" * 30, "--db", "x.db"],
                     words=("argument --replay",)), "refused"),
    ]
    for case, expected in cases:
        assert b.run_round_case(case)[0] == expected, case.what
    table = b.round_table({"3": Counter(refused=2, hang=1)})
    assert table.splitlines()[1].split() == ["#30.3", "3", "2", "0", "0", "1", "0"]
