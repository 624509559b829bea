"""The observer's Kalman filter: :class:`models.kalman.KalmanFilter` with a covariance step for its structure.

The transition matrix of the observer's model (:class:`twin.live.model.ObserverModel`) is block upper
triangular with a diagonal first block — the ROM's modal coordinates are decoupled first-order filters,
e^{−λh} — F = [[diag a, F₁₂], [0, F₂₂]], so F P Fᵀ costs O(r² c), c the few other states, instead of O(N³).
The measurement update is the standard form P − K H P (O(N² p)); the Joseph form of the base class costs two
N³ products.  Same numbers as the base class to rounding (tested).

**Consider states** (Schmidt–Kalman filter): a block of states whose uncertainty the covariance carries but
which the readings never update (their gain rows are zero).  For that gain the covariance valid for any
gain, P − K H P − (K H P)ᵀ + K S Kᵀ, equals P − X outside the consider block and P inside it, with
X = P Hᵀ S⁻¹ H P the update of the optimal gain — so the consider filter costs no more than the plain one.

**Sparse couplings.**  Columns of F₁₂ that are zero (states that do not drive the modes: offsets) are skipped,
and columns with a single nonzero (a disturbance that drives one modal coordinate) are applied as scaled rows
instead of through the matrix products; only the remaining columns take part in them.  F₂₂ (the disturbances'
own dynamics) is diagonal but for a few rows (a lagged air driven by the zone airs): it is applied as a scaling
plus those rows, found at each step.
"""
from __future__ import annotations

import numpy as np

from models.kalman import KalmanFilter


def _contiguous(index):
    """``index`` as a slice when it is a run of consecutive integers (a view instead of a copy), else as it is."""
    if len(index) and np.array_equal(index, np.arange(index[0], index[0] + len(index))):
        return slice(int(index[0]), int(index[0]) + len(index))
    return index


