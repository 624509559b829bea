"""Grey-system building blocks: AGO/IAGO, GM(1,1), GM(0,N) and GM(1,N) (thesis §3.4, §3.7).

Conventions shared by every grey estimator in ``models``
--------------------------------------------------------
* ``X`` is (n_samples, n_features) and ``y`` is (n_samples,), both
  **time-ordered** at a constant sampling interval; time is the sample index
  k = 1..n, so coefficients are per sample.
* Both are **zero-referenced**: the first sample is subtracted
  (``x⁰(k) = x(k) - x(1)``, thesis Table 5-9), so signed changes of
  temperature and displacement are modelled. ``predict(X)`` zero-references
  its own ``X`` to its first row and returns ``y_reference_ + Δŷ``, where
  ``y_reference_`` is the first training target. To continue a training run
  (the thesis's "calibrate on the first stage, predict the rest"), pass the
  whole input history from the training start and read off the tail.
* These are time-series models: predictions depend on sample order and on
  where the series starts, so scikit-learn's sample-order and subset
  invariance checks do not apply to them (see ``tests/test_models_sklearn.py``).
* Least squares uses ``lstsq`` (optionally with a relative ridge), never
  ``(BᵀB)⁻¹``: the regressors are cumulative sums and highly collinear.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray
from scipy.signal import lfilter
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.utils.validation import check_is_fitted

from ._threads import one_blas_thread
from ._validation import (
    check_n_features,
    require_parameters,
    validate_series,
    validate_x,
    validate_xy,
)
from .registry import register_model

#: the first sample of a grey model gives no equation (its equations are k = 2..n)
_FIRST_SAMPLE = "the first gives no equation"


def ago(x: ArrayLike, axis: int = 0) -> NDArray[np.float64]:
    """First-order accumulated generating operation ``x¹(k) = Σ_{j≤k} x⁰(j)`` (Eq 3.11).

    Parameters
    ----------
    x : array_like
        Series x⁰, in its own unit.
    axis : int, default 0
        The time axis.

    Returns
    -------
    ndarray, shape of ``x``
        x¹, in the unit of ``x`` × samples.
    """
    return np.cumsum(np.asarray(x, dtype=np.float64), axis=axis)


def iago(x1: ArrayLike, axis: int = 0) -> NDArray[np.float64]:
    """Inverse AGO ``x⁰(k) = x¹(k) - x¹(k-1)``, ``x⁰(1) = x¹(1)`` (Eq 3.12).

    Parameters
    ----------
    x1 : array_like
        Accumulated series x¹.
    axis : int, default 0
        The time axis.

    Returns
    -------
    ndarray, shape of ``x1``
        x⁰.
    """
    x1 = np.asarray(x1, dtype=np.float64)
    return np.diff(x1, axis=axis, prepend=np.zeros_like(np.take(x1, [0], axis=axis)))


def background_values(x1: ArrayLike, axis: int = 0) -> NDArray[np.float64]:
    """Mean-sequence ``z¹(k) = ½(x¹(k-1) + x¹(k))`` for k = 2..n (n-1 values).

    Parameters
    ----------
    x1 : array_like
        Accumulated series x¹, n samples along ``axis``.
    axis : int, default 0
        The time axis.

    Returns
    -------
    ndarray
        z¹, n − 1 samples along ``axis``, in the unit of ``x1``.
    """
    x1 = np.asarray(x1, dtype=np.float64)
    n = x1.shape[axis]
    return 0.5 * (np.take(x1, range(n - 1), axis=axis) + np.take(x1, range(1, n), axis=axis))


def grey_least_squares(B: ArrayLike, Y: ArrayLike, ridge: float = 0.0) -> NDArray[np.float64]:
    """Solve ``B θ ≈ Y``: lstsq if ``ridge == 0``, else ``(BᵀB + λI)θ = BᵀY``.

    ``λ = ridge × mean(diag BᵀB)`` is relative, so the ridge does not depend
    on units; with a ridge the (then positive definite) normal equations are
    solved directly, which is fast for thousands of candidate sensors.

    Parameters
    ----------
    B : array_like, shape (m, p)
        Design matrix.
    Y : array_like, shape (m,) or (m, q)
        Right-hand side(s).
    ridge : float, default 0.0
        Relative ridge λ / mean(diag BᵀB).

    Returns
    -------
    ndarray, shape (p,) or (p, q)
        θ.
    """
    B = np.asarray(B, dtype=np.float64)
    Y = np.asarray(Y, dtype=np.float64)
    if ridge > 0.0:
        gram = B.T @ B
        gram[np.diag_indices_from(gram)] += ridge * max(np.trace(gram) / gram.shape[0], 1e-300)
        return scipy.linalg.solve(gram, B.T @ Y, assume_a="pos")
    return np.linalg.lstsq(B, Y, rcond=None)[0]


def zero_reference(a: ArrayLike) -> NDArray[np.float64]:
    """Subtract the first sample (row) so every series starts at 0.

    Parameters
    ----------
    a : array_like, shape (n,) or (n, d)
        Time-ordered series, in their own units.

    Returns
    -------
    ndarray, shape of ``a``
        The changes since the first sample, in the same units.
    """
    a = np.asarray(a, dtype=np.float64)
    return a - a[:1]


# --------------------------------------------------------------------- GM(1,1)
@dataclass(frozen=True)
class GM11:
    """GM(1,1): ``x⁰(k) + a z¹(k) = b``, whitened ``dx¹/dt + a x¹ = b``.

    ``development_coefficient`` is a (per sample), ``grey_input`` is b (units
    of x per sample). Fit with :meth:`fit`; :meth:`predict` returns the
    time-response ``x̂⁰(1..n)`` restored by IAGO from
    ``x̂¹(k+1) = (x⁰(1) - b/a) e^{-ak} + b/a``. GM(1,1) is a univariate
    forecaster on the raw (not zero-referenced) series, as in the textbooks.
    """

    development_coefficient: float
    grey_input: float
    initial_value: float

    @classmethod
    def fit(cls, series: ArrayLike) -> GM11:
        """Least-squares ``[a, b]`` from ``Y = [x⁰(2..n)]``, ``B = [-z¹(k), 1]``.

        Parameters
        ----------
        series : array_like, shape (n,)
            The raw series x⁰ (at least 3 samples), in its own unit.

        Returns
        -------
        GM11
            The fitted model.
        """
        x0 = validate_series(series, min_samples=1, what="GM(1,1)")
        require_parameters(x0.size, 2, "GM(1,1)", lost=1, lost_reason=_FIRST_SAMPLE)
        z = background_values(ago(x0))
        a, b = grey_least_squares(np.column_stack([-z, np.ones_like(z)]), x0[1:])
        return cls(float(a), float(b), float(x0[0]))

    def predict(self, n_samples: int) -> np.ndarray:
        """Model values ``x̂⁰(1..n_samples)`` (fit range and beyond).

        Written as ``x̂¹(k+1) = x⁰(1) e^{-ak} + b (1 - e^{-ak}) / a``, with
        ``(1 - e^{-ak})/a`` from ``expm1``: the textbook form
        ``(x⁰(1) - b/a) e^{-ak} + b/a`` cancels catastrophically when a ≈ 0
        (a constant series fits a ≈ 1e-18), while this one tends smoothly to
        its limit ``x⁰(1) + b k``, a constant forecast ``x̂⁰ = b``.

        Parameters
        ----------
        n_samples : int
            Number of samples to return, from the first one of the fit.

        Returns
        -------
        ndarray, shape (n_samples,)
            x̂⁰, in the unit of the fitted series.
        """
        a, b = self.development_coefficient, self.grey_input
        k = np.arange(n_samples, dtype=np.float64)
        growth = k if a == 0.0 else -np.expm1(-a * k) / a
        x1 = self.initial_value * np.exp(-a * k) + b * growth
        return iago(x1)


# -------------------------------------------------------- GM(0,N) and GM(1,N)
def _gm0n_theta(X0, y0, ridge):
    """θ of ``z₁¹(k) = Σ_j θ_j x_j¹(k)``, k = 2..n (Eq 3.25), zero-referenced input."""
    return grey_least_squares(ago(X0)[1:], background_values(ago(y0)), ridge)


def _gm1n_theta(X0, y0, ridge):
    """``[a, b₂..b_N]`` of ``x₁⁰(k) + a z₁¹(k) = Σ_j b_j x_j¹(k)`` with ``B = [-z₁¹, x_j¹]``."""
    B = np.column_stack([-background_values(ago(y0)), ago(X0)[1:]])
    return grey_least_squares(B, y0[1:], ridge)


def _influence(theta_fn, n_extra, X, y, ridge, what):
    X, y = validate_xy(X, y, min_samples=3, what=what)
    if ridge == 0.0:  # unregularised: more equations than parameters
        require_parameters(X.shape[0], X.shape[1] + n_extra, what, lost=1, lost_reason=_FIRST_SAMPLE)
    return theta_fn(zero_reference(X), zero_reference(y), ridge)


def gm0n_influence(X: ArrayLike, y: ArrayLike, ridge: float = 0.0) -> NDArray[np.float64]:
    """GM(0,N) influence weights θ_j (Eqs 3.21–3.25) of each column of X on y.

    Zero-referenced AGO series; rank sensors by ``|θ_j|`` (thesis §4.3). With
    ``ridge > 0`` more sensors than samples are allowed.

    Parameters
    ----------
    X : array_like, shape (n_samples, n_features)
        Time-ordered candidate sensors (e.g. °C); zero-referenced here.
    y : array_like, shape (n_samples,)
        Time-ordered target (e.g. µm); zero-referenced here.
    ridge : float, default 0.0
        Relative ridge (see :func:`grey_least_squares`).

    Returns
    -------
    ndarray, shape (n_features,)
        θ_j, in the unit of ``y`` per unit of column j.
    """
    return _influence(_gm0n_theta, 0, X, y, ridge, "GM(0,N)")


def gm1n_influence(X: ArrayLike, y: ArrayLike, ridge: float = 0.0) -> NDArray[np.float64]:
    """GM(1,N) driving coefficients b_j (Eqs 3.27–3.30), the influence of each column on y.

    Parameters
    ----------
    X : array_like, shape (n_samples, n_features)
        Time-ordered candidate sensors (e.g. °C); zero-referenced here.
    y : array_like, shape (n_samples,)
        Time-ordered target (e.g. µm); zero-referenced here.
    ridge : float, default 0.0
        Relative ridge (see :func:`grey_least_squares`).

    Returns
    -------
    ndarray, shape (n_features,)
        b_j (the development coefficient a left out).
    """
    return _influence(_gm1n_theta, 1, X, y, ridge, "GM(1,N)")[1:]


class GreySeriesRegressor(RegressorMixin, BaseEstimator):
    """Base of the grey time-series estimators: zero-referencing, validation, tags.

    Subclasses implement ``_fit_changes(X0, y0)`` and ``_predict_changes(X0)``
    on zero-referenced arrays and set ``_n_parameters(n_features)``; the
    first ``_samples_without_equation()`` samples give no equation.
    """

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        # grey models are fitted on short, time-ordered series; generic random
        # data gives them low scores by design
        tags.regressor_tags.poor_score = True
        return tags

    def _n_parameters(self, n_features: int) -> int:
        raise NotImplementedError

    def _samples_without_equation(self) -> tuple[int, str]:
        """How many leading samples give no equation, and why (k = 2..n: the first)."""
        return 1, _FIRST_SAMPLE

    @one_blas_thread
    def fit(self, X: ArrayLike, y: ArrayLike) -> GreySeriesRegressor:
        """Fit on time-ordered ``X`` (n_samples, n_features) and ``y`` (n_samples,).

        Parameters
        ----------
        X : array_like, shape (n_samples, n_features)
            Time-ordered inputs at a constant sampling interval, in their own units.
        y : array_like, shape (n_samples,)
            Time-ordered target, in its own unit.

        Returns
        -------
        GreySeriesRegressor
            ``self``, fitted.
        """
        X, y = validate_xy(X, y, what=type(self).__name__)
        lost, why = self._samples_without_equation()
        require_parameters(X.shape[0], self._n_parameters(X.shape[1]), type(self).__name__, lost, why)
        self.y_reference_ = float(y[0])
        self.n_features_in_ = X.shape[1]
        self._fit_changes(zero_reference(X), zero_reference(y))
        return self

    def predict(self, X: ArrayLike) -> NDArray[np.float64]:
        """``y_reference_ +`` the predicted change from the first row of ``X``.

        Parameters
        ----------
        X : array_like, shape (n_samples, n_features)
            Time-ordered inputs from the start of the series to predict, at the training interval.

        Returns
        -------
        ndarray, shape (n_samples,)
            Prediction, in the unit of the training target.
        """
        check_is_fitted(self, "y_reference_")
        X = validate_x(X, what=type(self).__name__)
        check_n_features(self, X)
        return self.y_reference_ + self._predict_changes(zero_reference(X))


def chronological_prediction(model: BaseEstimator, X: NDArray[np.float64], y: NDArray[np.float64],
                             n_train: int) -> NDArray[np.float64]:
    """Fit ``model`` on the first ``n_train`` rows, return its prediction of rows ``n_train:``.

    ``X`` (n_samples, n_features) and ``y`` (n_samples,) are time-ordered;
    nothing is shuffled. The prediction has the unit of ``y`` (e.g. µm).
    A grey time-series model predicts changes since the first row of its
    input, so it is run over the whole series from the training start and
    the test part read off the tail (the thesis's "calibrate on the first
    stage, predict the rest"); a static model maps each test row on its own.

    Parameters
    ----------
    model : BaseEstimator
        An unfitted regressor (fitted here).
    X : ndarray, shape (n_samples, n_features)
        Time-ordered inputs.
    y : ndarray, shape (n_samples,)
        Time-ordered target.
    n_train : int
        Rows used for fitting.

    Returns
    -------
    ndarray, shape (n_samples - n_train,)
        Prediction of the rows after the training ones, in the unit of ``y``.
    """
    model.fit(X[:n_train], y[:n_train])
    if isinstance(model, GreySeriesRegressor):
        return model.predict(X)[n_train:]
    return model.predict(X[n_train:])


@register_model({"gm0n": {}}, time_series=True)
class GM0NRegressor(GreySeriesRegressor):
    """GM(0,N) predictor: ``x̂₁¹(k) = Σ_j θ_j x_j¹(k)``, restored by IAGO.

    Since IAGO of a weighted sum of AGO series is the same weighted sum of
    the original series, the prediction is ``Δŷ = X⁰ θ``: a zero-intercept
    linear model whose weights are estimated in the AGO domain.

    Parameters
    ----------
    ridge : float, default 0.0
        Relative ridge of the least squares (see :func:`grey_least_squares`).

    Attributes: ``coef_`` (θ, n_features), ``y_reference_``.
    """

    def __init__(self, ridge: float = 0.0):
        self.ridge = ridge

    def _n_parameters(self, n_features):
        return n_features

    def _fit_changes(self, X0, y0):
        self.coef_ = _gm0n_theta(X0, y0, self.ridge)

    def _predict_changes(self, X0):
        return X0 @ self.coef_


@register_model({"gm1n": {}}, time_series=True)
class GM1NRegressor(GreySeriesRegressor):
    """GM(1,N) predictor from the grey difference equation itself.

    Least squares with the corrected design matrix
    ``B = [-z₁¹(k), x₂¹(k) … x_N¹(k)]``, k = 2..n (Eqs 3.27–3.30; the thesis
    misprints the sign and one column), for the development coefficient a
    and driving coefficients b_j. Prediction:

    ``x₁⁰(k) + a·½(x₁¹(k-1) + x₁¹(k)) = F(k)``, ``F(k) = Σ_j b_j x_j¹(k)``,
    solved recursively: ``x₁¹(k) = ρ x₁¹(k-1) + F(k)/(1 + a/2)`` with
    ``ρ = (1 - a/2)/(1 + a/2)``, then IAGO. This avoids the textbook
    time-response formula, which assumes constant drivers.

    Parameters
    ----------
    ridge : float, default 0.0
        Relative ridge of the least squares (see :func:`grey_least_squares`).

    Attributes: ``development_coefficient_`` (a), ``coef_`` (b, n_features).
    """

    def __init__(self, ridge: float = 0.0):
        self.ridge = ridge

    def _n_parameters(self, n_features):
        return n_features + 1

    def _fit_changes(self, X0, y0):
        theta = _gm1n_theta(X0, y0, self.ridge)
        self.development_coefficient_ = float(theta[0])
        self.coef_ = theta[1:]

    def _predict_changes(self, X0):
        a = self.development_coefficient_
        drive = ago(X0) @ self.coef_
        with np.errstate(over="ignore", invalid="ignore"):
            x1 = lfilter([1.0 / (1.0 + a / 2.0)], [1.0, -(1.0 - a / 2.0) / (1.0 + a / 2.0)], drive)
        return iago(x1)
