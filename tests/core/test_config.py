"""The config toolkit (vasim.core.config) and the bounds table (vasim.core.bounds)."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from vasim.core import bounds
from vasim.core.bounds import FORCE_N, Bound
from vasim.core.config import (
    check_choice,
    check_int,
    check_keys,
    check_number,
    check_str,
    check_vec3,
    describe_range,
    parse_toml,
    rewrap,
    show,
)
from vasim.core.errors import ConfigError


def test_the_issue_message_reads_file_field_value_and_range() -> None:
    with pytest.raises(ConfigError) as info:
        check_number(1000.0, "fixtures.ff.max_force_n", gt=0.0, bound=FORCE_N,
                     file="protocols/schemas/ff.toml")
    assert str(info.value) == (
        "protocols/schemas/ff.toml: field 'fixtures.ff.max_force_n': got 1000.0, expected a "
        "finite number in (0, 3.3] N (the Phantom Omni's peak force, 3.3 N (Geomagic spec))")
    assert info.value.file == "protocols/schemas/ff.toml"
    assert info.value.field == "fixtures.ff.max_force_n"


@pytest.mark.parametrize(("kw", "text"), [
    ({"gt": 0.0}, "> 0"), ({"ge": 1}, ">= 1"), ({"lt": 90.0}, "< 90"),
    ({"gt": 0.0, "lt": 90.0}, "in (0, 90)"), ({"ge": 0.0, "le": 1.0}, "in [0, 1]"),
    ({"bound": Bound(1e-3, 10.0, "kg", "r")}, "in [0.001, 10] kg (r)"),
    ({"bound": Bound(0.0, 10.0, "kg", "r"), "gt": 0.0}, "in (0, 10] kg (r)"),
    ({"bound": Bound(0.0, 10.0, "", "r"), "le": 5.0}, "in [0, 5] (r)"),
])
def test_describe_range_takes_the_tighter_limit(kw: dict, text: str) -> None:
    assert describe_range(**kw) == text


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, 10**400, True, "1", None,
                                   [1.0]])
def test_check_number_refuses_non_numbers_and_non_finite(value: object) -> None:
    with pytest.raises(ConfigError, match=r"got .*, expected a finite number"):
        check_number(value, "x")


@given(st.floats(allow_nan=False, allow_infinity=False))
def test_check_number_accepts_exactly_the_bound(x: float) -> None:
    b = Bound(-2.5, 7.0, "m", "test")
    if -2.5 <= x <= 7.0:
        assert check_number(x, "x", bound=b) == x
    else:
        with pytest.raises(ConfigError):
            check_number(x, "x", bound=b)


def test_check_int_and_numpy_integers() -> None:
    assert check_int(np.int64(5), "n", lo=0, hi=6) == 5
    with pytest.raises(ConfigError, match=r"got 7, expected an integer in \[0, 6\]"):
        check_int(7, "n", lo=0, hi=6)
    with pytest.raises(ConfigError, match=r"got 1\.0, expected an integer"):
        check_int(1.0, "n")
    with pytest.raises(ConfigError, match="got True"):
        check_int(True, "n")


def test_keys_choice_str_vec3() -> None:
    assert check_keys({"a": 1}, ("a", "b"), "t", file="f.toml") == {"a": 1}
    with pytest.raises(ConfigError) as info:
        check_keys({"a": 1, "zz": 2}, ("a", "b"), "t", file="f.toml")
    assert info.value.field == "t.zz" and "unknown field (value 2), expected one of a, b" in str(
        info.value)
    with pytest.raises(ConfigError, match="missing required field") as info:
        check_keys({}, ("a",), "t", required=("a",))
    assert info.value.field == "t.a"
    with pytest.raises(ConfigError, match="got True, expected one of"):
        check_choice(True, "c", ("a", "b"))
    with pytest.raises(ConfigError, match="one-line"):
        check_str("a\nb", "s")
    assert check_vec3([1, 2, 3], "v") == (1.0, 2.0, 3.0)
    with pytest.raises(ConfigError, match="non-zero"):
        check_vec3((0, 0, 0), "v", nonzero=True)
    with pytest.raises(ConfigError, match=r"3 finite numbers in \[-1, 1\]"):
        check_vec3((0, 0, 2), "v", bound=Bound(-1, 1, "m", "r"))


def test_show_truncates_long_values() -> None:
    text = show("A" * 100_000)
    assert len(text) < 120 and text.endswith("... (100,000 characters)")
    assert show([0] * 1000).endswith("(1,000 items)")
    assert show(1.5) == "1.5"


def test_parse_toml_strips_a_bom_and_names_the_file() -> None:
    assert parse_toml("\ufeffa = 1\n", file="x.toml") == {"a": 1}
    with pytest.raises(ConfigError, match=r"^x\.toml: invalid TOML"):
        parse_toml("a = \n", file="x.toml")
    with pytest.raises(ConfigError, match="must be a string, got bytes"):
        parse_toml(b"a = 1", file="x.toml")


def test_rewrap_prefixes_the_field_and_keeps_an_inner_file() -> None:
    e = rewrap(ConfigError("got 1, expected 2", field="k"), "fixtures.ff", "s.toml")
    assert (e.file, e.field) == ("s.toml", "fixtures.ff.k")
    e = rewrap(ConfigError("m", file="mesh.obj", field="k"), "organs.x", "s.toml")
    assert e.file == "mesh.obj"


def test_every_bound_is_finite_ordered_and_explained() -> None:
    table = {k: v for k, v in vars(bounds).items() if isinstance(v, Bound)}
    assert len(table) >= 30
    for name, b in table.items():
        assert math.isfinite(b.low) and math.isfinite(b.high) and b.low <= b.high, name
        assert len(b.reason) > 10, name
        # products the simulator forms stay far from overflow
        assert max(abs(b.low), abs(b.high)) <= 2**63, name


def test_bounds_agree_with_the_device_and_the_runner() -> None:
    from vasim.fixtures.ff import DEVICE_MAX_FORCE_N
    from vasim.trials.kinds import MAX_TRIAL_TIME_S

    assert FORCE_N.high == DEVICE_MAX_FORCE_N == 3.3
    assert bounds.TRIAL_TIME_S.high == MAX_TRIAL_TIME_S
    assert bounds.workers_bound().high == 4 * (os.cpu_count() or 1)
    assert bounds.workers_bound().low == 0  # --workers 0: in this process
