"""AGO/IAGO, GM(1,1), GM(0,N), GM(1,N) against hand-worked and constructed references."""

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError

from models.grey import (
    GM0NRegressor,
    GM1NRegressor,
    GM11,
    ago,
    background_values,
    gm0n_influence,
    gm1n_influence,
    iago,
)


def test_ago_iago_by_hand():
    x0 = np.array([1.0, -2.0, 3.5])
    assert np.array_equal(ago(x0), [1.0, -1.0, 2.5])
    assert np.array_equal(iago(ago(x0)), x0)
    assert np.array_equal(background_values(ago(x0)), [0.0, 0.75])


def test_gm11_textbook_series_by_hand():
    # Liu & Lin's GM(1,1) example X⁰ = (2.874, 3.278, 3.337, 3.390, 3.679).
    # X¹ = (2.874, 6.152, 9.489, 12.879, 16.558); z¹ = (4.513, 7.8205, 11.184, 14.7185)
    # Regress Y = x⁰(2..5) = (3.278, 3.337, 3.390, 3.679) on z¹: Y = -a z + b.
    # mean z = 38.236/4 = 9.559, mean Y = 13.684/4 = 3.421
    # dz = (-5.046, -1.7385, 1.625, 5.1595), dY = (-0.143, -0.084, -0.031, 0.258)
    # Sxy = 0.721578 + 0.146034 - 0.050375 + 1.331151 = 2.148388
    # Sxx = 25.462116 + 3.02238225 + 2.640625 + 26.62044025 = 57.74556350
    # a = -Sxy/Sxx = -0.03720437..., b = 3.421 + a·9.559 = 3.0653634...
    a = -2.148388 / 57.7455635
    b = 3.421 + a * 9.559
    model = GM11.fit([2.874, 3.278, 3.337, 3.390, 3.679])
    assert model.development_coefficient == pytest.approx(a, abs=1e-6)
    assert model.grey_input == pytest.approx(b, abs=1e-6)
    # time response x̂¹(k+1) = (x⁰(1) - b/a) e^{-ak} + b/a, de-accumulated
    k = np.arange(5)
    x1 = (2.874 - b / a) * np.exp(-a * k) + b / a
    assert np.allclose(model.predict(5), np.diff(x1, prepend=0.0), atol=1e-5)


def test_gm11_constant_series_forecasts_the_constant():
    # A constant series fits a ≈ -3.5e-18 (rounding): the textbook response
    # (x⁰(1) - b/a) e^{-ak} + b/a cancelled to zeros. The limit a → 0 is x̂¹(k+1) = x⁰(1) + b k.
    model = GM11.fit([3.0, 3.0, 3.0, 3.0])
    assert abs(model.development_coefficient) < 1e-12
    assert np.allclose(model.predict(8), 3.0, rtol=1e-12)
    assert np.array_equal(GM11(0.0, 2.0, 5.0).predict(3), [5.0, 2.0, 2.0])  # exactly a = 0


def test_gm11_exact_on_constructed_series():
    # choose a, b, x⁰(1); then x⁰(k) + a(X¹(k-1) + x⁰(k)/2) = b holds exactly
    a, b = 0.12, 5.0
    x = [3.0]
    for _ in range(7):
        x.append((b - a * sum(x)) / (1.0 + a / 2.0))
    model = GM11.fit(x)
    assert model.development_coefficient == pytest.approx(a, abs=1e-12)
    assert model.grey_input == pytest.approx(b, abs=1e-12)


def drivers(n=60, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n)
    return np.column_stack([20 + np.sin(t / 7) + 0.1 * rng.standard_normal(n), 25 + t / 30.0, 18 - np.cos(t / 11)])


def test_gm0n_recovers_weights_from_its_own_equation():
    X = drivers()
    theta = np.array([1.5, -0.7, 2.0])
    X1 = ago(X - X[0])
    z = X1 @ theta  # z₁¹(k) = Σθ x_j¹(k) for k ≥ 2; build x₁¹ from z: x¹(k) = 2z(k) - x¹(k-1)
    y1 = np.zeros(len(X))
    for k in range(1, len(X)):
        y1[k] = 2.0 * z[k] - y1[k - 1]
    y = iago(y1) + 7.0
    assert np.allclose(gm0n_influence(X, y), theta, atol=1e-9)
    assert np.allclose(GM0NRegressor().fit(X, y).coef_, theta, atol=1e-9)


def test_gm1n_recovers_parameters_and_predicts_its_own_series():
    X = drivers()
    a, b = 0.3, np.array([0.4, -0.2, 0.25])
    X1 = ago(X - X[0])
    y1 = np.zeros(len(X))
    for k in range(1, len(X)):  # x⁰(k) + a(x¹(k-1) + x⁰(k))/2 = Σ b x_j¹(k), with x⁰(k) = x¹(k) - x¹(k-1)
        y1[k] = (X1[k] @ b - a * y1[k - 1] / 2.0 + y1[k - 1]) / (1.0 + a / 2.0)
    y = iago(y1) - 3.0
    model = GM1NRegressor().fit(X, y)
    assert model.development_coefficient_ == pytest.approx(a, abs=1e-9)
    assert np.allclose(model.coef_, b, atol=1e-9)
    assert np.allclose(gm1n_influence(X, y), b, atol=1e-9)
    assert np.allclose(model.predict(X), y, atol=1e-8)


def test_zero_reference_convention():
    X = drivers()
    y = (X - X[0]) @ np.array([1.0, 2.0, -1.0]) + 4.0
    model = GM0NRegressor().fit(X, y)
    assert model.y_reference_ == 4.0
    # an offset on the inputs does not change anything: only changes are modelled
    assert np.allclose(model.predict(X + 100.0), model.predict(X))
    assert model.predict(X)[0] == 4.0


def test_grey_errors():
    X = drivers(n=4)
    y = np.arange(4.0)
    with pytest.raises(ValueError, match=r"GM1NRegressor has 4 parameters to fit and needs at least 6 samples"):
        GM1NRegressor().fit(X, y)
    with pytest.raises(ValueError, match="GM.0,N. has 3 parameters to fit and needs at least 5 samples"):
        gm0n_influence(X[:3], y[:3])
    with pytest.raises(ValueError, match=r"GM\(1,1\) has 2 parameters to fit and needs at least 4 samples"):
        GM11.fit([1.0, 2.0, 3.0])
    with pytest.raises(NotFittedError):
        GM0NRegressor().predict(X)
