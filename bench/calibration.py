"""Calibration run: a simulated cohort's chapter-6 statistics side by side with the seed's.

Runs (unless ``--db`` already holds the cohort) ``python -m vasim study simulate --protocol
vf_learning_curve --subjects 46 --surgeons 31 --seed 7 --workers 2`` (~20 minutes on two
cores; pass ``--subjects 8`` for a quick look) and prints, for the simulated operator
calibrated to the seed (``vasim.operator.learning``, ``vasim.operator.questionnaire``):

* the fixture effect (6 levels: VF-free probes after the baseline and the 5 fixtures) and
  the trial effect (the 8 VF-free trials) on the cumulative error and the latency, as
  one-way repeated-measures ANOVAs on subject cell means (statsmodels ``AnovaRM``; the
  seed's F(5, 98131) and F(7, 98131) come from its per-sample ANOVA, so only the
  significance is comparable), for eq. 6.5's e (``total_error_l1``), the speed-independent
  path deviation (``path_dev_mean_mm``) and the mean latency;
* Tukey HSD among the five fixtures on the assisted trials (statsmodels
  ``pairwise_tukeyhsd``): the best fixture and whether it differs from the ones the seed
  says it does not (FF vs AG and MS on error; Mag vs AG on latency);
* the questionnaire: best / worst shares and mean ratings.

The seed's values (``/work/shared/seed/000_85d9e1bca86fa007.txt`` l. 5375-5390) are printed
next to each. The numbers are synthetic: a calibrated model reproduces the seed's results
by construction; it is for planning (power, dry runs), not evidence.

Usage: ``python -m bench.calibration [--subjects N] [--db PATH] [--workers W]``.

Last run (2026-11-27, 46 subjects / 31 surgeons, seed 7, 11.6 min with 2 workers on a loaded
machine, the calibration in ``vasim.operator.learning`` as committed): all six fixture and
trial effects significant (e: F(5,225) = 39.2, F(7,315) = 137.7; path deviation: 62.5,
28.6; latency: 41.2, 146.6; every p < 1e-28); path deviation FF 3.638 / AG 3.641 / MS
3.722 / Mag 3.762 / VG 3.958 mm (FF vs AG p_adj 1.00, vs MS 0.82); eq. 6.5's e: Mag best
(it follows latency, r(e, latency) = 0.996); latency Mag 0.487 s best, vs AG p_adj 0.62;
best Mag 35 / FF 24 / AG 24 / VG 9 / MS 9 %, worst VG 43 / MS 39 / AG 11 / Mag 7 / FF 0 %,
ratings FF 7.26, AG 6.63, Mag 6.57, VG 5.48, MS 4.83.
"""

from __future__ import annotations

import argparse
import os
import sqlite3
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
from statsmodels.stats.anova import AnovaRM
from statsmodels.stats.multicomp import pairwise_tukeyhsd

from vasim.operator.questionnaire import SEED_BEST_SHARE, SEED_MEAN_RATING, SEED_WORST_SHARE

FIXTURES = ("vg", "ag", "ms", "mag", "ff")
LABEL = {"none": "none", "vg": "VG", "ag": "AG", "ms": "MS", "mag": "Mag", "ff": "FF"}
SEED_F = {("fixture", "error"): "F(5,98131) = 35.030, p < 0.001",
          ("fixture", "latency"): "F(5,98131) = 44.099, p < 0.001",
          ("trial", "error"): "F(7,98131) = 22.871, p < 0.001",
          ("trial", "latency"): "F(7,98131) = 87.344, p < 0.001"}
"""The seed's ANOVA results (l. 5375-5377)."""


def simulate(db: Path, subjects: int, surgeons: int | None, seed: int, workers: int) -> None:
    """Runs the cohort through the CLI (the command the brief names)."""
    cmd = [sys.executable, "-m", "vasim", "study", "simulate", "--protocol",
           "vf_learning_curve", "--subjects", str(subjects), "--seed", str(seed),
           "--workers", str(workers), "--db", str(db), "--no-progress"]
    if surgeons is not None:
        cmd += ["--surgeons", str(surgeons)]
    subprocess.run(cmd, check=True)


