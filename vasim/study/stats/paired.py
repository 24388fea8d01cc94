"""Paired t-tests between all levels of a within factor, power analysis and the seed's gain.

spec/study.md §4 (chapter 5 experiments): paired Student t-test per pair of modes, power
test (power at the actual N and minimum N for power 0.9), gain = mean(StdT) / mean(MRCP).
spec/study.md §3 **decision**: with Holm correction these tests are the within-subject-correct
post hoc alternative to the RM Tukey HSD.
"""

from __future__ import annotations

import itertools
import math
import warnings
from typing import Any

import numpy as np
import pandas as pd
from scipy import optimize, stats
from statsmodels.stats.multitest import multipletests
from statsmodels.stats.power import TTestPower

from vasim.core.errors import ConfigError
from vasim.study.stats._data import StatsWarning, cell_means, error_ss_is_zero, finite_array

#: Column order of :func:`pairwise_paired` (also the JSON keys of ``vasim stats paired``).
PAIRED_COLUMNS: tuple[str, ...] = (
    "group1", "group2", "n", "mean_diff", "t", "df", "p", "ci_low", "ci_high", "cohen_dz",
    "power_observed", "n_power90", "n_power90_ceil", "p_holm", "p_bonf",
)

_POWER = TTestPower()


def paired_power(dz: float, n: float, alpha: float = 0.05) -> float:
    """Two-sided power of the paired (one-sample) t-test for effect ``dz`` with ``n`` pairs.

    Args:
        dz: standardised mean difference ``mean(d) / sd(d)`` (sign irrelevant).
        n: number of pairs (real-valued allowed, ``>= 2``); df = n - 1.
        alpha: two-sided significance level.

    Returns:
        ``P(|T| > t_{1-alpha/2, n-1})`` with ``T`` noncentral t, noncentrality
        ``dz sqrt(n)``; equal to R ``pwr.t.test(d=dz, n=n, type="paired")``.

    Notes:
        Computed as the sum of the two one-sided tails, each with
        ``statsmodels.stats.power.TTestPower`` (``alternative="larger"`` at ``alpha/2``
        for ``+|dz|`` and ``-|dz|``). This is the same quantity as statsmodels'
        ``"two-sided"`` option, which returns NaN when the far tail underflows in SciPy's
        ``nctdtr`` (e.g. ``dz = 3, n = 100``); a NaN tail is recomputed with
        ``scipy.stats.nct.sf`` (the two agree to 1e-16 where both are defined).

    Examples:
        >>> round(paired_power(0.0, 10), 6)
        0.05
        >>> round(paired_power(0.5112738, 32), 6)  # R pwr: d for power 0.8 at n = 32
        0.8
    """
    d = abs(float(dz))
    if not math.isfinite(d) or not n >= 2:
        return math.nan
    return _tail(d, n, alpha / 2) + _tail(-d, n, alpha / 2)


def _tail(d: float, n: float, alpha: float) -> float:
    """``P(T > t_{1-alpha, n-1})`` for noncentral t with noncentrality ``d sqrt(n)``."""
    value = float(_POWER.power(effect_size=d, nobs=n, alpha=alpha, alternative="larger"))
    if math.isnan(value):  # SciPy's nctdtr underflows in the far tail; same quantity:
        value = float(stats.nct.sf(stats.t.isf(alpha, n - 1), n - 1, d * math.sqrt(n)))
    return value


