"""Tests of Spearman correlations between items (vasim/study/stats/correlation.py).

References:
* Wikipedia, "Spearman's rank correlation coefficient", worked example (IQ vs hours of TV
  per week, 10 people, no ties): sum d^2 = 194, rho = 1 - 6*194/(10*99) = -29/165
  = -0.175757..., t-distribution p-value 0.6864058 one-sided (greater), i.e. two-sided
  2 * 0.3135942 = 0.6271884 (worked out on Cross Validated, question 22816).
  Data: tests/data/reference_spearman_iq_tv.csv.
* With ties (Likert answers): Pearson's r of average ranks (``scipy.stats.rankdata``
  and ``numpy.corrcoef``) as an independent computation, and the t approximation
  ``t = r sqrt((n-2)/(1-r^2))`` for p.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy import stats

from vasim.core.errors import ConfigError
from vasim.study.stats import SPEARMAN_COLUMNS, StatsWarning, read_long_csv, spearman_items

DATA = Path(__file__).resolve().parents[2] / "data"


def test_iq_tv_matches_published_example() -> None:
    data = read_long_csv(DATA / "reference_spearman_iq_tv.csv")
    res = spearman_items(data, subject="person", item="item", value="value")
    assert list(res.columns) == list(SPEARMAN_COLUMNS)
    r = res.iloc[0]
    assert (r["var1"], r["var2"], r["n"]) == ("IQ", "TV", 10)
    assert r["rho"] == pytest.approx(-29 / 165, rel=1e-12)
    assert r["p"] == pytest.approx(2 * 0.3135942, abs=2e-7)


def _likert(y: np.ndarray) -> pd.DataFrame:
    return pd.DataFrame([{"s": i, "q": f"q{j}", "v": y[i, j]}
                         for i in range(y.shape[0]) for j in range(y.shape[1])])


@settings(max_examples=40, deadline=None)
@given(y=hnp.arrays(np.float64, (9, 3), elements=st.integers(1, 5).map(float)))
def test_likert_with_ties_equals_pearson_of_ranks(y: np.ndarray) -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", StatsWarning)
        res = spearman_items(_likert(y), "s", "q", "v")
        res2 = spearman_items(_likert(np.exp(y)), "s", "q", "v")
    warned = any(issubclass(w.category, StatsWarning) for w in caught)
    assert warned == bool((np.ptp(y, axis=0) == 0).any())  # warns exactly for constant items
    assert len(res) == 3
    for r in res.to_dict("records"):
        a, b = y[:, int(r["var1"][1])], y[:, int(r["var2"][1])]
        if np.ptp(a) == 0 or np.ptp(b) == 0:
            assert math.isnan(r["rho"]) and math.isnan(r["p"])
            continue
        ref = float(np.corrcoef(stats.rankdata(a), stats.rankdata(b))[0, 1])
        assert r["rho"] == pytest.approx(ref, abs=1e-12)
        assert -1.0 <= r["rho"] <= 1.0 and 0.0 <= r["p"] <= 1.0
        if abs(ref) < 1 - 1e-9:
            t = ref * math.sqrt(7 / (1 - ref**2))
            assert r["p"] == pytest.approx(2 * stats.t.sf(abs(t), 7), rel=1e-9)
        # rank statistic: invariant to a strictly increasing recoding of the answers
        assert res2.loc[(res2["var1"] == r["var1"]) & (res2["var2"] == r["var2"]),
                        "rho"].iloc[0] == pytest.approx(r["rho"], abs=1e-12)


def test_missing_answers_pairwise_deletion() -> None:
    y = np.array([[1, 2, 3], [2, 1, 3], [3, 4, 5], [4, 3, 5], [5, 5, 4]], dtype=float)
    df = _likert(y)
    df.loc[(df["s"] == 0) & (df["q"] == "q2"), "v"] = np.nan  # an empty cell
    df = df[~((df["s"] == 4) & (df["q"] == "q1"))]  # an absent row
    res = spearman_items(df, "s", "q", "v").set_index(["var1", "var2"])
    assert res.loc[("q0", "q1"), "n"] == 4
    assert res.loc[("q0", "q2"), "n"] == 4
    assert res.loc[("q1", "q2"), "n"] == 3
    ref = stats.spearmanr(y[1:4, 1], y[1:4, 2]).statistic
    assert res.loc[("q1", "q2"), "rho"] == pytest.approx(ref)


def test_too_few_common_answers_nan_with_warning() -> None:
    df = pd.DataFrame({"s": [1, 2, 3, 1, 2], "q": ["a", "a", "a", "b", "b"],
                       "v": [1.0, 2.0, 3.0, 2.0, 1.0]})
    with pytest.warns(StatsWarning, match="2 common answers"):
        r = spearman_items(df, "s", "q", "v").iloc[0]
    assert r["n"] == 2 and math.isnan(r["rho"])


def test_bad_input() -> None:
    data = read_long_csv(DATA / "reference_spearman_iq_tv.csv")
    with pytest.raises(ConfigError, match="column 'answer' not found") as err:
        spearman_items(data, "person", "item", "answer")
    assert "reference_spearman_iq_tv.csv" in str(err.value)
    dup = pd.concat([data, data.iloc[[0]]])
    with pytest.raises(ConfigError, match="person=1 x item='IQ'"):
        spearman_items(dup, "person", "item", "value")
    text = data.astype({"value": object})
    text.loc[4, "value"] = "agree"
    with pytest.raises(ConfigError, match="non-numeric values at line 4: 'agree'"):
        spearman_items(text, "person", "item", "value")
    with pytest.raises(ConfigError, match="at least 2 items"):
        spearman_items(data[data["item"] == "IQ"], "person", "item", "value")
