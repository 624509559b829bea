"""Sensor selection from the snapshot matrix: POD modes and QR-pivoted (Q-DEIM) choice of sensors."""
from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def pod_modes(X: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """POD of the centred snapshot matrix X (n, p): (U, σ, Vᵀ), thin SVD (computed once, shared by axes and K).

    Parameters
    ----------
    X : ndarray, shape (n, p)
        Snapshots (rows: times; columns: candidate sensors, e.g. °C).

    Returns
    -------
    U : ndarray, shape (n, r)
        Temporal modes, r = min(n, p).
    s : ndarray, shape (r,)
        Singular values, descending (unit of X).
    Vt : ndarray, shape (r, p)
        Spatial loadings.
    """
    import scipy.linalg as la

    Xc = X - X.mean(axis=0)
    return la.svd(Xc, full_matrices=False, lapack_driver="gesdd", check_finite=False)


def qr_drift(X: NDArray[np.float64], y: NDArray[np.float64], k: int, n_modes: int = 20, noise_floor: float = 1e-3,
             pod: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]] | None = None
             ) -> tuple[NDArray[np.int_], NDArray[np.float64]]:
    """Q-DEIM (QR with column pivoting) on the drift-relevant POD modes of the snapshot matrix X (n, p).

    POD of the centred snapshots, X = U Σ Vᵀ, keeping modes above ``noise_floor`` of σ₁ (at most
    ``n_modes``); the drift's weight on mode i is |uᵢᵀ y| (its share of the drift signal).  The
    ``k`` modes of largest weight are the drift-relevant subspace; pivoted QR on their loadings
    Vᵀ (k × p) picks the ``k`` sensors from which those modal coordinates are best determined
    (well-conditioned Vᵀ[:, S]).  Returns the sensors (pivot order) and every candidate's
    drift-weighted loading norm.  ``pod``: the result of :func:`pod_modes` of X, when already known.

    Parameters
    ----------
    X : ndarray, shape (n, p)
        Snapshots of the candidates (e.g. °C).
    y : ndarray, shape (n,)
        The drift (e.g. µm).
    k : int
        Sensors to choose.
    n_modes : int, default 20
        Most POD modes considered.
    noise_floor : float, default 1e-3
        Modes with σ below this fraction of σ₁ are dropped.
    pod : tuple, optional
        ``pod_modes(X)``, when already computed.

    Returns
    -------
    sensors : ndarray of int, shape (k,)
        Chosen candidate columns, in pivot order.
    score : ndarray, shape (p,)
        Drift-weighted loading norm of every candidate (dimensionless).
    """
    from scipy.linalg import qr

    U, s, Vt = pod_modes(X) if pod is None else pod
    m = int(min(n_modes, np.sum(s > noise_floor * s[0])))
    yc = y - y.mean()
    weight = np.abs(U[:, :m].T @ yc) / max(np.linalg.norm(yc), 1e-300)
    modes = np.sort(np.argsort(-weight)[: min(k, m)])
    _, _, piv = qr(Vt[modes], pivoting=True, mode="economic")
    order = [int(c) for c in piv[: len(modes)]]
    score = np.linalg.norm(weight[:, None] * Vt[:m], axis=0)
    if len(order) < k:                                  # more sensors than modes: add by drift-weighted loading
        order += [int(c) for c in np.argsort(-score) if c not in order][: k - len(order)]
    return np.array(order, dtype=int), score
