"""Seed comparison: a declared scenario in, a synthetic cohort's outcomes out, beside the seed.

Every row has three columns: **seed** (the published number, seed
``/work/shared/seed/000_85d9e1bca86fa007.txt`` sec. 6.4.4), **assumed** (what the scenario
file declares for it, ``protocols/scenarios/*.toml``, or that it is not an input) and
**out** (what the analysis of the synthetic cohort gives). A row whose outcome is an input
(by construction of the engine) says so: agreement there is not evidence of anything. The
seed's numbers live here only, the comparison; none of them is an input of any scenario
(issue #25). A simulation is for validating the pipeline, power planning and dry runs,
never evidence about people (docs/simulation.md).

Engines: ``--engine outcome`` (default; the trial-level outcome engine in memory,
``vasim.study.power.outcome``: seconds) or ``--engine scripted`` (``vasim study simulate
--scenario`` into ``--db``, the 1 kHz operator: ~20 min for 46 subjects on two cores; a
complete ``--db`` is reused). ``--smoke``: 6 subjects (the bench's smoke mode).

Usage: ``python -m bench.calibration [--scenario NAME|FILE] [--effect-scale X]
[--engine outcome|scripted] [--subjects N] [--seed S] [--db PATH] [--smoke] [--markdown]``
(``--markdown``: the table of docs/seed-chapter6.md).

The page docs/seed-chapter6.md holds the last runs and says which rows are inputs.
"""

from __future__ import annotations

import argparse
import os
import sqlite3
import subprocess
import sys
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from statsmodels.stats.anova import AnovaRM

from vasim.operator.scenario import Scenario, load_scenario
from vasim.study.power.outcome import outcome_cohort
from vasim.study.protocol import load_protocol
from vasim.study.recovery import estimate_effects

FIXTURES = ("vg", "ag", "ms", "mag", "ff")
LABEL = {"none": "none", "vg": "VG", "ag": "AG", "ms": "MS", "mag": "Mag", "ff": "FF"}
PROTOCOL = "vf_learning_curve"

# ---- the seed's published results (comparison only; never an input) -----------------
SEED_BEST = {"mag": 36, "ff": 24, "ag": 19, "vg": 13, "ms": 8}
"""% naming each fixture best (seed l. 5386-5387)."""
SEED_WORST = {"ms": 39, "vg": 35, "ag": 14, "mag": 10, "ff": 2}
"""% naming each fixture least useful (seed l. 5388-5389)."""
SEED_RATING = {"ff": 7.08, "mag": 6.85, "ag": 6.38, "vg": 5.63, "ms": 4.74}
"""Mean 0-10 rating (seed l. 5389-5390)."""
SEED_F = {"fixture": "F(5,98131) = 35.030 (eq. 6.5 e, per-sample ANOVA)",
          "trial": "F(7,98131) = 22.871 (eq. 6.5 e, per-sample ANOVA)"}
"""The seed's ANOVAs (l. 5375-5377): per-sample df, so only the significance compares."""
SEED_ORDER = ("FF most effective on cumulative error, not significantly different from AG "
              "and MS (l. 5378-5380); no per-fixture ratio reported")


