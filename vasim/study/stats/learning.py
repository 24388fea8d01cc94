"""Learning curves: per-trial summaries (seed Figs. 6.17-6.18) and power-law fits.

spec/study.md §3: the learning curve uses the VF-free trials only (8 per subject), mean and
interquartile range of cumulative error and latency per trial index; §4: learning curves
over the 6 trials per mode. The power law of practice ``y = a n^(-b) [+ c]`` summarises a
curve by its initial level ``a``, learning rate ``b`` and optional asymptote ``c``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from scipy import optimize, stats

from vasim.core.errors import ConfigError
from vasim.study.stats._data import (
    StatsWarning,
    factor_column,
    finite_array,
    levels_of,
    numeric_column,
    require_columns,
    require_frame,
    source_of,
)

#: Columns of :func:`learning_curve_summary` (after the optional ``condition`` column).
SUMMARY_COLUMNS: tuple[str, ...] = ("trial", "n", "mean", "q25", "q75")

#: Columns of :func:`fit_learning_curves` (after the optional ``condition`` column).
FIT_COLUMNS: tuple[str, ...] = ("n_obs", "a", "b", "c", "se_a", "se_b", "se_c", "rss", "dof")


@dataclass(frozen=True, eq=False)
class PowerLawFit:
    """Least-squares fit of ``y = a n^(-b) [+ c]`` with parameter covariance.

    Attributes:
        a: level at trial 1 above the asymptote (unit of y).
        b: learning rate (dimensionless; > 0 means y decreases with practice).
        c: asymptote (unit of y); NaN when the model has no asymptote.
        se_a, se_b, se_c: standard errors (NaN when not estimable / not fitted).
        cov: (p, p) covariance of (a, b[, c]), residual variance scaled.
        n_obs: number of (trial, y) points fitted; dof: ``n_obs - p``.
        rss: residual sum of squares (unit of y squared).
        level: confidence level of :meth:`band`.
    """

    a: float
    b: float
    c: float
    se_a: float
    se_b: float
    se_c: float
    cov: np.ndarray = field(repr=False)
    n_obs: int
    dof: int
    rss: float
    level: float

    @property
    def asymptote(self) -> bool:
        """True when the asymptote ``c`` was fitted."""
        return not math.isnan(self.c)

    def predict(self, trial_index: Any) -> np.ndarray:
        """Fitted mean ``a n^(-b) + c`` at the given trial indices (> 0)."""
        n = np.asarray(trial_index, dtype=float)
        return self.a * n ** (-self.b) + (self.c if self.asymptote else 0.0)

    def band(self, trial_index: Any) -> pd.DataFrame:
        """Pointwise confidence band of the fitted mean curve (delta method).

        Args:
            trial_index: trial indices n > 0 at which to evaluate the band.

        Returns:
            Columns ``trial``, ``fit``, ``lower``, ``upper``.

        Notes:
            With gradient ``g(n) = (n^-b, -a ln(n) n^-b[, 1])`` and parameter covariance
            ``V``: ``fit -+ t_{(1+level)/2, dof} sqrt(g V g^T)``. It is a band for the mean
            curve, not a prediction interval for single trials.
        """
        n = finite_array(trial_index, "trial_index")
        if (n <= 0).any():
            raise ConfigError("band: trial indices must be > 0")
        fit = self.predict(n)
        grad = [n ** (-self.b), -self.a * np.log(n) * n ** (-self.b)]
        if self.asymptote:
            grad.append(np.ones_like(n))
        g = np.stack(grad, axis=1)
        var = np.einsum("ij,jk,ik->i", g, self.cov, g)
        half = float(stats.t.ppf(0.5 + self.level / 2.0, self.dof)) * np.sqrt(
            np.maximum(var, 0.0))
        return pd.DataFrame({"trial": n, "fit": fit, "lower": fit - half, "upper": fit + half})


def fit_power_law(trial_index: Any, y: Any, *, asymptote: bool = False,
                  level: float = 0.95) -> PowerLawFit:
    """Fits the power law of practice ``y = a n^(-b)`` (or ``a n^(-b) + c``).

    Args:
        trial_index: (N,) trial numbers n >= 1 (any positive real); repeated indices (one
            point per subject) are allowed.
        y: (N,) performance values (e.g. path deviation [mm] or latency [s]).
        asymptote: also fit the asymptote ``c`` (needs >= 3 distinct trial indices).
        level: confidence level of the standard band (0.95).

    Returns:
        :class:`PowerLawFit`.

    Raises:
        ConfigError: lengths differ, non-finite values, ``trial_index <= 0``, too few
            points (N must exceed the number of parameters) or distinct indices, or the
            fit does not converge.

    Notes:
        ``scipy.optimize.curve_fit`` (Levenberg-Marquardt), started from the log-log
        regression line (``c`` started just below ``min(y)``). The covariance is scaled by
        the residual variance ``rss / dof`` (``absolute_sigma=False``); the band is the
        delta-method band of :meth:`PowerLawFit.band`.

    Examples:
        >>> n = np.arange(1, 9)
        >>> fit = fit_power_law(n, 10.0 * n ** -0.5)
        >>> round(fit.a, 6), round(fit.b, 6)
        (10.0, 0.5)
    """
    n = finite_array(trial_index, "trial_index")
    yy = finite_array(y, "y")
    if n.size != yy.size:
        raise ConfigError(f"trial_index has {n.size} values but y has {yy.size}")
    if (n <= 0).any():
        raise ConfigError(f"trial indices must be > 0 for n^(-b), got min {n.min()!r}")
    if not 0.0 < level < 1.0:
        raise ConfigError(f"level must be in (0, 1), got {level!r}")
    n_par = 3 if asymptote else 2
    distinct = np.unique(n).size
    if distinct < n_par or n.size <= n_par:
        raise ConfigError(f"a power law with {n_par} parameters needs more than {n_par} points "
                          f"and at least {n_par} distinct trial indices; got {n.size} points, "
                          f"{distinct} distinct indices")
    p0 = _start(n, yy, asymptote)

    def model(x: np.ndarray, *p: float) -> np.ndarray:
        out = p[0] * x ** (-p[1])
        return out + p[2] if len(p) == 3 else out

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", optimize.OptimizeWarning)
        try:
            popt, pcov = optimize.curve_fit(model, n, yy, p0=p0, maxfev=20000)
        except (RuntimeError, ValueError) as exc:
            raise ConfigError(f"power-law fit did not converge: {exc}") from None
    rss = float(((yy - model(n, *popt)) ** 2).sum())
    if not np.isfinite(pcov).all():
        warnings.warn("power-law fit: parameter covariance not estimable, SEs are NaN",
                      StatsWarning, stacklevel=2)
        pcov = np.full((n_par, n_par), np.nan)
    se = np.sqrt(np.clip(np.diag(pcov), 0.0, None))
    return PowerLawFit(a=float(popt[0]), b=float(popt[1]),
                       c=float(popt[2]) if asymptote else math.nan,
                       se_a=float(se[0]), se_b=float(se[1]),
                       se_c=float(se[2]) if asymptote else math.nan,
                       cov=pcov, n_obs=int(n.size), dof=int(n.size - n_par), rss=rss,
                       level=level)


def _start(n: np.ndarray, y: np.ndarray, asymptote: bool) -> list[float]:
    """Starting values from the straight line of log(y - c0) against log(n)."""
    c0 = 0.0
    if asymptote:
        span = float(np.ptp(y)) or 1.0
        c0 = float(y.min()) - 0.1 * span
    shifted = y - c0
    if (shifted > 0).all() and np.unique(n).size > 1:
        slope, intercept = np.polyfit(np.log(n), np.log(shifted), 1)
        p0 = [float(math.exp(intercept)), float(-slope)]
    else:
        p0 = [float(np.mean(shifted)) or 1.0, 0.1]
    return [*p0, c0] if asymptote else p0


def _subject_trial_means(data: pd.DataFrame, dv: str, subject: str, trial: str,
                         condition: str | None) -> pd.DataFrame:
    data = require_frame(data)
    cols = [dv, subject, trial] + ([condition] if condition else [])
    require_columns(data, cols)
    frame = pd.DataFrame({"y": numeric_column(data, dv).to_numpy(),
                          "s": factor_column(data, subject).to_numpy(),
                          "t": factor_column(data, trial).to_numpy()})
    if condition:
        frame["c"] = factor_column(data, condition).to_numpy()
    keys = (["c"] if condition else []) + ["t", "s"]
    return frame.groupby(keys, sort=False)["y"].mean().reset_index()


def learning_curve_summary(data: pd.DataFrame, dv: str, subject: str, trial: str,
                           condition: str | None = None) -> pd.DataFrame:
    """Mean and interquartile range across subjects per trial index (seed Figs. 6.17-6.18).

    Args:
        data: long-format table; several rows per subject x trial (e.g. per-point rows)
            are averaged first, so every subject weighs the same.
        dv: dependent variable (finite numbers).
        subject: subject-identifier column.
        trial: trial-index column (sorted numerically if numeric).
        condition: optional column (fixture, teleoperation mode) giving one curve each.

    Returns:
        Columns ``[condition,] trial, n, mean, q25, q75``: number of subjects with that
        trial, their mean and 25th/75th percentiles (linear interpolation, R type 7 /
        NumPy default), sorted by condition and trial.

    Raises:
        ConfigError: missing column, non-finite ``dv`` or missing labels.

    Examples:
        >>> df = pd.DataFrame({"s": [1, 1, 2, 2, 3, 3], "trial": [1, 2] * 3,
        ...                    "e": [4.0, 2.0, 6.0, 3.0, 8.0, 4.0]})
        >>> learning_curve_summary(df, dv="e", subject="s", trial="trial").to_dict("records")[0]
        {'trial': 1, 'n': 3, 'mean': 6.0, 'q25': 5.0, 'q75': 7.0}
    """
    m = _subject_trial_means(data, dv, subject, trial, condition)
    groups = ["c", "t"] if condition else ["t"]
    g = m.groupby(groups, sort=False)["y"]
    out = pd.DataFrame({
        "n": g.size(), "mean": g.mean(),
        "q25": g.quantile(0.25), "q75": g.quantile(0.75),
    }).reset_index()
    out = out.rename(columns={"c": condition or "condition", "t": "trial"})
    order = ([condition] if condition else []) + ["trial"]
    out = _sort_by_levels(out, order, m)
    out["n"] = out["n"].astype("int64")
    return out[order + list(SUMMARY_COLUMNS[1:])].reset_index(drop=True)


def _sort_by_levels(out: pd.DataFrame, order: list[str], m: pd.DataFrame) -> pd.DataFrame:
    keys = []
    for col, src in zip(order, (["c", "t"] if len(order) == 2 else ["t"]), strict=True):
        rank = {v: i for i, v in enumerate(levels_of(m[src]))}
        keys.append(out[col].map(rank))
    idx = pd.DataFrame({f"k{i}": k for i, k in enumerate(keys)}).sort_values(
        [f"k{i}" for i in range(len(keys))]).index
    return out.loc[idx]


def fit_learning_curves(data: pd.DataFrame, dv: str, subject: str, trial: str,
                        condition: str | None = None, *,
                        asymptote: bool = False) -> pd.DataFrame:
    """Power-law fit per condition on the subject-level (trial, y) points.

    Args:
        data: long-format table; rows per subject x trial are averaged first.
        dv: dependent variable (finite numbers).
        subject: subject-identifier column.
        trial: numeric trial-index column (values > 0, e.g. 1..8).
        condition: optional column giving one curve per level.
        asymptote: fit ``a n^(-b) + c`` instead of ``a n^(-b)``.

    Returns:
        One row per condition: ``[condition,] n_obs, a, b, c, se_a, se_b, se_c, rss, dof``
        (see :class:`PowerLawFit`; ``c``/``se_c`` NaN without asymptote).

    Raises:
        ConfigError: as :func:`fit_power_law` (the message names the condition), or a
            non-numeric trial column.

    Examples:
        >>> df = pd.DataFrame({"s": [1] * 4 + [2] * 4, "trial": [1, 2, 3, 4] * 2,
        ...                    "e": [10.0, 5.0, 10 / 3, 2.5, 10.0, 5.0, 10 / 3, 2.5]})
        >>> r = fit_learning_curves(df, dv="e", subject="s", trial="trial")
        >>> round(float(r.loc[0, "b"]), 6)
        1.0
    """
    m = _subject_trial_means(data, dv, subject, trial, condition)
    src = source_of(data)
    t_num = pd.to_numeric(m["t"], errors="coerce")
    if t_num.isna().any():
        bad = m.loc[t_num.isna(), "t"].unique()[:5].tolist()
        raise ConfigError(f"trial column {trial!r} must be numeric for a power-law fit, got "
                          f"{bad!r}", file=src, field=trial)
    m["tn"] = t_num.astype(float)
    conds = levels_of(m["c"]) if condition else [None]
    rows = []
    for cond in conds:
        part = m if cond is None else m[m["c"] == cond]
        try:
            fit = fit_power_law(part["tn"].to_numpy(), part["y"].to_numpy(),
                                asymptote=asymptote)
        except ConfigError as exc:
            where = "" if cond is None else f" for {condition}={cond!r}"
            raise ConfigError(f"learning-curve fit{where}: {exc.reason}", file=src,
                              field=trial) from None
        row: dict[str, Any] = {} if cond is None or condition is None else {condition: cond}
        row.update(n_obs=fit.n_obs, a=fit.a, b=fit.b, c=fit.c, se_a=fit.se_a, se_b=fit.se_b,
                   se_c=fit.se_c, rss=fit.rss, dof=fit.dof)
        rows.append(row)
    cols = ([condition] if condition else []) + list(FIT_COLUMNS)
    return pd.DataFrame(rows, columns=cols)
