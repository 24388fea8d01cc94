"""Chapter 5 end to end at tiny sizes: sessions give each trial its mode practice, and
``bench/chapter5.py`` runs a cohort and prints the side-by-side table with the seed."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pandas as pd

from vasim.operator.teleop_profile import NEUTRAL
from vasim.study.protocol import load_protocol
from vasim.study.session import load_session, start_session
from vasim.study.store import TrialStore

ROOT = Path(__file__).resolve().parents[2]


def _bench() -> ModuleType:
    name = "_vasim_bench_chapter5"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, ROOT / "bench" / "chapter5.py")
        assert spec is not None and spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
    return sys.modules[name]


def test_a_session_gives_each_teleoperation_trial_its_modes_practice(tmp_path: Path) -> None:
    with TrialStore(tmp_path / "s.sqlite") as store:
        sid = start_session(store, load_protocol("mrcp_vs_stdt"), "S01", seed=3)
        session = load_session(store, sid)
        seen: dict[str, list[int]] = {}
        for t in session.schedule:
            cfg = session.trial_config(t)
            assert cfg.mode == t.condition and cfg.practice == t.index
            seen.setdefault(t.condition, []).append(cfg.mode_practice)
    # blocks of 6 in a random order: every mode counts its own trials 0..5
    assert seen == {m: [0, 1, 2, 3, 4, 5] for m in ("stdt", "mrcp", "mrcp_cam")}


def test_the_bench_runs_a_tiny_cohort_and_prints_it_beside_table_5_1() -> None:
    b = _bench()
    df = b.simulate(2, 7, NEUTRAL, 1, trials_per_mode=1, n_rings=2, max_time=300.0)
    assert len(df) == 6 and sorted(df.groupby("subject").size()) == [3, 3]
    assert set(df["mode"]) == {"stdt", "mrcp", "mrcp_cam"}
    assert df["completed"].all() and (df["Q"] >= 0).all() and (df["EM"] > 0).all()
    # StdT hands over by hand (1 side change for 2 rings), MRCP's kernel does it
    assert (df.loc[df["mode"] == "stdt", "transfers"] == 1).all()
    lines = b.side_by_side(df)
    text = "\n".join(lines)
    et = df.groupby("mode")["ET"].mean()     # one trial per subject and mode
    row = next(x for x in lines if x.strip().startswith("MRCP ") and "101.13" in x)
    assert f"{et['mrcp']:10.3f}" in row
    pct = 100.0 * (et["mrcp"] - et["stdt"]) / et["stdt"]
    assert f"MRCP vs StdT: simulated {pct:+.1f} %, seed -29.0 %" in text
    assert "seed t = 6.69, p = 2.14E-06" in text         # Table 5.2, ET StdT vs MRCP


def test_the_bench_prints_experiment_3_beside_table_5_4() -> None:
    b = _bench()
    rng = np.random.default_rng(3)
    rows = []
    for i, subj in enumerate(("A", "B", "C")):
        for mode, f in (("stdt", 1.0), ("mrcp", 0.5 if i < 2 else 1.5)):
            for n in (1, 2):
                v = f * float(np.exp(rng.normal(0, 0.05)))
                rows.append({"subject": subj, "mode": mode, "trial_number": n, "ET": 100 * v,
                             "EM": 2 * v, "Q": 0.0, "contact_time": 10 * v, "force": 5 * v,
                             "torque": 0.1 * v, "transfers": 3.0, "regrasps": 0.0,
                             "misaligned_transfers": 0.0, "em_to_ring": 1.0,
                             "em_to_via": 0.5, "em_transfer": 0.0})
    df = pd.DataFrame(rows)
    text = "\n".join(b.side_by_side(df, "mrcp_suture_dynamic"))
    cells = df.groupby(["subject", "mode"])["force"].mean().unstack()
    g = cells["stdt"].mean() / cells["mrcp"].mean()
    assert f"gain StdT/MRCP: simulated {g:.2f}, seed 2.49" in text   # 10740.27 / 4314.74
    assert "force [N s]" in text and "torque [N m s]" in text and "Q [" not in text
    assert "MRCP smaller for 2 of 3 (A, B)" in text                  # who benefits
    assert "MRCP+Cam" not in text.split("per trial")[0]
