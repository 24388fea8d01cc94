"""Issue #25 "Done when", at test size, with the FULL engine (the 1 kHz scripted operator
and the simulated fixtures through `simulate_cohort`, not the outcome engine): a cohort of
the shipped VF protocol at effect scale 0 (no fixture effect at all, mechanism included)
shows

1. no fixture chosen best by more subjects than chance allows,
2. mean ratings within the range chance allows,
3. no fixture effect on path deviation in the PRIMARY probe model.

Size: 10 subjects (one full set of the 10 Williams sequences, so block position is
balanced: practice cannot favour a fixture), trials cut at 4 s simulated (the knob
`max_trial_time`; every measure is still computed over what was run). The full-size run
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
from pathlib import Path

import numpy as np
from scipy import stats

from vasim.operator.scenario import load_scenario
from vasim.study.cohort import simulate_cohort
from vasim.study.protocol import load_protocol
from vasim.study.report.analysis import analyse_vf
from vasim.study.report.data import load_study
from vasim.study.report.primary import probe_model_tests

N = 10
FIXTURES = ("vg", "ag", "ms", "mag", "ff")
ALPHA = 0.01


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


def test_a_null_cohort_of_the_full_engine_shows_no_fixture_effect(tmp_path: Path) -> None:
    protocol = load_protocol("vf_learning_curve")
    db = tmp_path / "null.sqlite"
    rep = simulate_cohort(db, protocol, n_subjects=N, n_surgeons=7, seed=11, workers=0,
                          progress=False, max_trial_time=4.0,
                          scenario=load_scenario("seed_plausible"), effect_scale=0.0)
    assert rep.sessions_completed == N and rep.trials_run == N * 38
    data = load_study(db, protocol.name)
    post = data.answers[data.answers["questionnaire"] == "post"]

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
