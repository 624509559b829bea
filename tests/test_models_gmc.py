"""GMC(1,N) and GNNMCI(1,N): discretisations, coefficient recovery by LS and PSO."""

import numpy as np
import pytest

from models.gmc import GMCRegressor, convolution_response, deaccumulated_response
from models.gnnmci import GNNMCIRegressor, network_layers, network_output
from models.grey import ago


def test_trapezoid_response_equals_eq_3_14_sum():
    rng = np.random.default_rng(0)
    f = rng.standard_normal(12)
    b1 = 0.3
    S = convolution_response(f, b1)
    # Eq 3.14 (corrected): ½e^{-b1(t-1)}f(1) + Σ_{τ=2}^{t-1} e^{-b1(t-τ)}f(τ) + ½f(t), t = 1-based
    for t in range(2, 13):
        direct = 0.5 * np.exp(-b1 * (t - 1)) * f[0]
        direct += sum(np.exp(-b1 * (t - tau)) * f[tau - 1] for tau in range(2, t))
        direct += 0.5 * f[t - 1]
        assert S[t - 1] == pytest.approx(direct, rel=1e-12)
    assert S[0] == 0.0


def test_midpoint_response_equals_tien_eq_a2_sum():
    rng = np.random.default_rng(1)
    f = rng.standard_normal((10, 2))
    b1 = 0.2
    S = convolution_response(f, b1, "midpoint")
    # Σ_{τ=2}^{t} e^{-b1(t-τ+½)} · ½[f(τ) + f(τ-1)]
    for t in range(2, 11):
        direct = sum(np.exp(-b1 * (t - tau + 0.5)) * 0.5 * (f[tau - 1] + f[tau - 2]) for tau in range(2, t + 1))
        assert np.allclose(S[t - 1], direct, rtol=1e-12)


def synthetic(n=150, delay=0):
    t = np.arange(n + delay)
    X = np.column_stack([20 + 5 * (1 - np.exp(-t / 30)), 22 + np.sin(t / 20)])
    b1, b, u = 0.1, np.array([0.8, -0.3]), 0.05
    y = np.zeros(n + delay)
    y[delay:] = deaccumulated_response(ago(X - X[0])[: n] @ b + u, b1)
    return X, y + 1.0, (b1, b, u)


def test_gmc_least_squares_recovers_whitening_coefficients():
    X, y, (b1, b, u) = synthetic()
    model = GMCRegressor(calibration="ls").fit(X, y)
    # Tien's LS form (trapezoid on the ODE) and the trapezoid convolution are two
    # O(h²) discretisations; their small mismatch lands mostly on the small u
    assert model.development_coefficient_ == pytest.approx(b1, rel=0.01)
    assert np.allclose(model.coef_, b, rtol=0.01)
    assert model.control_ == pytest.approx(u, abs=0.02)


def test_gmc_pso_recovers_whitening_coefficients_without_ls_start():
    X, y, (b1, b, u) = synthetic()
    box = [[0.0, 0.5], [-2.0, 2.0], [-2.0, 2.0], [-0.5, 0.5]]
    model = GMCRegressor(calibration="pso", pso_bounds=box, init_from_ls=False, epochs=400, random_state=1)
    model.fit(X, y)
    assert model.development_coefficient_ == pytest.approx(b1, rel=0.01)
    assert np.allclose(model.coef_, b, rtol=0.01)
    assert model.control_ == pytest.approx(u, abs=0.002)
    assert np.allclose(model.predict(X), y, atol=1e-3)


def test_gmc_pso_from_ls_start_is_at_least_as_good_as_ls():
    X, y, _ = synthetic()
    ls = GMCRegressor().fit(X, y)
    pso = GMCRegressor(calibration="pso", epochs=30, random_state=0).fit(X, y)
    sse = lambda m: np.sum((m.predict(X) - y) ** 2)
    assert sse(pso) <= sse(ls)


def test_gmc_delay():
    X, y, (b1, b, _) = synthetic(delay=3)
    model = GMCRegressor(delay=3).fit(X, y)
    assert np.allclose(model.coef_, b, rtol=0.02)
    assert np.all(model.predict(X)[:3] == model.y_reference_)


def test_gnnmci_layers_reduce_to_eq_a4():
    rng = np.random.default_rng(2)
    X1 = ago(rng.standard_normal((20, 3)))
    w = np.array([0.15, -0.4, 0.5, -1.0, 2.0, 0.3])
    layers = network_layers(w, X1)
    assert np.allclose(layers["b"] * (1 + np.exp(-layers["a"])), 1.0)  # b · w₃ = 1
    assert np.allclose(layers["d"], network_output(w, X1), atol=1e-12)
    # Eq A.4 with x₁¹(1) = -w₂₁: x₁¹(1) e^{-w₁₁k} + G
    G = convolution_response(X1 @ w[2:5] + w[5], w[0], "midpoint")
    assert np.allclose(layers["d"], 0.4 * np.exp(-0.15 * np.arange(20)) + G)


def test_gnnmci_pso_recovers_weights_and_is_seeded():
    n = 120
    t = np.arange(n)
    X = np.column_stack([5 * (1 - np.exp(-t / 25)), np.sin(t / 15)])
    w_true = np.array([0.12, 0.0, 0.6, -0.4, 0.03])
    y = np.diff(network_output(w_true, ago(X - X[0])), prepend=0.0)
    box = [[0.0, 0.4], [-0.1, 0.1], [-2, 2], [-2, 2], [-0.2, 0.2]]
    fit = lambda seed: GNNMCIRegressor(pso_bounds=box, init_from_ls=False, epochs=250, random_state=seed).fit(X, y)
    model = fit(0)
    assert np.allclose(model.weights_[[0, 2, 3]], w_true[[0, 2, 3]], rtol=0.02)
    assert np.allclose(model.predict(X), y, atol=2e-3)
    assert np.array_equal(fit(0).weights_, model.weights_)


def test_gmc_errors():
    X, y, _ = synthetic(n=20)
    with pytest.raises(ValueError, match="calibration must be"):
        GMCRegressor(calibration="ga").fit(X, y)
    with pytest.raises(ValueError, match=r"GMCRegressor has 4 parameters to fit and needs at least 6 samples"):
        GMCRegressor().fit(X[:5], y[:5])
    with pytest.raises(ValueError, match="w11 >= 0"):
        GNNMCIRegressor(pso_bounds=[[-1, 1]] * 5).fit(X, y)
