"""GMC(1,N): grey model with convolution integral and delay r (Tien; thesis §3.6, Eqs 3.13–3.14).

Whitening equation on zero-referenced AGO series, with delay r (in samples):

    dx₁¹(t+r)/dt + b₁ x₁¹(t+r) = b₂ x₂¹(t) + … + b_N x_N¹(t) + u

b₁ is the development coefficient (1/sample), b₂..b_N the driving
coefficients, u the grey control parameter. Its response is the convolution
``x₁¹(t) = x₁¹(1) e^{-b₁(t-1)} + ∫₁ᵗ e^{-b₁(t-s)} f(s) ds`` with
``f = Σ_j b_j x_j¹ + u``, discretised by the trapezoid rule (Eq 3.14, with the
corrected last term ½f(t), not ½f(τ)):

    x̂₁¹(t) = x₁¹(1)e^{-b₁(t-1)} + ½e^{-b₁(t-1)}f(1) + Σ_{τ=2}^{t-1} e^{-b₁(t-τ)}f(τ) + ½f(t)

evaluated as the recursion ``S(t) = q S(t-1) + ½(f(t) + q f(t-1))``,
``q = e^{-b₁}``, in O(n). Prediction is the IAGO of x̂₁¹. With zero-referenced
data x₁¹(1) = 0, and the output is taken at rest for the first r samples.

Calibration:

* ``"ls"`` – Tien's least-squares form (digest §5.4; not printed in the
  thesis): ``x₁⁰(k) = -b₁ z₁¹(k) + Σ_j b_j z_j¹(k) + u``, k = 2..n.
* ``"pso"`` – particle swarm on ``[b₁, …, b_N, u]`` minimising the SSE of the
  de-accumulated output (Eq 3.17), 90 particles × 100 epochs, c1 = c2 = 2,
  ω 0.9 → 0.4 (thesis §6.3.2). Unless ``pso_bounds`` is given, the search
  box is the LS estimate ± (2|θ_LS| + 0.1 max|θ_LS|) with b₁ ≥ 0 (stable),
  and one particle starts at the LS estimate (clipped into the box), so PSO
  refines LS towards the output-error optimum.

The LS estimate itself is not constrained: on collinear inputs it can give
b₁ < 0, an unstable model whose prediction grows without bound; the
``development_coefficient_`` attribute tells.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.signal import lfilter

from .grey import GreySeriesRegressor, ago, background_values, grey_least_squares, iago
from .pso import PSOResult, particle_swarm_minimize
from .registry import register_model

if TYPE_CHECKING:
    from .gnnmci import GNNMCIRegressor


def convolution_response(f: ArrayLike, development_coefficient: float,
                         rule: Literal["trapezoid", "midpoint"] = "trapezoid") -> NDArray[np.float64]:
    """``S(t) ≈ ∫₁ᵗ e^{-b₁(t-s)} f(s) ds`` for t = 1..n (S(1) = 0), by recursion.

    ``rule="trapezoid"``: ``S(t) = q S(t-1) + ½(f(t) + q f(t-1))`` (Eq 3.14).
    ``rule="midpoint"``: ``S(t) = q S(t-1) + ½ q^{½} (f(t) + f(t-1))``, Tien's
    form used by GNNMCI (Eq A.2). ``f`` may be (n,) or (n, m) (columns are
    filtered independently).

    Parameters
    ----------
    f : array_like, shape (n,) or (n, m)
        The drive f(t), t = 1..n (one sample per time step).
    development_coefficient : float
        b₁, in 1/sample.
    rule : {"trapezoid", "midpoint"}, default "trapezoid"
        Quadrature of the convolution (see above).

    Returns
    -------
    ndarray, shape of ``f``
        S(t), in the unit of ``f`` × samples.
    """
    q = np.exp(-development_coefficient)
    if rule == "trapezoid":
        b = [0.5, 0.5 * q]
    elif rule == "midpoint":
        b = [0.5 * np.sqrt(q), 0.5 * np.sqrt(q)]
    else:
        raise ValueError(f"rule must be 'trapezoid' or 'midpoint', got {rule!r}.")
    f = np.asarray(f, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        s = lfilter(b, [1.0, -q], f, axis=0)
        # lfilter starts from f(0) = 0, which adds b₀ f(1) q^{t-1}; remove it
        decay = q ** np.arange(f.shape[0], dtype=np.float64)
        s -= b[0] * np.multiply.outer(decay, f[0]) if f.ndim > 1 else b[0] * f[0] * decay
    return s


def deaccumulated_response(f: ArrayLike, development_coefficient: float) -> NDArray[np.float64]:
    """Model output ``x̂₁⁰ = IAGO(S)`` for the drive ``f`` (zero initial state), trapezoid rule.

    Parameters
    ----------
    f : array_like, shape (n,)
        The drive ``Σ_j b_j x_j¹ + u``, one sample per time step.
    development_coefficient : float
        b₁, in 1/sample.

    Returns
    -------
    ndarray, shape (n,)
        x̂₁⁰, in the unit of the target series.
    """
    return iago(convolution_response(f, development_coefficient))


def pso_search_box(theta_ls: ArrayLike) -> NDArray[np.float64]:
    """Default PSO bounds (dim, 2) around ``θ_LS = [b₁, …]``: θ_LS ± (2|θ_LS| + 0.1 max|θ_LS|).

    The development coefficient b₁ is kept in [0, …): a thermal response
    decays, and b₁ < 0 gives an exponentially growing output that explodes
    on any long prediction.

    Parameters
    ----------
    theta_ls : array_like, shape (dim,)
        Least-squares estimate ``[b₁, b₂..b_N, u]`` (see :func:`tien_least_squares`).

    Returns
    -------
    ndarray, shape (dim, 2)
        Lower and upper bound of each parameter.
    """
    theta_ls = np.asarray(theta_ls, dtype=np.float64)
    half = 2.0 * np.abs(theta_ls) + 0.1 * max(np.max(np.abs(theta_ls)), 1e-12)
    box = np.column_stack([theta_ls - half, theta_ls + half])
    box[0] = [max(box[0, 0], 0.0), max(box[0, 1], 1e-3)]
    return box


def tien_least_squares(X0: NDArray[np.float64], y0: NDArray[np.float64], ridge: float = 0.0) -> NDArray[np.float64]:
    """``[b₁, b₂..b_N, u]`` from ``x₁⁰(k) = -b₁ z₁¹(k) + Σ b_j z_j¹(k) + u``, k = 2..n.

    Parameters
    ----------
    X0 : ndarray, shape (n, n_features)
        Zero-referenced inputs x_j⁰.
    y0 : ndarray, shape (n,)
        Zero-referenced target x₁⁰.
    ridge : float, default 0.0
        Relative ridge of the solve (see :func:`models.grey.grey_least_squares`).

    Returns
    -------
    ndarray, shape (n_features + 2,)
        ``[b₁ (1/sample), b₂..b_N, u]``.
    """
    Z = background_values(ago(X0))
    B = np.column_stack([-background_values(ago(y0)), Z, np.ones(Z.shape[0])])
    return grey_least_squares(B, y0[1:], ridge)


def run_swarm(estimator: GMCRegressor | GNNMCIRegressor,
              objective: Callable[[NDArray[np.float64]], NDArray[np.float64]], box: NDArray[np.float64],
              start: ArrayLike) -> PSOResult:
    """PSO with the estimator's swarm settings (``n_particles``, ``epochs``, ``c1``,
    ``c2``, ``inertia``, ``random_state``); one particle at ``start`` if
    ``estimator.init_from_ls``.

    Parameters
    ----------
    estimator : GMCRegressor or GNNMCIRegressor
        Holds the swarm settings.
    objective : callable
        Positions (n_particles, dim) → fitness (n_particles,) (vectorised).
    box : ndarray, shape (dim, 2)
        Search box.
    start : array_like, shape (dim,)
        The least-squares estimate, a starting particle (clipped into the box).

    Returns
    -------
    PSOResult
        See :func:`models.pso.particle_swarm_minimize`.
    """
    return particle_swarm_minimize(
        objective,
        box,
        n_particles=estimator.n_particles,
        max_iter=estimator.epochs,
        inertia=tuple(estimator.inertia),
        c1=estimator.c1,
        c2=estimator.c2,
        initial_positions=np.asarray(start)[None] if estimator.init_from_ls else None,
        random_state=estimator.random_state,
    )


@register_model({"gmc": {"random_state": 0}}, time_series=True)
class GMCRegressor(GreySeriesRegressor):
    """GMC(1,N) with delay, calibrated by least squares or PSO.

    Parameters
    ----------
    delay : int, default 0
        r, in samples: y(t + r) responds to X(t).
    calibration : {"ls", "pso"}, default "ls"
    ridge : float, default 0.0
        Relative ridge of the LS solve (see ``grey_least_squares``).
    n_particles, epochs, c1, c2, inertia :
        PSO settings (thesis: 90, 100, 2, 2, (0.9, 0.4)).
    pso_bounds : array-like (n_features + 2, 2) or None
        Search box for ``[b₁, b₂..b_N, u]``; None centres it on the LS
        estimate (see :func:`pso_search_box`).
    init_from_ls : bool, default True
        Start one particle at the LS estimate.
    random_state : int, RandomState or None
        Seeds the swarm.

    Attributes
    ----------
    development_coefficient_ : b₁ (1/sample)
    coef_ : (n_features,) driving coefficients b₂..b_N
    control_ : u
    n_iter_ : PSO epochs run (``calibration="pso"`` only)
    y_reference_ : first training target
    """

    def __init__(
        self,
        delay: int = 0,
        calibration: Literal["ls", "pso"] = "ls",
        ridge: float = 0.0,
        n_particles: int = 90,
        epochs: int = 100,
        c1: float = 2.0,
        c2: float = 2.0,
        inertia: tuple[float, float] = (0.9, 0.4),
        pso_bounds: ArrayLike | None = None,
        init_from_ls: bool = True,
        random_state: int | np.random.RandomState | None = None,
    ):
        self.delay = delay
        self.calibration = calibration
        self.ridge = ridge
        self.n_particles = n_particles
        self.epochs = epochs
        self.c1 = c1
        self.c2 = c2
        self.inertia = inertia
        self.pso_bounds = pso_bounds
        self.init_from_ls = init_from_ls
        self.random_state = random_state

    def _n_parameters(self, n_features):
        return n_features + 2  # b₁, b₂..b_N, u

    def _samples_without_equation(self):
        r = int(self.delay)
        if r == 0:
            return super()._samples_without_equation()
        return 1 + r, f"the first and the {r} lost to the delay give no equation"

    def _fit_changes(self, X0, y0):
        r = int(self.delay)
        if r < 0:
            raise ValueError(f"delay must be >= 0, got {self.delay!r}.")
        if self.calibration not in ("ls", "pso"):
            raise ValueError(f"calibration must be 'ls' or 'pso', got {self.calibration!r}.")
        X0, y0 = X0[: X0.shape[0] - r], y0[r:]
        theta = tien_least_squares(X0, y0, self.ridge)
        if self.calibration == "pso":
            X1 = ago(X0)

            def sse(particles):
                drive = X1 @ particles[:, 1:-1].T + particles[:, -1]  # (n, P)
                out = np.empty(particles.shape[0])
                with np.errstate(over="ignore", invalid="ignore"):  # unstable b₁ → inf, never best
                    for p, b1 in enumerate(particles[:, 0]):
                        out[p] = np.sum((deaccumulated_response(drive[:, p], b1) - y0) ** 2)
                return out

            box = pso_search_box(theta) if self.pso_bounds is None else np.asarray(self.pso_bounds, float)
            result = run_swarm(self, sse, box, theta)
            theta = result.position
            self.n_iter_ = result.n_iter
        self.development_coefficient_ = float(theta[0])
        self.coef_ = theta[1:-1].copy()
        self.control_ = float(theta[-1])

    def _predict_changes(self, X0):
        r = int(self.delay)
        out = np.zeros(X0.shape[0])
        drive = ago(X0[: X0.shape[0] - r]) @ self.coef_ + self.control_
        out[r:] = deaccumulated_response(drive, self.development_coefficient_)
        return out
