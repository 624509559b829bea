"""Particle swarm optimisation, vectorised over particles (Eberhart & Kennedy; thesis §3.5.1).

Velocity and position updates (Eqs 3.15–3.16 / A.7–A.8), with r1, r2 drawn
independently per particle and dimension (standard PSO; the thesis prints a
single R):

    V ← ω_k V + c1 r1 (Pbest - B) + c2 r2 (Gbest - B),    B ← B + V

The inertia ω_k falls linearly from ``inertia[0]`` to ``inertia[1]`` over
``max_iter`` epochs (0.9 → 0.4, thesis). Not given in the thesis and chosen
here: velocities are clamped to ``velocity_clamp × (upper - lower)`` per
dimension, and positions are clipped to the bounds with the velocity of a
clipped component set to zero (an absorbing wall). Non-finite fitness counts
as +inf, so a particle in a region where the model blows up is never best.
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike
from sklearn.utils import check_random_state

from ._validation import check_positive_int


@dataclass(frozen=True)
class PSOResult:
    """Outcome of :func:`particle_swarm_minimize`.

    ``position`` is the best position found, ``fitness`` its objective value,
    ``n_iter`` the epochs run and ``history`` the best fitness after each epoch.
    """

    position: np.ndarray
    fitness: float
    n_iter: int
    history: np.ndarray


def _as_bounds(bounds) -> tuple[np.ndarray, np.ndarray]:
    bounds = np.asarray(bounds, dtype=np.float64)
    if bounds.ndim != 2 or bounds.shape[1] != 2:
        raise ValueError(f"bounds must have shape (dim, 2), got {bounds.shape}.")
    lower, upper = bounds[:, 0], bounds[:, 1]
    if not np.all(np.isfinite(bounds)) or np.any(upper <= lower):
        raise ValueError("every bound must be finite with lower < upper.")
    return lower, upper


def particle_swarm_minimize(
    objective: Callable[[np.ndarray], np.ndarray | float],
    bounds: ArrayLike,
    *,
    n_particles: int = 90,
    max_iter: int = 100,
    inertia: tuple[float, float] = (0.9, 0.4),
    c1: float = 2.0,
    c2: float = 2.0,
    velocity_clamp: float = 0.2,
    tol: float = 0.0,
    n_iter_no_change: int | None = None,
    vectorized: bool = True,
    initial_positions: ArrayLike | None = None,
    random_state: int | np.random.RandomState | None = None,
) -> PSOResult:
    """Minimise ``objective`` over the box ``bounds`` with a particle swarm.

    Parameters
    ----------
    objective : callable
        If ``vectorized``, maps positions (n_particles, dim) to fitness
        (n_particles,); otherwise maps one position (dim,) to a float.
    bounds : array-like (dim, 2)
        Lower and upper bound of each dimension.
    n_particles, max_iter : int
        Swarm size M and epochs (thesis: 90 and 100).
    inertia : (ω_start, ω_end)
        Linearly decreasing inertia weight.
    c1, c2 : float
        Cognitive (self) and social (swarm) acceleration constants.
    velocity_clamp : float
        Maximum speed per epoch as a fraction of each dimension's range.
    tol, n_iter_no_change : float, int or None
        Early stop once the best fitness has improved by no more than
        ``tol × |best|`` for ``n_iter_no_change`` consecutive epochs.
        ``None`` runs all epochs.
    vectorized : bool, default True
        Whether ``objective`` takes the whole swarm at once.
    initial_positions : array-like (k, dim), optional
        Positions for the first k particles (e.g. a least-squares estimate);
        the others start uniformly at random.
    random_state : int, RandomState or None
        Same seed ⇒ identical result.

    Returns
    -------
    PSOResult
        The best position and fitness, the epochs run and the best fitness after each.
    """
    lower, upper = _as_bounds(bounds)
    dim = lower.size
    n_particles = check_positive_int(n_particles, "n_particles")
    max_iter = check_positive_int(max_iter, "max_iter")
    rng = check_random_state(random_state)
    span = upper - lower
    v_max = velocity_clamp * span

    def evaluate(positions):
        if vectorized:
            values = np.asarray(objective(positions), dtype=np.float64).reshape(-1)
        else:
            values = np.array([objective(p) for p in positions], dtype=np.float64)
        if values.shape != (positions.shape[0],):
            raise ValueError(
                f"objective returned shape {values.shape}, expected ({positions.shape[0]},)."
            )
        return np.where(np.isfinite(values), values, np.inf)

    positions = lower + rng.random_sample((n_particles, dim)) * span
    if initial_positions is not None:
        seeds = np.atleast_2d(np.asarray(initial_positions, dtype=np.float64))
        if seeds.shape[1] != dim or seeds.shape[0] > n_particles:
            raise ValueError(f"initial_positions must have shape (<= {n_particles}, {dim}).")
        positions[: seeds.shape[0]] = np.clip(seeds, lower, upper)
    velocities = (2.0 * rng.random_sample((n_particles, dim)) - 1.0) * v_max

    fitness = evaluate(positions)
    pbest, pbest_fit = positions.copy(), fitness.copy()
    g = int(np.argmin(pbest_fit))
    gbest, gbest_fit = pbest[g].copy(), float(pbest_fit[g])

    history = []
    stall = 0
    w_start, w_end = inertia
    for epoch in range(max_iter):
        w = w_start - (w_start - w_end) * epoch / max(max_iter - 1, 1)
        r1 = rng.random_sample((n_particles, dim))
        r2 = rng.random_sample((n_particles, dim))
        velocities = w * velocities + c1 * r1 * (pbest - positions) + c2 * r2 * (gbest - positions)
        np.clip(velocities, -v_max, v_max, out=velocities)
        positions = positions + velocities
        outside = (positions < lower) | (positions > upper)
        positions = np.clip(positions, lower, upper)
        velocities[outside] = 0.0

        fitness = evaluate(positions)
        better = fitness < pbest_fit
        pbest[better], pbest_fit[better] = positions[better], fitness[better]
        g = int(np.argmin(pbest_fit))
        previous = gbest_fit
        if pbest_fit[g] < gbest_fit:
            gbest, gbest_fit = pbest[g].copy(), float(pbest_fit[g])
        history.append(gbest_fit)

        if n_iter_no_change is not None:
            improved = previous - gbest_fit > tol * abs(previous)
            stall = 0 if improved else stall + 1
            if stall >= n_iter_no_change:
                break
    return PSOResult(gbest, gbest_fit, len(history), np.asarray(history))