def scripted_cohort(db: Path, scenario: str, scale: float, subjects: int, seed: int,
                    workers: int) -> tuple[pd.DataFrame, list[Mapping[str, Any]]]:
    """Runs (or continues) the cohort through the CLI and reads trials and answers."""
    subprocess.run([sys.executable, "-m", "vasim", "study", "simulate", "--protocol",
                    PROTOCOL, "--subjects", str(subjects), "--seed", str(seed), "--workers",
                    str(workers), "--db", str(db), "--scenario", scenario, "--effect-scale",
                    str(scale), "--no-progress"], check=True)
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    trials = pd.read_sql_query(
        "SELECT s.subject, q.condition, q.probe, q.probe_index, q.trial_index, q.variant, "
        "q.trial_id FROM scheduled_trials q JOIN sessions s ON s.id = q.session_id "
        "JOIN trials t ON t.id = q.trial_id WHERE t.status = 'completed' "
        f"AND s.protocol = '{PROTOCOL}'", con)
    tm = pd.read_sql_query("SELECT trial_id, metric, value FROM trial_metrics WHERE metric "
                           "IN ('path_dev_mean_mm', 'mean_latency')", con)
    trials = trials.join(tm.pivot(index="trial_id", columns="metric", values="value"),
                         on="trial_id")
    ans = pd.read_sql_query(
        "SELECT a.subject, a.item, a.key, a.value, a.value_num FROM answers a JOIN sessions s "
        f"ON s.id = a.session_id WHERE a.questionnaire = 'post' AND s.protocol = '{PROTOCOL}'",
        con)
    con.close()
    answers: list[Mapping[str, Any]] = []
    for _, g in ans.groupby("subject"):
        a: dict[str, Any] = {"rating": {}}
        for r in g.itertuples():
            if r.item == "rating":
                a["rating"][r.key] = r.value_num
            elif r.item in ("best_vf", "worst_vf"):
                a[r.item] = r.value
        answers.append(a)
    return trials, answers


def rm_anova(trials: pd.DataFrame, dv: str, effect: str) -> str:
    """One-way RM-ANOVA on subject cell means: ``fixture`` (assisted conditions + the
    VF-free probes after the baseline) or ``trial`` (the 8 VF-free trials)."""
    t = trials.dropna(subset=[dv])
    probe = t["probe"].astype(bool)
    if effect == "fixture":
        d = t[~probe | (t["probe_index"] > 3)]
        d = d.assign(level=np.where(d["probe"].astype(bool), "none", d["condition"]))
    else:
        d = t[probe].assign(level=lambda x: x["probe_index"].astype(int))
    cells = d.groupby(["subject", "level"], as_index=False)[dv].mean()
    full = cells.groupby("subject")["level"].nunique()
    keep = full[full == cells["level"].nunique()].index
    if len(keep) < 3:
        return "too few complete subjects"
    res = AnovaRM(cells[cells["subject"].isin(keep)], dv, "subject",
                  within=["level"]).fit().anova_table.iloc[0]
    return (f"F({int(res['Num DF'])},{int(res['Den DF'])}) = {res['F Value']:.2f}, "
            f"p = {res['Pr > F']:.2g}")


def rows(sc: Scenario, scale: float, engine: str, trials: pd.DataFrame,
         answers: Sequence[Mapping[str, Any]]) -> list[tuple[str, str, str, str]]:
    """(quantity, seed, assumed, out) rows (module docstring)."""
    eff = sc.effects(scale)
    est = estimate_effects(trials)
    by_input = engine == "outcome"
    out: list[tuple[str, str, str, str]] = []
    for c in FIXTURES:
        r = est["fixtures"].get(c) or {}
        got = ("-" if r.get("ratio") is None else
               f"{r['ratio']:.3f} [{r['ci_low']:.3f}, {r['ci_high']:.3f}]")
        note = " (INPUT: the outcome engine realises the assumed ratio)" if by_input else (
            " (INPUT x mechanism: the assumed factor on the operator's noise, times the "
            "simulated fixture's own effect)" if sc.mechanism(scale) > 0 else
            " (INPUT: the assumed factor on the operator's noise)")
        src = sc.source(f"fixtures.{c}.accuracy")
        out.append((f"{LABEL[c]} path-deviation ratio",
                    SEED_ORDER if c == "ff" else "not reported",
                    f"{eff[c].accuracy:g} ({src[:40]}...)", got + note))
    dv = "path_dev_mean_mm"
    out.append(("fixture effect (path deviation)", SEED_F["fixture"],
                "follows from the INPUT ratios above (an output of the inputs, not evidence)",
                rm_anova(trials, dv, "fixture")))
    g = sc.groups
    out.append(("trial (learning) effect (path deviation)", SEED_F["trial"],
                f"rates {g['surgeon'].learning_rate_mean:g}/{g['resident'].learning_rate_mean:g}, "
                f"asymptotes {g['surgeon'].asymptote:g}/{g['resident'].asymptote:g} "
                "(surgeon/resident)", rm_anova(trials, dv, "trial")))
    if "mean_latency" in trials.columns:
        out.append(("fixture effect (latency)", "F(5,98131) = 44.099", "speed factors "
                    + ", ".join(f"{LABEL[c]} {eff[c].speed:g}" for c in FIXTURES),
                    rm_anova(trials, "mean_latency", "fixture")
                    + " (follows from the INPUT speed factors and the mechanisms)"))
    else:
        out.append(("fixture effect (latency)", "F(5,98131) = 44.099", "-",
                    "not simulated by the outcome engine"))
    n = max(len(answers), 1)
    q = sc.questionnaire
    for c in FIXTURES:
        best = 100 * sum(a.get("best_vf") == c for a in answers) / n
        worst = 100 * sum(a.get("worst_vf") == c for a in answers) / n
        rating = np.mean([a["rating"][c] for a in answers if c in a.get("rating", {})])
        out.append((f"{LABEL[c]} best / worst / rating",
                    f"{SEED_BEST[c]} % / {SEED_WORST[c]} % / {SEED_RATING[c]:.2f}",
                    f"from own benefit b: logit tau {q.choice_noise:g}, rating "
                    f"{q.rating_centre:g} + {q.rating_per_benefit:g} b",
                    f"{best:.0f} % / {worst:.0f} % / {rating:.2f}"))
    return out


