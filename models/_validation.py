"""Input validation shared by every estimator and selection function in ``models``.

All checks happen once, at the public boundary, and the messages name the
problem (shape, NaN, too few samples) so a caller can fix the data.
"""

from __future__ import annotations

import numbers

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.base import BaseEstimator
from sklearn.utils.validation import check_array, check_X_y


def validate_xy(X: ArrayLike, y: ArrayLike, *, min_samples: int = 1,
                what: str = "the model") -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Return ``(X, y)`` as finite float arrays of shape (n, d) and (n,).

    Parameters
    ----------
    X : array_like, shape (n_samples, n_features)
        Inputs, in their own units (unchanged).
    y : array_like, shape (n_samples,)
        Target, in its own unit (unchanged).
    min_samples : int, default 1
        Fewest rows accepted.
    what : str, default "the model"
        Names the estimator in the error message.

    Returns
    -------
    X : ndarray of float64, shape (n_samples, n_features)
    y : ndarray of float64, shape (n_samples,)

    Raises
    ------
    ValueError
        Mismatched lengths, NaN/inf, or fewer than ``min_samples`` rows.
    """
    X, y = check_X_y(X, y, dtype=np.float64, y_numeric=True, ensure_all_finite=True)
    require_samples(X.shape[0], min_samples, what)
    return X, y


def validate_x(X: ArrayLike, *, min_samples: int = 1, what: str = "the model") -> NDArray[np.float64]:
    """Return ``X`` as a finite float array of shape (n, d).

    Parameters
    ----------
    X : array_like, shape (n_samples, n_features)
        Inputs, in their own units (unchanged).
    min_samples : int, default 1
        Fewest rows accepted.
    what : str, default "the model"
        Names the estimator in the error message.

    Returns
    -------
    ndarray of float64, shape (n_samples, n_features)

    Raises
    ------
    ValueError
        NaN/inf, a 1-D input, or fewer than ``min_samples`` rows.
    """
    X = check_array(X, dtype=np.float64, ensure_all_finite=True)
    require_samples(X.shape[0], min_samples, what)
    return X


def validate_series(x: ArrayLike, *, min_samples: int, what: str) -> NDArray[np.float64]:
    """Return a 1-D finite float series with at least ``min_samples`` points.

    Parameters
    ----------
    x : array_like, shape (n,)
        The series, in its own unit (unchanged).
    min_samples : int
        Fewest points accepted.
    what : str
        Names the model in the error message.

    Returns
    -------
    ndarray of float64, shape (n,)

    Raises
    ------
    ValueError
        Not 1-D, NaN/inf, or fewer than ``min_samples`` points.
    """
    x = check_array(np.asarray(x, dtype=np.float64), ensure_2d=False, ensure_all_finite=True)
    if x.ndim != 1:
        raise ValueError(f"{what} expects a 1-D series, got shape {x.shape}.")
    require_samples(x.shape[0], min_samples, what)
    return x


def require_samples(n_samples: int, min_samples: int, what: str) -> None:
    """Raise ``ValueError`` when there are fewer samples than ``what`` needs.

    Parameters
    ----------
    n_samples : int
        Samples available.
    min_samples : int
        Samples needed.
    what : str
        Names the model in the message.
    """
    if n_samples < min_samples:
        noun = "sample" if n_samples == 1 else "samples"
        raise ValueError(f"{what} needs at least {min_samples} samples, got {n_samples} {noun}.")


def require_parameters(
    n_samples: int, n_parameters: int, what: str, lost: int = 0, lost_reason: str = "", hint: str = ""
) -> None:
    """Raise ``ValueError`` unless the samples give more equations than there are parameters.

    ``lost`` samples give no equation, for the reason ``lost_reason`` (a grey
    model's first sample, a delay, an early-stopping split). With as many
    parameters as equations a fit reproduces its training data exactly
    (training error 0, "100 %" improvement) whatever the data mean; with more
    parameters it is underdetermined. Neither says anything about the model,
    so both are refused; ``hint`` is appended to the message.

    Parameters
    ----------
    n_samples : int
        Samples available.
    n_parameters : int
        Free parameters of the fit.
    what : str
        Names the model in the message.
    lost : int, default 0
        Samples that give no equation.
    lost_reason : str, default ""
        Why they give none (shown in the message).
    hint : str, default ""
        Appended to the message.
    """
    need = n_parameters + lost + 1
    if n_samples < need:
        noun = "sample" if n_samples == 1 else "samples"
        why = f" ({lost_reason})" if lost_reason else ""
        raise ValueError(
            f"{what} has {n_parameters} parameters to fit and needs at least {need} samples{why}, "
            f"got {n_samples} {noun}: with no more equations than parameters the fit is exact or "
            f"underdetermined and its training error means nothing.{hint}"
        )


def check_n_features(estimator: BaseEstimator, X: NDArray[np.float64]) -> None:
    """Raise ``ValueError`` if ``X`` does not have the width seen in ``fit``.

    Parameters
    ----------
    estimator : BaseEstimator
        A fitted estimator (has ``n_features_in_``).
    X : ndarray, shape (n_samples, n_features)
        Validated inputs.
    """
    if X.shape[1] != estimator.n_features_in_:
        raise ValueError(
            f"X has {X.shape[1]} features, but {type(estimator).__name__} "
            f"is expecting {estimator.n_features_in_} features as input."
        )


def check_positive_int(value: object, name: str, minimum: int = 1) -> int:
    """Return ``value`` if it is an integer >= ``minimum``, else raise ``ValueError``.

    Parameters
    ----------
    value : object
        The value to check (a Python or numpy integer passes).
    name : str
        Names the hyperparameter in the message.
    minimum : int, default 1
        Smallest value accepted.

    Returns
    -------
    int
        ``value`` as a Python int.
    """
    if not isinstance(value, numbers.Integral) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}.")
    return int(value)
