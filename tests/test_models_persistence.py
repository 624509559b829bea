"""JSON persistence: exact round trip for every estimator, clear version errors."""

import json

import numpy as np
import pytest

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
    load_model,
    save_model,
)
from models.registry import estimator_classes, registered_models

# the tests train tiny ANNs on purpose
pytestmark = pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")


def data(n=80):
    t = np.arange(n, dtype=float)
    X = np.column_stack([25 + np.sin(t / 9), 24 + t / 50, 26 - np.cos(t / 13)])
    return X, 3 * (X[:, 0] - 25) + (X[:, 1] - 24) ** 2


FITTED = [
    ANFISRegressor(n_rules=3, epochs=5, random_state=0),
    ANFISRegressor(init="grid", n_mfs=2, epochs=3, validation_fraction=0.2, random_state=0),
    AGOANFISRegressor(ANFISRegressor(n_rules=2, epochs=3, random_state=0)),
    ANNRegressor(hidden_layer_sizes=(6, 4), max_iter=100, random_state=0),
    GM0NRegressor(),
    GM1NRegressor(ridge=1e-9),
    GMCRegressor(delay=1),
    GMCRegressor(calibration="pso", n_particles=10, epochs=5, pso_bounds=np.array([[0, 1], [-5, 5], [-5, 5], [-5, 5], [-1, 1]]), init_from_ls=False, random_state=0),
    GNNMCIRegressor(n_particles=8, epochs=4, random_state=0),
    MLRRegressor(standardize=True),
    PCRRegressor(variance_threshold=0.9),
]


def test_every_estimator_is_registered():
    assert {type(e).__name__ for e in FITTED} | {"FuzzyCMeans"} <= set(estimator_classes())
    assert {e.cls.__name__ for e in registered_models().values()} <= set(estimator_classes())


@pytest.mark.parametrize("name", sorted(registered_models()))
def test_every_registered_model_round_trips_with_its_defaults(name, tmp_path):
    """Derived from the registry: a new model is checked here without editing this file."""
    X, y = data()
    estimator = registered_models()[name].make()
    if "epochs" in estimator.get_params(deep=False):
        estimator.set_params(epochs=3)                  # the round trip, not the fit, is under test
    estimator.fit(X, y)
    loaded = load_model(save_model(estimator, tmp_path / "model.json"))
    assert type(loaded) is type(estimator) and repr(loaded) == repr(estimator)
    np.testing.assert_array_equal(loaded.predict(X), estimator.predict(X))


def test_a_name_or_class_registered_twice_is_refused():
    from models.registry import register_model

    with pytest.raises(ValueError, match="registered twice"):
        register_model({"mlr": {}})(type("OtherRegressor", (), {}))
    with pytest.raises(ValueError, match="registered twice"):
        register_model()(type("MLRRegressor", (), {}))


@pytest.mark.parametrize("estimator", FITTED, ids=lambda e: type(e).__name__)
def test_round_trip_reproduces_predictions_exactly(estimator, tmp_path):
    X, y = data()
    estimator.fit(X, y)
    path = save_model(estimator, tmp_path / "model.json")
    loaded = load_model(path)
    assert type(loaded) is type(estimator)
    assert repr(loaded) == repr(estimator)
    assert np.array_equal(loaded.predict(X), estimator.predict(X))
    assert np.array_equal(loaded.predict(X[10:]), estimator.predict(X[10:]))
    assert "pickle" not in path.read_text()


def test_fcm_round_trip(tmp_path):
    X, _ = data()
    fcm = FuzzyCMeans(n_clusters=3, random_state=0).fit(X)
    loaded = load_model(save_model(fcm, tmp_path / "fcm.json"))
    assert np.array_equal(loaded.membership(X), fcm.membership(X))


def test_unfitted_round_trip(tmp_path):
    loaded = load_model(save_model(ANFISRegressor(n_rules=4), tmp_path / "a.json"))
    assert loaded.get_params() == ANFISRegressor(n_rules=4).get_params()


def rewrite(path, **changes):
    document = json.loads(path.read_text())
    document.update(changes)
    path.write_text(json.dumps(document))


def test_incompatible_version_names_file_field_and_value(tmp_path):
    path = save_model(MLRRegressor().fit(*data()), tmp_path / "m.json")
    rewrite(path, version=2)
    with pytest.raises(ValueError, match=r"m\.json: field 'version' has value 2"):
        load_model(path)


def test_unknown_class_and_format(tmp_path):
    path = save_model(MLRRegressor().fit(*data()), tmp_path / "m.json")
    rewrite(path, **{"class": "XGBRegressor"})
    with pytest.raises(ValueError, match=r"field 'class' has value 'XGBRegressor'"):
        load_model(path)
    rewrite(path, format="sklearn-pickle")
    with pytest.raises(ValueError, match=r"field 'format' has value 'sklearn-pickle'"):
        load_model(path)
    path.write_text("not json")
    with pytest.raises(ValueError, match="not a JSON model file"):
        load_model(path)