MARKDOWN_HEADER = ("quantity", "seed (published result)", "assumed (scenario input)",
                   "out (synthetic cohort)")
"""The columns of the Markdown table: a row label and the three columns of issue #25."""


def markdown_table(table: Sequence[tuple[str, str, str, str]]) -> str:
    """The rows as a Markdown table (``|`` in a cell escaped).

    Example:
        >>> print(markdown_table([("q", "1", "2", "3 (INPUT)")]))
        | quantity | seed (published result) | assumed (scenario input) | out (synthetic cohort) |
        |---|---|---|---|
        | q | 1 | 2 | 3 (INPUT) |
    """
    def cell(x: str) -> str:
        return x.replace("|", "\\|").replace("\n", " ")

    lines = ["| " + " | ".join(MARKDOWN_HEADER) + " |", "|---|---|---|---|"]
    lines += ["| " + " | ".join(cell(c) for c in row) + " |" for row in table]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="seed_plausible")
    ap.add_argument("--effect-scale", type=float, default=1.0)
    ap.add_argument("--engine", choices=["outcome", "scripted"], default="outcome")
    ap.add_argument("--subjects", type=int, default=46)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--db", type=Path, default=None,
                    help="scripted engine: the cohort database (simulated into it)")
    ap.add_argument("--smoke", action="store_true", help="6 subjects (smoke mode)")
    ap.add_argument("--markdown", action="store_true",
                    help="print the table as Markdown: | quantity | seed | assumed | out | "
                         "(docs/seed-chapter6.md)")
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    n = 6 if args.smoke else args.subjects
    sc = load_scenario(args.scenario)
    if args.engine == "outcome":
        coh = outcome_cohort(load_protocol(PROTOCOL), sc, n_subjects=n, seed=args.seed,
                             effect_scale=args.effect_scale)
        trials = coh.trials
        answers: Sequence[Mapping[str, Any]] = list(coh.answers.values())
    else:
        db = args.db or Path(tempfile.mkdtemp(prefix="vasim_calibration_")) / "c.sqlite"
        trials, answers = scripted_cohort(db, args.scenario, args.effect_scale, n, args.seed,
                                          args.workers)
    print(f"seed comparison: scenario {sc.name} ({sc.sha256[:12]}) x {args.effect_scale:g}, "
          f"{args.engine} engine, {trials['subject'].nunique()} subjects, seed {args.seed}; "
          "SYNTHETIC (not evidence about people)")
    table = rows(sc, args.effect_scale, args.engine, trials, answers)
    if args.markdown:
        print(markdown_table(table))
        return
    w = max(len(r[0]) for r in table)
    for q_, seed_, assumed, out in table:
        print(f"{q_:<{w}} | seed: {seed_}\n{'':<{w}} | assumed: {assumed}\n"
              f"{'':<{w}} | out: {out}")


if __name__ == "__main__":
    main()
