"""Statistical regressors: ANN (MLP), MLR and PCR, with explicit learned coefficients.

Each wrapper fits a scikit-learn pipeline and then keeps only plain arrays
(``coef_``, ``intercept_``, weights and scalings), so predictions are a few
lines of NumPy and :mod:`models.persistence` can store them without pickle.

* :class:`ANNRegressor` – thesis §6.3.1: a 26-10-1 feed-forward net (one tanh
  hidden layer of 10 units, linear output), standardised inputs and target,
  Adam with early stopping on a 10 % validation split, seeded.
* :class:`MLRRegressor` – ordinary least squares ``y = Xβ + β₀`` (seed 002).
* :class:`PCRRegressor` – principal component regression (seed 004):
  standardise, keep the fewest components whose cumulative explained
  variance reaches ``variance_threshold`` (default 0.85), regress on them.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.decomposition import PCA
from sklearn.linear_model import LinearRegression
from sklearn.neural_network import MLPRegressor
from sklearn.pipeline import Pipeline, make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.utils.validation import check_is_fitted

from ._threads import one_blas_thread
from ._validation import (
    check_n_features,
    require_parameters,
    require_samples,
    validate_x,
    validate_xy,
)
from .registry import register_model


def make_ann_pipeline(hidden_layer_sizes: Sequence[int] = (10,), alpha: float = 1e-4, max_iter: int = 2000,
                      random_state: int | np.random.RandomState | None = None) -> Pipeline:
    """Plain scikit-learn pipeline of the thesis ANN: StandardScaler → tanh MLP, early stopping.

    Parameters
    ----------
    hidden_layer_sizes : sequence of int, default (10,)
        Units per hidden layer.
    alpha : float, default 1e-4
        L2 penalty of the MLP.
    max_iter : int, default 2000
        Most Adam epochs.
    random_state : int, RandomState or None
        Seeds the weights and the early-stopping split.

    Returns
    -------
    Pipeline
        Unfitted ``StandardScaler → MLPRegressor`` (Adam, 10 % early-stopping split, 20 epochs' patience).
    """
    return make_pipeline(
        StandardScaler(),
        MLPRegressor(
            hidden_layer_sizes=hidden_layer_sizes,
            activation="tanh",
            solver="adam",
            alpha=alpha,
            max_iter=max_iter,
            early_stopping=True,
            validation_fraction=0.1,
            n_iter_no_change=20,
            random_state=random_state,
        ),
    )


def _scaling(scaler: StandardScaler):
    return scaler.mean_.copy(), scaler.scale_.copy()


class _LinearPredictor(RegressorMixin, BaseEstimator):
    """Shared ``predict = X @ coef_ + intercept_`` for the linear wrappers."""

    def predict(self, X: ArrayLike) -> NDArray[np.float64]:
        """Linear prediction ``X β + β₀``.

        Parameters
        ----------
        X : array_like, shape (n_samples, n_features)
            Inputs, in the units of the training inputs.

        Returns
        -------
        ndarray, shape (n_samples,)
            Prediction, in the unit of the training target.
        """
        check_is_fitted(self, "coef_")
        X = validate_x(X, what=type(self).__name__)
        check_n_features(self, X)
        return X @ self.coef_ + self.intercept_


@register_model({"mlr": {}})
class MLRRegressor(_LinearPredictor):
    """Multiple linear regression ``y = Σ β_j x_j + β₀``.

    ``standardize=True`` solves on standardised inputs (better conditioned for
    collinear temperatures); ``coef_``/``intercept_`` are always in input
    units, and ``standardized_coef_`` (per input standard deviation) is kept
    for ranking inputs.

    Parameters
    ----------
    standardize : bool, default False
        Solve on standardised inputs.
    """

    def __init__(self, standardize: bool = False):
        self.standardize = standardize

    @one_blas_thread
    def fit(self, X: ArrayLike, y: ArrayLike) -> MLRRegressor:
        """Ordinary least squares on ``X`` (n_samples, n_features).

        Parameters
        ----------
        X : array_like, shape (n_samples, n_features)
            Inputs, in their own units (e.g. °C).
        y : array_like, shape (n_samples,)
            Target, in its own unit (e.g. µm); the prediction has the same unit.

        Returns
        -------
        MLRRegressor
            ``self``, fitted.
        """
        X, y = validate_xy(X, y, what="MLRRegressor")
        require_parameters(X.shape[0], X.shape[1] + 1, f"MLRRegressor ({X.shape[1]} coefficients + intercept)")
        mean, scale = np.zeros(X.shape[1]), np.ones(X.shape[1])
        if self.standardize:
            mean, scale = _scaling(StandardScaler().fit(X))
        lr = LinearRegression().fit((X - mean) / scale, y)
        self.coef_ = lr.coef_ / scale
        self.intercept_ = float(lr.intercept_ - np.dot(self.coef_, mean))
        self.standardized_coef_ = self.coef_ * X.std(axis=0)
        self.n_features_in_ = X.shape[1]
        return self


@register_model({"pcr": {}})
class PCRRegressor(_LinearPredictor):
    """Principal component regression with variance-threshold component selection.

    Parameters
    ----------
    variance_threshold : float, default 0.85
        Keep the fewest principal components whose cumulative explained
        variance ratio is at least this (seed 004 keeps PC1 at > 85 %).
    n_components : int or None
        Fix the number of components instead.

    Attributes
    ----------
    n_components_ : components kept
    explained_variance_ratio_ : (n_features,) of all components
    x_mean_, x_scale_ : standardisation
    components_ : (n_components_, n_features) loadings (standardised units)
    component_coef_ : (n_components_,) regression on the scores
    coef_, intercept_ : equivalent linear model in input units
    """

    def __init__(self, variance_threshold: float = 0.85, n_components: int | None = None):
        self.variance_threshold = variance_threshold
        self.n_components = n_components

    @one_blas_thread
    def fit(self, X: ArrayLike, y: ArrayLike) -> PCRRegressor:
        """Standardise, project on the kept components, regress ``y`` on the scores.

        Parameters
        ----------
        X : array_like, shape (n_samples, n_features)
            Inputs, in their own units (e.g. °C).
        y : array_like, shape (n_samples,)
            Target, in its own unit (e.g. µm); the prediction has the same unit.

        Returns
        -------
        PCRRegressor
            ``self``, fitted.
        """
        X, y = validate_xy(X, y, min_samples=2, what="PCRRegressor")
        if not 0.0 < self.variance_threshold <= 1.0:
            raise ValueError(f"variance_threshold must be in (0, 1], got {self.variance_threshold!r}.")
        self.x_mean_, self.x_scale_ = _scaling(StandardScaler().fit(X))
        Z = (X - self.x_mean_) / self.x_scale_
        pca = PCA(svd_solver="full").fit(Z)
        self.explained_variance_ratio_ = pca.explained_variance_ratio_.copy()
        if self.n_components is None:
            cumulative = np.cumsum(self.explained_variance_ratio_)
            k = int(np.searchsorted(cumulative, self.variance_threshold - 1e-12) + 1)
        else:
            k = int(self.n_components)
        if not 1 <= k <= pca.components_.shape[0]:
            raise ValueError(f"n_components must be in [1, {pca.components_.shape[0]}], got {k}.")
        require_parameters(X.shape[0], k + 1, f"PCRRegressor ({k} component coefficients + intercept)")
        self.n_components_ = k
        self.components_ = pca.components_[:k].copy()
        lr = LinearRegression().fit(Z @ self.components_.T, y)
        self.component_coef_ = lr.coef_.copy()
        self.coef_ = (self.components_.T @ self.component_coef_) / self.x_scale_
        self.intercept_ = float(lr.intercept_ - np.dot(self.coef_, self.x_mean_))
        self.n_features_in_ = X.shape[1]
        return self


@register_model({"ann": {"random_state": 0}})
class ANNRegressor(RegressorMixin, BaseEstimator):
    """Feed-forward ANN of thesis §6.3.1 (default one hidden layer of 10 tanh units).

    Inputs and target are standardised; the network is trained by
    :func:`make_ann_pipeline` (Adam, early stopping, seeded) and its weights
    are then stored as arrays: ``coefs_``/``intercepts_`` (lists, one per
    layer), ``x_mean_``, ``x_scale_``, ``y_mean_``, ``y_scale_``.

    Parameters
    ----------
    hidden_layer_sizes : sequence of int, default (10,)
        Units per hidden layer.
    alpha : float, default 1e-4
        L2 penalty.
    max_iter : int, default 2000
        Most Adam epochs.
    random_state : int, RandomState or None
        Seeds the weights and the early-stopping split.
    """

    def __init__(self, hidden_layer_sizes: Sequence[int] = (10,), alpha: float = 1e-4, max_iter: int = 2000,
                 random_state: int | np.random.RandomState | None = None):
        self.hidden_layer_sizes = hidden_layer_sizes
        self.alpha = alpha
        self.max_iter = max_iter
        self.random_state = random_state

    @one_blas_thread
    def fit(self, X: ArrayLike, y: ArrayLike) -> ANNRegressor:
        """Train the network on ``X`` (n_samples, n_features), ``y`` (n_samples,).

        Parameters
        ----------
        X : array_like, shape (n_samples, n_features)
            Inputs, in their own units (e.g. °C).
        y : array_like, shape (n_samples,)
            Target, in its own unit (e.g. µm); the prediction has the same unit.

        Returns
        -------
        ANNRegressor
            ``self``, fitted.
        """
        X, y = validate_xy(X, y, what="ANNRegressor")
        sizes = [X.shape[1], *self.hidden_layer_sizes, 1]
        n_weights = sum((a + 1) * b for a, b in zip(sizes[:-1], sizes[1:]))
        n_min = n_weights + 1  # fewest samples whose 90 % left after the early-stopping split exceed the weights
        while n_min - int(np.ceil(0.1 * n_min)) <= n_weights:
            n_min += 1
        require_parameters(X.shape[0], n_weights, f"ANNRegressor ({'-'.join(map(str, sizes))} network)",
                           lost=n_min - n_weights - 1, lost_reason="10 % of them are the early-stopping split")
        require_samples(X.shape[0], 20, "ANNRegressor (10 % early-stopping split)")
        pipeline = make_ann_pipeline(
            tuple(self.hidden_layer_sizes), self.alpha, self.max_iter, self.random_state
        )
        self.y_mean_, self.y_scale_ = float(y.mean()), float(y.std() or 1.0)
        pipeline.fit(X, (y - self.y_mean_) / self.y_scale_)
        scaler, mlp = pipeline[0], pipeline[-1]
        self.x_mean_, self.x_scale_ = _scaling(scaler)
        self.coefs_ = [w.copy() for w in mlp.coefs_]
        self.intercepts_ = [b.copy() for b in mlp.intercepts_]
        self.n_iter_ = int(mlp.n_iter_)
        self.n_features_in_ = X.shape[1]
        return self

    def predict(self, X: ArrayLike) -> NDArray[np.float64]:
        """Forward pass: tanh hidden layers, linear output, de-standardised.

        Parameters
        ----------
        X : array_like, shape (n_samples, n_features)
            Inputs, in the units of the training inputs.

        Returns
        -------
        ndarray, shape (n_samples,)
            Prediction, in the unit of the training target.
        """
        check_is_fitted(self, "coefs_")
        X = validate_x(X, what="ANNRegressor")
        check_n_features(self, X)
        h = (X - self.x_mean_) / self.x_scale_
        for w, b in zip(self.coefs_[:-1], self.intercepts_[:-1]):
            h = np.tanh(h @ w + b)
        out = h @ self.coefs_[-1] + self.intercepts_[-1]
        return out[:, 0] * self.y_scale_ + self.y_mean_
