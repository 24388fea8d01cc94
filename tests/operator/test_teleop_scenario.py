"""Declared teleoperation scenarios (issue #25 item 6, issue #28): the mechanism alone has no
penalty, the assumed penalties are sourced, files are validated on load, a scenario of the
wrong kind for a protocol is refused, and no value of the seed's chapter-5 tables is in the
generative model."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from vasim.cli import main
from vasim.core.errors import ConfigError
from vasim.operator.scenario import load_scenario, parse_scenario
from vasim.operator.teleop_profile import NEUTRAL, TeleopEffects, scale_teleop
from vasim.study.cohort import check_scenario_kind, default_scenario_for
from vasim.study.protocol import load_protocol
from vasim.study.session import SessionSettings, load_session, start_session
from vasim.study.store import TrialStore

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "protocols" / "scenarios"

SEED_CHAPTER5_NUMBERS = (
    # Table 5.1 means and sds (ET, EM, Q per mode) and the ratios fitted to before
    "142.51", "101.13", "105.29", "46.97", "42.31", "41.16", "2580.13", "2195.05", "2185.89",
    "505.05", "373.37", "308.56", "8477.62", "2849.91", "3060.19", "4218.93", "1463.68",
    "1689.73", "1.175", "1.041",
    # Table 5.2 t values
    "6.69", "6.43", "5.76", "5.95", "7.49", "5.68",
    # Table 5.4 means and gains
    "181.51", "113.20", "113.2", "2293.26", "1891.62", "2012.61", "750.37", "10740.27",
    "4314.74", "1.19e6", "6.12e5", "1.60", "1.21", "2.68", "2.48", "1.95",
)
"""Values of the seed's Tables 5.1, 5.2 and 5.4 (as quoted in issues #21, #25, #28)."""


def test_the_mechanism_only_scenario_has_no_penalty() -> None:
    sc = load_scenario("teleop_mechanism_only")
    assert sc.kind == "teleop" and sc.teleop == NEUTRAL
    assert sc.teleop_effects(1.0) == NEUTRAL and sc.teleop_effects(3.0) == NEUTRAL
    assert not sc.fixtures and sc.outcome is None


def test_the_assumed_scenario_is_sourced_and_scales_to_the_mechanism() -> None:
    sc = load_scenario("teleop_assumed")
    assert sc.kind == "teleop" and sc.teleop is not None and sc.teleop != NEUTRAL
    for k in ("thread_time", "stdt_noise", "camera_cost"):
        src = sc.source(f"teleop.{k}")
        assert "seed l." in src and "assumed" in src and "not fitted" in src
    assert sc.teleop_effects(0.0) == NEUTRAL
    assert sc.teleop_effects(1.0) == sc.teleop
    assert sc.teleop_effects(0.5) == scale_teleop(sc.teleop, 0.5)


def _teleop_text(**teleop: str) -> str:
    text = (SCENARIOS / "teleop_mechanism_only.toml").read_text(encoding="utf-8")
    for k, v in teleop.items():
        text = re.sub(rf"^{k} = .*$", f"{k} = {v}", text, flags=re.M)
    return text


@pytest.mark.parametrize(("edit", "field", "words"), [
    ({"stdt_noise": "{ value = -0.5, source = \"assumed\" }"}, "teleop.stdt_noise.value",
     "-0.5"),
    ({"camera_cost": "{ value = 0.2 }"}, "teleop.camera_cost", "source"),
    ({"thread_time": "{ value = 11.0, source = \"assumed\" }"}, "teleop.thread_time.value",
     "11"),
])
def test_a_bad_teleop_value_is_one_line_naming_file_field_value(
        tmp_path: Path, edit: dict[str, str], field: str, words: str) -> None:
    p = tmp_path / "bad.toml"
    p.write_text(_teleop_text(**edit), encoding="utf-8")
    with pytest.raises(ConfigError) as ei:
        load_scenario(p)
    msg = str(ei.value)
    assert "\n" not in msg and str(p) in msg and field in msg and words in msg


def test_a_teleop_scenario_has_no_fixture_effects_and_needs_all_three_penalties() -> None:
    text = _teleop_text()
    ff = ('\n[fixtures.ff]\n' + "\n".join(
        f'{k} = {{ value = {v}, source = "assumed" }}' for k, v in (
            ("accuracy", 0.8), ("speed", 1.0), ("practice_weight", 1.0), ("carryover", 0.2),
            ("dependence", 0.0))) + "\n")
    with pytest.raises(ConfigError, match=r"fixtures.*teleoperation scenario"):
        parse_scenario(text + ff, file="x.toml")
    short = re.sub(r"^camera_cost = .*$\n", "", text, flags=re.M)
    with pytest.raises(ConfigError, match=r"teleop\.camera_cost"):
        parse_scenario(short, file="x.toml")


