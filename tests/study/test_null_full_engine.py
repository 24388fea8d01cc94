"""Issue #25 "Done when", at test size, with the FULL engine (the 1 kHz scripted operator
and the simulated fixtures through `simulate_cohort`, not the outcome engine): a cohort of
the shipped VF protocol at effect scale 0 (no fixture effect at all, mechanism included)
shows

1. no fixture chosen best by more subjects than chance allows,
2. mean ratings within the range chance allows,
3. no fixture effect on path deviation in the PRIMARY probe model.

Size: 10 subjects (one full set of the 10 Williams sequences, so block position is
balanced: practice cannot favour a fixture), trials cut at 2 s simulated (the knob
`max_trial_time`; every measure is still computed over what was run) at the power
command's coarse 2 ms control step, in memory (``vasim.study.power.cohort
.simulate_in_memory``: the very trial configurations `vasim study simulate` runs, the
physics and fixtures simulated, only the 1 kHz samples not stored); the answers are drawn
as a stored simulated session's (``_record_post``: from the subject's own measured
benefits). The full-size run
(`vasim study simulate --protocol vf_learning_curve --subjects 10 --effect-scale 0`, full
trials) is recorded in docs/simulation.md.

Thresholds come from the null distributions at this sample size, at a family-wise
false-failure rate of about 1 % per check (not tuned to pass):

* "chosen best": under the null each of the 5 fixtures is the best of a subject with
  probability 1/5 (subjects independent), so a fixture's count is Binomial(10, 1/5); the
  test fails at the smallest k with 5 P(X >= k) <= 0.01 (Bonferroni over the fixtures).
* ratings: the range of the 5 fixture means over their standard error (from the
  subject x fixture residual mean square, df (5-1)(10-1)) follows the studentized range
  distribution: the test fails above its 0.99 quantile.
* path deviation: the nested F test of the fixture practised (transfer model) fails at
  p < 0.01.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy import stats

from vasim.operator.scenario import load_scenario
from vasim.study.cohort import (
    cohort_subjects,
    measured_benefits,
    scenario_record,
    simulated_answers,
    subject_stream,
)
from vasim.study.power.cohort import simulate_in_memory, study_data
from vasim.study.power.design import COARSE_DT
from vasim.study.protocol import load_protocol
from vasim.study.report.analysis import analyse_vf
from vasim.study.report.primary import probe_model_tests

N = 10
FIXTURES = ("vg", "ag", "ms", "mag", "ff")
ALPHA = 0.01
MAX_TRIAL_TIME = 2.0
"""Simulated seconds per trial: the measures are computed over what was run (a 2 s trial
is ~1,000 coarse steps of the scripted operator on the path), and a null cohort has no
fixture effect at any trial length, so the thresholds above hold at any length. 2 s, not
the 4 s of before: half the cost (about 110 s of CPU on a loaded 2-core host; issue #31)."""


def binomial_threshold(n: int, k_levels: int, alpha: float) -> int:
    """Smallest count k with k_levels * P(Binomial(n, 1/k_levels) >= k) <= alpha.

    Example:
        >>> binomial_threshold(10, 5, 0.01)
        7
    """
    for k in range(n + 1):
        if k_levels * stats.binom.sf(k - 1, n, 1 / k_levels) <= alpha:
            return k
    return n + 1


def test_a_null_cohort_of_the_full_engine_shows_no_fixture_effect() -> None:
    protocol = load_protocol("vf_learning_curve")
    sc = load_scenario("seed_plausible")
    subjects = cohort_subjects(N, 7, 11, latin_square=True, scenario=sc)
    trials = simulate_in_memory(protocol, subjects, dt=COARSE_DT, max_trial_time=MAX_TRIAL_TIME,
                                extra={"scenario": scenario_record(sc, 0.0)})
    assert trials.n_trials == N * 38
    data = study_data(protocol, trials)
    # each subject's post-questionnaire as `vasim study simulate` draws it
    # (vasim.study.cohort._record_post): from its own measured benefits
    errors = trials.metrics["path_dev_mean_mm"].to_dict()
    rows = []
    for j, subj in enumerate(subjects, start=1):
        sched = trials.schedule[trials.schedule["session_id"] == j]
        b = measured_benefits(sched, errors)
        ans = simulated_answers(protocol, "post", subject_stream(subj.session_seed, 8), measured=b,
                                model=sc.questionnaire)
        rows.append({"session_id": j, "item": "best_vf", "key": "", "value": ans["best_vf"],
                     "value_num": math.nan})
        rows += [{"session_id": j, "item": "rating", "key": c, "value": "",
                  "value_num": float(v)} for c, v in ans["rating"].items()]
    post = pd.DataFrame(rows)

    # 1. chosen best
    best = post[post["item"] == "best_vf"]
    assert len(best) == N
    counts = best["value"].value_counts()
    k = binomial_threshold(N, len(FIXTURES), ALPHA)
    assert counts.max() < k, counts.to_dict()

    # 2. ratings: range of the fixture means / SE below the studentized range's 0.99 quantile
    r = post[post["item"] == "rating"].pivot(index="session_id", columns="key",
                                              values="value_num")[list(FIXTURES)]
    y = r.to_numpy(float)
    assert y.shape == (N, len(FIXTURES))
    resid = y - y.mean(axis=1, keepdims=True) - y.mean(axis=0) + y.mean()
    df = (len(FIXTURES) - 1) * (N - 1)
    se = math.sqrt((resid ** 2).sum() / df / N)
    spread = float(np.ptp(y.mean(axis=0)))
    q = float(stats.studentized_range.ppf(1 - ALPHA, len(FIXTURES), df))
    assert se == 0 or spread / se < q, (spread, se, q)

    # 3. path deviation: the primary probe model's fixture test
    tests = probe_model_tests(analyse_vf(data)).set_index("dv")
    row = tests.loc["path_deviation"]
    assert row["df1"] == len(FIXTURES) - 1 and math.isfinite(row["p_unc"])
    assert row["p_unc"] >= ALPHA, row.to_dict()
    print(f"null cohort (full engine, N={N}): best {counts.to_dict()} (fails at {k}); "
          f"rating means {np.round(y.mean(axis=0), 2).tolist()}, range/SE "
          f"{spread / se if se else 0:.2f} (q99 {q:.2f}); probe model "
          f"F({row['df1']:g},{row['df2']:g}) = {row['F']:.2f}, p = {row['p_unc']:.3f}")
