"""Dynamic grey-box thermal model: a low-order RC network driven by spindle heat and temperatures.

Model (continuous time, modal form of an RC network of order ``n_poles``)::

    P(t)      = (n(t) / speed_reference)^b                  spindle heat, b fitted (P ∝ n^b)
    u(t)      = [P, ΔT_1 … ΔT_q]                             ΔT_j = T_j(t) − T_j(first row), K
    ẋ_ij      = −λ_i (x_ij − u_j),   λ_i = 1/τ_i > 0         one first-order lag per pole i and input j
    y(t)      = c₀ + Σ_ij g_ij x_ij + Σ_j d_j ΔT_j           output, e.g. a drift in µm

The poles ``−λ_i = −1/τ_i`` are real and negative by construction (the time
constants ``τ_i`` are the fitted parameters, every one kept inside
``time_constant_bounds`` and at least twice the one before it), so every
fitted model is stable: a bounded input gives a bounded drift. The gains
``g``, feed-throughs ``d`` (temperature inputs only: spindle heat does not
move the tool instantly) and offset ``c₀`` enter linearly. They are solved
by least squares for given ``(τ, b)``, and ``(τ, b)`` minimise the
**simulation (output) error** over the whole record (variable projection,
:func:`scipy.optimize.least_squares`): the model is run from the first row,
never fed back measured outputs, so the fit rewards what a compensation
running for hours needs.

Layout of ``X`` (one row per sample, time-ordered):

* column 0: time in s, strictly increasing (the sampling may be irregular);
  with ``sampling_interval`` set there is no time column, the rows are that
  many seconds apart and every column below moves one to the left;
* column 1: spindle speed in rpm (≥ 0), held from one sample to the next;
* columns 2…: temperatures in °C. ``temperature_inputs`` (column indices,
  default: every column from 2 not in ``observed``) drive the model, e.g. the
  ambient; ``observed`` columns are *outputs* of the same network (thermometers
  on the structure): they are fitted jointly with ``y`` (sharing the poles and
  the exponent), and ``predict`` then runs the observer form
  (:meth:`GreyBoxRegressor.predict_filtered`, a :class:`~models.kalman.KalmanFilter`)
  that fuses them while the model runs. Like the inputs, they count as changes
  since their record's first row, where they must be read; elsewhere they may
  hold NaN (a missing reading).

``predict(X)`` assumes the machine is in thermal equilibrium with the first
row of ``X`` (every lag state equals its input there; a spindle running at
the first row counts as having run at that speed for ever): to continue a
run, pass the whole history from a rest state and read off the tail.

``fit`` takes several records at once (``record_starts``: the rows where a
new record begins, e.g. test days separated by nights at rest): each starts
in equilibrium with its own first row, its temperatures are referenced to
that row and its time restarts there; the records share the poles, the
exponent and the gains.
"""

from __future__ import annotations

import numbers
from collections.abc import Sequence
from itertools import pairwise

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares
from scipy.signal import lfilter
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.utils.validation import check_array, check_is_fitted

from ._threads import one_blas_thread
from ._validation import check_n_features, check_positive_int, require_parameters
from .kalman import KalmanFilter, discretize
from .registry import register_model
from .robust_covariance import consecutive_runs, half_widths, sandwich_covariance
from .speed import STANDSTILL_FRACTION, STANDSTILL_RPM, running

#: relative tolerance under which the steps count as uniform (then a fast recursive filter is used)
_UNIFORM_STEP = 1e-9
#: a step longer than this many times its record's median step, and than :data:`_GAP_MIN_S`, is a logging gap, across
#: which the intervals take the noise as independent (as between records): their autoregression and Bartlett windows
#: count in rows. Below it are jitter and irregular loggers (steps of 20–180 s are at most 1.8× their median) and a
#: few readings missed; an hour's gap at 60 s is 60×. The same two conditions as the gap diagnosis's outages
#: (twin.gap.outages.as_long_as_an_outage: OUTAGE_FACTOR and OUTAGE_MIN_S; models do not import twin). The simulation
#: steps over a gap exactly whatever its length.
_GAP_STEPS = 5.0
#: the shortest logging gap, s (the gap diagnosis's OUTAGE_MIN_S): a logger that switches between two rates (10 s
#: and 60 s) has steps 6× its median that are no gap; cut there, its record fell into runs of a few rows in which
#: no autoregression sees a correlation of 30 min, and the intervals came out ~6× too narrow. Shorter than the
#: structure's time constants (tens of minutes and more), such a step leaves neighbouring residuals correlated.
_GAP_MIN_S = 600.0
#: smallest ratio of successive time constants: coinciding poles make the gains ill-posed (two huge,
#: cancelling gains imitate a derivative that extrapolates wildly)
_MIN_RATIO = 2.0
#: two running speeds identify the exponent of P ∝ n^b when the larger is at least this factor above the smaller
_DISTINCT_SPEEDS = 1.05
#: start values of the time constants, s (machine-tool structures: minutes to hours); one fit per row
_STARTS = ((1800.0, 7200.0, 21600.0, 64800.0), (600.0, 3600.0, 14400.0, 57600.0), (3600.0, 21600.0, 86400.0, 345600.0))
#: the learned arrays a prediction reads, and their shapes: p poles, m = 1 + q inputs (the heat, then q temperatures),
#: o outputs (y, then the observed thermometers)
_LEARNED_SHAPES = {"time_constants_": "p", "poles_": "p", "gains_": "opm", "feedthrough_": "oq", "offset_": "o",
                   "output_std_": "o", "input_std_": "m"}
#: two-sided coverage of ``time_constants_interval_`` and ``exponent_interval_``
INTERVAL_LEVEL = 0.9
#: a pole may differ from −1/τ by this relative rounding: both are stored from one fit, one the reciprocal of the other
_POLE_ROUNDING = 1e-9


#: the largest decay exponent λ·Δt inside one closed-form stretch of :func:`_uneven_lag` (e^300 ≈ 2e130 stays
#: far from overflow, and a stretch still spans 300 time constants)
_STRETCH_DECAYS = 300.0


