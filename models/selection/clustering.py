"""Grouping of candidate sensors: FCM, fuzzy-equivalence λ-cuts and the maximal tree.

Fuzzy equivalence (seed 002) and maximal tree (seed 004) are the same
partition. For a similarity R (here ``|Pearson r|`` between sensors, in
[0, 1]; the sign of a correlation says nothing about redundancy), the max–min
transitive closure ``t(R) = R^(2l)`` has ``t(R)_ij`` = the largest, over all
paths from i to j, of the weakest link on the path. In a maximum spanning
tree (Prim's algorithm) the tree path between i and j is such a best path,
so ``t(R)_ij`` is the weakest edge on it, and the λ-cut of t(R) groups
exactly the sensors joined by tree edges ≥ λ (single linkage). This module
therefore builds the tree in O(n²) instead of iterating O(n³) max–min
products; :func:`max_min_transitive_closure` keeps the explicit iteration as
the reference, and the tests check both agree.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .._validation import check_positive_int, validate_x
from ..fcm import FuzzyCMeans
from ..grey import zero_reference


def similarity_matrix(X: ArrayLike) -> NDArray[np.float64]:
    """``|r_ij|`` between the columns (sensors) of X, (n_sensors, n_sensors), diagonal 1.

    Seed 002 normalises ``c_i = x_i / max|x_i|`` first; Pearson r is
    scale-invariant, so that step does not change R.

    Parameters
    ----------
    X : array_like, shape (n_samples, n_sensors)
        Sensor records (e.g. °C), one column per sensor.

    Returns
    -------
    ndarray, shape (n_sensors, n_sensors)
        R in [0, 1] (0 against a constant sensor).
    """
    X = validate_x(X, what="similarity_matrix")
    Xc = X - X.mean(axis=0)
    norm = np.sqrt(np.sum(Xc * Xc, axis=0))
    Xn = np.divide(Xc, norm, out=np.zeros_like(Xc), where=norm > 0)
    R = np.clip(np.abs(Xn.T @ Xn), 0.0, 1.0)
    np.fill_diagonal(R, 1.0)
    return R


def maximum_spanning_tree(R: ArrayLike) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """Prim's maximum spanning tree of a dense similarity matrix.

    O(n²) time, vectorised over the fringe.

    Parameters
    ----------
    R : array_like, shape (n, n)
        Symmetric similarity.

    Returns
    -------
    edges : ndarray of int, shape (n - 1, 2)
        Tree edges, in the order Prim adds them.
    weights : ndarray, shape (n - 1,)
        Their similarities.
    """
    R = np.asarray(R, dtype=np.float64)
    n = R.shape[0]
    in_tree = np.zeros(n, dtype=bool)
    in_tree[0] = True
    best = R[0].copy()
    parent = np.zeros(n, dtype=np.intp)
    edges = np.empty((n - 1, 2), dtype=np.intp)
    weights = np.empty(n - 1)
    for step in range(n - 1):
        j = int(np.argmax(np.where(in_tree, -np.inf, best)))
        edges[step] = parent[j], j
        weights[step] = best[j]
        in_tree[j] = True
        closer = (R[j] > best) & ~in_tree
        best[closer] = R[j, closer]
        parent[closer] = j
    return edges, weights


def tree_clusters(n: int, edges: ArrayLike, weights: ArrayLike, lam: float) -> NDArray[np.int32]:
    """Labels (n,) of the connected parts left after cutting tree edges with weight < λ.

    Parameters
    ----------
    n : int
        Number of sensors.
    edges : array_like of int, shape (n - 1, 2)
        Tree edges (see :func:`maximum_spanning_tree`).
    weights : array_like, shape (n - 1,)
        Their similarities.
    lam : float
        Threshold λ: edges at or above it are kept.

    Returns
    -------
    ndarray of int, shape (n,)
        Group label of each sensor, 0..n_groups − 1.
    """
    keep = np.asarray(weights) >= lam
    e = np.asarray(edges)[keep]
    graph = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def lambda_for_n_groups(weights: ArrayLike, n_groups: int) -> float:
    """Threshold λ whose cut of the tree (edge ``weights``) gives ``n_groups`` groups.

    Cutting the k weakest of the n - 1 edges leaves k + 1 groups, so λ is the
    ``n_groups``-th smallest weight (ties can merge groups; the caller gets
    fewer then). For ``n_groups = n`` λ is just above the largest weight.

    Parameters
    ----------
    weights : array_like, shape (n - 1,)
        Edge weights of the maximum spanning tree.
    n_groups : int
        Wanted number of groups, 1..n.

    Returns
    -------
    float
        λ.
    """
    w = np.sort(np.asarray(weights, dtype=np.float64))
    n = w.size + 1
    n_groups = check_positive_int(n_groups, "n_groups")
    if n_groups > n:
        raise ValueError(f"cannot make {n_groups} groups from {n} sensors.")
    if n_groups == n:
        return float(np.nextafter(w[-1], np.inf))
    return float(w[n_groups - 1])


def fuzzy_equivalence_clusters(X: ArrayLike, lam: float | None = None,
                               n_groups: int | None = None) -> tuple[NDArray[np.int32], float]:
    """Seed 002 fuzzy clustering: |Pearson| similarity, transitive closure, λ-cut.

    Give either the threshold ``lam`` or the wanted ``n_groups`` (λ is then
    chosen by :func:`lambda_for_n_groups`). Returns ``(labels, lam)``. The
    closure is taken through the maximum spanning tree (module docstring),
    so this is also seed 004's maximal-tree clustering.

    Parameters
    ----------
    X : array_like, shape (n_samples, n_sensors)
        Sensor records, one column per sensor.
    lam : float, optional
        Threshold λ in [0, 1].
    n_groups : int, optional
        Wanted number of groups.

    Returns
    -------
    labels : ndarray of int, shape (n_sensors,)
        Group of each sensor.
    lam : float
        The threshold used.
    """
    if (lam is None) == (n_groups is None):
        raise ValueError("give exactly one of lam or n_groups.")
    R = similarity_matrix(X)
    edges, weights = maximum_spanning_tree(R)
    if lam is None:
        lam = lambda_for_n_groups(weights, n_groups)
    return tree_clusters(R.shape[0], edges, weights, lam), float(lam)


def transitive_closure(R: ArrayLike) -> NDArray[np.float64]:
    """Max–min transitive closure t(R) via the maximum spanning tree, O(n²).

    Tree edges are merged from strongest to weakest (Kruskal order); when two
    groups first join through an edge of weight w, every pair across them
    gets ``t(R) = w``.

    Parameters
    ----------
    R : array_like, shape (n, n)
        Symmetric similarity.

    Returns
    -------
    ndarray, shape (n, n)
        t(R); its diagonal is that of ``R``.
    """
    R = np.asarray(R, dtype=np.float64)
    n = R.shape[0]
    edges, weights = maximum_spanning_tree(R)
    T = np.empty((n, n))
    np.fill_diagonal(T, np.diag(R))
    members = {i: [i] for i in range(n)}
    root = np.arange(n)
    for idx in np.argsort(-weights, kind="stable"):
        a, b = root[edges[idx]]
        ma, mb = members.pop(a), members.pop(b)
        T[np.ix_(ma, mb)] = weights[idx]
        T[np.ix_(mb, ma)] = weights[idx]
        merged = ma + mb
        root[merged] = a
        members[a] = merged
    return T


def max_min_transitive_closure(R: ArrayLike) -> NDArray[np.float64]:
    """Reference closure by repeated max–min squaring, ``R ← R∘R`` until ``R^(2l) = R^(2l+1)``.

    ``(R∘R)_ij = max_k min(R_ik, R_kj)``. O(n³ log n); for small n and tests.

    Parameters
    ----------
    R : array_like, shape (n, n)
        Symmetric similarity with unit diagonal.

    Returns
    -------
    ndarray, shape (n, n)
        t(R).
    """
    R = np.asarray(R, dtype=np.float64)
    while True:
        squared = np.array([np.minimum(row[:, None], R).max(axis=0) for row in R])
        if np.array_equal(squared, R):
            return R
        R = squared


def fcm_sensor_clusters(X: ArrayLike, n_clusters: int, features: ArrayLike | None = None, m: float = 2.0,
                        random_state: int | np.random.RandomState | None = None) -> NDArray[np.intp]:
    """FCM labels (n_sensors,) for the sensors (columns) of X.

    By default each sensor is clustered on its zero-referenced time series
    normalised by its largest change, ``x⁰_i / max|x⁰_i|`` (shape matters,
    not scale; thesis option (a)). Pass ``features`` (n_sensors, n_features),
    e.g. influence weights as a column, to cluster on those instead (option (b)).

    Parameters
    ----------
    X : array_like, shape (n_samples, n_sensors)
        Time-ordered sensor records (e.g. °C).
    n_clusters : int
        Number of groups.
    features : array_like, shape (n_sensors, n_features), optional
        What to cluster the sensors on instead of their normalised series.
    m : float, default 2.0
        FCM fuzziness.
    random_state : int, RandomState or None
        Seeds FCM.

    Returns
    -------
    ndarray of int, shape (n_sensors,)
        Cluster of largest membership of each sensor.
    """
    X = validate_x(X, what="fcm_sensor_clusters")
    if features is None:
        X0 = zero_reference(X)
        peak = np.max(np.abs(X0), axis=0)
        features = np.divide(X0, peak, out=np.zeros_like(X0), where=peak > 0).T
    features = np.asarray(features, dtype=np.float64).reshape(X.shape[1], -1)
    return FuzzyCMeans(n_clusters=n_clusters, m=m, random_state=random_state).fit(features).labels_
