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
