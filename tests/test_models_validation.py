"""Bad input gives clear errors: shapes, NaN, too few samples, unfitted models."""

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError

from models import (
    AGOANFISRegressor,
    ANFISRegressor,
    ANNRegressor,
    FuzzyCMeans,
    GM0NRegressor,
    GM1NRegressor,
    GMCRegressor,
    GNNMCIRegressor,
    MLRRegressor,
    PCRRegressor,
    select_sensors,
)

REGRESSORS = [
    ANFISRegressor(n_rules=2, epochs=2, random_state=0),
    AGOANFISRegressor(ANFISRegressor(n_rules=2, epochs=2, random_state=0)),
    ANNRegressor(hidden_layer_sizes=(3,), max_iter=50, random_state=0),
    GM0NRegressor(),
    GM1NRegressor(),
    GMCRegressor(),
    GNNMCIRegressor(n_particles=5, epochs=2, random_state=0),
    MLRRegressor(),
    PCRRegressor(),
]
ids = [type(e).__name__ for e in REGRESSORS]

# the tests train tiny ANNs on purpose
pytestmark = pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")


def data(n=40, d=3):
    t = np.arange(n, dtype=float)
    X = np.column_stack([np.sin(t / (5 + j)) + j for j in range(d)])
    return X, X.sum(axis=1) + 0.01 * t


@pytest.mark.parametrize("estimator", REGRESSORS, ids=ids)
def test_mismatched_lengths(estimator):
    X, y = data()
    with pytest.raises(ValueError, match="inconsistent numbers of samples"):
        estimator.fit(X, y[:-1])


@pytest.mark.parametrize("estimator", REGRESSORS, ids=ids)
def test_nan_in_x_and_y(estimator):
    X, y = data()
    Xn = X.copy()
    Xn[3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        estimator.fit(Xn, y)
    yn = y.copy()
    yn[5] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        estimator.fit(X, yn)


@pytest.mark.parametrize("estimator", REGRESSORS, ids=ids)
def test_unfitted_predict(estimator):
    with pytest.raises(NotFittedError):
        estimator.predict(data()[0])


@pytest.mark.parametrize("estimator", REGRESSORS, ids=ids)
def test_wrong_width_at_predict(estimator):
    X, y = data()
    estimator.fit(X, y)
    with pytest.raises(ValueError, match="X has 2 features, but .* is expecting 3"):
        estimator.predict(X[:, :2])


@pytest.mark.parametrize(
    ("estimator", "n_parameters", "n_ok"),
    [
        (MLRRegressor(), 4, 5),  # 3 coefficients + intercept
        (PCRRegressor(n_components=2), 3, 4),
        (ANNRegressor(hidden_layer_sizes=(4,), max_iter=5, random_state=0), 21, 25),  # 3-4-1; 10 % split held out
        (ANFISRegressor(n_rules=2, epochs=2, random_state=0), 20, 21),  # 2 × 4 consequents + 2 × 3 × (c, σ)
        (AGOANFISRegressor(ANFISRegressor(n_rules=2, epochs=2, random_state=0)), 20, 21),
        (GM0NRegressor(), 3, 5),  # grey: the first sample gives no equation
        (GM1NRegressor(), 4, 6),
        (GMCRegressor(), 5, 7),
        (GMCRegressor(delay=2), 5, 9),
        (GNNMCIRegressor(n_particles=5, epochs=2, random_state=0), 6, 8),
    ],
    ids=["MLR", "PCR", "ANN", "ANFIS", "AGO-ANFIS", "GM0N", "GM1N", "GMC", "GMC-delay2", "GNNMCI"],
)
def test_every_model_needs_more_equations_than_parameters(estimator, n_parameters, n_ok):
    # with as many equations as unknowns the fit is exact: "RMSE 1e-16, 100 %" on any data
    X, y = data(d=3)
    with pytest.raises(ValueError, match=f"has {n_parameters} parameters to fit and needs at least {n_ok} samples"):
        estimator.fit(X[: n_ok - 1], y[: n_ok - 1])
    estimator.fit(X[:n_ok], y[:n_ok])


def test_mlr_on_as_many_inputs_as_rows_is_refused():
    # 3 rows × 3 inputs, and 10 rows × 16 inputs: before, exact fits with training RMSE ~1e-16
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="4 parameters to fit and needs at least 5 samples, got 3 samples"):
        MLRRegressor().fit(rng.random((3, 3)), rng.random(3))
    with pytest.raises(ValueError, match="17 parameters to fit and needs at least 18 samples, got 10 samples"):
        MLRRegressor().fit(rng.random((10, 16)), rng.random(10))


def test_clusters_larger_than_samples():
    X, _ = data(n=4)
    with pytest.raises(ValueError, match="n_clusters=5 is larger than the number of samples"):
        FuzzyCMeans(n_clusters=5).fit(X)
    # ANFIS-FCM has (n_features + 1) consequents and 2 n_features premises per rule, so it refuses earlier
    with pytest.raises(ValueError, match="20 parameters to fit and needs at least 21 samples, got 4"):
        ANFISRegressor(n_rules=5, epochs=1).fit(X[:, :1], np.arange(4.0))


def test_selection_input_errors():
    X, y = data()
    with pytest.raises(ValueError, match="NaN"):
        select_sensors(np.where(X > 2.5, np.nan, X), y)
    with pytest.raises(ValueError, match="inconsistent numbers of samples"):
        select_sensors(X, y[:-2])
