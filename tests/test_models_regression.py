"""ANN, MLR, PCR wrappers and AGO-ANFIS against analytic references."""

import numpy as np
import pytest

from models.ago_anfis import AGOANFISRegressor
from models.anfis import ANFISRegressor
from models.regression import ANNRegressor, MLRRegressor, PCRRegressor, make_ann_pipeline


def test_mlr_exact_on_linear_data_with_and_without_standardisation():
    rng = np.random.default_rng(0)
    X = rng.normal(25, 3, (50, 3))
    y = X @ np.array([2.0, -1.0, 0.5]) + 4.0
    for standardize in (False, True):
        model = MLRRegressor(standardize=standardize).fit(X, y)
        assert np.allclose(model.coef_, [2.0, -1.0, 0.5])
        assert model.intercept_ == pytest.approx(4.0)
        assert np.allclose(model.standardized_coef_, model.coef_ * X.std(axis=0))


def test_pcr_keeps_components_up_to_variance_threshold():
    rng = np.random.default_rng(1)
    t = rng.standard_normal(400)
    # three standardised columns: two copies of one latent factor plus an independent one.
    # Correlation eigenvalues ≈ (2, 1, 0): PC1 explains ≈ 2/3, PC1+PC2 ≈ 1.
    X = np.column_stack([t, t + 1e-3 * rng.standard_normal(400), rng.standard_normal(400)])
    y = 3.0 * t + 1.0
    one = PCRRegressor(variance_threshold=0.6).fit(X, y)
    two = PCRRegressor(variance_threshold=0.85).fit(X, y)
    assert one.n_components_ == 1 and two.n_components_ == 2
    assert one.explained_variance_ratio_[0] == pytest.approx(2 / 3, abs=0.02)
    assert np.allclose(two.predict(X), y, atol=1e-2)
    assert PCRRegressor(n_components=3).fit(X, y).n_components_ == 3


def test_ann_default_architecture_and_seed():
    rng = np.random.default_rng(2)
    X = rng.uniform(-1, 1, (1000, 26))
    y = np.tanh(X[:, 0] + 0.5 * X[:, 1])
    a = ANNRegressor(random_state=0).fit(X, y)
    assert [w.shape for w in a.coefs_] == [(26, 10), (10, 1)]  # 26-10-1
    assert np.sqrt(np.mean((a.predict(X) - y) ** 2)) < 0.1 * y.std()
    b = ANNRegressor(random_state=0).fit(X, y)
    assert np.array_equal(a.predict(X), b.predict(X))
    # the stored arrays reproduce the scikit-learn pipeline the wrapper trained
    pipeline = make_ann_pipeline(random_state=0).fit(X, (y - y.mean()) / y.std())
    assert pipeline[-1].activation == "tanh" and pipeline[-1].early_stopping
    assert np.allclose(a.predict(X), pipeline.predict(X) * y.std() + y.mean(), atol=1e-12)


def test_ago_anfis_reproduces_a_linear_grey_series():
    # If y⁰ is linear in X⁰, then y¹ is linear in X¹: every ANFIS consequent can match it
    # exactly, and IAGO restores y exactly — also beyond the training range.
    t = np.arange(80.0)
    X = np.column_stack([20 + np.sin(t / 9), 21 + t / 40])
    y = (X - X[0]) @ np.array([1.5, -2.0]) + 0.7
    model = AGOANFISRegressor(ANFISRegressor(n_rules=2, epochs=5, random_state=0)).fit(X[:50], y[:50])
    assert np.allclose(model.predict(X), y, atol=1e-4)  # limited by the LSE ridge
    assert model.get_params()["anfis__n_rules"] == 2
