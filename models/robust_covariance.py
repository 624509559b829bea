"""Covariance of least-squares parameters whose residuals are autocorrelated: a prewhitened sandwich.

For residuals ``r`` (rows in time order) and their Jacobian ``J`` at the optimum, the parameters' covariance is
``H⁻¹ S H⁻¹`` with ``H = JᵀJ`` and ``S`` the variance of the score ``Jᵀr``. Gauss–Newton's ``S = σ² H``
assumes white residuals; an output error that lasts hours makes it several times too narrow. Here:

1. each output's residual is whitened by an autoregression ``r_t = Σ φ_i r_(t−i) + v_t`` (Yule–Walker, order
   by AIC up to ``12 (n/100)^(1/4)``), and its Jacobian rows filtered by the same AR backwards in time,
   ``W = Φ⁻ᵀJ``, so that ``Jᵀr = Wᵀv`` exactly (Andrews & Monahan's prewhitening, applied to the residual
   rather than to the scores: here the Jacobian is a function of time, not a stationary series);
2. whatever correlation the whitened scores ``W_t v_t`` keep is taken up by a Bartlett (Newey–West) estimator
   with Andrews' AR(1) plug-in bandwidth (:func:`bartlett_long_run`, which the gap diagnosis uses on its own
   scores, not prewhitened);
3. the fit absorbs the slowest part of the noise into its parameters, which leaves the residual less
   persistent than the noise: each output's scores are scaled up by ``n_eff / (n_eff − k)`` (the variance by its
   square, twice the usual small-sample correction: a heuristic, chosen on the coverage bench below, not
   derived), with ``n_eff`` its effective number of independent rows (``n γ₀ / long-run variance``) and ``k``
   its share of the parameters fitted (its leverage ``trace(J_o (JᵀJ)⁻¹ J_oᵀ)``, plus an equal share of the
   profiled ones); an interval takes Student's t with Welch–Satterthwaite's degrees of freedom over the
   outputs' parts of its variance, ``n_eff − k`` with one output. An output with ``n_eff ≤ k`` has no scale that
   can be estimated: its part stays in the variance unscaled and out of that count, and makes undetermined only a
   quantity whose variance it makes more than :data:`MAX_UNSCALED_SHARE` of. Pooling ``n_eff`` over the outputs
   instead let a noisy white thermometer that hardly sets τ add thousands of independent rows, which undid both
   corrections for the drift that does: the observer form's intervals covered 79–81 % with a thermometer of 0.3 K,
   88–89 % now.

On a grey-box fit of a known 2-node network with AR(1) noise of 30 min correlation (48 h at 60 s), the Bartlett
estimator alone covered the time constants and the exponent 69–73 % of the time at a nominal 90 %, this one
86–89 %; over seven kinds of noise (``bench/greybox_intervals.py``), 49–90 % against 78–93 %. Rows come in
segments (records, or runs of fitted rows between rows left out) whose noise is taken as independent of each
other's; an output not read on a row (``read``) is left out there, not taken as a residual of 0 (which would
read as a stretch the model fitted exactly).
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import pairwise

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter
from scipy.special import stdtrit

#: cap on an AR(1) coefficient in Andrews' plug-in bandwidth: nearer 1 the formula blows up. 0.99 rather than
#: Andrews & Monahan's 0.97: the gap diagnosis (:func:`twin.gap.fit.parameter_sd`) feeds scores that are not
#: prewhitened, whose lag-1 correlation is often above 0.97, and its coverage was checked with 0.99; the prewhitened
#: scores here seldom come near either cap
MAX_PLUG_IN_RHO = 0.99
#: largest relative error of the leverage traces' sum, which is the number of parameters for an exact ``(JᵀJ)⁻¹``:
#: rounding leaves ~1e-12 for a well-posed fit; a JᵀJ of condition ~1e16 gives errors of order 1
LEVERAGE_TOLERANCE = 1e-6
#: largest fraction of a quantity's variance that outputs whose scale cannot be estimated (no more independent rows
#: than their share of the parameters) may make, unscaled, before the quantity is called undetermined. Below it,
#: that part (whose scale factor, unknown, is > 1) would have to be underestimated three-fold for the standard error
#: to be 1.095× too small (√(0.9 + 3 × 0.1)), which leaves a nominal 90 % interval covering 86.6 % (a normal
#: quantity): within the 78–93 % the estimator covers on the bench. Kept unscaled in the covariance: leaving it out
#: would narrow the interval further
MAX_UNSCALED_SHARE = 0.1


def sandwich_covariance(jacobian: NDArray[np.float64], residuals: NDArray[np.float64],
                        segments: Sequence[tuple[int, int]], n_fitted: int,
                        read: NDArray[np.bool_] | None = None,
                        transform: NDArray[np.float64] | None = None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Covariance of the parameters of a least-squares fit with autocorrelated residuals, and the degrees of
    freedom of each.

    Parameters
    ----------
    jacobian : ndarray, shape (n_rows, n_outputs, n_parameters)
        ∂ residual / ∂ parameter at the optimum (the residuals' units per parameter unit).
    residuals : ndarray, shape (n_rows, n_outputs)
        Residuals at the optimum, rows in time order.
    segments : sequence of (int, int)
        ``[start, stop)`` rows of each stretch of consecutive rows; noise is independent between stretches.
    n_fitted : int
        Parameters of the whole fit, these and any profiled out (e.g. linear ones solved for every step): they
        absorb part of the noise. The profiled ones, ``n_fitted − n_parameters``, are taken as shared equally by
        the outputs (as the grey-box model's gains: each output has as many of its own).
    read : ndarray of bool, shape (n_rows, n_outputs), optional
        Whether each output was read at each row (default: all). An unread entry is left out, not taken as a
        residual of 0: its output's autoregression runs on the entries read, broken where they are, and a row
        that no output read splits its segment.
    transform : ndarray, shape (m, n_parameters), optional
        Linear map to the quantities the intervals are on (default: the parameters themselves), e.g. to log τ:
        the degrees of freedom depend on how the outputs share each quantity's variance.

    Returns
    -------
    covariance : ndarray, shape (m, m)
        Of the transformed parameters, in their units squared. Infinite (rows and columns) for a quantity more than
        :data:`MAX_UNSCALED_SHARE` of whose variance comes from outputs whose data hold no more independent rows than
        their share of the parameters; for all if every output is such, or the Jacobian is (nearly) singular.
    dof : ndarray, shape (m,)
        Degrees of freedom of a Student t interval on each (> 0): with one output ``n_eff − n_fitted``; 1 where
        the variance is infinite.
    """
    if read is not None:   # keep the rows some output read: a row nobody read is a break in time
        any_read = read.any(axis=1)
        jacobian, residuals, read = jacobian[any_read], residuals[any_read], read[any_read]
        jacobian = np.where(read[:, :, None], jacobian, 0.0)   # an unread entry weighs nothing in JᵀJ either
        segments = consecutive_runs(any_read, segments)
    n_parameters = jacobian.shape[2]
    transform = np.eye(n_parameters) if transform is None else transform
    whitened = [_prewhitened_output(residuals[:, o], jacobian[:, o, :], segments,
                                    None if read is None else read[:, o]) for o in range(residuals.shape[1])]
    J = jacobian.reshape(-1, n_parameters)
    try:
        bread = np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return _undetermined(len(transform))
    # each output's share of the parameters fitted: its leverage trace(J_o (JᵀJ)⁻¹ J_oᵀ) on its rows plus an equal
    # share of the profiled ones (the fit absorbs an output's noise into the parameters it sets, not another's)
    leverage = np.einsum("tok,kj,toj->o", jacobian, bread, jacobian)
    # the traces sum to n_parameters for an exact inverse; a near-singular JᵀJ (condition ~1e16) inverts without an
    # error but not to its inverse, and normalising the shares would hide it behind variances of ~1e14
    if not abs(leverage.sum() - n_parameters) <= LEVERAGE_TOLERANCE * n_parameters:
        return _undetermined(len(transform))
    shares = n_parameters * (leverage / leverage.sum()) + (n_fitted - n_parameters) / len(leverage)
    # an output with no more independent rows than its share of the parameters has its noise fitted (nearly)
    # exactly: the variance its scores make cannot be scaled up, nor its degrees of freedom counted
    estimable = np.array([n_eff > share for (_, n_eff), share in zip(whitened, shares)])
    if not estimable.any():
        return _undetermined(len(transform))
    scaled = [score * (n_eff / (n_eff - share)) if ok else score
              for (score, n_eff), share, ok in zip(whitened, shares, estimable)]
    sandwich = transform @ bread
    covariance = sandwich @ bartlett_long_run(sum(scaled), segments) @ sandwich.T
    parts = np.array([np.diag(sandwich @ bartlett_long_run(score, segments) @ sandwich.T) for score in scaled])
    dof = _welch_satterthwaite(parts[estimable], [n_eff - share for (_, n_eff), share, ok
                                                  in zip(whitened, shares, estimable) if ok])
    return _without_unscalable(covariance, dof, parts[~estimable].sum(axis=0))


