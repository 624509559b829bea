"""Fuzzy c-means clustering (Bezdek 1981; thesis §3.3.2.1, Eqs 3.7–3.9).

Membership of sample j in cluster i, with fuzziness m > 1:

    μ_ij = 1 / Σ_k (d_ij / d_kj)^(2/(m-1)),     d_ij = ‖x_j - c_i‖

centres ``c_i = Σ_j μ_ij^m x_j / Σ_j μ_ij^m`` and objective
``J = Σ_i Σ_j μ_ij^m d_ij²``. Iteration stops when the relative decrease of J
falls below ``tol`` (thesis: "improvement below a tolerance").

Two validity indices help choose the number of clusters c:
``partition_coefficient`` (1/c … 1, larger is crisper) and
``xie_beni_index`` (compactness / separation, smaller is better).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.base import BaseEstimator, ClusterMixin
from sklearn.utils import check_random_state
from sklearn.utils.validation import check_is_fitted

from ._threads import one_blas_thread
from ._validation import check_n_features, check_positive_int, validate_x
from .registry import register_model


def squared_distances(X: np.ndarray, centers: np.ndarray) -> np.ndarray:
    """Squared Euclidean distances, shape (n_samples, n_clusters), never negative.

    Parameters
    ----------
    X : ndarray, shape (n_samples, n_features)
        Samples.
    centers : ndarray, shape (n_clusters, n_features)
        Cluster centres, in the units of ``X``.

    Returns
    -------
    ndarray, shape (n_samples, n_clusters)
        ``‖x_j − c_i‖²``, in the squared units of ``X`` (rounding below 0 clipped to 0).
    """
    d2 = (
        np.einsum("ij,ij->i", X, X)[:, None]
        - 2.0 * X @ centers.T
        + np.einsum("ij,ij->i", centers, centers)[None, :]
    )
    return np.maximum(d2, 0.0)


def fcm_membership(d2: np.ndarray, m: float) -> np.ndarray:
    """Memberships (n_samples, n_clusters) from squared distances (Eq 3.7).

    Computed in log-space, ``μ ∝ d²^(-1/(m-1))`` normalised per row with a
    max-shift, so a sample lying exactly on a centre gets membership 1 there
    instead of a 0/0.

    Parameters
    ----------
    d2 : ndarray, shape (n_samples, n_clusters)
        Squared distances (see :func:`squared_distances`).
    m : float
        Fuzziness exponent (> 1).

    Returns
    -------
    ndarray, shape (n_samples, n_clusters)
        Memberships μ, each row summing to 1.
    """
    log_w = -np.log(np.maximum(d2, np.finfo(np.float64).tiny)) / (m - 1.0)
    log_w -= log_w.max(axis=1, keepdims=True)
    w = np.exp(log_w)
    return w / w.sum(axis=1, keepdims=True)


def partition_coefficient(membership: np.ndarray) -> float:
    """Bezdek's partition coefficient ``PC = Σ_ij μ_ij² / n`` (1/c ≤ PC ≤ 1).

    Parameters
    ----------
    membership : ndarray, shape (n_samples, n_clusters)
        Memberships μ (rows sum to 1).

    Returns
    -------
    float
        PC; larger is crisper.
    """
    membership = np.asarray(membership, dtype=np.float64)
    return float(np.sum(membership**2) / membership.shape[0])


def xie_beni_index(X: ArrayLike, membership: ArrayLike, centers: ArrayLike, m: float = 2.0) -> float:
    """Xie–Beni index ``Σ μ^m d² / (n · min_{i≠k} ‖c_i - c_k‖²)``; smaller is better.

    Undefined (NaN) for a single cluster; infinite if two centres coincide.

    Parameters
    ----------
    X : array_like, shape (n_samples, n_features)
        Samples.
    membership : array_like, shape (n_samples, n_clusters)
        Memberships μ.
    centers : array_like, shape (n_clusters, n_features)
        Cluster centres, in the units of ``X``.
    m : float, default 2.0
        Fuzziness exponent.

    Returns
    -------
    float
        The index (dimensionless), NaN or inf in the cases above.
    """
    X = np.asarray(X, dtype=np.float64)
    centers = np.asarray(centers, dtype=np.float64)
    if centers.shape[0] < 2:
        return float("nan")
    compactness = np.sum(np.asarray(membership) ** m * squared_distances(X, centers))
    sep = squared_distances(centers, centers)
    np.fill_diagonal(sep, np.inf)
    min_sep = sep.min()
    if min_sep == 0.0:
        return float("inf")
    return float(compactness / (X.shape[0] * min_sep))


@register_model()
class FuzzyCMeans(ClusterMixin, BaseEstimator):
    """Fuzzy c-means clustering with seeded initialisation.

    Parameters
    ----------
    n_clusters : int, default 3
        Number of clusters c (must not exceed the number of samples).
    m : float, default 2.0
        Fuzziness exponent (> 1); 2 is the genfis3/MATLAB default.
    tol : float, default 1e-5
        Stop when ``(J_prev - J) / J_prev < tol``.
    max_iter : int, default 100
    random_state : int, RandomState or None
        Seeds the choice of the initial centres among the samples.

    Attributes
    ----------
    cluster_centers_ : (n_clusters, n_features)
    membership_ : (n_samples, n_clusters) training memberships μ_ji
    labels_ : (n_samples,) cluster of largest membership
    objective_ : final J
    n_iter_ : iterations run
    partition_coefficient_, xie_beni_index_ : validity indices of the fit
    """

    def __init__(self, n_clusters: int = 3, m: float = 2.0, tol: float = 1e-5, max_iter: int = 100,
                 random_state: int | np.random.RandomState | None = None):
        self.n_clusters = n_clusters
        self.m = m
        self.tol = tol
        self.max_iter = max_iter
        self.random_state = random_state

    @one_blas_thread
    def fit(self, X: ArrayLike, y: object = None) -> FuzzyCMeans:
        """Cluster the rows of ``X`` (n_samples, n_features).

        Parameters
        ----------
        X : array_like, shape (n_samples, n_features)
            Samples, in any units (distances are Euclidean in them).
        y : ignored
            Present for the scikit-learn API.

        Returns
        -------
        FuzzyCMeans
            ``self``, fitted.
        """
        X = validate_x(X, what="FuzzyCMeans")
        c = check_positive_int(self.n_clusters, "n_clusters")
        if c > X.shape[0]:
            raise ValueError(
                f"n_clusters={c} is larger than the number of samples ({X.shape[0]})."
            )
        if not self.m > 1.0:
            raise ValueError(f"fuzziness m must be > 1, got {self.m!r}.")
        rng = check_random_state(self.random_state)
        centers = X[rng.choice(X.shape[0], size=c, replace=False)].copy()
        objective = np.inf
        for n_iter in range(1, check_positive_int(self.max_iter, "max_iter") + 1):
            membership = fcm_membership(squared_distances(X, centers), self.m)
            um = membership**self.m
            centers = (um.T @ X) / um.sum(axis=0)[:, None]
            new_objective = float(np.sum(um * squared_distances(X, centers)))
            converged = objective - new_objective < self.tol * max(new_objective, 1e-300)
            objective = new_objective
            if converged:
                break
        self.cluster_centers_ = centers
        self.membership_ = fcm_membership(squared_distances(X, centers), self.m)
        self.labels_ = self.membership_.argmax(axis=1)
        self.objective_ = objective
        self.n_iter_ = n_iter
        self.partition_coefficient_ = partition_coefficient(self.membership_)
        self.xie_beni_index_ = xie_beni_index(X, self.membership_, centers, self.m)
        self.n_features_in_ = X.shape[1]
        return self

    def membership(self, X: ArrayLike) -> NDArray[np.float64]:
        """Memberships of new samples in the fitted clusters, (n_samples, n_clusters).

        Parameters
        ----------
        X : array_like, shape (n_samples, n_features)
            Samples, in the units of the training data.

        Returns
        -------
        ndarray, shape (n_samples, n_clusters)
            Memberships μ, each row summing to 1.
        """
        check_is_fitted(self, "cluster_centers_")
        X = validate_x(X, what="FuzzyCMeans")
        check_n_features(self, X)
        return fcm_membership(squared_distances(X, self.cluster_centers_), self.m)

    def predict(self, X: ArrayLike) -> NDArray[np.intp]:
        """Cluster of largest membership for each row of ``X``.

        Parameters
        ----------
        X : array_like, shape (n_samples, n_features)
            Samples, in the units of the training data.

        Returns
        -------
        ndarray of int, shape (n_samples,)
            Cluster indices.
        """
        return self.membership(X).argmax(axis=1)