def _uneven_lag(time, rate, U, start):
    """First-order lag ``s' = rate (u − s)`` of ZOH inputs at uneven times, in closed form.

    With ``E_k = rate (t_k − t_c)`` from a stretch's first row c,
    ``s_k = e^{−E_k} (s_c + Σ_{j<k} (1 − e^{−rate Δt_j}) u_j e^{E_{j+1}})``:
    the recurrence ``s_{k+1} = a_k s_k + (1 − a_k) u_k`` as a cumulative sum,
    so a record with jitter costs a few array passes instead of a loop over
    rows. A stretch ends before ``E`` passes :data:`_STRETCH_DECAYS`. The sum's
    rounding, scaled back by ``e^{−E_k}``, is of the order of the recurrence's
    own (``tests/test_models_greybox.py`` compares the two).

    Parameters
    ----------
    time : ndarray, shape (n,)
        Strictly increasing, s.
    rate : float
        1/τ, 1/s.
    U : ndarray, shape (n, m)
        Inputs, held from each row to the next.
    start : ndarray, shape (m,)
        The lag's value at row 0.

    Returns
    -------
    ndarray, shape (n, m)
    """
    out = np.empty_like(U)
    out[0] = start
    decays = rate * (time - time[0])
    first = 0
    while first < len(time) - 1:
        stop = int(np.searchsorted(decays, decays[first] + _STRETCH_DECAYS, side="right"))
        if stop <= first + 1:   # one step longer than a stretch (a logging gap): e^{E} would overflow
            a = np.exp(-rate * (time[first + 1] - time[first]))
            out[first + 1] = a * out[first] + (1.0 - a) * U[first]
            first += 1
            continue
        grow = np.exp(rate * (time[first + 1: stop] - time[first]))[:, None]   # e^{E_k}, k = first+1 … stop-1
        gain = -np.expm1(-rate * np.diff(time[first:stop]))[:, None]          # 1 − a_j
        out[first + 1: stop] = (out[first] + np.cumsum(gain * U[first: stop - 1] * grow, axis=0)) / grow
        first = stop - 1
    return out


def _check_learned_array(name, value, shape, because):
    """Raise a ValueError unless the learned attribute ``name`` is a finite numeric array of ``shape``, which
    ``because`` (the settings that make it) explains."""
    if not isinstance(value, np.ndarray) or not np.issubdtype(value.dtype, np.number):
        raise ValueError(f"GreyBoxRegressor: learned attribute {name!r} is {_shown(value)}, expected an array of "
                         "numbers.")
    if value.shape != shape:
        raise ValueError(f"GreyBoxRegressor: learned attribute {name!r} has shape {value.shape}, but {because} make "
                         f"it {shape}.")
    if not np.all(np.isfinite(value)):
        raise ValueError(f"GreyBoxRegressor: learned attribute {name!r} is {_shown(value.tolist())}, expected "
                         "finite numbers.")


def _shown(value, limit=120):
    """``repr(value)``, cut to ``limit`` characters for a message."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _pair(value, name):
    """``(low, high)`` floats of a two-number setting, or a ValueError that shows the form wanted."""
    try:
        low, high = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"GreyBoxRegressor: {name} must be two numbers [low, high], got {value!r}.") from None
    return low, high


def _check_finite_nonnegative(value, name):
    """Raise a ValueError naming the setting ``name`` unless ``value`` is a finite number >= 0."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = np.nan
    if not 0 <= number < np.inf:
        raise ValueError(f"GreyBoxRegressor: {name} must be finite and >= 0, got {value!r}.")


def _column_numbers(value, name):
    """Column indices of a setting (a list of whole numbers), or a ValueError that shows the form wanted."""
    try:
        columns = tuple(int(c) for c in value)
    except (TypeError, ValueError):
        columns = None
    if columns is None or any(c != v for c, v in zip(columns, value)):
        raise ValueError(f"GreyBoxRegressor: {name} must be a list of column numbers, got {value!r}.")
    return columns


def _time_constants(fractions, log_low, log_high):
    """Time constants τ₁ < … < τ_n (s) inside ``[exp(log_low), exp(log_high)]``, each at least :data:`_MIN_RATIO`
    times the one before, from stick-breaking fractions in [0, 1]: τ_i is placed at ``fractions[i]`` of the room
    left between _MIN_RATIO·τ_(i−1) and the highest place that still leaves room for the poles after it.  The map
    is smooth and one-to-one, so a box-bounded fit of the fractions keeps every pole inside the bounds."""
    n, log_ratio = len(fractions), np.log(_MIN_RATIO)
    log_tau = np.empty(n)
    low = log_low
    for i, fraction in enumerate(fractions):
        high = log_high - (n - 1 - i) * log_ratio
        log_tau[i] = low + fraction * (high - low)
        low = log_tau[i] + log_ratio
    return np.exp(log_tau)


def _stick_fractions(taus, log_low, log_high):
    """The fractions of :func:`_time_constants` that give the ascending ``taus`` (s), moved inside the bounds."""
    n, log_ratio = len(taus), np.log(_MIN_RATIO)
    fractions = np.empty(n)
    low = log_low
    for i, tau in enumerate(taus):
        high = log_high - (n - 1 - i) * log_ratio
        fractions[i] = np.clip((np.log(tau) - low) / (high - low), 1e-6, 1.0 - 1e-6)
        low = low + fractions[i] * (high - low) + log_ratio
    return fractions


def _log_time_constant_jacobian(fractions, log_low, log_high):
    """``∂ log τ / ∂ fractions`` (n, n) of :func:`_time_constants`. Each log τ_i is affine in every fraction (it is
    placed linearly, in log space, in the room the poles before it leave), so a unit step gives it exactly."""
    base = np.log(_time_constants(fractions, log_low, log_high))
    return np.column_stack([np.log(_time_constants(fractions + step, log_low, log_high)) - base
                            for step in np.eye(len(fractions))])


def _clipped_interval(estimate, below, above, low, high):
    """``(n, 2)`` intervals ``[below, above]`` cut to the bounds ``[low, high]`` the fit keeps to (an estimate on a
    bound gets a one-sided interval, an unidentified one the whole range), never leaving out the ``estimate``."""
    return np.column_stack([np.minimum(np.maximum(below, low), estimate), np.maximum(np.minimum(above, high), estimate)])


