"""Kalman filtering of discrete-time linear state-space models: the observer of a thermal model.

The model, with inputs ``u`` held (or averaged) over each step of ``dt`` s::

    x[k+1] = F x[k] + G u[k] + w[k],    w ~ N(0, Q)
    y[k]   = H x[k] + J u[k] + v[k],    v ~ N(0, R)

:func:`discretize` turns a continuous model ``ẋ = A x + B u`` (with a
continuous process-noise intensity) into ``F, G, Q`` for any step, however
stiff the model; :class:`KalmanFilter` fuses measurements that may be missing
(NaN) at any step, and estimates any other linear output ``z = L x + M u`` (a
drift nobody measures) with its variance.  Arrays only: the models that use it (a thermal ROM, a grey-box RC
network) supply the matrices.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import cho_factor, cho_solve, expm

#: Largest ‖A‖₁·h of the Van Loan step: e^{‖A‖h} ≤ e, so its blocks e^{−Ah} and e^{Aᵀh} stay near 1 and their
#: product keeps full precision (at ‖A‖·dt ≈ 700 e^{−A dt} overflows; long before, it cancels to noise).
VAN_LOAN_SPAN = 1.0


def discretize(A: ArrayLike, B: ArrayLike, dt: float, noise_intensity: ArrayLike | None = None
               ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64] | None]:
    """Exact discretisation of ``ẋ = A x + B u + w`` for inputs constant over a step of ``dt`` s (any dt ≥ 0).

    Parameters
    ----------
    A : (n, n) array, 1/s
    B : (n, m) array
    dt : step, s
    noise_intensity : (n, n) array or None
        Continuous white-noise intensity ``Q_c`` of ``w`` (state unit² per s).

    Returns
    -------
    F, G, Q : the step matrices; ``Q = ∫₀^dt e^{As} Q_c e^{Aᵀs} ds`` (:func:`noise_covariance`), or ``None``
        when no intensity is given.

    Raises
    ------
    ValueError
        If ``dt`` is negative or not finite.
    """
    if not (np.isfinite(dt) and dt >= 0):
        raise ValueError(f"discretize: the step must be a finite number of seconds ≥ 0, got {dt}")
    A = np.atleast_2d(np.asarray(A, float))
    B = np.asarray(B, float).reshape(A.shape[0], -1)
    n, m = B.shape
    block = np.zeros((n + m, n + m))
    block[:n, :n], block[:n, n:] = A, B
    step = expm(block * dt)      # e^{A dt} decays: scipy's scaling and squaring is stable for any dt
    F, G = step[:n, :n], step[:n, n:]
    if noise_intensity is None:
        return F, G, None
    return F, G, noise_covariance(A, noise_intensity, dt)


def noise_covariance(A: ArrayLike, noise_intensity: ArrayLike, dt: float) -> NDArray[np.float64]:
    """``Q = ∫₀^dt e^{As} Q_c e^{Aᵀs} ds``: Van Loan over a short step h, then doubled up to ``dt``.

    Van Loan's block exponential holds e^{−Ah}, which grows as fast as the stiffest mode decays: over a
    long step it overflows (NaN) or cancels.  So it is taken over h = dt / 2ᵏ with ‖A‖₁·h ≤
    :data:`VAN_LOAN_SPAN`, and ``Q(2h) = Q(h) + e^{Ah} Q(h) e^{Aᵀh}`` (exact) doubles it k times — a sum of
    positive semi-definite terms, so nothing cancels, whatever dt.

    Parameters
    ----------
    A : (n, n) array, 1/s
        The continuous state matrix.
    noise_intensity : (n, n) array
        ``Q_c``, state unit² per s.
    dt : float
        Step, s (≥ 0).

    Returns
    -------
    numpy.ndarray
        (n, n) symmetric ``Q``, state unit².
    """
    A = np.atleast_2d(np.asarray(A, float))
    Qc = np.asarray(noise_intensity, float)
    n = A.shape[0]
    span = float(np.abs(A).sum(axis=0).max()) * dt
    doublings = int(np.ceil(np.log2(span / VAN_LOAN_SPAN))) if span > VAN_LOAN_SPAN else 0
    h = dt / 2.0 ** doublings
    van_loan = np.zeros((2 * n, 2 * n))
    van_loan[:n, :n], van_loan[:n, n:], van_loan[n:, n:] = -A, Qc, A.T
    E = expm(van_loan * h)
    F = E[n:, n:].T
    Q = F @ E[:n, n:]
    for _ in range(doublings):
        Q = 0.5 * (Q + Q.T)
        Q = Q + F @ Q @ F.T
        F = F @ F
    return 0.5 * (Q + Q.T)


@dataclass
class FilterResult:
    """States and outputs of a filtered record (one row per step)."""

    state: np.ndarray            #: (N, n) filtered state means
    state_variance: np.ndarray   #: (N, n) diagonal of the filtered state covariance
    output: np.ndarray | None    #: (N, p) estimates of ``z = L x + M u`` (if L was given)
    output_std: np.ndarray | None  #: (N, p) their standard deviations
    normalised_innovation: np.ndarray  #: (N,) squared Mahalanobis innovation per step (NaN: nothing measured)
    measured: np.ndarray         #: (N,) number of measurements used per step


class KalmanFilter:
    """Linear Kalman filter with missing measurements (NaN) and extra estimated outputs.

    Parameters
    ----------
    F, G : state transition and input matrices of one step
    H, J : measurement matrices (``y = H x + J u``); ``J`` may be ``None``
    Q : process-noise covariance of one step
    R : measurement-noise covariance, (p, p) or a vector of variances
    """

    def __init__(self, F: ArrayLike, G: ArrayLike, H: ArrayLike, J: ArrayLike | None, Q: ArrayLike, R: ArrayLike):
        self.F = np.atleast_2d(np.asarray(F, float))
        n = self.F.shape[0]
        self.G = np.asarray(G, float).reshape(n, -1)
        self.H = np.asarray(H, float).reshape(-1, n)
        p, m = self.H.shape[0], self.G.shape[1]
        self.J = np.zeros((p, m)) if J is None else np.asarray(J, float).reshape(p, m)
        self.Q = np.asarray(Q, float).reshape(n, n)
        R = np.asarray(R, float)
        self.R = np.diag(R) if R.ndim == 1 else R.reshape(p, p)
        if not (np.all(np.isfinite(self.Q)) and np.all(np.isfinite(self.R))):
            raise ValueError("Kalman filter: Q and R must be finite")
        self.reset(np.zeros(n), np.eye(n))

    def reset(self, x0: ArrayLike, P0: ArrayLike) -> KalmanFilter:
        """Start again from the state mean ``x0`` and covariance ``P0``.

        Parameters
        ----------
        x0 : array_like, shape (n,)
            State mean, in the state's units.
        P0 : array_like, shape (n, n) or (n,)
            State covariance, or its diagonal (state units²).

        Returns
        -------
        KalmanFilter
            ``self``.
        """
        n = self.F.shape[0]
        self.x = np.asarray(x0, float).reshape(n).copy()
        P0 = np.asarray(P0, float)
        self.P = np.diag(P0) if P0.ndim == 1 else P0.reshape(n, n).copy()
        return self

    def predict(self, u: ArrayLike) -> KalmanFilter:
        """Advance one step with the input ``u`` held (or averaged) over it.

        Parameters
        ----------
        u : array_like, shape (m,)
            Input over the step, in the model's input units.

        Returns
        -------
        KalmanFilter
            ``self``.
        """
        self.x = self.F @ self.x + self.G @ np.asarray(u, float)
        P = self.F @ self.P @ self.F.T + self.Q
        self.P = 0.5 * (P + P.T)
        return self

    def update(self, y: ArrayLike, u: ArrayLike) -> float:
        """Fuse the measurements ``y`` (NaN = missing) taken with input ``u``.

        Parameters
        ----------
        y : array_like, shape (p,)
            Measurements, in the output units; NaN for a missing one.
        u : array_like, shape (m,)
            Input at the measurement (for the feedthrough ``J u``).

        Returns
        -------
        float
            The squared Mahalanobis norm of the innovation (χ² with as many
            degrees of freedom as measurements used), or NaN if none was.
        """
        y = np.asarray(y, float)
        seen = np.isfinite(y)
        if not seen.any():
            return np.nan
        H = self.H[seen]
        innovation = y[seen] - H @ self.x - self.J[seen] @ np.asarray(u, float)
        S = H @ self.P @ H.T + self.R[np.ix_(seen, seen)]
        factor = cho_factor(0.5 * (S + S.T))
        PHt = self.P @ H.T
        K = cho_solve(factor, PHt.T).T
        self.x = self.x + K @ innovation
        # Joseph form: stays symmetric positive semi-definite in round-off
        I_KH = np.eye(len(self.x)) - K @ H
        P = I_KH @ self.P @ I_KH.T + K @ self.R[np.ix_(seen, seen)] @ K.T
        self.P = 0.5 * (P + P.T)
        return float(innovation @ cho_solve(factor, innovation))

    def estimate(self, L: ArrayLike, M: ArrayLike | None, u: ArrayLike
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Mean and standard deviation of ``z = L x + M u`` for the present state.

        Parameters
        ----------
        L : array_like, shape (q, n)
            Output rows on the state.
        M : array_like, shape (q, m), or None
            Feedthrough of the input (None: none).
        u : array_like, shape (m,)
            Input.

        Returns
        -------
        mean : ndarray, shape (q,)
            Estimates of z, in its units.
        std : ndarray, shape (q,)
            Their standard deviations (from the state covariance only), same units.
        """
        L = np.asarray(L, float).reshape(-1, len(self.x))
        mean = L @ self.x + (0.0 if M is None else np.asarray(M, float) @ np.asarray(u, float))
        variance = np.einsum("ij,jk,ik->i", L, self.P, L)
        return mean, np.sqrt(np.maximum(variance, 0.0))

    def filter(self, U: ArrayLike, Y: ArrayLike, L: ArrayLike | None = None,
               M: ArrayLike | None = None) -> FilterResult:
        """Filter a whole record: measure-update at step k, then predict to k + 1.

        Parameters
        ----------
        U : (N, m) inputs; row k is the input over [t_k, t_{k+1})
        Y : (N, p) measurements at t_k (NaN = missing)
        L, M : optional extra outputs ``z = L x + M u`` to estimate at every t_k

        Returns
        -------
        FilterResult
            Filtered states, their variances, the extra outputs with their
            standard deviations (None without ``L``) and the innovations.
        """
        U = np.asarray(U, float).reshape(len(U), -1)
        Y = np.asarray(Y, float).reshape(len(U), -1)
        N, n = len(U), len(self.x)
        states, variances = np.empty((N, n)), np.empty((N, n))
        nis, used = np.full(N, np.nan), np.isfinite(Y).sum(axis=1)
        z = zs = None
        if L is not None:
            L = np.asarray(L, float).reshape(-1, n)
            z, zs = np.empty((N, L.shape[0])), np.empty((N, L.shape[0]))
        for k in range(N):
            nis[k] = self.update(Y[k], U[k])
            states[k], variances[k] = self.x, np.diag(self.P)
            if L is not None:
                z[k], zs[k] = self.estimate(L, M, U[k])
            if k + 1 < N:
                self.predict(U[k])
        return FilterResult(states, variances, z, zs, nis, used)
