"""The seed pipelines (GRA+FCM, GM influence+FCM, sensitivity+fuzzy equivalence, maximal tree),
with the sensor grouping computed once per K and shared by several targets."""
from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .clustering import fcm_sensor_clusters, fuzzy_equivalence_clusters
from .ranking import grey_relational_grade, influence_weights, target_correlation, thermal_error_sensitivity
from .select import representatives

SEED_METHODS = ("gra+fcm", "gm-influence+fcm", "sensitivity+fuzzy-equivalence", "maximal-tree")


class SeedSelector:
    """The seed pipelines of :mod:`models.selection` with the per-K FCM/tree grouping shared across axes.

    Equivalent to ``models.selection.select_sensors(X, y, method, K, random_state=seed)``
    (checked in the tests), but the grouping — which depends on the series,
    not the target — is computed once per K and reused for Z and Y.

    Parameters
    ----------
    X : ndarray, shape (n_samples, n_sensors)
        Time-ordered candidate records (e.g. °C), one column per sensor.
    random_state : int, RandomState or None, default 0
        Seeds FCM.
    """

    def __init__(self, X: NDArray[np.float64], random_state: int | np.random.RandomState | None = 0):
        self.X = X
        self.random_state = random_state
        self._groups = {}

    def groups(self, kind: Literal["fcm", "tree"], k: int, keep: NDArray[np.intp] | None = None) -> NDArray[np.intp]:
        """Group label of every candidate for ``k`` groups, computed once per (kind, k, keep).

        Parameters
        ----------
        kind : {"fcm", "tree"}
            FCM on the normalised series, or the maximal-tree (fuzzy-equivalence) cut.
        k : int
            Number of groups.
        keep : ndarray of int, optional
            ``"tree"`` only: the candidates that take part; the others get label -1.

        Returns
        -------
        ndarray of int, shape (n_sensors,)
            Group labels (-1: in no group).
        """
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

    def select(self, method: str, k: int, scores: dict[str, NDArray[np.float64]]) -> NDArray[np.intp]:
        """The ``k`` sensors of a seed ``method``, best first; ``scores``: :func:`seed_scores` of X and the target.

        Parameters
        ----------
        method : str
            One of :data:`SEED_METHODS`.
        k : int
            Sensors to choose.
        scores : dict of str to ndarray
            :func:`seed_scores` of X and the target.

        Returns
        -------
        ndarray of int
            Chosen columns of X, best score first (fewer than ``k`` when groups merge).
        """
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


def seed_scores(X: ArrayLike, y: ArrayLike) -> dict[str, NDArray[np.float64]]:
    """The per-sensor scores the seed pipelines rank by (grade, influence, sensitivity, correlation).

    Parameters
    ----------
    X : array_like, shape (n_samples, n_sensors)
        Time-ordered candidate records (e.g. °C).
    y : array_like, shape (n_samples,)
        The thermal error (e.g. µm).

    Returns
    -------
    dict of str to ndarray
        ``grade``, ``influence`` (GM(0,N)), ``sensitivity``, ``correlation``: one score per sensor.
    """
    return {"grade": grey_relational_grade(X, y), "influence": influence_weights(X, y, "gm0n"),
            "sensitivity": thermal_error_sensitivity(X, y), "correlation": target_correlation(X, y)}
