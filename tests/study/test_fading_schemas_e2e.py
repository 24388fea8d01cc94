"""End to end with tiny sizes (issue #18 items 1 and 3): ``vasim study simulate`` of the
shipped vf_fading and vf_schemas protocols (shortened: fewer variants and trials, a short
time limit), then ``vasim report``: the faded, adaptive and combined conditions are
analysed and asked about under their own labels, and every sample carries its gain."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from vasim.cli import main
from vasim.core.resources import studies_dir
from vasim.study.store import TrialStore


def tiny(name: str, tmp_path: Path, *replacements: tuple[str, str]) -> Path:
    """The shipped protocol ``name`` with its blocks shortened (same conditions, rules and
    questionnaire), written to ``tmp_path``."""
    text = (studies_dir() / f"{name}.toml").read_text(encoding="utf-8")
    for old, new in replacements:
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / f"{name}.toml"
    path.write_text(text, encoding="utf-8")
    return path


def simulate_and_report(protocol: Path, tmp_path: Path) -> tuple[Path, Path]:
    db, out = tmp_path / "study.db", tmp_path / "report"
    assert main(["study", "simulate", "--protocol", str(protocol), "--subjects", "2",
                 "--db", str(db), "--max-time", "3", "--workers", "0",
                 "--no-progress"]) == 0
    assert main(["report", "--db", str(db), "--out", str(out), "--no-progress"]) == 0
    assert (out / "index.html").is_file() and (out / "summary.json").is_file()
    return db, out


def levels(out: Path, expected: list[str]) -> None:
    """The fixture factor's levels: every condition analysed, in report order."""
    cells = pd.read_csv(out / "tables" / "vf_cells_fixture.csv")
    assert set(cells["fixture"]) == set(expected)
    aov = pd.read_csv(out / "tables" / "vf_rm_anova.csv")
    assert aov["levels"].iloc[0].split(", ") == expected


def test_vf_fading_simulates_and_reports(tmp_path: Path):
    protocol = tiny("vf_fading", tmp_path,
                    ("variants = [1, 2, 3, 4]\nrepetitions = 2", "variants = [1]\nrepetitions = 2"),
                    ("repetitions = 3", "repetitions = 1"),
                    # two trials per block: a two-stage schedule (a longer one is refused)
                    ("gain_schedule = [1.0, 0.75, 0.5, 0.25]", "gain_schedule = [1.0, 0.5]"))
    db, out = simulate_and_report(protocol, tmp_path)
    levels(out, ["none", "Mag", "Mag faded", "Mag adaptive", "FF", "FF faded",
                 "FF adaptive"])
    ratings = pd.read_csv(out / "tables" / "questionnaire_ratings.csv")
    assert set(ratings["condition"]) == {"ff", "ff_faded", "ff_adaptive", "mag",
                                         "mag_faded", "mag_adaptive"}
    html = (out / "index.html").read_text(encoding="utf-8")
    assert "FF faded" in html and "Mag adaptive" in html
    stages = pd.read_csv(out / "tables" / "vf_gain_stages.csv")
    faded = stages[stages["condition"] == "FF faded"]
    assert faded["planned_gain"].astype(float).tolist() == [1.0, 0.5]
    assert faded["gain_mean"].tolist() == [1.0, 0.5]
    adaptive = stages[stages["condition"] == "Mag adaptive"]
    assert set(adaptive["planned_gain"]) == {"adaptive"}
    assert adaptive["gain_mean"].between(0.25, 1.0).all()
    after = pd.read_csv(out / "tables" / "vf_probe_after_block.csv")
    assert list(after["block_condition"]) == ["Mag", "Mag faded", "Mag adaptive", "FF",
                                              "FF faded", "FF adaptive"]
    with TrialStore(db, readonly=True) as st:
        sched = pd.concat([st.schedule(int(s)) for s in st.sessions()["id"]])
        for cond, expected in (("ff_faded", [1.0, 0.5]), ("mag_faded", [1.0, 0.5]),
                               ("ff", [1.0, 1.0]), ("none", None)):
            rows = sched[sched["condition"] == cond]
            for _, r in rows.iterrows():
                g = st.samples(int(r["trial_id"]))["gain"]
                want = 1.0 if expected is None else expected[int(r["trial_in_block"])]
                assert len(g) and np.all(g == want), (cond, r["trial_in_block"])
        for _, r in sched[sched["condition"] == "ff_adaptive"].iterrows():
            g = st.samples(int(r["trial_id"]))["gain"].to_numpy()
            assert g.min() >= 0.25 and g.max() <= 1.0 and abs(g[0] - 0.5) < 0.01


def test_vf_schemas_simulates_and_reports(tmp_path: Path):
    protocol = tiny("vf_schemas", tmp_path,
                    ("variants = [1, 2, 3, 4, 5, 6]", "variants = [1]"),
                    ("repetitions = 3", "repetitions = 1"))
    _, out = simulate_and_report(protocol, tmp_path)
    levels(out, ["none", "VG", "AG", "Mag", "FF", "AG+Mag", "Mag+FF", "VG+AG"])
    assert not (out / "tables" / "vf_gain_stages.csv").exists()  # no faded/adaptive block
    choices = pd.read_csv(out / "tables" / "questionnaire_choices.csv")
    best_schema = choices[choices["item"] == "best_schema"]
    assert list(best_schema["value"]) == ["ag_mag", "mag_ff", "vg_ag"]
    assert best_schema["count"].sum() == 2  # both subjects chose one