def _without_unscalable(covariance, dof, unscalable):
    """``(covariance, dof)`` with each quantity undetermined (infinite variance, 1 degree of freedom) whose
    variance the outputs that cannot be scaled (their parts ``unscalable``, unscaled) make more than
    :data:`MAX_UNSCALED_SHARE` of. A smaller part stays in the covariance unscaled (leaving it out would narrow the
    interval further) and out of the degrees of freedom."""
    undetermined = unscalable > MAX_UNSCALED_SHARE * np.diag(covariance)
    covariance, dof = covariance.copy(), dof.copy()
    covariance[undetermined, :] = covariance[:, undetermined] = np.inf
    dof[undetermined] = 1.0
    return covariance, dof


def _undetermined(n_parameters):
    """``(covariance, dof)`` of parameters the data do not determine: infinite variances (1 degree of freedom)."""
    return np.full((n_parameters, n_parameters), np.inf), np.ones(n_parameters)


def _welch_satterthwaite(parts, dofs):
    """Degrees of freedom of each transformed parameter's variance, a sum of the outputs' parts ``V_o`` (rows of
    ``parts``: the sandwich of output o's scores alone), each with ``n_eff_o − share_o`` of its own (``dofs``):
    ``(Σ V_o)² / Σ V_o² / dof_o``. The cross-output terms are left out of this count (their expectation is 0 for
    independent noises), not of the covariance."""
    dofs = np.asarray(dofs)[:, None]
    spread = np.sum(parts ** 2 / dofs, axis=0)
    # a quantity no output varies has a variance of 0, whatever its degrees of freedom
    return np.divide(parts.sum(axis=0) ** 2, spread, out=np.full(parts.shape[1], dofs.sum()), where=spread > 0)