class ModalKalmanFilter(KalmanFilter):
    """The Kalman filter of the observer (see the module docstring).

    Parameters
    ----------
    order : int
        r, the number of leading states whose block of F is diagonal.
    F, G, H, J, Q, R
        As :class:`models.kalman.KalmanFilter` (R a vector of variances).
    consider : slice, optional
        The consider states (contiguous), never updated by the readings.
    couplings : tuple, optional
        ``(dense, single_columns, single_rows)``: the columns of F₁₂ (counted from r) that may be anything,
        and those whose only nonzero is in the given modal row; every other column of F₁₂ is zero.
        Default: every column dense.
    """

    def __init__(self, order: int, F: np.ndarray, G: np.ndarray, H: np.ndarray, J: np.ndarray, Q: np.ndarray,
                 R: np.ndarray, consider: slice | None = None, couplings: tuple | None = None) -> None:
        super().__init__(F, G, H, J, Q, R)
        self.order, self.consider = order, consider
        self._variances = np.diagonal(self.R).copy()
        c = self.F.shape[0] - order
        dense, cols, rows = couplings or (np.arange(c), np.array([], int), np.array([], int))
        self._dense = _contiguous(np.asarray(dense, int))
        self._cols, self._rows = np.asarray(cols, int), np.asarray(rows, int)

    def _coupled(self, F12_dense, F12_single, M):
        """F₁₂ @ M for M (c, k), from F₁₂'s dense columns and single nonzeros (its sparsity)."""
        out = F12_dense @ M[self._dense]
        out[self._rows] += F12_single[:, None] * M[self._cols]
        return out

    @staticmethod
    def _times_F22_transposed(f22, mixed, E, M):
        """M @ F₂₂ᵀ for M (k, c), with F₂₂ = diag(f22) + E, E (its rows ``mixed``) the only off-diagonal part."""
        out = M * f22[None, :]
        out[:, mixed] += M @ E.T
        return out

    def predict(self, u: np.ndarray) -> ModalKalmanFilter:
        """Advance one step with the input ``u`` held over it (uses :attr:`F`, :attr:`G`, :attr:`Q`).

        Parameters
        ----------
        u : ndarray, shape (n_inputs,)
            Plant inputs held over the step (°C, K/m, W) and a trailing 1.

        Returns
        -------
        self : ModalKalmanFilter
            The filter, advanced.
        """
        r, F, P = self.order, self.F, self.P
        a, F12, F22 = np.diagonal(F)[:r], F[:r, r:], F[r:, r:]
        dense, single = F12[:, self._dense], F12[self._rows, self._cols]
        f22 = np.diagonal(F22)
        mixed = np.flatnonzero(np.count_nonzero(F22, axis=1) > (f22 != 0.0))
        E = F22[mixed].copy()
        E[np.arange(len(mixed)), mixed] = 0.0
        P12, P22 = P[:r, r:], P[r:, r:]
        T12 = a[:, None] * P12 + self._coupled(dense, single, P22)                   # (F P)₁₂
        T11 = a[:, None] * P[:r, :r] + self._coupled(dense, single, P12.T)           # (F P)₁₁
        out = np.empty_like(P)
        out[:r, :r] = T11 * a[None, :] + self._coupled(dense, single, T12.T).T
        out[:r, r:] = self._times_F22_transposed(f22, mixed, E, T12)
        out[r:, :r] = out[:r, r:].T
        FP22 = f22[:, None] * P22                                                     # F₂₂ P₂₂
        FP22[mixed] += E @ P22
        out[r:, r:] = self._times_F22_transposed(f22, mixed, E, FP22)
        out += self.Q
        self.P = 0.5 * (out + out.T)
        self.x = F @ self.x + self.G @ u
        return self

    def innovations(self, y: np.ndarray, u: np.ndarray) -> tuple:
        """The innovation of the readings ``y`` and its covariance, as :meth:`update` uses them.

        Parameters
        ----------
        y : ndarray, shape (n_thermometers,)
            Readings, °C; NaN = missing.
        u : ndarray, shape (n_inputs,)
            The plant inputs at the reading.

        Returns
        -------
        tuple
            ``(seen, ν, H P, S)``: the readings present (bool, (n_thermometers,)), their innovation (°C), H P with
            H their rows, and the innovation covariance S (°C²).
        """
        seen = np.isfinite(y)
        H = self.H[seen] if not seen.all() else self.H
        innovation = y[seen] - H @ self.x - self.J[seen] @ u
        HP = H @ self.P
        S = HP @ H.T
        S.flat[::len(S) + 1] += self._variances[seen]
        return seen, innovation, HP, S

    def update(self, y: np.ndarray, u: np.ndarray, prepared: tuple | None = None) -> float:
        """Fuse the readings ``y`` (NaN = missing) taken with the input ``u``.

        Parameters
        ----------
        y : ndarray, shape (n_thermometers,)
            Readings, °C; NaN = missing.
        u : ndarray, shape (n_inputs,)
            The plant inputs at the reading.
        prepared : tuple, optional
            :meth:`innovations` of these readings in the present state, if already computed.

        Returns
        -------
        float
            The normalised innovation squared (χ² with as many degrees of freedom as readings), NaN if
            nothing was read.
        """
        seen = np.isfinite(y)
        if not seen.any():
            return np.nan
        _, innovation, HP, S = self.innovations(y, u) if prepared is None else prepared
        solved = np.linalg.solve(S, np.column_stack([HP, innovation]))
        gain_t, weighted = solved[:, :-1], solved[:, -1]        # Kᵀ = S⁻¹ H P, S⁻¹ ν
        nis = float(innovation @ weighted)
        self.log_likelihood = -0.5 * (nis + np.linalg.slogdet(S)[1] + len(S) * np.log(2.0 * np.pi))
        c = self.consider
        if c is None:
            self.x = self.x + gain_t.T @ innovation
            self.P = self.P - HP.T @ gain_t
        else:
            kept = self.P[c, c].copy()
            step = gain_t.T @ innovation
            step[c] = 0.0
            self.x = self.x + step
            self.P = self.P - HP.T @ gain_t
            self.P[c, c] = kept
        return nis
