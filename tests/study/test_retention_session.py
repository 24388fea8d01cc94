"""Retention and transfer in sessions: a later sitting stops the run and resumes after its
delay (or a recorded simulated one), the simulated operator's forgetting and transfer per
trial, and the report's side-by-side section checked against the stored trials."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from vasim.core.errors import StoreError
from vasim.operator.learning import DEFAULT_EFFECTS
from vasim.operator.retention import DEFAULT_RETENTION
from vasim.study.cohort import CohortPlan, CohortRun, simulate_cohort
from vasim.study.protocol import load_protocol
from vasim.study.report.data import load_study
from vasim.study.report.sections.retention import phase_cells, retention_section
from vasim.study.session import (
    SITTING_EVENT,
    SessionSettings,
    load_session,
    run_session,
    start_session,
)
from vasim.study.store import TrialStore


def _weight(cond: str) -> float:
    return 1.0 if cond == "none" else DEFAULT_EFFECTS[cond].practice_weight


def test_a_later_sitting_waits_for_its_delay_or_records_a_simulated_one(tmp_path: Path) -> None:
    p = load_protocol("vf_retention")
    with TrialStore(tmp_path / "r.db") as st:
        sid = start_session(st, p, "S01", seed=2, settings=SessionSettings(max_trial_time=0.2))
        assert run_session(st, sid, progress=False) == 13          # sitting 1 only
        with pytest.raises(StoreError, match=r"sitting 2 \(block 'retention'\) begins 7 d "
                                             r"after the previous trial .* due "):
            run_session(st, sid, progress=False)
        assert run_session(st, sid, progress=False, simulate_delay=True) == 4
        sched = st.schedule(sid)
        assert st.session(sid)["status"] == "completed"
        first = int(sched["trial_id"].iloc[13])
        ev = st.events(first)
        rec = json.loads(ev[ev["kind"] == SITTING_EVENT]["detail"].iloc[0])
        assert (rec["sitting"], rec["block"], rec["delay_days"], rec["day"], rec["simulated"]) \
            == (2, "retention", 7.0, 7.0, True)
        assert 0.0 <= rec["elapsed_days"] < 0.01                   # no real waiting
        others = [int(t) for t in sched["trial_id"] if int(t) != first]
        assert not any((st.events(t)["kind"] == SITTING_EVENT).any() for t in others)

        s = load_session(st, sid)
        conds = [t.condition for t in s.schedule]
        r7 = DEFAULT_RETENTION.retained(7.0)
        # first retention trial: all 13 earlier trials are 7 days old, on trained paths
        ret = s.schedule[13]
        assert s.practice_weights(ret) == pytest.approx([r7] * 13)
        assert s.trial_config(ret).practice == round(sum(map(_weight, conds[:13])) * r7)
        # first transfer trial (variant 5): day-0 trials forgotten and transferred, the two
        # same-day retention trials (variant 0) transferred only
        tr = s.schedule[15]
        assert tr.variant == 5 and tr.block == "transfer"
        expect = [r7 * 0.7] * 13 + [0.7, 0.7]
        assert s.practice_weights(tr) == pytest.approx(expect)
        assert s.trial_config(tr).practice == round(
            sum(_weight(c) * w for c, w in zip(conds[:15], expect, strict=True)))
        # sitting 1 is unchanged by the hook: the calibrated practice count
        assert s.trial_config(s.schedule[12]).practice == round(
            sum(map(_weight, conds[:12])))


def test_report_puts_acquisition_retention_and_transfer_side_by_side(tmp_path: Path) -> None:
    db = tmp_path / "c.db"
    simulate_cohort(db, load_protocol("vf_retention"),
                    CohortPlan(n_subjects=3, n_surgeons=1, seed=5, max_trial_time=0.3),
                    CohortRun(workers=0, progress=False))
    data = load_study(db)
    assert data.protocol is not None
    assert len(data.sittings) == 3 and all(json.loads(r)["simulated"]
                                           for r in data.sittings["record"])
    cells = phase_cells(data, data.protocol)
    with TrialStore(db, readonly=True) as st:
        wide = st.trial_metrics(wide=True)
        for sid, subj in zip(st.sessions()["id"], st.sessions()["subject"], strict=True):
            sch = st.schedule(int(sid))
            ids = sch["trial_id"].astype(int).tolist()
            acq, ret, trans = ids[12], ids[13:15], ids[15:17]   # fixed positions of the file
            for phase, picked in (("acquisition", [acq]), ("retention", ret),
                                  ("transfer", trans)):
                got = cells[(cells["subject"] == subj) & (cells["phase"] == phase)
                            & (cells["dv"] == "path_dev_mean_mm")]["value"].item()
                assert got == pytest.approx(np.mean(wide.loc[picked, "path_dev_mean_mm"]))
    section, prov = retention_section(data)
    tables = {b.name: b.data for b in section.blocks if getattr(b, "name", "")
              and hasattr(b, "data")}
    pairs = tables["retention_pairs"]
    row = pairs[(pairs["dv"] == "path_dev_mean_mm") & (pairs["group1"] == "acquisition")
                & (pairs["group2"] == "retention")].iloc[0]
    d = cells[cells["dv"] == "path_dev_mean_mm"].pivot(index="subject", columns="phase",
                                                       values="value")
    diff = (d["acquisition"] - d["retention"]).to_numpy()
    assert row["n"] == 3 and row["mean_diff"] == pytest.approx(diff.mean())
    assert row["t"] == pytest.approx(diff.mean() / (diff.std(ddof=1) / np.sqrt(3)))
    assert set(tables["retention_phases"]["phase"]) == {"acquisition", "retention",
                                                        "transfer"}
    assert any(b.__class__.__name__ == "FigureBlock" for b in section.blocks)
    assert len(prov) == len(cells)
    # the learning-curve analysis keeps to the acquisition trials (0.3 s trials reach no
    # point, so they are all listed as excluded: analysed or excluded, never retention)
    from vasim.study.report.analysis import analyse_vf

    vf = analyse_vf(data)
    seen = set(vf.trials["trial_id"]) | set(vf.excluded["trial_id"])
    acq = data.analysed[data.analysed["block"].isin(("baseline", "ff", "mag"))]
    assert seen == set(acq["trial_id"]) and len(seen) == 3 * 13


def test_cli_stops_at_the_sitting_and_resumes_with_a_simulated_delay(tmp_path: Path,
                                                                     capsys) -> None:
    from vasim.cli import main

    db = str(tmp_path / "c.db")
    assert main(["study", "run", "--protocol", "vf_retention", "--subject", "C01", "--db", db,
                 "--seed", "1", "--max-time", "0.1", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "13/17 trials completed, status running" in out
    assert "the next sitting (block 'retention') begins 7 d after the last trial" in out
    assert main(["study", "resume", "--db", db, "--subject", "C01", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "due 20" in err and "--simulate-delay" in err and err.count("\n") == 1
    assert main(["study", "resume", "--db", db, "--subject", "C01", "--no-progress",
                 "--simulate-delay"]) == 0
    out = capsys.readouterr().out
    assert "4 trial(s) run" in out and "17/17 trials completed, status completed" in out