def consecutive_runs(kept: NDArray[np.bool_], segments: Sequence[tuple[int, int]]) -> list[tuple[int, int]]:
    """``[start, stop)``, counted in the kept rows, of each run of consecutive kept rows inside one segment.

    Parameters
    ----------
    kept : ndarray of bool, shape (n_rows,)
        The rows kept.
    segments : sequence of (int, int)
        ``[start, stop)`` of each stretch of rows, counted in all rows.

    Returns
    -------
    list of (int, int)
        The stretches of the kept rows, in time order, none empty.
    """
    rows = np.flatnonzero(kept)
    breaks = (np.diff(rows) > 1) | np.isin(rows[1:], [start for start, _ in segments])
    return list(pairwise([0, *(np.flatnonzero(breaks) + 1).tolist(), len(rows)])) if rows.size else []


def half_widths(covariance: NDArray[np.float64], dof: float | NDArray[np.float64], level: float) -> NDArray[np.float64]:
    """Half-widths of two-sided intervals at ``level`` (e.g. 0.9) from a covariance: Student t quantile × standard
    error, in the parameters' units (infinite where the variance is).

    Parameters
    ----------
    covariance : ndarray, shape (k, k)
    dof : float or ndarray, shape (k,)
        Degrees of freedom of the t quantile, one for all or one per parameter.
    level : float
        Coverage, between 0 and 1.

    Returns
    -------
    ndarray, shape (k,)
    """
    variance = np.maximum(np.diag(covariance), 0.0)   # an exact fit's variance of 0 may round to −1e-16
    return stdtrit(dof, 0.5 + level / 2.0) * np.sqrt(variance)


def _prewhitened_output(residual, jacobian, segments, read):
    """``(scores, n_eff)`` of one output: its whitened scores ``W_t v_t`` on every row (0 where it was not read:
    such a row adds nothing to ``Jᵀr``) and its effective number of independent rows, from the rows read only."""
    if read is None or read.all():
        v, filtered, n_eff = _prewhitened(residual, jacobian, segments)
        return filtered * v[:, None], n_eff
    scores = np.zeros_like(jacobian)
    if read.any():
        v, filtered, n_eff = _prewhitened(residual[read], jacobian[read], consecutive_runs(read, segments))
        scores[read] = filtered * v[:, None]
        return scores, n_eff
    return scores, 0.0


def _prewhitened(residual, jacobian, segments):
    """``(v, W, n_eff)``: the residual whitened by its AR model, the Jacobian filtered by it backwards in time
    (``Jᵀr = Wᵀv``), and the residual's effective number of independent rows."""
    gamma = _autocovariances(residual, segments, int(12.0 * (len(residual) / 100.0) ** 0.25))
    if not gamma[0] > 0:   # an exact fit: nothing to whiten, and no scatter
        return residual, jacobian, float(len(residual))
    a, innovation = _autoregression(gamma, len(residual))
    whitened, filtered = np.empty_like(residual), np.empty_like(jacobian)
    for start, stop in segments:
        whitened[start:stop] = lfilter(a, [1.0], residual[start:stop])
        filtered[start:stop] = lfilter([1.0], a, jacobian[start:stop][::-1], axis=0)[::-1]
    return whitened, filtered, len(residual) * gamma[0] * a.sum() ** 2 / innovation


