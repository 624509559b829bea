"""The seed pipelines (GRA+FCM, GM influence+FCM, sensitivity+fuzzy equivalence, maximal tree),
with the sensor grouping computed once per K and shared by several targets."""
from __future__ import annotations

import numpy as np

from .clustering import fcm_sensor_clusters, fuzzy_equivalence_clusters
from .ranking import grey_relational_grade, influence_weights, target_correlation, thermal_error_sensitivity
from .select import representatives

SEED_METHODS = ("gra+fcm", "gm-influence+fcm", "sensitivity+fuzzy-equivalence", "maximal-tree")


class SeedSelector:
    """The seed pipelines of :mod:`models.selection` with the per-K FCM/tree grouping shared across axes.

    Equivalent to ``models.selection.select_sensors(X, y, method, K, random_state=seed)``
    (checked in the tests), but the grouping — which depends on the series,
    not the target — is computed once per K and reused for Z and Y.
    """

    def __init__(self, X, random_state=0):
        self.X = X
        self.random_state = random_state
        self._groups = {}

    def groups(self, kind, k, keep=None):
        key = (kind, k, None if keep is None else keep.tobytes())
        if key not in self._groups:
            if kind == "fcm":
                g = fcm_sensor_clusters(self.X, k, random_state=self.random_state)
            elif keep is None:
                g = np.asarray(fuzzy_equivalence_clusters(self.X, n_groups=k)[0], dtype=np.intp)
            else:                                   # sensors left out of the tree are in no group (-1)
                g = np.full(self.X.shape[1], -1, dtype=np.intp)
                g[keep] = fuzzy_equivalence_clusters(self.X[:, keep], n_groups=k)[0]
            self._groups[key] = g
        return self._groups[key]

    def select(self, method, k, scores):
        """The ``k`` sensors of a seed ``method``, best first; ``scores``: :func:`seed_scores` of X and the target."""
        if method in ("gra+fcm", "gm-influence+fcm"):
            groups = self.groups("fcm", k)
            s = scores["grade"] if method == "gra+fcm" else scores["influence"]
        elif method == "sensitivity+fuzzy-equivalence":
            n = self.X.shape[1]
            keep = np.argsort(-scores["sensitivity"], kind="stable")[:max(k, int(np.ceil(n / 2)))]
            groups = self.groups("tree", k, keep)
            s = scores["grade"]
        elif method == "maximal-tree":
            groups = self.groups("tree", k)
            s = scores["correlation"]
        else:
            raise ValueError(f"unknown seed method {method!r}; seed methods: {SEED_METHODS}")
        picks = representatives(groups, s)
        return picks[np.argsort(-s[picks], kind="stable")]


def seed_scores(X, y):
    """The per-sensor scores the seed pipelines rank by (grade, influence, sensitivity, correlation)."""
    return {"grade": grey_relational_grade(X, y), "influence": influence_weights(X, y, "gm0n"),
            "sensitivity": thermal_error_sensitivity(X, y), "correlation": target_correlation(X, y)}
