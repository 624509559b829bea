"""Time histories of a thermal system's named inputs (ambient °C, power W, …)."""
from __future__ import annotations

import numpy as np

from .errors import FEAInputError


class SampledSeries:
    """A piecewise-linear input from samples ``(times_s, values)``; held constant outside them."""

    def __init__(self, times_s, values, name="series"):
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


class InputSchedule:
    """Evaluates the input vector ``u(t)`` of a :class:`~fea.heat.ThermalSystem`.

    ``sources`` maps each input name to a number, a vectorised callable
    ``f(t_s) -> value`` or a :class:`SampledSeries`.  Constant inputs set in
    the problem itself are filled in.  A missing or unknown name, or a value
    that is not finite, raises :class:`FEAInputError` naming it and the time.
    """

    def __init__(self, system, sources):
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

    def sample(self, times_s):
        """Input matrix (len(times_s), n_inputs) at the given times."""
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
            raise FEAInputError(f"input {self.names[j]!r} is {out[i, j]} at t = {t[i]} s")
        return out

    def __call__(self, t):
        return self.sample([t])[0]
