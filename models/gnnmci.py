"""GNNMCI(1,N): grey neural network with convolution integral (thesis Appendix A).

GMC(1,N) in Tien's form (Eq A.2, index-consistent reading)

    x̂₁¹(t) = x₁¹(1) e^{-b₁(t-1)} + Σ_{τ=2}^{t} e^{-b₁(t-τ+½)} · ½[f(τ) + f(τ-1)]

(the appendix re-indexes t → k+1 but keeps the bounds τ = 1..k with f(τ-1),
which would need f(0); the kernel exponent k - τ + ½ fixes the interval
[τ-1, τ] used here) is mapped onto a four-layer network whose input is the
time index k = t - 1 and whose weights are trained by PSO (Eqs A.5–A.9):

* Layer A: ``a = w₁₁ k`` (w₁₁ = b₁, development coefficient)
* Layer B: ``b = 1 / (1 + e^{-a})`` (sigmoid)
* Layer C: ``c₁ = b w₂₁``; ``c_j = b w₂ⱼ C_j(k)`` for each driving input and
  ``c_u = b w₂ᵤ C_u(k)``, where ``C_j`` is the AGO input ``x_j¹`` and
  ``C_u`` the unit series, both passed through the convolution kernel of
  Eq A.3 (without it the network would be a static regression)
* Layer D: ``d = w₃ Σ c - θ`` with ``w₃ = 1 + e^{-w₁₁ k}`` and the bias
  ``θ = w₂₁ (1 + e^{-w₁₁ k})`` (Eq A.6, read with the initial value
  x₁¹(1) = -w₂₁; as printed it would depend on the output itself).

Because ``b · w₃ = 1``, ``d = -w₂₁ e^{-w₁₁ k} + Σ_j w₂ⱼ C_j + w₂ᵤ C_u``, i.e.
Eq A.4 exactly; w₂₁ is a free weight (≈ 0 for zero-referenced data, thesis:
0.001). The output is de-accumulated (IAGO) for prediction, and the PSO
fitness is the SSE of that de-accumulated output (Eq A.9). PSO settings
follow thesis §5.4: 90 particles, 100 epochs, c1 = 1.5, c2 = 2,
ω 0.9 → 0.4. The development coefficient is bounded to w₁₁ ≥ 0 (a stable,
decaying kernel), which also keeps ``e^{-w₁₁ k}`` from overflowing.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import expit

from .gmc import convolution_response, pso_search_box, run_swarm, tien_least_squares
from .grey import GreySeriesRegressor, ago, iago
from .registry import register_model


def network_output(weights: ArrayLike, X1: NDArray[np.float64]) -> NDArray[np.float64]:
    """Layer-D output x̂₁¹ in the algebraically reduced form of Eq A.4 (b · w₃ = 1).

    ``-w₂₁ e^{-w₁₁ k} + conv(Σ_j w₂ⱼ x_j¹ + w₂ᵤ)``: one convolution per weight
    vector instead of one per input, which is what PSO evaluates.

    Parameters
    ----------
    weights : array_like, shape (n_inputs + 3,)
        ``[w₁₁ (1/sample), w₂₁, w₂₂..w₂ₙ, w₂ᵤ]``.
    X1 : ndarray, shape (n, n_inputs)
        AGO inputs x_j¹.

    Returns
    -------
    ndarray, shape (n,)
        x̂₁¹, the accumulated target estimate.
    """
    weights = np.asarray(weights, dtype=np.float64)
    w11, w21, w2 = weights[0], weights[1], weights[2:]
    k = np.arange(X1.shape[0], dtype=np.float64)
    drive = X1 @ w2[:-1] + w2[-1]
    return -w21 * np.exp(-w11 * k) + convolution_response(drive, w11, "midpoint")


def network_layers(weights: ArrayLike, X1: NDArray[np.float64]) -> dict[str, NDArray[np.float64]]:
    """Layer outputs A–D for one weight vector ``[w₁₁, w₂₁, w₂₂..w₂ₙ, w₂ᵤ]``.

    ``X1`` is the (n, n_inputs) AGO input. Returns ``a``, ``b`` (n,),
    ``c`` (n, n_inputs + 2) and ``d`` (n,), the network estimate of x̂₁¹.
    This is the thesis's layer-by-layer mapping, for inspection;
    :func:`network_output` gives the same ``d`` faster.

    Parameters
    ----------
    weights : array_like, shape (n_inputs + 3,)
        ``[w₁₁ (1/sample), w₂₁, w₂₂..w₂ₙ, w₂ᵤ]``.
    X1 : ndarray, shape (n, n_inputs)
        AGO inputs x_j¹.

    Returns
    -------
    dict of str to ndarray
        ``a``, ``b`` (n,), ``c`` (n, n_inputs + 2), ``d`` (n,).
    """
    weights = np.asarray(weights, dtype=np.float64)
    w11, w21, w2 = weights[0], weights[1], weights[2:]
    k = np.arange(X1.shape[0], dtype=np.float64)
    a = w11 * k
    b = expit(a)
    drivers = convolution_response(np.column_stack([X1, np.ones(X1.shape[0])]), w11, "midpoint")
    c = np.column_stack([b * w21, b[:, None] * w2[None, :] * drivers])
    w3 = 1.0 + np.exp(-a)
    theta = w21 * w3
    d = w3 * c.sum(axis=1) - theta
    return {"a": a, "b": b, "c": c, "d": d}


@register_model({"gnnmci": {"random_state": 0}}, time_series=True)
class GNNMCIRegressor(GreySeriesRegressor):
    """GNNMCI(1,N) trained by PSO (thesis Appendix A).

    Parameters
    ----------
    n_particles, epochs, c1, c2, inertia :
        PSO settings (thesis §5.4: 90, 100, 1.5, 2, (0.9, 0.4)).
    pso_bounds : array-like (n_features + 3, 2) or None
        Box for ``[w₁₁, w₂₁, w₂₂..w₂ₙ, w₂ᵤ]``. None centres it on the Tien
        least-squares estimate (:func:`~models.gmc.pso_search_box`, w₁₁ ≥ 0)
        with w₂₁ in ±(0.1 max|θ_LS|).
    init_from_ls : bool, default True
        Start one particle at the least-squares weights.
    random_state : int, RandomState or None

    Attributes
    ----------
    weights_ : (n_features + 3,) ``[w₁₁, w₂₁, w₂₂..w₂ₙ, w₂ᵤ]``
    development_coefficient_ : w₁₁
    n_iter_ : PSO epochs run
    y_reference_ : first training target
    """

    def __init__(
        self,
        n_particles: int = 90,
        epochs: int = 100,
        c1: float = 1.5,
        c2: float = 2.0,
        inertia: tuple[float, float] = (0.9, 0.4),
        pso_bounds: ArrayLike | None = None,
        init_from_ls: bool = True,
        random_state: int | np.random.RandomState | None = None,
    ):
        self.n_particles = n_particles
        self.epochs = epochs
        self.c1 = c1
        self.c2 = c2
        self.inertia = inertia
        self.pso_bounds = pso_bounds
        self.init_from_ls = init_from_ls
        self.random_state = random_state

    def _n_parameters(self, n_features):
        return n_features + 3

    def _fit_changes(self, X0, y0):
        X1 = ago(X0)
        theta = tien_least_squares(X0, y0)  # [b₁, b₂..b_N, u]
        start = np.concatenate([[theta[0], 0.0], theta[1:]])  # clipped into the box by PSO
        if self.pso_bounds is None:
            box = pso_search_box(theta)
            w21_half = 0.1 * max(np.max(np.abs(theta)), 1e-12)
            box = np.vstack([box[:1], [[-w21_half, w21_half]], box[1:]])
        else:
            box = np.asarray(self.pso_bounds, dtype=np.float64)
            if box[0, 0] < 0.0:
                raise ValueError("GNNMCI needs a development coefficient w11 >= 0 (pso_bounds[0]).")

        def sse(particles):
            with np.errstate(over="ignore", invalid="ignore"):
                return np.array([np.sum((iago(network_output(w, X1)) - y0) ** 2) for w in particles])

        result = run_swarm(self, sse, box, start)
        self.weights_ = result.position
        self.n_iter_ = result.n_iter
        self.development_coefficient_ = float(result.position[0])

    def _predict_changes(self, X0):
        return iago(network_output(self.weights_, ago(X0)))
