"""A simulated session runs its stored scenario (vasim/study/session.py trial_config,
vasim/study/cohort.py, vasim study simulate --scenario/--effect-scale; issue #25 item 3)."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from vasim.cli import main
from vasim.operator.scenario import load_scenario
from vasim.study.cohort import cohort_subjects, scenario_record
from vasim.study.power.cohort import subject_session
from vasim.study.protocol import load_protocol
from vasim.study.store import TrialStore

TINY = """
name = "tiny_scenario"
description = "two-block test protocol"
task = "trajectory"
max_trial_time_s = 0.2
[randomisation]
block_order = "random"
variant_order = "random"
[[blocks]]
name = "baseline"
condition = "none"
probe = true
counterbalance = false
[[blocks]]
name = "ff"
condition = "ff"
variants = [1]
probes_after = 1
"""


@pytest.fixture
def tiny(tmp_path: Path) -> Path:
    p = tmp_path / "tiny.toml"
    p.write_text(TINY)
    return p


def _configs(scenario: str, scale: float):
    p = load_protocol("vf_learning_curve")
    sc = load_scenario(scenario)
    subj = cohort_subjects(1, 1, seed=3, scenario=sc)[0]
    s = subject_session(p, subj, dt=1e-3, max_trial_time=None,
                        extra={"scenario": scenario_record(sc, scale)})
    return subj, [(st, s.trial_config(st)) for st in s.schedule], sc


@pytest.mark.parametrize("scenario,scale", [("seed_plausible", 0.0), ("null", 1.0)])
def test_no_fixture_effect_means_no_operator_factor_and_no_mechanism(scenario, scale):
    subj, cfgs, _ = _configs(scenario, scale)
    for st, cfg in cfgs:
        assert cfg.profile is not None
        assert cfg.profile.noise == pytest.approx(subj.profile.noise)
        assert cfg.gain == (1.0 if st.condition == "none" else 0.0)


def test_the_declared_effect_reaches_the_operator_at_full_mechanism():
    subj, cfgs, sc = _configs("seed_plausible", 1.0)
    for st, cfg in cfgs:
        assert cfg.gain == 1.0
        if st.condition != "none":
            assert cfg.profile.noise == pytest.approx(
                subj.profile.noise * sc.fixtures[st.condition].accuracy)


def test_simulate_stores_the_scenario_text_and_hash(tmp_path: Path, tiny: Path):
    db = tmp_path / "s.db"
    assert main(["study", "simulate", "--protocol", str(tiny), "--subjects", "1",
                 "--workers", "0", "--db", str(db), "--scenario", "null",
                 "--effect-scale", "0.5", "--no-progress"]) == 0
    with TrialStore(db) as st:
        rec = st.session(int(st.sessions()["id"].iloc[0]))["config"]["extra"]["scenario"]
        assert st.sessions()["operator"].iloc[0] == "scripted (declared scenario, synthetic)"
    text = load_scenario("null").text
    assert rec == {"name": "null", "text": text, "effect_scale": 0.5,
                   "sha256": hashlib.sha256(text.encode()).hexdigest()}
    # continuing under another scenario is refused (exit 2, the field named)
    assert main(["study", "simulate", "--protocol", str(tiny), "--subjects", "1",
                 "--workers", "0", "--db", str(db), "--no-progress"]) == 2


def test_bad_scenario_and_effect_scale_are_exit_2(tmp_path: Path, capsys):
    args = ["study", "simulate", "--protocol", "vf_learning_curve", "--db",
            str(tmp_path / "x.db")]
    assert main([*args, "--scenario", "nope"]) == 2
    assert "'--scenario': got 'nope'" in capsys.readouterr().err
    assert main([*args, "--effect-scale", "-1"]) == 2   # argparse's range check
    assert "--effect-scale: got -1.0" in capsys.readouterr().err