def n_for_power(dz: float, power: float = 0.9, alpha: float = 0.05) -> float:
    """Exact real-valued number of pairs at which the paired t-test reaches ``power``.

    Args:
        dz: standardised mean difference (sign irrelevant).
        power: target two-sided power, in ``(alpha, 1)``.
        alpha: two-sided significance level.

    Returns:
        The root ``n >= 2`` of ``paired_power(dz, n, alpha) = power`` (Brent's method,
        ``xtol = 1e-10``); NaN when ``dz = 0`` (no finite n reaches the power). The t-test
        needs ``n >= 2`` (df >= 1, as R ``pwr``, which searches ``n > 2``): when the power
        at ``n = 2`` already reaches the target (``|dz| > 14.82`` for power 0.9) the
        result is 2.0, the smallest valid sample, not an extrapolated root.

    Examples:
        >>> round(n_for_power(0.5, power=0.75), 4)  # R pwr.t.test: n = 29.7355
        29.7355
    """
    d = abs(float(dz))
    if not (alpha < power < 1.0) or not math.isfinite(d) or d == 0.0:
        return math.nan

    def gap(n: float) -> float:
        return paired_power(d, n, alpha) - power

    # Bracket around the normal approximation n ~ ((z_{1-a/2} + z_power) / d)^2, where the
    # noncentrality stays moderate and SciPy's noncentral t is accurate.
    guess = ((stats.norm.isf(alpha / 2) + stats.norm.ppf(power)) / d) ** 2
    lo, hi = 2.0, max(4.0, 2.0 * guess + 10.0)
    if gap(lo) >= 0:
        return lo
    for _ in range(60):
        if gap(hi) > 0:
            break
        lo, hi = hi, 2.0 * hi
    else:
        return math.nan
    return float(optimize.brentq(gap, lo, hi, xtol=1e-10, rtol=4 * np.finfo(float).eps))


def min_n_for_power(dz: float, power: float = 0.9, alpha: float = 0.05) -> int | None:
    """Smallest integer number of pairs (>= 2) with ``paired_power >= power``; None if none."""
    return _smallest_n(dz, n_for_power(dz, power, alpha), power, alpha)


def _smallest_n(dz: float, n_real: float, power: float, alpha: float) -> int | None:
    """Smallest integer n >= 2 with power >= target, given the real-valued root."""
    if math.isnan(n_real):
        return None
    n_int = max(2, math.ceil(n_real))
    while n_int > 2 and paired_power(dz, n_int - 1, alpha) >= power:
        n_int -= 1
    while paired_power(dz, n_int, alpha) < power:
        n_int += 1
    return n_int


