"""Input validation shared by every estimator and selection function in ``models``.

All checks happen once, at the public boundary, and the messages name the
problem (shape, NaN, too few samples) so a caller can fix the data.
"""

from __future__ import annotations

import numbers

import numpy as np
from sklearn.utils.validation import check_array, check_X_y


def validate_xy(X, y, *, min_samples: int = 1, what: str = "the model"):
    """Return ``(X, y)`` as finite float arrays of shape (n, d) and (n,).

    Raises ``ValueError`` for mismatched lengths, NaN/inf, or fewer than
    ``min_samples`` rows (``what`` names the estimator in the message).
    """
    X, y = check_X_y(X, y, dtype=np.float64, y_numeric=True, ensure_all_finite=True)
    require_samples(X.shape[0], min_samples, what)
    return X, y


def validate_x(X, *, min_samples: int = 1, what: str = "the model"):
    """Return ``X`` as a finite float array of shape (n, d)."""
    X = check_array(X, dtype=np.float64, ensure_all_finite=True)
    require_samples(X.shape[0], min_samples, what)
    return X


def validate_series(x, *, min_samples: int, what: str):
    """Return a 1-D finite float series with at least ``min_samples`` points."""
    x = check_array(np.asarray(x, dtype=np.float64), ensure_2d=False, ensure_all_finite=True)
    if x.ndim != 1:
        raise ValueError(f"{what} expects a 1-D series, got shape {x.shape}.")
    require_samples(x.shape[0], min_samples, what)
    return x


def require_samples(n_samples: int, min_samples: int, what: str) -> None:
    """Raise ``ValueError`` when there are fewer samples than ``what`` needs."""
    if n_samples < min_samples:
        noun = "sample" if n_samples == 1 else "samples"
        raise ValueError(
            f"{what} needs at least {min_samples} samples, got {n_samples} {noun} "
            "(fewer samples than parameters to estimate)."
        )


def check_n_features(estimator, X) -> None:
    """Raise ``ValueError`` if ``X`` does not have the width seen in ``fit``."""
    if X.shape[1] != estimator.n_features_in_:
        raise ValueError(
            f"X has {X.shape[1]} features, but {type(estimator).__name__} "
            f"is expecting {estimator.n_features_in_} features as input."
        )


def check_positive_int(value, name: str, minimum: int = 1) -> int:
    """Return ``value`` if it is an integer >= ``minimum``, else raise ``ValueError``."""
    if not isinstance(value, numbers.Integral) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}.")
    return int(value)