def load(db: Path) -> tuple[pd.DataFrame, pd.DataFrame, str]:
    """(per-trial frame, answers frame, operator label) of the cohort's completed trials."""
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    trials = pd.read_sql_query(
        "SELECT s.subject, q.condition, q.probe, q.probe_index, q.trial_index, q.trial_id "
        "FROM scheduled_trials q JOIN sessions s ON s.id = q.session_id "
        "JOIN trials t ON t.id = q.trial_id WHERE t.status = 'completed' "
        "AND s.protocol = 'vf_learning_curve'", con)
    tm = pd.read_sql_query(
        "SELECT trial_id, metric, value FROM trial_metrics WHERE metric IN "
        "('total_error_l1', 'path_dev_mean_mm', 'mean_latency', 'error_l1_sum_mm_s')", con)
    wide = tm.pivot(index="trial_id", columns="metric", values="value")
    trials = trials.join(wide, on="trial_id")
    answers = pd.read_sql_query(
        "SELECT a.subject, a.item, a.key, a.value, a.value_num FROM answers a JOIN sessions s "
        "ON s.id = a.session_id WHERE a.questionnaire = 'post' "
        "AND s.protocol = 'vf_learning_curve'", con)
    ops = pd.read_sql_query("SELECT DISTINCT operator FROM sessions", con)["operator"]
    con.close()
    return trials, answers, ", ".join(ops)


def _rm(cells: pd.DataFrame, dv: str, within: str) -> str:
    full = cells.dropna(subset=[dv]).groupby("subject")[within].nunique()
    levels = cells[within].nunique()
    keep = full[full == levels].index
    data = cells[cells["subject"].isin(keep)].dropna(subset=[dv])
    if len(keep) < 3:
        return "too few complete subjects"
    res = AnovaRM(data, dv, "subject", within=[within]).fit().anova_table.iloc[0]
    return (f"F({int(res['Num DF'])},{int(res['Den DF'])}) = {res['F Value']:.3f}, "
            f"p = {res['Pr > F']:.3g} (n = {len(keep)})")


def anovas(trials: pd.DataFrame) -> list[tuple[str, str, str, str]]:
    """(effect, measure, simulated, seed) rows."""
    rows = []
    t = trials.copy()
    # fixture factor: assisted conditions + the VF-free probes after the baseline (4..8)
    fx = t[(~t["probe"].astype(bool)) | (t["probe_index"] > 3)]
    fx = fx.assign(level=np.where(fx["probe"].astype(bool), "none", fx["condition"]))
    vf_free = t[t["probe"].astype(bool)].assign(level=lambda d: d["probe_index"].astype(int))
    for measure, dv in (("error", "total_error_l1"), ("error", "path_dev_mean_mm"),
                        ("latency", "mean_latency")):
        cells = fx.groupby(["subject", "level"], as_index=False)[dv].mean()
        rows.append(("fixture", dv, _rm(cells, dv, "level"), SEED_F[("fixture", measure)]))
        cells = vf_free.groupby(["subject", "level"], as_index=False)[dv].mean()
        rows.append(("trial", dv, _rm(cells, dv, "level"), SEED_F[("trial", measure)]))
    return rows


