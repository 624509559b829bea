"""scikit-learn conventions: estimator checks, clone/get/set_params, cross-validation."""

import numpy as np
import pytest
from sklearn.base import BaseEstimator, clone
from sklearn.model_selection import TimeSeriesSplit, cross_val_score
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.utils.estimator_checks import parametrize_with_checks

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
)
from models.registry import estimator_classes

# The grey estimators are time-series models of zero-referenced series: a
# prediction depends on where the series starts and on sample order, so the
# checks that shuffle or subsample X cannot hold for them.
TIME_SERIES = {
    "check_methods_sample_order_invariance": "time-series model: output depends on sample order",
    "check_methods_subset_invariance": "time-series model: a subset is a different series",
}
# Every model refuses to fit no more samples than parameters. The checks fit
# 10-40 samples of up to 10 features, so ANFIS runs with one rule (3 d + 1
# parameters) and the ANN with one hidden unit (d + 3 weights); these two
# checks fit 10 samples of 3 features, no more than ANFIS's 10 parameters.
TOO_FEW_SAMPLES = {
    "check_estimators_nan_inf": "fits 10 samples, no more than ANFIS's 10 parameters",
    "check_regressors_no_decision_function": "fits 10 samples, no more than ANFIS's 10 parameters",
}
EXPECTED = {
    "ANFISRegressor": TOO_FEW_SAMPLES,
    "AGOANFISRegressor": {**TIME_SERIES, **TOO_FEW_SAMPLES},
    "ANNRegressor": {
        "check_estimators_nan_inf": "fits 10 samples; early stopping needs 20",
        "check_regressors_no_decision_function": "fits 10 samples; early stopping needs 20",
        "check_fit2d_1feature": "fits 10 samples; early stopping needs 20",
        "check_n_features_in_after_fitting": "fits 15 samples; early stopping needs 20",
        "check_regressors_train": "one hidden unit scores R² < 0.5 (accuracy: test_models_regression)",
    },
    "GM0NRegressor": TIME_SERIES,
    "GM1NRegressor": TIME_SERIES,
    "GMCRegressor": TIME_SERIES,
    "GNNMCIRegressor": TIME_SERIES,
}

ESTIMATORS = [
    FuzzyCMeans(random_state=0),
    ANFISRegressor(n_rules=1, epochs=5, random_state=0),
    MLRRegressor(),
    PCRRegressor(),
    ANNRegressor(hidden_layer_sizes=(1,), max_iter=200, random_state=0),
    GM0NRegressor(),
    GM1NRegressor(),
    GMCRegressor(),
    GMCRegressor(calibration="pso", n_particles=10, epochs=5, random_state=0),
    GNNMCIRegressor(n_particles=10, epochs=5, random_state=0),
    AGOANFISRegressor(ANFISRegressor(n_rules=1, epochs=2, random_state=0)),
]

#: Registered estimators the generic checks cannot drive, each with why and where its conventions are tested.
CHECKED_ELSEWHERE = {
    "GreyBoxRegressor": "X's first column is time and must increase, which the checks' random X break; clone, "
                        "params, persistence and fitting are tested in test_models_greybox.py",
}

# the tests train tiny ANNs on purpose
pytestmark = pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")


@parametrize_with_checks(ESTIMATORS, expected_failed_checks=lambda est: EXPECTED.get(type(est).__name__, {}))
def test_sklearn_estimator_checks(estimator, check):
    # some checks draw from numpy's global RNG (check_methods_sample_order_invariance permutes the rows with
    # it): unseeded, an expected failure passed in about 1 run of 20 (AGO-ANFIS with one rule is order-invariant
    # except at the first row, so a permutation that keeps row 0 in place passes)
    np.random.seed(0)
    check(estimator)


def test_every_registered_estimator_is_checked():
    """A model registers itself once (models.registry); it must then be checked here or say why not."""
    checked = {type(e).__name__ for e in ESTIMATORS}
    assert not checked & set(CHECKED_ELSEWHERE)
    assert set(estimator_classes()) == checked | set(CHECKED_ELSEWHERE)


@pytest.mark.parametrize("estimator", ESTIMATORS, ids=lambda e: type(e).__name__)
def test_clone_and_params(estimator):
    plain = lambda e: {k: v for k, v in e.get_params().items() if not isinstance(v, BaseEstimator)}
    twin = clone(estimator)
    assert plain(twin) == plain(estimator) and repr(twin) == repr(estimator)
    key = next(iter(estimator.get_params(deep=False)))
    value = estimator.get_params()[key]
    assert clone(estimator).set_params(**{key: value}).get_params()[key] == value


def drift_data(n=240, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n)
    X = np.column_stack([25 + 3 * np.sin(t / 30), 24 + t / 60, 26 + np.cos(t / 17)])
    y = 4 * (X[:, 0] - 25) - 2 * (X[:, 1] - 24) ** 2 + 0.1 * rng.standard_normal(n)
    return X, y


@pytest.mark.parametrize(
    "estimator",
    [ANFISRegressor(n_rules=3, epochs=10, random_state=0), MLRRegressor(), PCRRegressor(variance_threshold=0.99)],
    ids=["ANFIS", "MLR", "PCR"],
)
def test_cross_val_score_with_time_series_split(estimator):
    X, y = drift_data()
    scores = cross_val_score(estimator, X, y, cv=TimeSeriesSplit(n_splits=3), scoring="neg_root_mean_squared_error")
    assert scores.shape == (3,) and np.all(np.isfinite(scores))
    again = cross_val_score(clone(estimator), X, y, cv=TimeSeriesSplit(n_splits=3), scoring="neg_root_mean_squared_error")
    assert np.array_equal(scores, again)  # seeded ⇒ identical


def test_anfis_in_a_pipeline_and_grid_of_params():
    X, y = drift_data()
    pipe = make_pipeline(StandardScaler(), ANFISRegressor(n_rules=2, epochs=5, random_state=0))
    pipe.set_params(anfisregressor__n_rules=3).fit(X, y)
    assert pipe[-1].consequents_.shape == (3, 4)