def test_the_scenario_kind_must_be_the_protocols() -> None:
    tele, vf = load_protocol("mrcp_suture_dynamic"), load_protocol("vf_learning_curve")
    assert default_scenario_for(tele).name == "teleop_mechanism_only"
    assert default_scenario_for(vf).name == "seed_plausible"
    check_scenario_kind(tele, load_scenario("teleop_assumed"))
    check_scenario_kind(vf, load_scenario("null"))
    with pytest.raises(ConfigError, match="VF scenario 'seed_plausible'"):
        check_scenario_kind(tele, load_scenario("seed_plausible"), "s.toml")
    with pytest.raises(ConfigError, match="teleoperation scenario 'teleop_assumed'"):
        check_scenario_kind(vf, load_scenario("teleop_assumed"))


@pytest.mark.parametrize(("protocol", "scenario", "kind"), [
    ("mrcp_suture_dynamic", "seed_plausible", "VF scenario"),
    ("mrcp_vs_stdt", "null", "VF scenario"),
    ("vf_learning_curve", "teleop_mechanism_only", "teleoperation scenario"),
])
def test_study_simulate_refuses_the_wrong_kind_in_one_line_naming_the_file(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], protocol: str, scenario: str,
        kind: str) -> None:
    db = tmp_path / "c.sqlite"
    rc = main(["study", "simulate", "--protocol", protocol, "--subjects", "2", "--workers",
               "0", "--db", str(db), "--scenario", scenario, "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1
    assert f"{scenario}.toml" in err and kind in err and "--scenario" in err
    assert not db.exists()


def test_a_session_gives_its_teleop_trials_the_scenarios_penalties(tmp_path: Path) -> None:
    from vasim.study.cohort import scenario_record

    sc = load_scenario("teleop_assumed")
    protocol = load_protocol("mrcp_suture_dynamic")
    with TrialStore(tmp_path / "s.sqlite") as store:
        for scale in (1.0, 0.0):
            sid = start_session(store, protocol, f"S{int(scale)}", seed=3,
                                settings=SessionSettings(
                                    operator="scripted",
                                    extra={"scenario": scenario_record(sc, scale)}))
            session = load_session(store, sid)
            cfgs = [session.trial_config(t) for t in session.schedule]
            assert {c.mode_effects for c in cfgs} == {sc.teleop_effects(scale)}
        plain = load_session(store, start_session(store, protocol, "S9", seed=3))
        assert {plain.trial_config(t).mode_effects for t in plain.schedule} == {None}


def test_a_stored_config_record_gives_back_the_penalties() -> None:
    from vasim.trials.teleop_config import TeleopTrialConfig
    from vasim.trials.vf_run import config_record

    eff = TeleopEffects(thread_time=2.0, stdt_noise=0.5, camera_cost=0.5)
    cfg = TeleopTrialConfig(mode="mrcp", mode_effects=eff)
    from vasim.operator.profile import OperatorProfile

    rec = config_record(cfg, OperatorProfile.intermediate())
    assert rec["mode_effects"] == {"thread_time": 2.0, "stdt_noise": 0.5, "camera_cost": 0.5}
    assert TeleopTrialConfig(mode="mrcp", mode_effects=rec["mode_effects"]).mode_effects == eff
    assert "mode_effects" not in config_record(TeleopTrialConfig(mode="mrcp"),
                                                     OperatorProfile.intermediate())
    with pytest.raises(ConfigError, match="mode_effects"):
        TeleopTrialConfig(mode="mrcp", mode_effects={"stdt_noise": -1.0})


def _files() -> list[Path]:
    return sorted((ROOT / "vasim" / "operator").glob("*.py")) + sorted(SCENARIOS.glob("*.toml"))


@pytest.mark.parametrize("path", _files(), ids=lambda p: p.name)
def test_no_value_of_the_seeds_chapter5_tables_is_in_the_generative_model(path: Path) -> None:
    text = path.read_text(encoding="utf-8")
    found = [n for n in SEED_CHAPTER5_NUMBERS
             if re.search(rf"(?<![\d.]){re.escape(n)}(?![\d])", text)]
    assert not found, f"{path.name} holds seed chapter-5 table values {found}"


def test_the_scan_would_find_a_table_value() -> None:
    text = "thread_time = 10.0  # fitted to MRCP's ET, 101.13 s"
    assert any(re.search(rf"(?<![\d.]){re.escape(n)}(?![\d])", text)
               for n in SEED_CHAPTER5_NUMBERS)