def tukey(trials: pd.DataFrame, dv: str, best_is: str, not_different_from: tuple[str, ...],
          ) -> str:
    """Best fixture by mean of ``dv`` on assisted trials and Tukey HSD against the others."""
    a = trials[~trials["probe"].astype(bool) & trials["condition"].isin(FIXTURES)]
    a = a.dropna(subset=[dv])
    means = a.groupby("condition")[dv].mean().sort_values()
    best = str(means.index[0])
    res = pairwise_tukeyhsd(a[dv].to_numpy(), a["condition"].map(LABEL).to_numpy())
    tab = pd.DataFrame(res.summary().data[1:], columns=res.summary().data[0])

    def sig(x: str, y: str) -> str:
        row = tab[((tab["group1"] == LABEL[x]) & (tab["group2"] == LABEL[y]))
                  | ((tab["group1"] == LABEL[y]) & (tab["group2"] == LABEL[x]))]
        return f"p_adj = {float(row['p-adj'].iloc[0]):.3f}" if len(row) else "-"

    order = ", ".join(f"{LABEL[c]} {v:.4g}" for c, v in means.items())
    others = "; ".join(f"{LABEL[best_is]} vs {LABEL[o]} {sig(best_is, o)}"
                       for o in not_different_from)
    return (f"best {LABEL[best]} (seed: {LABEL[best_is]}); means {order}; {others} "
            f"(seed: not significant)")


def questionnaire(answers: pd.DataFrame) -> list[tuple[str, str, str, str]]:
    """(fixture, best share, worst share, mean rating) rows, simulated vs seed."""
    rows = []
    n_best = max((answers["item"] == "best_vf").sum(), 1)
    n_worst = max((answers["item"] == "worst_vf").sum(), 1)
    for c in ("mag", "ff", "ag", "vg", "ms"):
        best = (answers[answers["item"] == "best_vf"]["value"] == c).sum() / n_best
        worst = (answers[answers["item"] == "worst_vf"]["value"] == c).sum() / n_worst
        r = answers[(answers["item"] == "rating") & (answers["key"] == c)]["value_num"]
        rows.append((LABEL[c], f"{100 * best:.0f} % (seed {100 * SEED_BEST_SHARE[c]:.0f} %)",
                     f"{100 * worst:.0f} % (seed {100 * SEED_WORST_SHARE[c]:.0f} %)",
                     f"{r.mean():.2f} (seed {SEED_MEAN_RATING[c]:.2f})"))
    return rows


def report(db: Path) -> None:
    """Prints the statistics of the cohort in ``db`` beside the seed's."""
    trials, answers, operator = load(db)
    n_subj = trials["subject"].nunique()
    print(f"cohort: {n_subj} subjects, {len(trials)} completed trials; operator: {operator}")
    print("synthetic data: the seed's results are reproduced by construction (planning only)")
    r = trials[["total_error_l1", "mean_latency"]].dropna()
    rp = trials[["path_dev_mean_mm", "mean_latency"]].dropna()
    print(f"r(e sum, latency) = {r.corr().iloc[0, 1]:.3f}   "
          f"r(path deviation, latency) = {rp.corr().iloc[0, 1]:.3f}")
    print("\nRM-ANOVA on subject cell means (seed: per-sample ANOVA)")
    for effect, dv, sim, seed in anovas(trials):
        print(f"  {effect:8s} {dv:18s} {sim:45s} | seed {seed}")
    print("\nTukey HSD among the fixtures (assisted trials)")
    for dv in ("total_error_l1", "path_dev_mean_mm"):
        print(f"  {dv}: {tukey(trials, dv, 'ff', ('ag', 'ms'))}")
    print(f"  mean_latency: {tukey(trials, 'mean_latency', 'mag', ('ag',))}")
    print("\nQuestionnaire: best, worst, mean rating")
    for row in questionnaire(answers):
        print("  {:4s} best {:22s} worst {:22s} rating {}".format(*row))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--subjects", type=int, default=46)
    ap.add_argument("--surgeons", type=int, default=None,
                    help="default: 31 of 46, scaled for other sizes (the CLI's)")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--db", type=Path, default=None,
                    help="cohort database (simulated into it unless complete)")
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    if args.db is None:
        tmp = tempfile.mkdtemp(prefix="vasim_calibration_")
        args.db = Path(tmp) / "calibration.sqlite"
    simulate(args.db, args.subjects, args.surgeons, args.seed, args.workers)
    report(args.db)


if __name__ == "__main__":
    main()
