"""One-call sensor selection: score, group, keep one representative per group.

``select_sensors(X, y, method=..., n_select=K)`` returns the chosen column
indices of X and their scores. Methods:

=================================  ==========================================================
``"gra"``, ``"similitude"``,        rank all sensors by one score and keep the top K
``"gm0n"``, ``"gm1n"``,
``"sensitivity"``, ``"correlation"``
``"gra+fcm"``                      FCM into K groups; in each, the largest grey relational grade
                                   (thesis Fig 3-1 with GRA)
``"gm-influence+fcm"``             FCM into K groups; in each, the largest GM(0,N) influence
                                   (thesis §4.4, Table 5-4)
``"sensitivity+fuzzy-equivalence"``  keep the more sensitive half (at least K), fuzzy-equivalence
                                   λ-cut into K groups, in each the largest grey grade (seed 002)
``"maximal-tree"``                 maximum spanning tree cut into K groups, in each the sensor
                                   most correlated with y (seed 004)
=================================  ==========================================================

``cluster_on`` chooses what FCM clusters: ``"series"`` (each sensor's
normalised time series) or ``"scores"`` (the sensor's score);
``representative`` overrides the score used inside groups (``"grade"``,
``"correlation"`` or ``"influence"``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import check_positive_int, validate_xy
from .clustering import fcm_sensor_clusters, fuzzy_equivalence_clusters
from .ranking import (
    grey_relational_grade,
    influence_weights,
    similitude_degree,
    target_correlation,
    thermal_error_sensitivity,
)

_SCORES = {
    "gra": grey_relational_grade,
    "grade": grey_relational_grade,
    "similitude": similitude_degree,
    "gm0n": lambda X, y: influence_weights(X, y, "gm0n"),
    "influence": lambda X, y: influence_weights(X, y, "gm0n"),
    "gm1n": lambda X, y: influence_weights(X, y, "gm1n"),
    "sensitivity": thermal_error_sensitivity,
    "correlation": target_correlation,
}
_PIPELINES = {
    "gra+fcm": "grade",
    "gm-influence+fcm": "influence",
    "sensitivity+fuzzy-equivalence": "grade",
    "maximal-tree": "correlation",
}
METHODS = tuple(k for k in _SCORES if k not in ("grade", "influence")) + tuple(_PIPELINES)


@dataclass(frozen=True)
class SensorSelection:
    """Result of :func:`select_sensors`.

    ``indices``: chosen columns of X, best score first; ``scores``: their
    scores; ``groups``: group label of every candidate (-1 = not grouped,
    e.g. dropped by the sensitivity pre-selection; all 0 for plain rankings);
    ``method``: the method name.
    """

    indices: np.ndarray
    scores: np.ndarray
    groups: np.ndarray
    method: str


def representatives(groups: ArrayLike, scores: ArrayLike) -> NDArray[np.intp]:
    """Index of the best-scoring member of each group (groups labelled >= 0).

    Parameters
    ----------
    groups : array_like of int, shape (n_sensors,)
        Group label of each sensor (-1: in no group).
    scores : array_like, shape (n_sensors,)
        Score of each sensor (larger is better).

    Returns
    -------
    ndarray of int, shape (n_groups,)
        One sensor index per group, in the order of the group labels.
    """
    groups = np.asarray(groups)
    scores = np.asarray(scores, dtype=np.float64)
    picks = []
    for g in np.unique(groups[groups >= 0]):
        members = np.flatnonzero(groups == g)
        picks.append(members[np.argmax(scores[members])])
    return np.asarray(picks, dtype=np.intp)


def select_sensors(
    X: ArrayLike,
    y: ArrayLike,
    method: str = "gra+fcm",
    n_select: int = 5,
    *,
    cluster_on: str = "series",
    representative: str | None = None,
    random_state: int | np.random.RandomState | None = None,
) -> SensorSelection:
    """Choose ``n_select`` of the sensors (columns of X) for predicting y.

    See the module docstring for the methods. ``random_state`` seeds FCM.

    Parameters
    ----------
    X : array_like, shape (n_samples, n_sensors)
        Time-ordered candidate sensors (e.g. °C).
    y : array_like, shape (n_samples,)
        The thermal error (e.g. µm).
    method : str, default "gra+fcm"
        One of :data:`METHODS`.
    n_select : int, default 5
        Sensors to choose (K).
    cluster_on : {"series", "scores"}, default "series"
        What FCM clusters.
    representative : str, optional
        Score used inside groups, overriding the method's.
    random_state : int, RandomState or None
        Seeds FCM.

    Returns
    -------
    SensorSelection
        Chosen columns (best first; fewer than ``n_select`` when groups merge), their scores and the groups.
    """
    X, y = validate_xy(X, y, min_samples=3, what="select_sensors")
    n_select = check_positive_int(n_select, "n_select")
    n_sensors = X.shape[1]
    if n_select > n_sensors:
        raise ValueError(f"n_select={n_select} is larger than the {n_sensors} candidate sensors.")
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {METHODS}.")
    if cluster_on not in ("series", "scores"):
        raise ValueError(f"cluster_on must be 'series' or 'scores', got {cluster_on!r}.")

    if method not in _PIPELINES:
        scores = _SCORES[method](X, y)
        order = np.argsort(-scores, kind="stable")[:n_select]
        return SensorSelection(order, scores[order], np.zeros(n_sensors, dtype=np.intp), method)

    criterion = representative or _PIPELINES[method]
    if criterion not in _SCORES:
        raise ValueError(f"unknown representative score {criterion!r}.")
    scores = _SCORES[criterion](X, y)
    groups = np.full(n_sensors, -1, dtype=np.intp)
    if method in ("gra+fcm", "gm-influence+fcm"):
        features = scores[:, None] if cluster_on == "scores" else None
        groups = fcm_sensor_clusters(X, n_select, features=features, random_state=random_state)
    elif method == "sensitivity+fuzzy-equivalence":
        sensitivity = thermal_error_sensitivity(X, y)
        n_keep = max(n_select, int(np.ceil(n_sensors / 2)))
        kept = np.argsort(-sensitivity, kind="stable")[:n_keep]
        groups[kept] = fuzzy_equivalence_clusters(X[:, kept], n_groups=n_select)[0]
    else:  # maximal-tree
        groups = fuzzy_equivalence_clusters(X, n_groups=n_select)[0]
    picks = representatives(groups, scores)
    order = picks[np.argsort(-scores[picks], kind="stable")]
    return SensorSelection(order, scores[order], groups, method)
