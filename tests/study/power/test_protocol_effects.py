"""A protocol's ``[power]`` table: effect sizes from the protocol file, validated on load,
the command line overriding it (vasim/study/protocol/power.py, vasim/cli/power.py)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

from tests.study.power.conftest import TINY_POWER
from vasim.cli import main
from vasim.core.errors import ConfigError
from vasim.operator.learning import DEFAULT_EFFECTS
from vasim.study.power.design import PowerDesign
from vasim.study.protocol import load_protocol, parse_protocol
from vasim.study.protocol.power import PowerPlan

WITH_POWER = TINY_POWER + """
[power]
effect_scale = 0.5

[power.effects.ff]
accuracy = 0.8

[power.effects.mag]
speed = 0.9
"""


def test_power_table_is_loaded_with_the_protocol() -> None:
    p = parse_protocol(WITH_POWER)
    assert p.power == PowerPlan(effect_scale=0.5, effects={"ff": {"accuracy": 0.8},
                                                           "mag": {"speed": 0.9}})
    base = p.power.base_effects()
    # the named fields replace the calibration's, the rest keep it
    assert base["ff"].accuracy == 0.8 and base["ff"].speed == DEFAULT_EFFECTS["ff"].speed
    assert base["mag"].speed == 0.9 and base["mag"].accuracy == DEFAULT_EFFECTS["mag"].accuracy
    assert base["vg"] == DEFAULT_EFFECTS["vg"]
    assert parse_protocol(TINY_POWER).power is None


@pytest.mark.parametrize(("table", "field", "words"), [
    ("[power]\neffect_scale = 7.0\n", "power.effect_scale", "got 7.0, expected"),
    ("[power]\neffect_scale = 'half'\n", "power.effect_scale", "'half'"),
    ("[power]\nscale = 0.5\n", "power.scale", "unknown field"),
    ("[power]\neffects = 3\n", "power.effects", "got 3"),
    ("[power.effects.ff]\nacuracy = 0.8\n", "power.effects.ff.acuracy", "unknown field"),
    ("[power.effects.ff]\naccuracy = 'x'\n", "power.effects.ff.accuracy", "'x'"),
    ("[power.effects.ff]\naccuracy = 0.0\n", "power.effects.ff", "accuracy must be"),
    ("[power.effects.ff]\ncarryover = 1.5\n", "power.effects.ff", "carryover must be"),
    ("[power.effects.ag]\naccuracy = 0.9\n", "power.effects.ag",
     "a condition of the protocol (none, mag, ff)"),
])
def test_bad_power_tables_name_file_field_and_value(tmp_path: Path, table: str, field: str,
                                                    words: str) -> None:
    path = tmp_path / "p.toml"
    path.write_text(TINY_POWER + "\n" + table, encoding="utf-8")
    with pytest.raises(ConfigError) as info:
        load_protocol(path)
    assert info.value.field == field, info.value
    assert str(info.value.file) == str(path) and words in str(info.value), info.value


class _Captured(Exception):
    def __init__(self, design: PowerDesign) -> None:
        super().__init__("captured")
        self.design = design


def _design_of(argv: list[str], monkeypatch: pytest.MonkeyPatch) -> PowerDesign:
    """The design ``vasim study power`` would run (Ray is never started)."""
    import vasim.study.power.driver as driver

    def capture(_protocol: Any, design: PowerDesign, **_kw: Any) -> None:
        raise _Captured(design)

    monkeypatch.setattr(driver, "run_power", capture)
    with pytest.raises(_Captured) as info:
        main(["study", "power", "--subjects", "4", "--cohorts", "1", *argv])
    return info.value.design


def test_protocol_effects_are_used_and_the_command_line_overrides_them(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "p.toml"
    path.write_text(WITH_POWER, encoding="utf-8")
    proto = ["--protocol", str(path)]
    # the protocol alone: s = 0.5 over accuracy 0.8 -> 1 + 0.5 (0.8 - 1) = 0.9
    d = _design_of(proto, monkeypatch)
    assert d.effect_scale == 0.5
    assert math.isclose(d.effects["ff"].accuracy, 0.9)
    assert math.isclose(d.effects["mag"].speed, 0.95)            # 1 + 0.5 (0.9 - 1)
    ag = DEFAULT_EFFECTS["ag"].accuracy                              # the scenario's
    assert math.isclose(d.effects["ag"].accuracy, 1 + 0.5 * (ag - 1))
    # --effect-scale wins over the protocol's scale; the protocol's effects stay
    d = _design_of([*proto, "--effect-scale", "1"], monkeypatch)
    assert d.effect_scale == 1.0 and d.effects["ff"].accuracy == 0.8
    # an --effects file wins field by field; fields it leaves out keep the protocol's
    efile = tmp_path / "e.toml"
    efile.write_text("[ff]\naccuracy = 0.7\n", encoding="utf-8")
    d = _design_of([*proto, "--effects", str(efile), "--effect-scale", "1"], monkeypatch)
    assert d.effects["ff"].accuracy == 0.7 and d.effects["mag"].speed == 0.9
    # no [power] table: the calibration at scale 1, as before
    plain = tmp_path / "plain.toml"
    plain.write_text(TINY_POWER, encoding="utf-8")
    d = _design_of(["--protocol", str(plain)], monkeypatch)
    assert d.effect_scale == 1.0 and d.effects == dict(DEFAULT_EFFECTS)
