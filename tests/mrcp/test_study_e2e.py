"""End to end: ``vasim study simulate`` of the MRCP protocol (short schedule), then
``vasim report``; the report's MRCP section is compared with the stored trials."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from tests.trials.test_teleop import short_protocol
from vasim.cli import main
from vasim.study.store import TrialStore


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("mrcp_e2e")
    db, out = d / "cohort.sqlite", d / "report"
    assert main(["study", "simulate", "--protocol", str(short_protocol(d)), "--subjects", "2",
                 "--workers", "0", "--seed", "5", "--db", str(db)]) == 0
    assert main(["report", "--db", str(db), "--out", str(out), "--no-progress"]) == 0
    return db, out


def _stored(db: Path) -> pd.DataFrame:
    with TrialStore(db, readonly=True) as st:
        rows = []
        for sid in st.sessions()["id"]:
            sched = st.schedule(int(sid))
            subject = st.session(int(sid))["subject"]
            for _, r in sched.iterrows():
                m = st.trial_metrics(int(r["trial_id"])).set_index("metric")["value"]
                rows.append({"subject": subject, "mode": r["condition"],
                             "trial_id": int(r["trial_id"]), **m.to_dict()})
    return pd.DataFrame(rows)


def test_every_scheduled_trial_ran_in_its_mode(study) -> None:
    db, _ = study
    with TrialStore(db, readonly=True) as st:
        assert st.sessions()["status"].tolist() == ["completed", "completed"]
        trials = st.trials()
        assert (trials["status"] == "completed").all() and (trials["task"] == "needle").all()
        modes = sorted(st.trial(int(t))["config"]["mode"] for t in trials["id"])
    assert modes == ["mrcp", "mrcp", "mrcp_cam", "mrcp_cam", "stdt", "stdt"]


def test_report_mrcp_section_is_filled_from_the_stored_trials(study) -> None:
    db, out = study
    data = _stored(db)
    html = (out / "index.html").read_text(encoding="utf-8")
    assert "MRCP vs standard teleoperation" in html
    trials = pd.read_csv(out / "tables" / "mrcp_trials.csv")
    assert sorted(trials["trial_id"]) == sorted(data["trial_id"])
    # the stored metrics prefixed: the report's keys contact_time etc. are metric names too
    merged = trials.merge(data.rename(columns=lambda c: c if c == "trial_id" else f"s_{c}"),
                          on="trial_id")
    for key, metric in (("ET", "completion_time"), ("EM", "path_l2"),
                        ("contact_time", "contact_time"), ("force", "accumulated_force"),
                        ("torque", "accumulated_torque")):
        pd.testing.assert_series_equal(merged[key], merged[f"s_{metric}"], check_names=False,
                                       rtol=1e-12)
    gains = pd.read_csv(out / "tables" / "mrcp_gains.csv")
    means = data.groupby(["subject", "mode"])["completion_time"].mean().unstack()
    for mode, label in (("mrcp", "MRCP"), ("mrcp_cam", "MRCP+Cam")):
        row = gains[(gains["metric"] == "ET") & (gains["mode"] == label)].iloc[0]
        assert row["gain"] == pytest.approx(means["stdt"].mean() / means[mode].mean(),
                                            rel=1e-12)
        assert row["n_subjects"] == 2
    paired = pd.read_csv(out / "tables" / "mrcp_paired.csv")
    assert {"ET", "EM"} <= set(paired["metric"])