def _estimate_text(value, interval, bounds, unit=""):
    """``1.15 h (90 %: 1.04 … 1.27)``: ``value`` and its interval (None: none stored), saying where ``value`` sits on
    one of ``bounds`` and where the interval is all of them."""
    notes = [f"on its {side} bound" for side, bound in zip(("lower", "upper"), bounds)
             if np.isclose(value, bound, rtol=1e-6, atol=0.0)]
    if interval is not None:
        anywhere = np.allclose(interval, bounds, rtol=1e-6, atol=0.0)
        notes.append(f"{INTERVAL_LEVEL * 100:g} %: {interval[0]:.3g} … {interval[1]:.3g}"
                     + (", the whole range: not determined" if anywhere else ""))
    return f"{value:.3g}{unit}" + (f" ({'; '.join(notes)})" if notes else "")


@register_model({"greybox": {"sampling_interval": 1.0}}, time_series=True, takes_time=True,
                first_input=("spindle speed", "rpm"), observer=True, predicts_level=True)
class GreyBoxRegressor(RegressorMixin, BaseEstimator):
    """Grey-box RC-network thermal-drift model, fitted by output-error minimisation.

    Parameters
    ----------
    n_poles : int, 1–4
        Order of the RC network (number of distinct real poles).
    speed_reference : float, rpm
        Speed at which the heat input P is 1 (it only scales the gains).
    exponent : float
        Exponent b of ``P ∝ n^b``: the start value when ``fit_exponent``, else fixed.
    fit_exponent : bool
        Fit b within ``exponent_bounds``; only where the rows fitted (weight > 0) run
        (:func:`models.speed.running`) at two speeds at least :data:`_DISTINCT_SPEEDS` apart: at one speed b
        only scales the gains and cannot be identified (a free fit runs it to a bound, and the model
        extrapolates to other speeds by an arbitrary n^b), so it stays at ``exponent``. A fit whose rows never
        run is refused: the spindle's heat cannot be identified there.
    exponent_bounds : (float, float)
    time_constant_bounds : (float, float), s
        Every time constant stays inside; the poles are −1/τ.
    temperature_inputs : tuple of int or None
        Columns of ``X`` (≥ 2) that drive the model; None = every column from 2 not in ``observed``.
    observed : tuple of int
        Columns of ``X`` (≥ 2) modelled as outputs and fused by the observer.
    observed_weight : float, finite, >= 0
        Weight of the observed thermometers in the fit, relative to ``y``
        (every output's residual is divided by its training standard deviation).
    process_noise : float
        Observer process noise, as the stationary variance of each state in
        units of its input's training variance (dimensionless).
    max_nfev : int
        Budget of residual evaluations of the nonlinear fit (per start; three deterministic starts).
    sampling_interval : float or None, s
        None: column 0 of X is the time. A number: X has no time column and
        its rows are this far apart (``twin train`` sets it from the record).

    Attributes
    ----------
    time_constants_ : (n_poles,) s, ascending; ``poles_`` = −1/τ (1/s)
    exponent_ : b
    exponent_fitted_ : whether b was fitted (False: one running speed, or ``fit_exponent`` False)
    time_constants_interval_ : (n_poles, 2) s, each τ's :data:`INTERVAL_LEVEL` (90 %) confidence interval
        ``[low, high]``, symmetric in log τ (:meth:`_intervals`), cut to ``time_constant_bounds``
    exponent_interval_ : (2,) or None, b's 90 % interval cut to ``exponent_bounds``; None when b is not fitted
    gains_ : (n_outputs, n_poles, n_inputs) g (output 0 is y, then the observed columns)
    feedthrough_ : (n_outputs, n_temperature_inputs) d
    offset_ : (n_outputs,) c₀
    output_std_ : (n_outputs,) training RMSE of each output (the observer's measurement noise)
    input_std_ : (n_inputs,) training standard deviation of each input
    training_rmse_ : simulation RMSE of y on the training rows
    y_reference_ : the first training target, so ``predict − y_reference_`` is the predicted change of y
        since the training start, as for the grey time-series models
    n_features_in_
    """

    def __init__(self, n_poles: int = 2, speed_reference: float = 1000.0, exponent: float = 1.0,
                 fit_exponent: bool = True, exponent_bounds: tuple[float, float] = (0.5, 3.0),
                 time_constant_bounds: tuple[float, float] = (60.0, 1e6),
                 temperature_inputs: Sequence[int] | None = None, observed: Sequence[int] = (),
                 observed_weight: float = 1.0, process_noise: float = 0.01, max_nfev: int = 200,
                 sampling_interval: float | None = None):
        self.n_poles = n_poles
        self.speed_reference = speed_reference
        self.exponent = exponent
        self.fit_exponent = fit_exponent
        self.exponent_bounds = exponent_bounds
        self.time_constant_bounds = time_constant_bounds
        self.temperature_inputs = temperature_inputs
        self.observed = observed
        self.observed_weight = observed_weight
        self.process_noise = process_noise
        self.max_nfev = max_nfev
        self.sampling_interval = sampling_interval

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.regressor_tags.poor_score = True  # a time-series model: random rows are not a record
        tags.input_tags.allow_nan = True       # observed thermometers may miss readings
        return tags

    # ------------------------------------------------------------ inputs
    def _layout(self):
        """``(time column or None, speed column, first temperature column)`` of the caller's X."""
        if self.sampling_interval is None:
            return 0, 1, 2
        if not (isinstance(self.sampling_interval, (int, float)) and 0 < self.sampling_interval < np.inf):
            raise ValueError(f"GreyBoxRegressor: sampling_interval must be a positive number of s or None, "
                             f"got {self.sampling_interval!r}.")
        return None, 0, 1

    def _columns(self, n_features):
        """``(temperature input columns, observed columns)`` of the caller's X, checked against its width."""
        time_col, _, first = self._layout()
        names = "column 0 is time_s, column 1 spindle_rpm" if time_col == 0 else "column 0 is spindle_rpm"
        if n_features < first:
            raise ValueError(f"GreyBoxRegressor: X needs at least {first} columns ({names}, then temperatures), "
                             f"got {n_features}.")
        observed = _column_numbers(self.observed, "observed")
        if self.temperature_inputs is None:
            inputs = tuple(c for c in range(first, n_features) if c not in observed)
        else:
            inputs = _column_numbers(self.temperature_inputs, "temperature_inputs")
        for name, cols in (("temperature_inputs", inputs), ("observed", observed)):
            bad = [c for c in cols if not first <= c < n_features]
            if bad:
                raise ValueError(f"GreyBoxRegressor: {name} has column {bad[0]}, but temperature columns are "
                                 f"{first}..{n_features - 1} ({names}).")
        if set(inputs) & set(observed):
            raise ValueError(f"GreyBoxRegressor: columns {sorted(set(inputs) & set(observed))} are both inputs and observed.")
        return inputs, observed

    @staticmethod
    def _records(n_rows, record_starts):
        """``[start, stop)`` rows of each record, from the rows where the records after the first start."""
        starts = np.asarray(record_starts if record_starts is not None else (), dtype=float).ravel()
        if starts.size and (not np.all(starts == np.round(starts)) or np.any(np.diff(starts) < 2)
                            or starts[0] < 2 or starts[-1] > n_rows - 2):
            raise ValueError(f"GreyBoxRegressor: record_starts must be increasing row numbers with at least 2 rows "
                             f"in every record (2..{n_rows - 2} for {n_rows} rows), got {starts.tolist()}.")
        edges = [0, *starts.astype(int).tolist(), n_rows]
        return list(pairwise(edges))

    def _check_x(self, X, inputs, records, allow_nan_in=()):
        """``(time s, speed rpm)`` with finite time/speed/inputs, time strictly increasing in each record,
        speed >= 0."""
        time_col, speed_col, _ = self._layout()
        must_be_finite = [c for c in (time_col, speed_col) if c is not None] + list(inputs)
        bad = ~np.isfinite(X[:, must_be_finite])
        if bad.any():
            row, col = np.argwhere(bad)[0]
            raise ValueError(
                f"GreyBoxRegressor: X row {row}, column {must_be_finite[col]} is {X[row, must_be_finite[col]]}; "
                "time, speed and temperature inputs must be finite."
            )
        others = [c for c in range(X.shape[1]) if c not in must_be_finite and c not in allow_nan_in]
        if others and not np.all(np.isfinite(X[:, others])):
            raise ValueError("GreyBoxRegressor: X has NaN or inf in a column the model does not use as an input.")
        if time_col is None:
            time = np.arange(len(X)) * float(self.sampling_interval)
        else:
            time = X[:, time_col]
            steps = np.diff(time)
            restarts = [start - 1 for start, _ in records[1:]]   # a record's clock restarts
            steps[restarts] = 1.0
            if np.any(steps <= 0):
                k = int(np.argmax(steps <= 0))
                raise ValueError(f"GreyBoxRegressor: time (column 0) must increase strictly, but row {k + 1} has "
                                 f"{time[k + 1]} s after {time[k]} s.")
        speed = X[:, speed_col]
        if np.any(speed < 0):
            k = int(np.argmax(speed < 0))
            raise ValueError(f"GreyBoxRegressor: spindle speed (column {speed_col}) must be >= 0 rpm, row {k} has "
                             f"{speed[k]:g}.")
        return time, speed

    def _inputs(self, X, speed, inputs, exponent, records):
        """``u = [P, ΔT…]`` (n, 1 + q): heat from the speed, temperatures referenced to their record's first
        row."""
        heat = (speed / self.speed_reference) ** exponent
        return np.column_stack([heat, self._since_start(X[:, list(inputs)], records)])

    @staticmethod
    def _since_start(values, records):
        """``values`` (n, q) less their record's first row: the change since each record's start."""
        first = np.repeat([start for start, _ in records], [stop - start for start, stop in records])
        return values - values[first]

    def _observed_since_start(self, X, observed, records):
        """The observed thermometers as changes since each record's first row (K), which must be read: at rest
        there the network's outputs are its inputs' (an absolute offset shared by records that start at other
        temperatures would bias the fit and the observer)."""
        values = X[:, list(observed)]
        for start, _ in records:
            missing = np.flatnonzero(~np.isfinite(values[start]))
            if missing.size:
                raise ValueError(f"GreyBoxRegressor: observed column {observed[missing[0]]} is "
                                 f"{values[start, missing[0]]} at row {start}, a record's first row; its change is "
                                 "counted from there, so that reading is needed.")
        return self._since_start(values, records)

    # ------------------------------------------------------------ simulation
    @staticmethod
    def _states(time, U, lam, records):
        """Lag states x_ij (n, n_poles, m) with ZOH inputs, each record starting in equilibrium
        x_ij(t₀) = u_j(t₀)."""
        S = np.empty((len(U), len(lam), U.shape[1]))
        for start, stop in records:
            t, u = time[start:stop], U[start:stop]
            steps = np.diff(t)
            uniform = np.ptp(steps) <= _UNIFORM_STEP * steps[0]
            for i, rate in enumerate(lam):
                if uniform:
                    a = np.exp(-rate * steps[0])
                    S[start:stop, i, :] = lfilter([0.0, 1.0 - a], [1.0, -a], u, axis=0, zi=u[:1])[0]
                else:
                    S[start:stop, i, :] = _uneven_lag(t, rate, u, u[0])
        return S

    @staticmethod
    def _design(S, U):
        """Regressors ``[1, x_ij…, ΔT_j…]`` for the linear parameters."""
        return np.column_stack([np.ones(len(U)), S.reshape(len(U), -1), U[:, 1:]])

    def _unpack(self, theta, log_bounds, fit_exponent):
        """``(1/τ per pole, b)`` from the fitted parameters (stick fractions, then b when it is fitted)."""
        lam = 1.0 / _time_constants(theta[: self.n_poles], *log_bounds)
        return lam, theta[self.n_poles] if fit_exponent else float(self.exponent)

    def determined_by(self, span_s: float) -> bool:
        """Whether records lasting ``span_s`` (the longest one) determine the fitted poles: the slowest time
        constant is shorter than that and off the upper bound of ``time_constant_bounds``.

        A slower pole is seen only at its start, where its response is nearly
        a ramp, which a slower pole with a larger gain, or two with gains of
        opposite sign, fit as well: its gain is then a guess.

        Parameters
        ----------
        span_s : float
            Duration of the longest training record, s.

        Returns
        -------
        bool
        """
        check_is_fitted(self, "time_constants_")
        slowest, high = float(np.max(self.time_constants_)), _pair(self.time_constant_bounds, "time_constant_bounds")[1]
        return slowest < float(span_s) and slowest < high * (1.0 - 1e-6)

    # ------------------------------------------------------------ fit
    def _checked_settings(self):
        """``(n_poles, (τ low, τ high) s)``, each checked."""
        n_poles = check_positive_int(self.n_poles, "n_poles")
        if n_poles > 4:
            raise ValueError(f"GreyBoxRegressor: n_poles must be 1-4, got {n_poles}.")
        lo, hi = _pair(self.time_constant_bounds, "time_constant_bounds")
        if not 0 < lo < hi < np.inf:
            raise ValueError(f"GreyBoxRegressor: time_constant_bounds must be 0 < low < high s, got {self.time_constant_bounds!r}.")
        if not 0 < float(self.speed_reference) < np.inf:
            raise ValueError(f"GreyBoxRegressor: speed_reference must be a positive speed in rpm, got {self.speed_reference!r}.")
        b_low, b_high = _pair(self.exponent_bounds, "exponent_bounds")
        if not b_low < b_high:
            raise ValueError(f"GreyBoxRegressor: exponent_bounds must be low < high, got {self.exponent_bounds!r}.")
        for name in ("process_noise", "observed_weight"):
            _check_finite_nonnegative(getattr(self, name), name)
        return n_poles, (lo, hi)

    @staticmethod
    def _checked_data(X, y, sample_weight):
        """``(X, y, weights)`` as float arrays: y 1-D with one value per row, weights finite and ≥ 0."""
        X = check_array(X, dtype=np.float64, ensure_all_finite=False, ensure_min_samples=2)
        y = check_array(np.asarray(y, float), ensure_2d=False, dtype=np.float64)
        if y.ndim != 1 or len(y) != len(X):
            raise ValueError(f"GreyBoxRegressor: y must be 1-D with one value per row of X ({len(X)}), got shape {y.shape}.")
        w = np.ones(len(y)) if sample_weight is None else np.asarray(sample_weight, float)
        if w.shape != y.shape or not np.all(np.isfinite(w)) or np.any(w < 0):
            raise ValueError("GreyBoxRegressor: sample_weight must be finite, >= 0 and one per row of X.")
        return X, y, w

    def _fits_exponent(self, speed, used):
        """Whether b is fitted: the fitted rows (``used``) run at two distinct speeds (rpm); a ValueError where
        they never run (:func:`models.speed.running`), as a spindle's heat seen nowhere cannot be identified: its
        gain and b would be fitted to the noise of a tachometer at rest and extrapolate to any real speed."""
        speeds = speed[used & running(speed)]   # a measured standstill reads a few rpm: not a second speed
        if not speeds.size:
            column = self._layout()[1]
            raise ValueError(f"GreyBoxRegressor: the spindle never runs on the rows fitted (spindle speed, column "
                             f"{column}, at most {speed[used].max():g} rpm; it runs above {STANDSTILL_RPM:g} rpm and "
                             f"{STANDSTILL_FRACTION:.0%} of the top speed), so the heat of the spindle cannot be "
                             "identified: fit on rows where it runs.")
        return bool(self.fit_exponent and speeds.max() >= _DISTINCT_SPEEDS * speeds.min())

    def _least_squares(self, residuals, n_poles, log_bounds, fit_exponent):
        """The best of the deterministic restarts (:data:`_STARTS`) of the bounded fit in (stick fractions, b)."""
        if n_poles > 1 and log_bounds[1] - log_bounds[0] <= (n_poles - 1) * np.log(_MIN_RATIO):
            raise ValueError(f"GreyBoxRegressor: time_constant_bounds {self.time_constant_bounds!r} are too narrow "
                             f"for {n_poles} poles {_MIN_RATIO:g}x apart.")
        lower, upper = np.zeros(n_poles), np.ones(n_poles)
        if fit_exponent:
            b_lo, b_hi = _pair(self.exponent_bounds, "exponent_bounds")
            lower, upper = np.r_[lower, b_lo], np.r_[upper, b_hi]
        budget = check_positive_int(self.max_nfev, "max_nfev")
        best = None
        for taus in _STARTS:  # deterministic restarts: the simulation error has local minima
            start = _stick_fractions(np.asarray(taus[:n_poles]), *log_bounds)
            if fit_exponent:
                start = np.r_[start, float(self.exponent)]
            start = np.clip(start, lower + 1e-9, upper - 1e-9)
            result = least_squares(residuals, start, bounds=(lower, upper), max_nfev=budget)
            if best is None or result.cost < best.cost:
                best = result
        return best

    @one_blas_thread
    def fit(self, X: ArrayLike, y: ArrayLike, sample_weight: ArrayLike | None = None,
            record_starts: Sequence[int] = ()) -> GreyBoxRegressor:
        """Fit on one time-ordered record, or on several (``record_starts``); ``sample_weight`` (≥ 0) weights
        the residuals.

        A weight of 0 leaves a row's target out of the fit while the model
        still runs through it (its inputs are known): blocked cross-validation
        holds out a middle block this way.

        Parameters
        ----------
        X : array-like, shape (n_samples, n_features)
            The record in the layout of the class docstring: time (s), spindle speed (rpm), temperatures (°C).
        y : array-like, shape (n_samples,)
            The target, e.g. a drift in µm.
        sample_weight : array-like, shape (n_samples,), optional
            Non-negative residual weights; default all 1.
        record_starts : sequence of int, default ()
            Rows where another record begins (increasing, each record at least 2 rows). Every record
            starts at rest, in equilibrium with its first row (the time column restarts there, and its
            temperatures are referenced to it); the records share every parameter.

        Returns
        -------
        self : GreyBoxRegressor
            The fitted model.
        """
        n_poles, (lo, hi) = self._checked_settings()
        X, y, w = self._checked_data(X, y, sample_weight)
        inputs, observed = self._columns(X.shape[1])
        n_outputs, m = 1 + len(observed), 1 + len(inputs)
        n_linear = 1 + n_poles * m + len(inputs)
        n_parameters = n_outputs * n_linear + n_poles + int(bool(self.fit_exponent))
        require_parameters(int(np.count_nonzero(w)), n_parameters, "GreyBoxRegressor",
                           hint=" Use fewer poles or temperature inputs.")
        records = self._records(len(X), record_starts)
        time, speed = self._check_x(X, inputs, records, allow_nan_in=observed)
        outputs = np.column_stack([y, self._observed_since_start(X, observed, records)])
        present = np.isfinite(outputs)   # an observed thermometer may miss readings: they weigh 0
        outputs = np.where(present, outputs, 0.0)
        used = w > 0
        W = w[:, None] * present
        fit_exponent = self._fits_exponent(speed, used)

        every_reading = bool(present[used].all())
        scale = outputs[used].std(axis=0) if every_reading else np.array(
            [outputs[used & present[:, o], o].std() for o in range(n_outputs)])
        scale[~(scale > 0)] = 1.0
        weights = np.sqrt(W) / scale * np.r_[1.0, np.full(n_outputs - 1, float(self.observed_weight))]

        log_bounds = (np.log(lo), np.log(hi))

        def linear(theta):
            lam, exponent = self._unpack(theta, log_bounds, fit_exponent)
            U = self._inputs(X, speed, inputs, exponent, records)
            Phi = self._design(self._states(time, U, lam, records), U)
            norm = np.sqrt(np.sum(Phi[used] ** 2, axis=0))
            norm[norm == 0] = 1.0
            design, root = (Phi / norm)[used], np.sqrt(W[used])
            if every_reading:   # one solve for every output
                coef = np.linalg.lstsq(design * root[:, :1], outputs[used] * root[:, :1], rcond=None)[0]
            else:                     # each output on the rows where it was read
                coef = np.column_stack([np.linalg.lstsq(design * root[:, [o]], outputs[used, o] * root[:, o],
                                                        rcond=None)[0] for o in range(n_outputs)])
            return coef / norm[:, None], Phi, U

        def residuals(theta):
            coef, Phi, _ = linear(theta)
            return ((Phi @ coef - outputs) * weights)[used].ravel()

        best = self._least_squares(residuals, n_poles, log_bounds, fit_exponent)
        coef, Phi, U = linear(best.x)
        lam, exponent = self._unpack(best.x, log_bounds, fit_exponent)

        self.time_constants_ = 1.0 / lam
        self.poles_ = -lam
        self.exponent_ = float(exponent)
        self.exponent_fitted_ = fit_exponent
        self.time_constants_interval_, self.exponent_interval_ = self._intervals(
            best, self._fitted_segments(used, records, time), (weights > 0)[used], n_outputs * n_linear + len(best.x),
            log_bounds)
        self.offset_ = coef[0].copy()
        self.gains_ = coef[1: 1 + n_poles * m].T.reshape(n_outputs, n_poles, m).copy()
        self.feedthrough_ = coef[1 + n_poles * m:].T.copy()
        fitted = Phi @ coef
        self.output_std_ = np.sqrt(np.average((fitted - outputs) ** 2, axis=0, weights=W))
        self.input_std_ = U[used].std(axis=0)
        self.training_rmse_ = float(self.output_std_[0])
        self.y_reference_ = float(y[0])
        self.n_features_in_ = X.shape[1]
        self.n_iterations_ = int(best.nfev)
        return self

    @staticmethod
    def _fitted_segments(used, records, time):
        """``[start, stop)``, counted in the fitted rows (``used``), of each run of consecutive rows inside one
        record and between its logging gaps (a step of ``time``, s, over :data:`_GAP_STEPS` times the record's
        median step and at least :data:`_GAP_MIN_S`): the stretches along which a residual follows the one before it
        in time."""
        stretches = []
        for start, stop in records:
            steps = np.diff(time[start:stop])
            gaps = start + 1 + np.flatnonzero((steps > _GAP_STEPS * np.median(steps)) & (steps >= _GAP_MIN_S))
            stretches += pairwise([start, *gaps.tolist(), stop])
        return consecutive_runs(used, stretches)

    def _intervals(self, best, segments, read, n_fitted, log_bounds):
        """``(time_constants_interval_ s, exponent_interval_ or None)`` of the fit ``best`` (a
        :func:`scipy.optimize.least_squares` result in stick fractions, then b); ``read`` (fitted rows, outputs)
        marks the entries that weigh in the fit; the others (an observed thermometer's NaN, or every reading of one
        with ``observed_weight`` 0) are left out of the covariance, not counted as residuals of 0.

        The covariance is the prewhitened sandwich of :func:`models.robust_covariance.sandwich_covariance` on the
        Jacobian of the profiled residual (the gains solved for every step, so it already holds their
        uncertainty), taken to ``(log τ, b)``: the output error lasts hours, and Gauss–Newton's
        ``(JᵀJ)⁻¹σ²`` covered a known network's τ 10–17 % and b 12 % of the time at a nominal 90 %, these
        86–89 % (``bench/greybox_intervals.py``). ``n_fitted`` counts every parameter of the fit, gains included.
        """
        n_poles, n_rows, k = len(self.time_constants_), segments[-1][1], len(best.x)
        to_log = np.eye(k)   # (fractions, b) → (log τ, b); singular where a pole leaves the next no room
        to_log[:n_poles, :n_poles] = _log_time_constant_jacobian(best.x[:n_poles], *log_bounds)
        covariance, dof = sandwich_covariance(best.jac.reshape(n_rows, -1, k), best.fun.reshape(n_rows, -1), segments,
                                              n_fitted, read, transform=to_log)
        half = half_widths(covariance, dof, INTERVAL_LEVEL)   # infinite for a quantity the data do not determine
        tau = self.time_constants_
        # symmetric in log τ; a half-width past the bounds' whole span reaches them anyway (and e^inf overflows)
        factor = np.exp(np.minimum(half[:n_poles], np.ptp(log_bounds)))
        taus = _clipped_interval(tau, tau / factor, tau * factor,
                                 *_pair(self.time_constant_bounds, "time_constant_bounds"))
        if not self.exponent_fitted_:
            return taus, None
        b = self.exponent_
        return taus, _clipped_interval(b, b - half[n_poles:], b + half[n_poles:],
                                       *_pair(self.exponent_bounds, "exponent_bounds"))[0]

    def check_fitted(self) -> None:
        """Raise a ValueError naming a learned attribute that no fit gives, as a model file edited by hand may hold.

        Cheap (no data): :meth:`predict` runs it, and :func:`models.persistence.load_model` on every model it
        reads. It checks that every learned attribute a prediction reads is there, its type, its shape
        (``n_poles``, ``n_features_in_``, ``temperature_inputs`` and ``observed`` make it) and finite values,
        and the physics of the fit: time constants > 0 s, poles ``−1/τ`` < 0 (1/s, a stable lag), and
        ``exponent_`` > 0 (with b ≤ 0 a spindle at rest would heat as much as a running one, or without bound).
        A model without any learned attribute (not fitted) passes.

        Raises
        ------
        ValueError
            Naming the attribute (or setting) and its value.
        """
        names = (*_LEARNED_SHAPES, "exponent_", "n_features_in_")
        if not any(hasattr(self, name) for name in names):
            return
        missing = [name for name in names if not hasattr(self, name)]
        if missing:
            raise ValueError(f"GreyBoxRegressor: learned attribute {missing[0]!r} is missing; a fitted model has "
                             f"{', '.join(names)}.")
        n_poles, _ = self._checked_settings()
        if isinstance(self.n_features_in_, bool) or not isinstance(self.n_features_in_, numbers.Integral):
            raise ValueError(f"GreyBoxRegressor: learned attribute 'n_features_in_' is {self.n_features_in_!r}, "
                             "expected a whole number of columns.")
        inputs, observed = self._columns(self.n_features_in_)
        sizes = {"p": n_poles, "m": 1 + len(inputs), "q": len(inputs), "o": 1 + len(observed)}
        for name, dims in _LEARNED_SHAPES.items():
            _check_learned_array(name, getattr(self, name), tuple(sizes[d] for d in dims),
                                 f"n_poles = {n_poles}, n_features_in_ = {self.n_features_in_} and observed = "
                                 f"{tuple(observed)}")
        self._check_fitted_physics()
        self._check_fitted_intervals(n_poles)

    def _check_fitted_physics(self):
        """Raise a ValueError for a time constant ≤ 0 s, a pole that is not ``−1/τ`` < 0, or a b ≤ 0."""
        tau, poles, b = self.time_constants_, self.poles_, self.exponent_
        if np.any(tau <= 0):
            raise ValueError(f"GreyBoxRegressor: learned attribute 'time_constants_' is {tau.tolist()} s; a time "
                             "constant must be > 0 s.")
        if np.any(poles >= 0):
            raise ValueError(f"GreyBoxRegressor: learned attribute 'poles_' is {poles.tolist()} 1/s; a pole >= 0 is "
                             "an unstable lag, and a fitted model's poles are -1/tau < 0.")
        if not np.allclose(poles, -1.0 / tau, rtol=_POLE_ROUNDING, atol=0.0):
            raise ValueError(f"GreyBoxRegressor: learned attribute 'poles_' is {poles.tolist()} 1/s, but "
                             f"time_constants_ {tau.tolist()} s make them {(-1.0 / tau).tolist()} (-1/tau).")
        if isinstance(b, bool) or not isinstance(b, numbers.Real) or not 0 < b < np.inf:
            raise ValueError(f"GreyBoxRegressor: learned attribute 'exponent_' is {b!r}, expected a finite number "
                             "> 0 (the b of P ~ n^b).")

    def _check_fitted_intervals(self, n_poles):
        """Raise a ValueError for an interval that is not ``[low, high]`` of finite numbers around its estimate.
        A model saved before the intervals were stored has none, and loads."""
        for name, estimates, shape in (("time_constants_interval_", self.time_constants_, (n_poles, 2)),
                                       ("exponent_interval_", np.array([self.exponent_]), (2,))):
            interval = getattr(self, name, None)
            if interval is None:
                continue
            _check_learned_array(name, interval, shape, f"n_poles = {n_poles} and the two ends of an interval")
            low, high = interval.reshape(-1, 2).T
            if not np.all((low <= estimates) & (estimates <= high)):
                raise ValueError(f"GreyBoxRegressor: learned attribute {name!r} is {interval.tolist()}, which does "
                                 f"not hold the estimates {estimates.tolist()}: expected [low, high] around each.")

    def parameter_summary(self) -> str:
        """The fitted time constants (h) and exponent b, each with its 90 % interval, for a person to read.

        For example ``τ1 = 1.15 h (90 %: 1.04 … 1.27), τ2 = 11.8 h (90 %: 6.13 … 22.7); b = 1.59 (90 %: 1.47 …
        1.71)``. An estimate on a bound of ``time_constant_bounds`` or ``exponent_bounds`` says so (its interval
        stops there), a b that was not fitted is marked as fixed, and a model saved before the intervals were
        stored gives the estimates alone.

        Returns
        -------
        str
        """
        check_is_fitted(self, "time_constants_")
        intervals = getattr(self, "time_constants_interval_", None)
        hours = np.array(_pair(self.time_constant_bounds, "time_constant_bounds")) / 3600.0
        taus = [f"τ{i + 1} = " + _estimate_text(tau / 3600.0, None if intervals is None else intervals[i] / 3600.0,
                                                 hours, " h") for i, tau in enumerate(self.time_constants_)]
        if not getattr(self, "exponent_fitted_", True):
            exponent = f"{self.exponent_:.3g} (fixed: the rows fitted run at one speed, or fit_exponent is off)"
        else:
            exponent = _estimate_text(self.exponent_, getattr(self, "exponent_interval_", None),
                                      _pair(self.exponent_bounds, "exponent_bounds"))
        return f"{', '.join(taus)}; b = {exponent}"

    def _fitted_inputs(self, X, allow_nan_observed=False):
        self.check_fitted()   # first: a model missing some learned attributes is named, not called unfitted
        check_is_fitted(self, "time_constants_")
        X = check_array(X, dtype=np.float64, ensure_all_finite=False, ensure_min_samples=2)
        check_n_features(self, X)
        inputs, observed = self._columns(X.shape[1])
        whole = self._records(len(X), ())   # a record to predict is one, from rest at its first row
        time, speed = self._check_x(X, inputs, whole, allow_nan_in=observed if allow_nan_observed else ())
        return X, time, observed, self._inputs(X, speed, inputs, self.exponent_, whole), whole

    def predict_outputs(self, X: ArrayLike) -> np.ndarray:
        """Simulated outputs (n, 1 + n_observed): y, then the observed thermometers' changes since the first row (K).

        Parameters
        ----------
        X : array-like, shape (n_samples, n_features)
            A record in the layout of the fit; observed columns may hold NaN (they are not used).

        Returns
        -------
        outputs : ndarray, shape (n_samples, 1 + n_observed)
            y (its unit) and the simulated changes of the observed thermometers since the first row, K.
        """
        _, time, _, U, whole = self._fitted_inputs(X, allow_nan_observed=True)
        S = self._states(time, U, -self.poles_, whole)
        return (self.offset_ + np.einsum("kij,nij->nk", self.gains_, S) + U[:, 1:] @ self.feedthrough_.T)

    def predict(self, X: ArrayLike) -> np.ndarray:
        """y from equilibrium at the first row of ``X``: simulated, or observed (see below).

        Without ``observed`` columns this is the pure simulation (no measured
        output is used); with them it is :meth:`predict_filtered`, which fuses
        those thermometers as the model runs.

        Parameters
        ----------
        X : array-like, shape (n_samples, n_features)
            A record in the layout of the fit.

        Returns
        -------
        y : ndarray, shape (n_samples,)
            The predicted target, in the unit of the training target (e.g. µm).
        """
        if self.observed:
            return self.predict_filtered(X)
        return self.predict_outputs(X)[:, 0]

    # ------------------------------------------------------------ observer
    def state_space(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Continuous ``(A, B, C, D)`` with inputs ``[P, ΔT…, 1]`` and outputs ``[y, observed…]``.

        States are ordered pole-major (x_00, x_01, …); the last input is a
        constant 1 carrying the offsets.

        Returns
        -------
        A : ndarray, shape (n_states, n_states)
            State matrix, 1/s (diagonal, −1/τ).
        B : ndarray, shape (n_states, n_inputs + 1)
            Input matrix, 1/s.
        C : ndarray, shape (1 + n_observed, n_states)
            Output matrix (the gains g).
        D : ndarray, shape (1 + n_observed, n_inputs + 1)
            Feed-through: none for spindle heat, d for the temperature inputs, the offsets c₀ last.
        """
        check_is_fitted(self, "time_constants_")
        n_outputs, n_poles, m = self.gains_.shape
        lam = np.repeat(-self.poles_, m)
        A = np.diag(-lam)
        B = np.zeros((n_poles * m, m + 1))
        B[np.arange(n_poles * m), np.tile(np.arange(m), n_poles)] = lam
        C = self.gains_.reshape(n_outputs, -1)
        D = np.column_stack([np.zeros(n_outputs), self.feedthrough_, self.offset_])
        return A, B, C, D

    def predict_filtered(self, X: ArrayLike) -> np.ndarray:
        """y estimated by the Kalman observer that fuses the ``observed`` thermometers (NaN = missing).

        The model runs as in :meth:`predict`; at every row the readings of the
        observed columns correct the states (measurement noise: their training
        RMSE; process noise: ``process_noise``). Without observed columns this
        is the simulation.

        No standard deviation is returned. The filter's covariance rests on the
        assumed ``process_noise`` and leaves out the error of the model itself,
        so its band is not a calibrated interval. A band rescaled to the
        training residuals covered about 95 % of a record like the training
        one, but far less of one with an unmodelled heat or at an unseen speed,
        which is where a band would be wanted.

        Parameters
        ----------
        X : array-like, shape (n_samples, n_features)
            A record in the layout of the fit; NaN in an observed column is a missing reading.

        Returns
        -------
        y : ndarray, shape (n_samples,)
            The filtered estimate of y (its unit, e.g. µm).
        """
        X, time, observed, U, whole = self._fitted_inputs(X, allow_nan_observed=True)
        readings = self._observed_since_start(X, observed, whole)
        A, B, C, D = self.state_space()
        _, n_poles, m = self.gains_.shape
        lam = np.repeat(-self.poles_, m)
        intensity = np.diag(2.0 * lam * self.process_noise * np.tile(np.maximum(self.input_std_, 1e-12) ** 2, n_poles))
        U1 = np.column_stack([U, np.ones(len(U))])
        kf = KalmanFilter(np.eye(len(lam)), B, C[1:], D[1:], np.zeros((len(lam), len(lam))),
                          np.maximum(self.output_std_[1:], 1e-12) ** 2)
        x0 = np.repeat(U[:1], n_poles, axis=0).ravel()
        kf.reset(x0, np.diag(np.diag(intensity) / (2.0 * lam)))
        steps = np.diff(time)
        cache = {}
        mean = np.empty(len(X))
        for k in range(len(X)):
            if observed:
                kf.update(readings[k], U1[k])
            mean[k] = kf.estimate(C[:1], D[:1], U1[k])[0][0]
            if k + 1 < len(X):
                dt = float(steps[k])
                if dt not in cache:
                    cache[dt] = discretize(A, B, dt, intensity)
                kf.F, kf.G, kf.Q = cache[dt]
                kf.predict(U1[k])
        return mean
