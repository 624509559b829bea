"""Per-sensor scores against the thermal error: relational grades, influence, sensitivity.

Every function takes candidate sensors as the columns of ``X``
(n_samples, n_sensors), time-ordered, and the thermal error ``y``
(n_samples,), and returns one score per sensor (larger = more relevant).
All are vectorised over sensors.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import validate_xy
from ..grey import gm0n_influence, gm1n_influence, zero_reference

_NORMALISATIONS = ("range", "initial", "mean", "none")


def _normalise(a: np.ndarray, how: str) -> np.ndarray:
    """Column-wise dimensionless sequences for Deng's GRA; constant columns map to 0."""
    if how == "none":
        return a
    if how == "range":
        lo, span = a.min(axis=0), np.ptp(a, axis=0)
        return np.divide(a - lo, span, out=np.zeros_like(a), where=span > 0)
    ref = a[0] if how == "initial" else a.mean(axis=0)
    return np.divide(a, ref, out=np.zeros_like(a), where=ref != 0)


def grey_relational_grade(X: ArrayLike, y: ArrayLike, rho: float = 0.5,
                          normalization: Literal["range", "initial", "mean", "none"] = "range"
                          ) -> NDArray[np.float64]:
    """Deng's grey relational grade γ_0i of each sensor i with the thermal error.

    ``ξ_0i(k) = (Δmin + ρΔmax) / (Δ_0i(k) + ρΔmax)``, ``Δ_0i(k) = |x_0(k) - x_i(k)|``,
    where Δmin and Δmax are the minimum and **maximum over all sensors i and
    samples k** (seed 002 prints Δmax as a min of mins; that is a misprint),
    and ``γ_0i = mean_k ξ_0i(k)``. Sequences are first made dimensionless:
    ``"range"`` (min–max, default), ``"initial"`` (x/x(1)), ``"mean"`` or ``"none"``.

    Parameters
    ----------
    X : array_like, shape (n_samples, n_sensors)
        Time-ordered candidate sensors (e.g. °C).
    y : array_like, shape (n_samples,)
        The thermal error (e.g. µm).
    rho : float, default 0.5
        Distinguishing coefficient ρ, in (0, 1].
    normalization : {"range", "initial", "mean", "none"}, default "range"
        How sequences are made dimensionless.

    Returns
    -------
    ndarray, shape (n_sensors,)
        γ_0i in (0, 1].
    """
    X, y = validate_xy(X, y, min_samples=2, what="grey_relational_grade")
    if normalization not in _NORMALISATIONS:
        raise ValueError(f"normalization must be one of {_NORMALISATIONS}, got {normalization!r}.")
    if not 0.0 < rho <= 1.0:
        raise ValueError(f"distinguishing coefficient rho must be in (0, 1], got {rho!r}.")
    ref = _normalise(y[:, None], normalization)
    delta = np.abs(ref - _normalise(X, normalization))
    d_min, d_max = delta.min(), delta.max()
    if d_max == 0.0:
        return np.ones(X.shape[1])
    xi = (d_min + rho * d_max) / (delta + rho * d_max)
    return xi.mean(axis=0)


def similitude_degree(X: ArrayLike, y: ArrayLike) -> NDArray[np.float64]:
    """Liu's similitude degree ``ε_0i = 1 / (1 + |s_0 - s_i|)`` (thesis Eq 4.1).

    On zero-referenced series x⁰(k) = x(k) - x(1),
    ``s_0 - s_i = Σ_{k=2}^{n-1} (x_0⁰(k) - x_i⁰(k)) + ½(x_0⁰(n) - x_i⁰(n))``,
    the trapezoid integral of the difference. ε depends on the units of X
    and y (the thesis uses raw °C and µm).

    Parameters
    ----------
    X : array_like, shape (n_samples, n_sensors)
        Time-ordered candidate sensors (e.g. °C).
    y : array_like, shape (n_samples,)
        The thermal error (e.g. µm).

    Returns
    -------
    ndarray, shape (n_sensors,)
        ε_0i in (0, 1].
    """
    X, y = validate_xy(X, y, min_samples=2, what="similitude_degree")
    diff = zero_reference(y)[:, None] - zero_reference(X)
    s = diff[1:-1].sum(axis=0) + 0.5 * diff[-1]
    return 1.0 / (1.0 + np.abs(s))


