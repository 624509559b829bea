"""Time histories of a thermal system's named inputs (ambient °C, power W, …) and their means over time steps.

The θ-method is driven by the mean of each input over each step, so that the
energy a load injects in a step is exactly ∫ u dt whatever the step grid:
a heat source switched off in the middle of a step injects its power for
the part of the step it ran.  :func:`interval_means` computes those means by
Gauss–Legendre quadrature on the sub-intervals between the step times and
the inputs' *breakpoints* (the times where an input jumps or kinks), which
is exact for inputs that are polynomials of degree ≤ 5 between breakpoints:
piecewise-constant duty cycles, piecewise-linear samples.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from .errors import FEAInputError

if TYPE_CHECKING:
    from .heat import ThermalSystem

#: Gauss–Legendre nodes per sub-interval: exact for polynomials of degree ≤ 2·3 − 1 = 5.
QUADRATURE_NODES = 3
#: Sub-intervals evaluated at once (bounds the temporary arrays of long runs).
QUADRATURE_CHUNK = 2**16


def interval_means(values_at: Callable[[np.ndarray], np.ndarray], times_s: np.ndarray,
                   breakpoints_s: Sequence[float] | np.ndarray = (), nodes: int = QUADRATURE_NODES) -> np.ndarray:
    """Mean of a vector-valued input over each interval [tᵢ, tᵢ₊₁] of ``times_s``.

    Each interval is split at the breakpoints inside it and every piece
    integrated by Gauss–Legendre quadrature; the input is evaluated only
    inside pieces, so a value exactly at a jump is never used.

    Parameters
    ----------
    values_at : callable
        ``values_at(t)`` returns the input at times ``t`` (k,) as (k, m) or (k,).
    times_s : ndarray
        Interval ends, s, increasing.
    breakpoints_s : sequence of float
        Times where the input jumps or kinks, s.
    nodes : int
        Gauss–Legendre points per piece.

    Returns
    -------
    ndarray, shape (len(times_s) − 1, m)
        The means, in the input's units.
    """
    t = np.asarray(times_s, float)
    cuts = np.asarray(breakpoints_s, float).ravel()
    edges = np.union1d(t, cuts[(cuts > t[0]) & (cuts < t[-1])])
    x, w = np.polynomial.legendre.leggauss(nodes)
    interval = np.searchsorted(t, edges[:-1], side="right") - 1          # the step each piece lies in
    sums = None
    for start in range(0, len(edges) - 1, QUADRATURE_CHUNK):
        a, b = edges[:-1][start:start + QUADRATURE_CHUNK], edges[1:][start:start + QUADRATURE_CHUNK]
        half = 0.5 * (b - a)
        points = (0.5 * (a + b))[:, None] + half[:, None] * x
        values = np.asarray(values_at(points.ravel()), float)
        values = values.reshape(len(a), nodes, -1)
        pieces = np.einsum("pnm,pn->pm", values, half[:, None] * w)
        if sums is None:
            sums = np.zeros((len(t) - 1, pieces.shape[1]))
        np.add.at(sums, interval[start:start + len(a)], pieces)
    return sums / np.diff(t)[:, None]


def step_means(schedule: InputSchedule, step_times_s: np.ndarray, theta: float) -> np.ndarray:
    """Inputs driving each step of the θ-method: the schedule's step means.

    A schedule without ``means`` (an object with ``sample`` only, e.g. a
    measured record whose samples describe the interval before them) is
    taken at its θ-weighted step ends, θ u(tᵢ₊₁) + (1 − θ) u(tᵢ).

    Parameters
    ----------
    schedule : InputSchedule
        Or any object with ``sample(times)`` and optionally ``means(step_times)``.
    step_times_s : ndarray
        Step ends, s.
    theta : float
        The scheme's θ.

    Returns
    -------
    ndarray, shape (len(step_times_s) − 1, n_inputs)
        Inputs per step.
    """
    means = getattr(schedule, "means", None)
    if means is not None:
        return np.asarray(means(step_times_s), float)
    u = schedule.sample(step_times_s)
    return theta * u[1:] + (1.0 - theta) * u[:-1]


class SampledSeries:
    """A piecewise-linear input from samples ``(times_s, values)``; held constant outside them.

    Parameters
    ----------
    times_s : ndarray
        Sample times, s, strictly increasing.
    values : ndarray
        Samples, in the input's unit.
    name : str
        Named in errors.
    """

    def __init__(self, times_s: np.ndarray, values: np.ndarray, name: str = "series") -> None:
        t = np.asarray(times_s, dtype=float)
        v = np.asarray(values, dtype=float)
        if t.ndim != 1 or t.shape != v.shape or len(t) == 0:
            raise FEAInputError(f"{name}: times and values must be 1-D of equal length, got {t.shape} and {v.shape}")
        if not np.isfinite(t).all() or not np.isfinite(v).all():
            raise FEAInputError(f"{name}: samples must be finite")
        if np.any(np.diff(t) <= 0):
            i = int(np.flatnonzero(np.diff(t) <= 0)[0])
            raise FEAInputError(f"{name}: time must increase strictly, but t[{i + 1}] = {t[i + 1]} "
                                f"follows t[{i}] = {t[i]}")
        self.times_s, self.values, self.name = t, v, name

    def __call__(self, t):
        return np.interp(t, self.times_s, self.values)

    @property
    def breakpoints_s(self) -> np.ndarray:
        """Where the series kinks: its sample times, s."""
        return self.times_s


class InputSchedule:
    """Evaluates the input vector ``u(t)`` of a :class:`~fea.heat.ThermalSystem` and its step means.

    ``sources`` maps each input name to a number, a vectorised callable
    ``f(t_s) -> value`` or a :class:`SampledSeries`.  Constant inputs set in
    the problem itself are filled in.  ``breakpoints_s`` lists the times
    where a callable input jumps or kinks (e.g. when a heater switches), so
    that step means are exact however the steps fall (a
    :class:`SampledSeries` gives its own).  A missing or unknown name, or a
    value that is not finite, raises :class:`FEAInputError` naming it and the time.

    Parameters
    ----------
    system : ThermalSystem
        Gives the input names.
    sources : dict
        Input name → number, callable ``f(t_s) -> value`` or :class:`SampledSeries`.
    breakpoints_s : sequence of float
        Jumps and kinks of the callable inputs, s.
    """

    def __init__(self, system: ThermalSystem, sources: dict[str, float | Callable | SampledSeries],
                 breakpoints_s: Sequence[float] = ()) -> None:
        self.names = list(system.input_names)
        given = dict(system.constant_inputs)
        given.update(sources)
        unknown = sorted(set(given) - set(self.names))
        if unknown:
            raise FEAInputError(f"unknown input(s) {unknown}; the system's inputs are {self.names}")
        missing = [n for n in self.names if n not in given]
        if missing:
            raise FEAInputError(f"no value given for input(s) {missing}")
        self.sources = [given[n] for n in self.names]
        cuts = [np.asarray(breakpoints_s, float).ravel()]
        cuts += [s.breakpoints_s for s in self.sources if isinstance(s, SampledSeries)]
        self.breakpoints_s = np.unique(np.concatenate(cuts))

    def sample(self, times_s: np.ndarray) -> np.ndarray:
        """The inputs at some times.

        Parameters
        ----------
        times_s : ndarray
            Times, s.

        Returns
        -------
        ndarray, shape (len(times_s), n_inputs)
            Input values (°C, K/m, W, …).
        """
        t = np.atleast_1d(np.asarray(times_s, dtype=float))
        out = np.empty((len(t), len(self.names)))
        for j, source in enumerate(self.sources):
            if callable(source):
                try:
                    values = np.broadcast_to(np.asarray(source(t), dtype=float), t.shape)
                except (TypeError, ValueError):
                    values = np.array([float(source(x)) for x in t])
            else:
                values = np.full(t.shape, float(source))
            out[:, j] = values
        bad = ~np.isfinite(out)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise FEAInputError(f"input {self.names[j]!r} is {out[i, j]} at t = {t[i]:.6g} s")
        return out

    def means(self, step_times_s: np.ndarray) -> np.ndarray:
        """Exact mean inputs over each step, see :func:`interval_means`.

        Parameters
        ----------
        step_times_s : ndarray
            Step ends, s.

        Returns
        -------
        ndarray, shape (len(step_times_s) − 1, n_inputs)
            Mean inputs.
        """
        return interval_means(self.sample, step_times_s, self.breakpoints_s)

    def __call__(self, t):
        return self.sample([t])[0]
