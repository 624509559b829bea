"""Temperature-sensor selection: scores, sensor grouping and one-call pipelines."""

from .clustering import (
    fcm_sensor_clusters,
    fuzzy_equivalence_clusters,
    lambda_for_n_groups,
    max_min_transitive_closure,
    maximum_spanning_tree,
    similarity_matrix,
    transitive_closure,
    tree_clusters,
)
from .ranking import (
    grey_relational_grade,
    influence_weights,
    similitude_degree,
    target_correlation,
    thermal_error_sensitivity,
)
from .forward import greedy_loso
from .modal import pod_modes, qr_drift
from .pipelines import SEED_METHODS, SeedSelector, seed_scores
from .select import METHODS, SensorSelection, representatives, select_sensors

__all__ = [
    "METHODS",
    "SEED_METHODS",
    "SeedSelector",
    "greedy_loso",
    "pod_modes",
    "qr_drift",
    "seed_scores",
    "SensorSelection",
    "fcm_sensor_clusters",
    "fuzzy_equivalence_clusters",
    "grey_relational_grade",
    "influence_weights",
    "lambda_for_n_groups",
    "max_min_transitive_closure",
    "maximum_spanning_tree",
    "representatives",
    "select_sensors",
    "similarity_matrix",
    "similitude_degree",
    "target_correlation",
    "thermal_error_sensitivity",
    "transitive_closure",
    "tree_clusters",
]
