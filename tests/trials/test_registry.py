"""The trial-kind registry (``vasim.trials.registry``): every configuration finds its kind,
and ``run_trial`` runs and stores it through that kind."""

from __future__ import annotations

from pathlib import Path

import pytest

from vasim.records.trial_metrics import MetricParams
from vasim.study.store import TrialStore
from vasim.trials.kinds import TELEOPERATION_MODES
from vasim.trials.registry import TRIAL_KINDS, TrialKind, TrialKinds, kind_name, run_trial
from vasim.trials.teleop_config import TeleopTrialConfig
from vasim.trials.teleop_run import run_teleop_trial, simulate_teleop, teleop_meta
from vasim.trials.vf import TrialConfig
from vasim.trials.vf_run import run_vf_trial, simulate_vf, vf_meta


def test_every_kind_is_registered_once_with_its_runner() -> None:
    assert TRIAL_KINDS.names() == ("mrcp", "mrcp_cam", "stdt", "vf")
    assert len(TRIAL_KINDS) == 4 and list(TRIAL_KINDS) == list(TRIAL_KINDS.names())
    vf = TRIAL_KINDS["vf"]
    assert (vf.run, vf.meta, vf.simulate) == (run_vf_trial, vf_meta, simulate_vf)
    for mode in TELEOPERATION_MODES:
        k = TRIAL_KINDS[mode]
        assert (k.run, k.meta, k.simulate) == (run_teleop_trial, teleop_meta, simulate_teleop)


@pytest.mark.parametrize("mode", [None, *TELEOPERATION_MODES])
def test_a_config_finds_its_kind(mode: str | None) -> None:
    cfg = TrialConfig() if mode is None else TeleopTrialConfig(mode=mode)
    assert kind_name(cfg) == ("vf" if mode is None else mode)
    assert TRIAL_KINDS.of(cfg).name == kind_name(cfg)


def test_a_kind_refuses_a_config_of_another_class() -> None:
    reg = TrialKinds()  # a kind named like a teleoperation mode but built for VF configs
    reg.add(TrialKind("stdt", run=run_vf_trial, meta=vf_meta, simulate=simulate_vf))
    with pytest.raises(TypeError, match="'stdt' runs a VfTrialConfig, got a TeleopTrialCon"):
        reg.of(TeleopTrialConfig(mode="stdt"))


def test_a_duplicate_or_bad_name_is_refused() -> None:
    reg = TrialKinds()
    kind = TrialKind("vf", run=run_vf_trial, meta=vf_meta, simulate=simulate_vf)
    assert reg.add(kind) is kind and "vf" in reg
    with pytest.raises(ValueError, match="already registered"):
        reg.add(TrialKind("vf", run=run_vf_trial, meta=vf_meta, simulate=simulate_vf))
    with pytest.raises(ValueError, match="lower-case identifier"):
        reg.add(TrialKind("Bad-Name", run=run_vf_trial, meta=vf_meta, simulate=simulate_vf))
    with pytest.raises(KeyError, match=r"unknown trial kind 'mrcp'.*known: vf"):
        reg["mrcp"]


def test_run_trial_runs_and_stores_each_kind_through_its_runner(tmp_path: Path) -> None:
    with TrialStore(tmp_path / "s.sqlite") as st:
        vf_res, vf_id = run_trial(TrialConfig(schema="none", scene="none", seed=1,
                                              max_time=0.3), st)
        tele_res, tele_id = run_trial(TeleopTrialConfig(mode="stdt", scene="none", seed=1,
                                                        max_time=0.3), st)
        rows = st.trials().set_index("id")
    assert vf_id is not None and tele_id is not None and vf_id != tele_id
    # the VF kind: 1 ms steps on the trajectory; the teleoperation kind: 18 ms station
    # cycles on the needle task, no fixture schema
    assert float(vf_res.samples.view()["t"][0]) == pytest.approx(1e-3)
    assert float(tele_res.samples.view()["t"][0]) == pytest.approx(0.018)
    assert tele_res.summary["mode"] == "stdt" and "mode" not in vf_res.summary
    assert rows.loc[vf_id, "task"] == "trajectory" and rows.loc[tele_id, "task"] == "needle"
    assert rows.loc[tele_id, "schema"] == "none"
    assert (rows["status"] == "completed").all()


def test_the_meta_builders_share_one_signature() -> None:
    cfg = TrialConfig(schema="ff", seed=3)
    m = TRIAL_KINDS.of(cfg).meta(cfg, session_id=None, schedule_index=None, protocol="p")
    assert (m.task, m.schema, m.seed, m.protocol) == ("trajectory", "ff", 3, "p")
    t = TeleopTrialConfig(mode="mrcp", seed=3)
    tm = TRIAL_KINDS.of(t).meta(t, protocol="q")
    assert (tm.task, tm.schema, tm.dt, tm.protocol) == ("needle", "none", 0.018, "q")


def test_simulate_gives_the_cohort_writer_its_dict() -> None:
    cfg = TrialConfig(schema="none", scene="none", seed=2, max_time=0.2)
    out = TRIAL_KINDS.of(cfg).simulate(cfg, MetricParams())
    assert set(out) == {"columns", "active_fixtures", "metrics", "summary", "events",
                        "trial_metrics", "wall_time", "sim_time"}
    assert out["sim_time"] == pytest.approx(float(out["columns"]["t"][-1]))