def influence_weights(X: ArrayLike, y: ArrayLike, model: Literal["gm0n", "gm1n"] = "gm0n",
                      ridge: float = 1e-6) -> NDArray[np.float64]:
    """``|θ_j|`` from GM(0,N) (``model="gm0n"``) or ``|b_j|`` from GM(1,N) (``"gm1n"``).

    Solved with a relative ridge (default 1e-6) rather than ``(BᵀB)⁻¹``: with
    hundreds of collinear candidate sensors the plain normal equations are
    singular (thesis §4.3 implementation note).

    Parameters
    ----------
    X : array_like, shape (n_samples, n_sensors)
        Time-ordered candidate sensors (e.g. °C).
    y : array_like, shape (n_samples,)
        The thermal error (e.g. µm).
    model : {"gm0n", "gm1n"}, default "gm0n"
        The grey model.
    ridge : float, default 1e-6
        Relative ridge.

    Returns
    -------
    ndarray, shape (n_sensors,)
        |θ_j| or |b_j|.
    """
    if model == "gm0n":
        return np.abs(gm0n_influence(X, y, ridge))
    if model == "gm1n":
        return np.abs(gm1n_influence(X, y, ridge))
    raise ValueError(f"model must be 'gm0n' or 'gm1n', got {model!r}.")


def thermal_error_sensitivity(X: ArrayLike, y: ArrayLike, min_response: float = 0.05) -> NDArray[np.float64]:
    """Seed 002 Eq (2): ``G_i = 1 / sqrt(Σ_k (ΔX_i(k)/ΔY(k) - mean_k ΔX_i/ΔY)²)``.

    ΔX and ΔY are changes since the first sample (increments between
    consecutive samples make the ratio noise-dominated). Samples where
    ``|ΔY| < min_response × max|ΔY|`` are left out, since the ratio is
    undefined where the error has not moved. A larger G means the sensor's
    temperature change is a steadier multiple of the thermal error.

    Parameters
    ----------
    X : array_like, shape (n_samples, n_sensors)
        Time-ordered candidate sensors (e.g. °C).
    y : array_like, shape (n_samples,)
        The thermal error (e.g. µm).
    min_response : float, default 0.05
        Fraction of max|ΔY| below which samples are left out.

    Returns
    -------
    ndarray, shape (n_sensors,)
        G_i, in units of y per unit of X (inf for an exact multiple).
    """
    X, y = validate_xy(X, y, min_samples=3, what="thermal_error_sensitivity")
    dY = zero_reference(y)
    keep = np.abs(dY) >= min_response * np.max(np.abs(dY))
    keep[0] = False
    if keep.sum() < 2:
        raise ValueError("the thermal error barely changes: sensitivity is undefined.")
    ratio = zero_reference(X)[keep] / dY[keep, None]
    spread = np.sqrt(np.sum((ratio - ratio.mean(axis=0)) ** 2, axis=0))
    with np.errstate(divide="ignore"):
        return 1.0 / spread


def target_correlation(X: ArrayLike, y: ArrayLike) -> NDArray[np.float64]:
    """``|r|``, the absolute Pearson correlation of each sensor with the thermal error.

    Parameters
    ----------
    X : array_like, shape (n_samples, n_sensors)
        Time-ordered candidate sensors (e.g. °C).
    y : array_like, shape (n_samples,)
        The thermal error (e.g. µm).

    Returns
    -------
    ndarray, shape (n_sensors,)
        |r| in [0, 1] (0 for a constant sensor).
    """
    X, y = validate_xy(X, y, min_samples=2, what="target_correlation")
    Xc = X - X.mean(axis=0)
    yc = y - y.mean()
    denom = np.sqrt(np.sum(Xc * Xc, axis=0) * np.sum(yc * yc))
    return np.abs(np.divide(Xc.T @ yc, denom, out=np.zeros(X.shape[1]), where=denom > 0))