def _autocovariances(x, segments, max_lag):
    """``γ_0 … γ_max_lag`` of ``x`` pooled over the segments (divided by the row count: a positive-definite
    sequence, as Levinson–Durbin needs)."""
    gamma = np.zeros(max_lag + 1)
    for start, stop in segments:
        part = x[start:stop]
        for lag in range(min(max_lag + 1, len(part))):
            gamma[lag] += part[: len(part) - lag] @ part[lag:]
    return gamma / len(x)


def _autoregression(gamma, n_rows):
    """``(a, σ²)``: the filter ``[1, −φ₁ … −φ_p]`` of the Yule–Walker autoregression whose order (0 …
    len(gamma) − 1) has the lowest AIC, and its innovation variance (Levinson–Durbin gives every order at once)."""
    phi, variance = np.zeros(0), gamma[0]
    best = (n_rows * np.log(variance), phi, variance)
    for order in range(1, len(gamma)):
        reflection = (gamma[order] - phi @ gamma[order - 1: 0: -1]) / variance
        phi = np.r_[phi - reflection * phi[::-1], reflection]
        variance *= 1.0 - reflection ** 2
        if not variance > 0:   # the residual is predicted exactly: no higher order is estimable
            break
        aic = n_rows * np.log(variance) + 2 * order
        if aic < best[0]:
            best = (aic, phi, variance)
    return np.r_[1.0, -best[1]], best[2]


def bartlett_long_run(scores: NDArray[np.float64], segments: Sequence[tuple[int, int]]) -> NDArray[np.float64]:
    """Bartlett (Newey–West) long-run covariance ``Σ_|l|≤L (1 − |l|/(L+1)) Γ_l`` of score series, summed over
    segments whose scores are independent of each other's; L from :func:`andrews_bandwidth`.

    Computed as ``Σ_t B_t B_tᵀ / (L+1)`` with ``B_t`` the sums over windows of L+1 rows that overhang the segment's
    ends (each product ``s_j s_kᵀ`` is counted in L+1−|j−k| windows); a window is no longer than its segment.

    Parameters
    ----------
    scores : ndarray, shape (n_rows, k)
        Score of each row (for least squares, the residual times its Jacobian row), rows in time order.
    segments : sequence of (int, int)
        ``[start, stop)`` rows of each stretch of consecutive rows.

    Returns
    -------
    ndarray, shape (k, k)
        In the scores' units squared.
    """
    lags = andrews_bandwidth(scores, segments)
    long_run = np.zeros((scores.shape[1], scores.shape[1]))
    for start, stop in segments:
        span = min(lags, stop - start - 1)
        padded = np.zeros((stop - start + 2 * span + 1, scores.shape[1]))
        padded[span + 1: span + 1 + stop - start] = scores[start:stop]
        cumulative = np.cumsum(padded, axis=0)
        windows = cumulative[span + 1:] - cumulative[: -span - 1]
        long_run += windows.T @ windows / (span + 1)
    return long_run


def andrews_bandwidth(scores: NDArray[np.float64], segments: Sequence[tuple[int, int]]) -> int:
    """Bartlett bandwidth, Andrews' (1991) AR(1) plug-in ``1.1447 (α(1) n)^(1/3)`` over the score components.

    Each component's lag-1 correlation ρ is fitted to the demeaned scores within the segments (at a bound of a
    fit the scores keep a mean, which is no correlation) and clipped to ±:data:`MAX_PLUG_IN_RHO`; the components
    weigh equally, ``α(1) = Σ 4ρ² / ((1−ρ)⁶(1+ρ)²) / Σ 1/(1−ρ)⁴`` (Andrews' weights 1/σ⁴: the components are in
    different parameters' units, and the bandwidth must not depend on them). A component that does not vary
    is left out.

    Parameters
    ----------
    scores : ndarray, shape (n_rows, k)
        Score series, rows in time order.
    segments : sequence of (int, int)
        ``[start, stop)`` rows of each stretch of consecutive rows.

    Returns
    -------
    int
        Lags, in rows: from 1 to ``max(n_rows // 2, 1)``.
    """
    centred = scores - scores.mean(axis=0)
    lagged = sum(np.sum(centred[start: stop - 1] * centred[start + 1: stop], axis=0) for start, stop in segments)
    power = np.sum(centred ** 2, axis=0)
    informative = power > 0
    if not informative.any():
        return 1
    rho = np.clip(lagged[informative] / power[informative], -MAX_PLUG_IN_RHO, MAX_PLUG_IN_RHO)
    alpha = np.sum(4.0 * rho ** 2 / ((1.0 - rho) ** 6 * (1.0 + rho) ** 2)) / np.sum(1.0 / (1.0 - rho) ** 4)
    return int(np.clip(np.ceil(1.1447 * (alpha * len(scores)) ** (1.0 / 3.0)), 1, max(len(scores) // 2, 1)))
