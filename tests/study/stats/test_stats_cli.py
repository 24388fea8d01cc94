"""Tests of ``vasim stats`` through ``vasim.cli.main`` (exact JSON keys, null, exit codes)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from vasim.cli import main

DATA = Path(__file__).resolve().parents[2] / "data"

RM_KEYS = ["SS", "SS_error", "MS", "MS_error", "df1", "df2", "F", "p_unc", "eps_gg", "eps_hf",
           "eps_lb", "p_gg", "p_hf", "p_lb", "np2", "ges", "mauchly_W", "mauchly_chi2",
           "mauchly_df", "mauchly_p", "mauchly_p_anderson"]
TUKEY_ROW = ["group1", "group2", "mean1", "mean2", "diff", "se", "q", "lwr", "upr", "p_adj"]
PAIRED_ROW = ["group1", "group2", "n", "mean_diff", "t", "df", "p", "ci_low", "ci_high",
              "cohen_dz", "power_observed", "n_power90", "n_power90_ceil", "p_holm", "p_bonf"]


def _strict(text: str) -> Any:
    def no_constant(name: str) -> None:
        raise AssertionError(f"non-standard JSON token {name}")

    return json.loads(text, parse_constant=no_constant)


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(["stats", *argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_rm_anova_json_keys_and_null(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = _run(capsys, "rm-anova", "--csv", str(DATA / "reference_rm_anova2.csv"),
                        "--dv", "Performance", "--subject", "Subject", "--within",
                        "Time, Metric", "--json")
    assert code == 0
    doc = _strict(out)
    assert list(doc) == ["rm_anova"]
    assert list(doc["rm_anova"]) == ["Time", "Metric", "Time:Metric"]
    for effect in doc["rm_anova"].values():
        assert list(effect) == RM_KEYS
    time = doc["rm_anova"]["Time"]
    assert [time[k] for k in ("mauchly_W", "mauchly_chi2", "mauchly_df", "mauchly_p")] == [
        None, None, None, None]
    assert time["eps_gg"] == 1.0 and time["df1"] == 1 and time["df2"] == 9
    assert doc["rm_anova"]["Metric"]["F"] == pytest.approx(26.959, abs=5e-4)  # JASP


def test_rm_anova_table(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = _run(capsys, "rm-anova", "--csv", str(DATA / "reference_bushtucker.csv"),
                        "--dv", "retch", "--subject", "celebrity", "--within", "food")
    assert code == 0
    assert "primary analysis" in out and "8 subjects" in out
    assert "food" in out and "3.7938" in out and "0.5328" in out


def test_tukey_json_both_modes(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = _run(capsys, "tukey", "--csv", str(DATA / "reference_plantgrowth.csv"),
                        "--dv", "weight", "--between", "group", "--json")
    assert code == 0
    doc = _strict(out)
    assert list(doc) == ["tukey"]
    assert list(doc["tukey"]) == ["ms_error", "df_error", "k", "q_crit", "comparisons"]
    assert [list(c) for c in doc["tukey"]["comparisons"]] == [TUKEY_ROW] * 3
    assert doc["tukey"]["comparisons"][2]["p_adj"] == pytest.approx(0.0120064, abs=5e-8)
    code, out, _ = _run(capsys, "tukey", "--csv", str(DATA / "reference_bushtucker.csv"),
                        "--dv", "retch", "--subject", "celebrity", "--within", "food", "--json")
    doc = _strict(out)
    assert code == 0 and doc["tukey"]["df_error"] == 21 and doc["tukey"]["k"] == 4
    code, out, _ = _run(capsys, "tukey", "--csv", str(DATA / "reference_bushtucker.csv"),
                        "--dv", "retch", "--subject", "celebrity", "--within", "food")
    assert "repeated measures" in out and "assumes sphericity" in out


def test_paired_json_keys(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = _run(capsys, "paired", "--csv", str(DATA / "reference_sleep.csv"), "--dv",
                        "extra", "--subject", "ID", "--within", "group", "--json")
    assert code == 0
    doc = _strict(out)
    assert list(doc) == ["paired"] and list(doc["paired"]) == ["tests"]
    (test,) = doc["paired"]["tests"]
    assert list(test) == PAIRED_ROW
    assert round(test["t"], 4) == -4.0621 and test["n_power90_ceil"] == 9
    assert isinstance(test["n_power90_ceil"], int) and isinstance(test["df"], int)


def test_paired_null_for_undefined(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    p = tmp_path / "const.csv"
    pd.DataFrame({"s": [1, 2, 3] * 2, "c": ["a"] * 3 + ["b"] * 3,
                  "y": [1.0, 2.0, 3.0, 2.0, 3.0, 4.0]}).to_csv(p, index=False)
    code, out, err = _run(capsys, "paired", "--csv", str(p), "--dv", "y", "--subject", "s",
                          "--within", "c", "--json")
    assert code == 0
    (test,) = _strict(out)["paired"]["tests"]
    assert test["t"] is None and test["p"] is None and test["n_power90_ceil"] is None
    assert test["mean_diff"] == -1.0
    assert "note: " in err and "all differences are equal" in err


def test_spearman_json_keys(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = _run(capsys, "spearman", "--csv",
                        str(DATA / "reference_spearman_iq_tv.csv"), "--subject", "person",
                        "--item", "item", "--value", "value", "--json")
    assert code == 0
    doc = _strict(out)
    assert list(doc) == ["spearman"] and list(doc["spearman"]) == ["tests"]
    assert [list(t) for t in doc["spearman"]["tests"]] == [["var1", "var2", "n", "rho", "p"]]
    assert doc["spearman"]["tests"][0]["rho"] == pytest.approx(-29 / 165)


def test_singular_design_json_null_and_note(capsys: pytest.CaptureFixture[str],
                                            tmp_path: Path) -> None:
    p = tmp_path / "few.csv"
    y = np.array([[1.0, 3.0, 2.0, 5.0, 4.0], [2.0, 2.5, 4.0, 4.5, 6.0], [0.5, 4.0, 3.0, 7.0, 4.5]])
    pd.DataFrame([{"s": i, "vf": f"v{j}", "e": y[i, j]} for i in range(3) for j in range(5)]
                 ).to_csv(p, index=False)
    code, out, err = _run(capsys, "rm-anova", "--csv", str(p), "--dv", "e", "--subject", "s",
                          "--within", "vf", "--json")
    assert code == 0
    vf = _strict(out)["rm_anova"]["vf"]
    assert vf["mauchly_W"] is None and vf["mauchly_p"] is None
    assert isinstance(vf["eps_gg"], float)
    assert "singular" in err


@pytest.mark.parametrize(("argv", "needle"), [
    (["rm-anova", "--csv", "missing.csv", "--dv", "y", "--subject", "s", "--within", "c"],
     "missing.csv: CSV file not found"),
    (["rm-anova", "--csv", str(DATA / "reference_bushtucker.csv"), "--dv", "retching",
      "--subject", "celebrity", "--within", "food"], "column 'retching' not found"),
    (["paired", "--csv", "UNBALANCED", "--dv", "extra", "--subject", "ID", "--within",
      "group"], "unbalanced design"),
    (["tukey", "--csv", str(DATA / "reference_plantgrowth.csv"), "--dv", "weight"],
     "tukey needs --between COL"),
    (["rm-anova", "--csv", str(DATA / "reference_rm_anova2.csv"), "--dv", "Performance",
      "--subject", "Subject", "--within", "Time,,Metric"],
         "field '--within': got 'Time,,Metric', expected one factor or two"),
])
def test_errors_exit_2_with_one_line(capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                     argv: list[str], needle: str) -> None:
    if "UNBALANCED" in argv:
        p = tmp_path / "unbalanced.csv"
        p.write_text("\n".join((DATA / "reference_sleep.csv").read_text().splitlines()[:-1]))
        argv = [str(p) if a == "UNBALANCED" else a for a in argv]
    code, out, err = _run(capsys, *argv)
    assert code == 2
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("vasim stats: error: ")
    assert needle in lines[0]


# --- issue #16: undefined statistics, labels as text, duplicated columns ----------------

MIXED_KEYS = ["SS", "DF1", "DF2", "MS", "F", "p_unc", "np2", "eps", "p_GG_corr", "ng2",
              "SS_error", "MS_error", "W_spher", "p_spher"]


def test_rm_anova_constant_dv_effect_sizes_null(capsys: pytest.CaptureFixture[str],
                                                tmp_path: Path) -> None:
    # Issue #16: a constant dependent variable reported np2 = ges = 1.0.
    p = tmp_path / "const.csv"
    p.write_text("s,c,y\n" + "".join(f"{s},{c},0.1\n" for s in range(1, 5) for c in "abc"))
    code, out, err = _run(capsys, "rm-anova", "--csv", str(p), "--dv", "y", "--subject", "s",
                          "--within", "c", "--json")
    assert code == 0
    c = _strict(out)["rm_anova"]["c"]
    assert c["np2"] is None and c["ges"] is None and c["F"] is None and c["p_unc"] is None
    assert "zero error variance" in err and "effect sizes undefined" in err


def test_rm_anova_subject_codes_are_text(capsys: pytest.CaptureFixture[str],
                                         tmp_path: Path) -> None:
    # "1", "01" and "1.0" are three subjects: df2 = (3 - 1) (2 - 1) = 2, not 0 or 1.
    p = tmp_path / "codes.csv"
    p.write_text("s,c,y\n1,a,1\n1,b,2\n01,a,2\n01,b,4.5\n1.0,a,3\n1.0,b,3.5\n")
    code, out, _ = _run(capsys, "rm-anova", "--csv", str(p), "--dv", "y", "--subject", "s",
                        "--within", "c", "--json")
    assert code == 0
    c = _strict(out)["rm_anova"]["c"]
    # differences b - a: 1, 2.5, 0.5 -> mean 4/3; F = t^2 of the paired t-test
    d = np.array([1.0, 2.5, 0.5])
    t = d.mean() / (d.std(ddof=1) / np.sqrt(3))
    assert c["df2"] == 2 and c["F"] == pytest.approx(t**2, rel=1e-12)


def test_tukey_between_labels_are_text(capsys: pytest.CaptureFixture[str],
                                       tmp_path: Path) -> None:
    p = tmp_path / "groups.csv"
    p.write_text("g,y\n1,1\n1,2\n1,3\n1.0,4\n1.0,5\n1.0,6\n")
    code, out, _ = _run(capsys, "tukey", "--csv", str(p), "--dv", "y", "--between", "g",
                        "--json")
    assert code == 0
    doc = _strict(out)["tukey"]
    assert doc["k"] == 2 and doc["df_error"] == 4
    assert doc["comparisons"][0]["group1"] == "1" and doc["comparisons"][0]["group2"] == "1.0"
    assert doc["comparisons"][0]["diff"] == 3.0


def test_duplicated_column_exit_2(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    p = tmp_path / "dup.csv"
    p.write_text("s,c,y,y\n1,a,1,2\n")
    code, out, err = _run(capsys, "rm-anova", "--csv", str(p), "--dv", "y", "--subject", "s",
                          "--within", "c")
    assert code == 2 and out == ""
    assert f"{p}: field 'y': column 'y' appears 2 times in the header" in err


def test_mixed_anova_json(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = _run(capsys, "mixed-anova", "--csv",
                        str(DATA / "reference_mixed_anova_unbalanced.csv"), "--dv", "Scores",
                        "--subject", "Subject", "--within", "Time", "--between", "Group",
                        "--json")
    assert code == 0
    doc = _strict(out)["mixed_anova"]
    assert list(doc) == ["Group", "Time", "Interaction"]
    assert all(list(row) == MIXED_KEYS for row in doc.values())
    assert round(doc["Time"]["F"], 4) == 1.7071  # JASP (pingouin's test_parametric.py)
    assert doc["Time"]["p_spher"] == pytest.approx(0.7535238, abs=5e-8)  # ez
    assert doc["Group"]["eps"] is None and doc["Group"]["DF2"] == 23


def test_mixed_anova_table(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = _run(capsys, "mixed-anova", "--csv",
                        str(DATA / "reference_mixed_anova.csv"), "--dv", "Scores",
                        "--subject", "Subject", "--within", "Time", "--between", "Group")
    assert code == 0
    assert "60 subjects (Control 30, Meditation 30)" in out
    assert "5.0517" in out and "0.9981" in out


def test_mixed_model_json_and_note(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    rng = np.random.default_rng(2)
    subj = np.repeat([f"S{i:02d}" for i in range(15)], 6)
    x = np.tile(np.arange(6), 15)
    y = 3.0 - 0.5 * x + np.repeat(rng.normal(0, 1, 15), 6) + rng.normal(0, 0.3, 90)
    p = tmp_path / "lmm.csv"
    pd.DataFrame({"subject": subj, "trial": x, "error": y}).to_csv(p, index=False)
    code, out, err = _run(capsys, "mixed-model", "--csv", str(p), "--formula",
                          "error ~ trial", "--groups", "subject", "--json")
    assert code == 0
    doc = _strict(out)["mixed_model"]
    assert list(doc["fixed"]) == ["Intercept", "trial"]
    assert list(doc["fixed"]["trial"]) == ["coef", "se", "z", "p", "ci_low", "ci_high"]
    trial = doc["fixed"]["trial"]
    assert trial["ci_low"] < -0.5 < trial["ci_high"]
    assert doc["n_groups"] == 15 and doc["n_obs"] == 90 and doc["converged"] is True
    assert doc["note"] == "" and err == ""
    # no subject effect, 4 small groups: the boundary fit is noted
    rng = np.random.default_rng(1)
    q = tmp_path / "boundary.csv"
    pd.DataFrame({"s": np.repeat(["a", "b", "c", "d"], 5), "y": rng.normal(size=20),
                  "x": np.tile(np.arange(5.0), 4)}).to_csv(q, index=False)
    code, out, err = _run(capsys, "mixed-model", "--csv", str(q), "--formula", "y ~ x",
                          "--groups", "s")
    assert code == 0
    assert "note: " in out and "boundary" in out
