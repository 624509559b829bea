"""Accuracy metrics for thermal-error models (thesis §3.8, Eqs 3.31–3.32).

All functions take the measured thermal response ``y_true`` and the model
output ``y_pred`` (same units, e.g. µm) and return a float. The residual is
``y_pred - y_true`` (model minus measured, thesis Table 5-10).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike


def _pair(y_true, y_pred):
    y_true = np.asarray(y_true, dtype=np.float64).ravel()
    y_pred = np.asarray(y_pred, dtype=np.float64).ravel()
    if y_true.shape != y_pred.shape:
        raise ValueError(f"y_true has {y_true.size} values but y_pred has {y_pred.size}.")
    if y_true.size == 0:
        raise ValueError("metrics need at least one sample.")
    return y_true, y_pred


def rmse(y_true: ArrayLike, y_pred: ArrayLike) -> float:
    """Root-mean-square error ``sqrt(Σ(Z-P)²/n)`` (Eq 3.31), in the units of y.

    Parameters
    ----------
    y_true : array_like
        Measured thermal response (e.g. µm).
    y_pred : array_like
        Model output, same shape and unit.

    Returns
    -------
    float
        RMSE, in the unit of y.
    """
    y_true, y_pred = _pair(y_true, y_pred)
    return float(np.sqrt(np.mean((y_pred - y_true) ** 2)))


def nse(y_true: ArrayLike, y_pred: ArrayLike) -> float:
    """Nash–Sutcliffe efficiency ``1 - Σ(Z-P)²/Σ(Z-Z̄)²`` (Eq 3.32), range (-∞, 1].

    Parameters
    ----------
    y_true : array_like
        Measured thermal response (e.g. µm).
    y_pred : array_like
        Model output, same shape and unit.

    Returns
    -------
    float
        NSE (dimensionless).
    """
    y_true, y_pred = _pair(y_true, y_pred)
    spread = np.sum((y_true - y_true.mean()) ** 2)
    if spread == 0.0:
        raise ValueError("NSE is undefined for a constant y_true.")
    return float(1.0 - np.sum((y_pred - y_true) ** 2) / spread)


def pearson_r(y_true: ArrayLike, y_pred: ArrayLike) -> float:
    """Pearson correlation coefficient R between measured and predicted, range [-1, 1].

    Parameters
    ----------
    y_true : array_like
        Measured thermal response (e.g. µm).
    y_pred : array_like
        Model output, same shape and unit.

    Returns
    -------
    float
        R (dimensionless).
    """
    y_true, y_pred = _pair(y_true, y_pred)
    a = y_true - y_true.mean()
    b = y_pred - y_pred.mean()
    denom = np.sqrt(np.sum(a * a) * np.sum(b * b))
    if denom == 0.0:
        raise ValueError("Pearson R is undefined when either series is constant.")
    return float(np.sum(a * b) / denom)


def max_abs_residual(y_true: ArrayLike, y_pred: ArrayLike) -> float:
    """Maximum absolute residual ``max|P - Z|`` (the thesis's "±x µm").

    Parameters
    ----------
    y_true : array_like
        Measured thermal response (e.g. µm).
    y_pred : array_like
        Model output, same shape and unit.

    Returns
    -------
    float
        max |P − Z|, in the unit of y.
    """
    y_true, y_pred = _pair(y_true, y_pred)
    return float(np.max(np.abs(y_pred - y_true)))


def improvement_percent(y_true: ArrayLike, y_pred: ArrayLike) -> float:
    """Compensation improvement ``(1 - max|P - Z| / max|Z|) × 100`` in %.

    ``y_true`` is the uncompensated thermal error (zero means no error), so
    ``max|Z|`` is the error without compensation and ``max|P - Z|`` the error
    left after it. Thesis example: 64 µm error, ±4 µm residual → 93.75 %.

    Parameters
    ----------
    y_true : array_like
        Measured thermal response (e.g. µm).
    y_pred : array_like
        Model output, same shape and unit.

    Returns
    -------
    float
        Improvement, in %.
    """
    y_true, y_pred = _pair(y_true, y_pred)
    peak = np.max(np.abs(y_true))
    if peak == 0.0:
        raise ValueError("improvement is undefined when the thermal error is zero everywhere.")
    return float((1.0 - max_abs_residual(y_true, y_pred) / peak) * 100.0)
