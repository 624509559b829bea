"""Signal tools of the gap diagnosis: first-order lags, frequency bands, noise levels, time alignment."""
from __future__ import annotations

import numpy as np
from scipy.signal import lfilter, lfilter_zi

#: Frequency bands of the residual breakdown, by period in hours: (name, shortest, longest).
BANDS = (("slow drift (> 30 h, incl. trend)", 30.0, np.inf),
         ("daily cycle (6–30 h)", 6.0, 30.0),
         ("fast (< 6 h)", 0.0, 6.0))


def lag(x: np.ndarray, step_s: float, tau_s: float) -> np.ndarray:
    """First-order lag ``τ ẏ = x − y`` of signals x (n,) or (n, k) on a uniform grid, starting in equilibrium.

    Exact for x linear between the samples (the recursion of
    :func:`twin.core.scenario.first_order_lag`); τ ≤ 0 returns x unchanged.

    Parameters
    ----------
    x : ndarray, shape (n,) or (n, k)
        Signals on the grid, rows in time (any unit).
    step_s : float
        Grid step, s.
    tau_s : float
        Time constant τ, s; τ ≤ 0 (or fewer than 2 samples) returns a copy of x.

    Returns
    -------
    ndarray, shape of x
        The lagged signals, unit of x; y[0] = x[0].
    """
    x = np.asarray(x, float)
    tau_s = float(tau_s)
    if tau_s <= 0.0 or len(x) < 2:
        return x.copy()
    a = np.exp(-step_s / tau_s)
    c = tau_s * (1.0 - a) / step_s
    b, den = np.array([1.0 - c, c - a]), np.array([1.0, -a])
    zi = lfilter_zi(b, den)
    if x.ndim == 1:
        y, _ = lfilter(b, den, x, zi=zi * x[0])
        return y
    y, _ = lfilter(b, den, x, axis=0, zi=zi[:, None] * x[0][None, :])
    return y


def uniform_grid(t_start: float, t_end: float, step_s: float) -> np.ndarray:
    """Times t_start, t_start + h, … covering t_end (the last point ≥ t_end).

    Parameters
    ----------
    t_start, t_end : float
        First and last time to cover, s.
    step_s : float
        Step h, s.

    Returns
    -------
    ndarray, shape (n_grid,)
        The grid times, s; at least 2 points.
    """
    n = int(np.ceil((t_end - t_start) / step_s - 1e-9)) + 1
    return t_start + step_s * np.arange(max(n, 2))


class Interpolator:
    """Linear interpolation from a uniform grid to given times, precomputed once (rows (n_grid, …) → (n_times, …)).

    Times outside the grid take the value of its nearest end.  Call it on values with rows on the grid.

    Parameters
    ----------
    grid : ndarray, shape (n_grid,)
        Uniform grid times, s (at least 2).
    times : ndarray, shape (n_times,)
        Times to interpolate to, s.
    """

    def __init__(self, grid: np.ndarray, times: np.ndarray):
        grid, times = np.asarray(grid, float), np.asarray(times, float)
        h = grid[1] - grid[0]
        pos = np.clip((times - grid[0]) / h, 0.0, len(grid) - 1.0)
        self.i0 = np.minimum(np.floor(pos).astype(int), len(grid) - 2)
        self.f = (pos - self.i0)

    def __call__(self, Y: np.ndarray) -> np.ndarray:
        Y = np.asarray(Y)
        f = self.f.reshape((-1,) + (1,) * (Y.ndim - 1))
        return (1.0 - f) * Y[self.i0] + f * Y[self.i0 + 1]


def step_values(times: np.ndarray, values: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """A piecewise-constant measured signal (value at tⱼ describes (tⱼ₋₁, tⱼ]) on a grid: the next sample's value.

    Parameters
    ----------
    times : ndarray, shape (n,)
        Sample times tⱼ, s, increasing.
    values : ndarray, shape (n,) or (n, k)
        Sampled values (any unit).
    grid : ndarray, shape (n_grid,)
        Times to evaluate at, s; after the last sample the last value holds.

    Returns
    -------
    ndarray, shape (n_grid,) or (n_grid, k)
        Values on the grid, unit of ``values``.
    """
    k = np.searchsorted(times, grid - 1e-9, side="left")
    return np.asarray(values, float)[np.clip(k, 0, len(times) - 1)]


def noise_level(y: np.ndarray) -> np.ndarray:
    """Per-column white-noise level (std) of sampled signals (n, k) from second differences, robust to spikes.

    For white noise of std σ the second difference has std σ√6; the top 5 %
    (steps of the duty cycle) are trimmed.

    Parameters
    ----------
    y : ndarray, shape (n,) or (n, k)
        Sampled signals, rows in time (any unit); NaNs are skipped.

    Returns
    -------
    ndarray, shape (k,)
        Noise std per column, unit of y; NaN for a column with fewer than 8 finite samples.
    """
    y = np.asarray(y, float)
    if y.ndim == 1:
        y = y[:, None]
    out = np.full(y.shape[1], np.nan)
    for j in range(y.shape[1]):
        col = y[np.isfinite(y[:, j]), j]
        if len(col) < 8:
            continue
        d2 = np.abs(np.diff(col, 2))
        d2 = np.sort(d2)[: max(1, int(0.95 * len(d2)))]
        out[j] = float(np.sqrt(np.mean(d2 ** 2) / 6.0))
    return out


def band_split(t: np.ndarray, r: np.ndarray) -> list[np.ndarray]:
    """Split residuals r (n, k) sampled at times t (s) into :data:`BANDS` → list of (n, k) arrays summing to r.

    The series is resampled on a uniform grid (median step), its linear trend
    goes to the slow band, and the rest is split by FFT period; the bands are
    interpolated back to t.  NaNs are filled by interpolation first.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Sample times, s, increasing.
    r : ndarray, shape (n,) or (n, k)
        Residuals (any unit), NaN where missing.

    Returns
    -------
    list of ndarray, shape (n, k)
        One part per band of :data:`BANDS`, in its order, unit of r (NaNs of r filled).
    """
    t = np.asarray(t, float)
    r = np.asarray(r, float)
    if r.ndim == 1:
        r = r[:, None]
    filled = r.copy()
    for j in range(r.shape[1]):
        ok = np.isfinite(r[:, j])
        filled[:, j] = np.interp(t, t[ok], r[ok, j]) if ok.any() else 0.0
    h = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    grid = uniform_grid(t[0], t[-1], h)
    g = np.column_stack([np.interp(grid, t, filled[:, j]) for j in range(r.shape[1])])
    X = np.column_stack([np.ones(len(grid)), (grid - grid.mean()) / max(np.ptp(grid), 1.0)])
    coef, *_ = np.linalg.lstsq(X, g, rcond=None)
    trend = X @ coef
    rest = g - trend
    spec = np.fft.rfft(rest, axis=0)
    freq = np.fft.rfftfreq(len(grid), d=h)
    period_h = np.divide(1.0, freq, out=np.full_like(freq, np.inf), where=freq > 0) / 3600.0
    out = []
    for _, lo, hi in BANDS:
        mask = (period_h >= lo) & ((period_h < hi) | (hi == np.inf))
        part = np.fft.irfft(spec * mask[:, None], n=len(grid), axis=0)
        if hi == np.inf:
            part = part + trend
        out.append(np.column_stack([np.interp(t, grid, part[:, j]) for j in range(r.shape[1])]))
    return out
