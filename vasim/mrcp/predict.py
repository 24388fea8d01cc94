"""Trajectory prediction for the MRCP kernel (spec/mrcp.md §3, seed section 3.3).

Teleoperation admits no path planning, so the kernel evaluates robots on a short
*predicted* trajectory of the task. The reference predictor fits a least-squares polynomial
(degree ``l <= 3``) to the last ``n`` observed samples as a function of time and
extrapolates it; each predicted value carries a normal distribution ``N(p̂_o, σ_o)`` from the
prediction interval

    p̂_o ± t_{α/2, n-(l+1)} · S_R · sqrt(1 + v_hh),
    S_R² = Σ e_i² / (n - (l+1)),   v_hh = x_h' (X'X)^{-1} x_h,

with ``X`` the design matrix (leading column of ones). ``σ_o = S_R sqrt(1 + v_hh)`` is the
standard error of a new observation; ``half_width = t · σ_o``. **Decision** (spec §3): the
extracted seed drops the inverse in ``v_hh``; the inverse is the textbook formula (checked
against statsmodels' ``get_prediction(...).obs_ci`` in the tests).

Any object with a ``predict(times, values, future_times) -> Prediction`` method is a
:class:`Predictor` and can replace :class:`PolynomialPredictor` in the kernel.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray
from scipy.stats import t as student_t

from vasim.core.geometry import matrix_from_rotvec, rotvec_from_matrix

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Prediction:
    """Predicted values with their uncertainty.

    Attributes:
        times: ``(K,)`` absolute times of the predicted points [s].
        mean: ``(K, d)`` predicted values p̂_o.
        std: ``(K, d)`` standard error of a new observation σ_o = S_R sqrt(1 + v_hh).
        half_width: ``(K, d)`` half width of the (1 - α) prediction interval, t·σ_o.
    """

    times: FloatArray
    mean: FloatArray
    std: FloatArray
    half_width: FloatArray


@runtime_checkable
class Predictor(Protocol):
    """Anything that predicts future values of sampled signals with an uncertainty."""

    def predict(self, times: FloatArray, values: FloatArray,
                future_times: FloatArray) -> Prediction:
        """Predict ``values`` (``(n, d)`` observed at ``times`` ``(n,)``) at ``future_times``."""
        ...


@lru_cache(maxsize=256)
def _t_quantile(alpha: float, dof: int) -> float:
    return float(student_t.ppf(1.0 - alpha / 2.0, dof))


def _vander(x: FloatArray, degree: int) -> FloatArray:
    """Design matrix with a leading column of ones: ``[1, x, x², ...]``."""
    return np.vander(x, degree + 1, increasing=True)


@dataclass(frozen=True)
class PolynomialPredictor:
    """Least-squares polynomial extrapolation with prediction intervals (seed eq. 3.3-3.11).

    Args:
        degree: polynomial degree ``l`` (0..3). With few samples the degree drops to
            ``n - 1``; with no residual degree of freedom left (``n = l + 1``, including a
            single sample) the fit is exact and the uncertainty is reported as zero.
        alpha: ``1 - confidence`` of the prediction interval (0.05 = 95 %).

    Example:
        >>> import numpy as np
        >>> p = PolynomialPredictor(degree=1)
        >>> t = np.arange(5) * 0.1
        >>> pred = p.predict(t, (2.0 * t)[:, None], np.array([0.5]))
        >>> round(float(pred.mean[0, 0]), 6), round(float(pred.std[0, 0]), 9)
        (1.0, 0.0)
    """

    degree: int = 2
    alpha: float = 0.05

    def __post_init__(self) -> None:
        if not 0 <= self.degree <= 3:
            raise ValueError(f"PolynomialPredictor.degree must be in 0..3, got {self.degree!r}")
        if not 0.0 < self.alpha < 1.0:
            raise ValueError(f"PolynomialPredictor.alpha must be in (0, 1), got {self.alpha!r}")

    def predict(self, times: FloatArray, values: FloatArray,
                future_times: FloatArray) -> Prediction:
        """Fit every column of ``values`` against ``times`` and extrapolate.

        Args:
            times: ``(n,)`` observation times [s], strictly increasing.
            values: ``(n, d)`` observed values (``(n,)`` is taken as one column).
            future_times: ``(K,)`` times to predict at [s].

        Returns:
            A :class:`Prediction` with ``(K, d)`` arrays.

        Raises:
            ValueError: on empty input or mismatched lengths.
        """
        t = np.asarray(times, dtype=np.float64)
        y = np.asarray(values, dtype=np.float64)
        if y.ndim == 1:
            y = y[:, None]
        tf = np.asarray(future_times, dtype=np.float64)
        n = t.shape[0]
        if n == 0 or y.shape[0] != n:
            raise ValueError(f"predict: need n >= 1 samples with matching values, got times "
                             f"{t.shape} and values {y.shape}")
        k = tf.shape[0]
        if n == 1:
            zeros = np.zeros((k, y.shape[1]))
            return Prediction(tf, np.repeat(y[-1:], k, axis=0), zeros, zeros.copy())
        deg = min(self.degree, n - 1)
        # Time relative to the last sample and scaled: well-conditioned normal equations.
        t0 = t[-1]
        scale = max(float(t[-1] - t[0]), 1e-9)
        x = (t - t0) / scale
        xf = (tf - t0) / scale
        design = _vander(x, deg)
        xtx_inv = np.linalg.inv(design.T @ design)
        coef = xtx_inv @ (design.T @ y)
        resid = y - design @ coef
        dof = n - (deg + 1)
        if dof == 0:        # an exact fit: no residual to estimate the spread from
            zeros = np.zeros((k, y.shape[1]))
            return Prediction(tf, _vander(xf, deg) @ coef, zeros, zeros.copy())
        s_r = np.sqrt(np.sum(resid * resid, axis=0) / dof)
        design_f = _vander(xf, deg)
        mean = design_f @ coef
        v_hh = np.einsum("ki,ij,kj->k", design_f, xtx_inv, design_f)
        std = np.sqrt(1.0 + v_hh)[:, None] * s_r[None, :]
        return Prediction(tf, mean, std, _t_quantile(self.alpha, dof) * std)


def predict_rotations(times: FloatArray, rotations: FloatArray, future_times: FloatArray,
                      predictor: Predictor) -> FloatArray:
    """Extrapolate an orientation history: ``(K, 3, 3)`` predicted rotation matrices.

    The rotations are expressed as rotation vectors relative to the last observed one
    (``log(R_last' R_i)``, small near the present), each component is predicted with
    ``predictor``, and mapped back: ``R_last exp(ω̂)``.

    Args:
        times: ``(n,)`` observation times [s].
        rotations: ``(n, 3, 3)`` observed world-from-task rotations.
        future_times: ``(K,)`` times to predict at [s].
        predictor: the predictor used for the three rotation-vector components.
    """
    rot = np.asarray(rotations, dtype=np.float64)
    last = rot[-1]
    rel = rotvec_from_matrix(last.T @ rot)  # each rotation relative to the last
    pred = predictor.predict(times, rel, future_times)
    return last @ matrix_from_rotvec(pred.mean)