def pairwise_paired(data: pd.DataFrame, dv: str, subject: str, within: str) -> pd.DataFrame:
    """Paired Student t-tests between every pair of levels of a within factor.

    Several rows per subject x level are averaged first; the design must be balanced.

    Args:
        data: long-format table.
        dv: dependent-variable column (finite numbers).
        subject: subject-identifier column (at least 2 subjects).
        within: within-subject factor column (at least 2 levels).

    Returns:
        One row per pair (``group1`` before ``group2`` in level order), columns
        :data:`PAIRED_COLUMNS`:

        - ``group1``, ``group2``: the levels; ``n``: number of subjects (pairs).
        - ``mean_diff``: mean of ``d = group1 - group2`` (as R ``t.test(x, y, paired=TRUE)``).
        - ``t``, ``df``, ``p``: t statistic, ``n - 1``, two-sided p-value.
        - ``ci_low``, ``ci_high``: 95 % confidence interval of the mean difference.
        - ``cohen_dz``: ``mean(d) / sd(d)``.
        - ``power_observed``: two-sided power at alpha = .05 for ``|dz|`` and ``n``
          (:func:`paired_power`; "observed" power, a function of p).
        - ``n_power90``: real-valued n for power 0.9 (:func:`n_for_power`), NaN if dz = 0;
          ``n_power90_ceil``: smallest integer n with power >= 0.9 (nullable integer).
        - ``p_holm``, ``p_bonf``: Holm and Bonferroni adjusted p-values over this family of
          pairs (``statsmodels.stats.multitest.multipletests``).

    Raises:
        ConfigError: as :func:`vasim.study.stats.anova.rm_anova`.

    Notes:
        A pair whose differences are all equal has ``sd(d) = 0``: t, p, dz and power are
        NaN (a :class:`StatsWarning` is issued) and the pair is left out of the Holm and
        Bonferroni family. "Equal" is within round-off
        (:func:`vasim.study.stats._data.error_ss_is_zero` of ``sum (d - mean d)^2`` against
        the pair's cell means), so differences equal up to float rounding do not produce a
        dz of 1e15.

    Examples:
        >>> df = pd.DataFrame({"s": [1, 2, 3, 4] * 2, "c": ["a"] * 4 + ["b"] * 4,
        ...                    "y": [1.0, 2.0, 3.0, 4.0, 2.0, 2.5, 4.5, 5.5]})
        >>> r = pairwise_paired(df, dv="y", subject="s", within="c")
        >>> r[["group1", "group2", "n", "mean_diff", "df"]].to_dict("records")
        [{'group1': 'a', 'group2': 'b', 'n': 4, 'mean_diff': -1.125, 'df': 3}]
    """
    cm = cell_means(data, dv, subject, [within])
    y = cm.values
    n, k = y.shape
    levels = cm.levels[0]
    tcrit = float(stats.t.ppf(0.975, n - 1))
    rows: list[dict[str, Any]] = []
    for i, j in itertools.combinations(range(k), 2):
        d = y[:, i] - y[:, j]
        mean = float(d.mean())
        sd = float(d.std(ddof=1))
        row: dict[str, Any] = {"group1": levels[i], "group2": levels[j], "n": n,
                               "mean_diff": mean, "df": n - 1}
        ss_d = sd * sd * (n - 1)
        if math.isfinite(sd) and not error_ss_is_zero(ss_d, y[:, [i, j]]):
            se = sd / math.sqrt(n)
            t = mean / se
            dz = mean / sd
            n90 = n_for_power(dz, 0.9)
            row.update(t=t, p=float(2.0 * stats.t.sf(abs(t), n - 1)),
                       ci_low=mean - tcrit * se, ci_high=mean + tcrit * se, cohen_dz=dz,
                       power_observed=paired_power(dz, n), n_power90=n90,
                       n_power90_ceil=_smallest_n(dz, n90, 0.9, 0.05))
        else:
            why = (f"all differences are equal ({mean!r})" if math.isfinite(sd) else
                   "the differences overflow (not finite)")
            warnings.warn(f"pairwise_paired {levels[i]!r} vs {levels[j]!r}: {why}, t-test and "
                          f"dz undefined", StatsWarning, stacklevel=2)
            row.update(t=math.nan, p=math.nan, ci_low=mean, ci_high=mean, cohen_dz=math.nan,
                       power_observed=math.nan, n_power90=math.nan, n_power90_ceil=None)
        rows.append(row)
    out = pd.DataFrame(rows, columns=list(PAIRED_COLUMNS[:-2]))
    out["n"] = out["n"].astype("int64")
    out["df"] = out["df"].astype("int64")
    out["n_power90_ceil"] = pd.array(out["n_power90_ceil"].tolist(), dtype="Int64")
    p = out["p"].to_numpy(dtype=float)
    ok = np.isfinite(p)
    holm = np.full(len(p), np.nan)
    bonf = np.full(len(p), np.nan)
    if ok.any():
        holm[ok] = multipletests(p[ok], method="holm")[1]
        bonf[ok] = multipletests(p[ok], method="bonferroni")[1]
    out["p_holm"] = holm
    out["p_bonf"] = bonf
    return out[list(PAIRED_COLUMNS)]


MAX_GAIN = 1e9
"""Largest ratio of means :func:`gain` reports; beyond it ``mean(b)`` is round-off."""


def gain(a: Any, b: Any) -> float:
    """The seed's gain: ratio of means, ``mean(a) / mean(b)`` (e.g. StdT over MRCP).

    Args:
        a: values of the reference mode (the seed: StdT), any unit.
        b: values of the compared mode (the seed: MRCP), same unit.

    Returns:
        ``mean(a) / mean(b)``; > 1 means ``b`` has the smaller mean (for times, errors or
        forces: ``b`` is better).

    Raises:
        ConfigError: empty or non-finite input, ``mean(b) == 0``, or ``mean(b)`` at
            round-off level beside ``mean(a)`` (``|mean(a) / mean(b)| > 1e9``: e.g. a target
            displacement of 1e-17 m that is zero up to floating point; such a ratio
            measures the rounding, not the mode).

    Examples:
        >>> round(gain([142.0, 143.02], [101.0, 101.26]), 4)  # seed exp. 2 ET: 142.51/101.13
        1.4092
    """
    x = finite_array(a, "gain: a")
    z = finite_array(b, "gain: b")
    mb, ma = float(z.mean()), float(x.mean())
    if mb == 0.0:
        raise ConfigError("gain: mean(b) is zero, the ratio of means is undefined")
    if abs(ma) > MAX_GAIN * abs(mb):
        raise ConfigError(f"gain: mean(b) = {mb:.3g} is zero up to round-off beside mean(a) = "
                          f"{ma:.3g} (ratio > {MAX_GAIN:.0e}): the ratio of means is undefined")
    return ma / mb
