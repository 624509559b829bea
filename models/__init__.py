"""Data-driven thermal-error models: array in, array out (no ``fea``/``twin`` imports).

Estimators follow the scikit-learn contract (``fit``/``predict``,
``get_params``/``set_params``, seeded ``random_state``). Grey estimators are
time-series models of zero-referenced series (see :mod:`models.grey`). Every estimator registers
itself once in :mod:`models.registry` (its command-line names, defaults, time-series trait); persistence
and ``twin train`` read that registry.
"""

from .ago_anfis import AGOANFISRegressor
from .anfis import ANFISRegressor
from .fcm import FuzzyCMeans, partition_coefficient, xie_beni_index
from .gmc import GMCRegressor, convolution_response
from .gnnmci import GNNMCIRegressor, network_layers, network_output
from .grey import (
    GM11,
    GM0NRegressor,
    GM1NRegressor,
    ago,
    background_values,
    chronological_prediction,
    gm0n_influence,
    gm1n_influence,
    iago,
)
from .kalman import FilterResult, KalmanFilter, discretize
from .metrics import improvement_percent, max_abs_residual, nse, pearson_r, rmse
from .persistence import load_model, save_model
from .pso import PSOResult, particle_swarm_minimize
from .registry import model_names, model_traits, register_model, registered_models
from .regression import ANNRegressor, MLRRegressor, PCRRegressor, make_ann_pipeline
from .selection import SensorSelection, select_sensors

__all__ = [
    "GM11",
    "AGOANFISRegressor",
    "ANFISRegressor",
    "ANNRegressor",
    "FilterResult",
    "FuzzyCMeans",
    "GM0NRegressor",
    "GM1NRegressor",
    "GMCRegressor",
    "GNNMCIRegressor",
    "KalmanFilter",
    "MLRRegressor",
    "PCRRegressor",
    "PSOResult",
    "SensorSelection",
    "ago",
    "background_values",
    "chronological_prediction",
    "convolution_response",
    "discretize",
    "gm0n_influence",
    "gm1n_influence",
    "iago",
    "improvement_percent",
    "load_model",
    "make_ann_pipeline",
    "max_abs_residual",
    "model_names",
    "model_traits",
    "network_layers",
    "network_output",
    "nse",
    "particle_swarm_minimize",
    "partition_coefficient",
    "pearson_r",
    "register_model",
    "registered_models",
    "rmse",
    "save_model",
    "select_sensors",
    "xie_beni_index",
]
