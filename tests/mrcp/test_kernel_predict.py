"""Trajectory predictor: against statsmodels' OLS prediction intervals and exact polynomials."""

from __future__ import annotations

import numpy as np
import pytest
import statsmodels.api as sm
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from vasim.mrcp.predict import PolynomialPredictor, Predictor, predict_rotations


@pytest.mark.parametrize("degree", [1, 2, 3])
def test_prediction_interval_matches_statsmodels(degree: int) -> None:
    rng = np.random.default_rng(degree)
    t = np.linspace(0.0, 0.3, 12)
    y = np.column_stack([np.sin(3 * t) + 0.01 * rng.standard_normal(12),
                         t ** 2 + 0.02 * rng.standard_normal(12)])
    tf = np.array([0.33, 0.4, 0.5])
    pred = PolynomialPredictor(degree=degree, alpha=0.1).predict(t, y, tf)
    for col in range(2):
        # Independent implementation: statsmodels OLS on the same design (powers of t).
        res = sm.OLS(y[:, col], np.vander(t, degree + 1, increasing=True)).fit()
        frame = res.get_prediction(np.vander(tf, degree + 1, increasing=True)).summary_frame(
            alpha=0.1)
        np.testing.assert_allclose(pred.mean[:, col], frame["mean"], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(pred.mean[:, col] - pred.half_width[:, col],
                                   frame["obs_ci_lower"], rtol=1e-7, atol=1e-10)
        np.testing.assert_allclose(pred.mean[:, col] + pred.half_width[:, col],
                                   frame["obs_ci_upper"], rtol=1e-7, atol=1e-10)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-2.0, 2.0), min_size=4, max_size=4))
def test_exact_cubic_is_extrapolated_exactly(coef: list[float]) -> None:
    t = np.linspace(0.0, 0.2, 10)
    y = np.polynomial.polynomial.polyval(t, coef)
    tf = np.array([0.25, 0.3])
    pred = PolynomialPredictor(degree=3).predict(t, y, tf)
    np.testing.assert_allclose(pred.mean[:, 0], np.polynomial.polynomial.polyval(tf, coef),
                               atol=1e-8)
    assert np.all(pred.std < 1e-6)


def test_uncertainty_grows_with_the_horizon() -> None:
    rng = np.random.default_rng(0)
    t = np.linspace(0.0, 0.2, 10)
    y = t + 0.01 * rng.standard_normal(10)
    pred = PolynomialPredictor(degree=1).predict(t, y, np.array([0.25, 0.4, 0.8]))
    assert np.all(np.diff(pred.std[:, 0]) > 0.0)


def test_few_samples_degrade_gracefully() -> None:
    p = PolynomialPredictor(degree=2)
    one = p.predict(np.array([0.0]), np.array([[1.0, 2.0]]), np.array([0.1, 0.2]))
    np.testing.assert_array_equal(one.mean, [[1.0, 2.0], [1.0, 2.0]])
    two = p.predict(np.array([0.0, 0.1]), np.array([0.0, 1.0]), np.array([0.2]))
    assert two.mean[0, 0] == pytest.approx(2.0)      # a line through two samples
    assert two.std[0, 0] == 0.0


def test_bad_input_is_named() -> None:
    with pytest.raises(ValueError, match="degree"):
        PolynomialPredictor(degree=5)
    with pytest.raises(ValueError, match="alpha"):
        PolynomialPredictor(alpha=1.5)
    with pytest.raises(ValueError, match="n >= 1"):
        PolynomialPredictor().predict(np.zeros(0), np.zeros((0, 1)), np.ones(1))


def test_rotation_at_constant_rate() -> None:
    t = np.linspace(0.0, 0.2, 8)
    omega = np.array([0.3, -0.2, 1.0])
    rots = Rotation.from_rotvec(t[:, None] * omega).as_matrix()
    tf = np.array([0.3])
    out = predict_rotations(t, rots, tf, PolynomialPredictor(degree=1))
    expected = Rotation.from_rotvec(tf[0] * omega).as_matrix()
    np.testing.assert_allclose(out[0], expected, atol=1e-9)
    assert isinstance(PolynomialPredictor(), Predictor)
