"""Sensor errors and sampling of the benchmark's truth records, written independently of :mod:`twin.gap.effects`.

The diagnosis models a thermometer's lag as one first-order filter
(:func:`twin.gap.signals.lag`).  A real mounting is not that: a pad and the
sensor's own body make a second-order response, a wire-wound probe in a
bore has a dead time.  These functions make such readings from the true
signals by other routes (a state-space simulation by :func:`scipy.signal.lsim`,
interpolation for a dead time), so a truth built with them never has
exactly the form the library fits.

Sampling: a logger samples at its own times (45 s, irregular 30–70 s, a
clock 15 s off the minute).  :func:`resample` takes a finely sampled truth
(the FE's own output grid) to such times: sensors by linear interpolation
between the fine samples (their error is second order in the fine step),
operating conditions as the scenario's values at the new times.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.signal import lsim

from ..core.dataset import Dataset
from ..core.machine_definition import room_zone
from ..core.scenario import Scenario
from ..errors import TwinInputError


def _check_uniform(t, what):
    t = np.asarray(t, float)
    d = np.diff(t)
    if len(t) < 2 or not np.allclose(d, d[0], rtol=1e-9, atol=1e-9):
        raise TwinInputError(f"{what}: needs a uniformly sampled signal (got steps {d.min():g}–{d.max():g} s)")
    return t


def second_order_lag(t: np.ndarray, y: np.ndarray, tau1_s: float, tau2_s: float) -> np.ndarray:
    """Readings of a sensor with response 1 / ((τ₁s + 1)(τ₂s + 1)) to true signals y (n,) or (n, k), from rest at y[0].

    Continuous-time state space simulated by :func:`scipy.signal.lsim` (input linear between samples).

    Parameters
    ----------
    t : ndarray, shape (n,)
        Uniformly spaced sample times, s (anything else raises :class:`~twin.errors.TwinInputError`).
    y : ndarray, shape (n,) or (n, k)
        True signals at ``t`` (any unit, e.g. °C), one column per sensor.
    tau1_s, tau2_s : float
        The two time constants, s (> 0).

    Returns
    -------
    ndarray, shape of ``y``
        The readings, in the unit of ``y``.
    """
    t = _check_uniform(t, "second_order_lag")
    if tau1_s <= 0 or tau2_s <= 0:
        raise TwinInputError(f"second_order_lag: time constants must be > 0 s, got {tau1_s}, {tau2_s}")
    y = np.asarray(y, float)
    cols = y.reshape(len(t), -1)
    a1, a0 = tau1_s + tau2_s, tau1_s * tau2_s
    # ẍ·a0 + ẋ·a1 + x = u  →  companion form, state (x, ẋ)
    A = np.array([[0.0, 1.0], [-1.0 / a0, -a1 / a0]])
    B = np.array([[0.0], [1.0 / a0]])
    C, D = np.array([[1.0, 0.0]]), np.array([[0.0]])
    out = np.empty_like(cols)
    for j in range(cols.shape[1]):
        u = cols[:, j]
        _, yo, _ = lsim((A, B, C, D), u - u[0], t - t[0], X0=[0.0, 0.0], interp=True)
        out[:, j] = yo + u[0]
    return out.reshape(y.shape)


def dead_time(t: np.ndarray, y: np.ndarray, delay_s: float) -> np.ndarray:
    """Readings delayed by ``delay_s`` (transport delay; the first value held before it).

    Parameters
    ----------
    t : ndarray, shape (n,)
        Sample times, s (increasing).
    y : ndarray, shape (n,) or (n, k)
        True signals at ``t`` (any unit), one column per sensor.
    delay_s : float
        Transport delay, s.

    Returns
    -------
    ndarray, shape of ``y``
        ``y`` at ``t − delay_s`` (linear interpolation), in the unit of ``y``.
    """
    t = np.asarray(t, float)
    y = np.asarray(y, float)
    cols = y.reshape(len(t), -1)
    out = np.column_stack([np.interp(t - delay_s, t, cols[:, j]) for j in range(cols.shape[1])])
    return out.reshape(y.shape)


def sample_times(duration_s: float, kind: str, seed: int = 0) -> np.ndarray:
    """Logger times over [0, duration]: ``"45s"`` / any ``"<n>s"`` regular, ``"irregular"`` (30–70 s steps,
    seeded), ``"clock_offset"`` (every 60 s, 15 s after the minute).

    Parameters
    ----------
    duration_s : float
        Length of the record, s.
    kind : str
        ``"<n>s"`` (regular every n s from 0), ``"irregular"`` or ``"clock_offset"``; anything else raises
        :class:`~twin.errors.TwinInputError`.
    seed : int, default 0
        Random seed of the ``"irregular"`` steps.

    Returns
    -------
    ndarray, shape (n_samples,)
        Increasing sample times within [0, ``duration_s``], s.
    """
    if kind == "irregular":
        rng = np.random.default_rng(seed)
        steps = rng.uniform(30.0, 70.0, int(duration_s / 30.0) + 2)
        t = np.concatenate([[0.0], np.cumsum(steps)])
        return t[t <= duration_s]
    if kind == "clock_offset":
        return np.arange(15.0, duration_s + 1e-9, 60.0)
    if kind.endswith("s"):
        try:
            step = float(kind[:-1])
        except ValueError:
            step = 0.0
        if step > 0:
            return np.arange(0.0, duration_s + 1e-9, step)
    raise TwinInputError(f"unknown sampling {kind!r}; use '<n>s' (e.g. '45s'), 'irregular' or 'clock_offset'")


def resample(dataset: Dataset, times_s: np.ndarray, scenario: Scenario) -> Dataset:
    """The record at other times: sensors interpolated from the fine truth, operating conditions from the scenario.

    Parameters
    ----------
    dataset : Dataset
        The finely sampled truth record.
    times_s : ndarray, shape (n_samples,)
        New sample times, s, within the record's span.
    scenario : Scenario
        The scenario the record was made with (spindle speed, rpm, and feeds, mm/min, at ``times_s``).

    Returns
    -------
    Dataset
        The same channels at ``times_s``; its metadata's ``sampling`` gives the count, first time and median step
        (s).
    """
    times_s = np.asarray(times_s, float)
    t = dataset.time_s
    if times_s.min() < t[0] - 1e-9 or times_s.max() > t[-1] + 1e-9:
        raise TwinInputError(f"resample: times {times_s.min():g}–{times_s.max():g} s outside the record "
                             f"({t[0]:g}–{t[-1]:g} s)")
    rpm, feeds = scenario.operating(times_s)
    columns = []
    for j, c in enumerate(dataset.channels):
        if c.kind == "spindle_speed":
            columns.append(rpm)
        elif c.kind == "feed":
            columns.append(feeds[c.name[-1]])
        else:
            columns.append(np.interp(times_s, t, dataset.values[:, j]))
    meta = dict(dataset.metadata)
    meta["sampling"] = {"n": len(times_s), "first_s": float(times_s[0]),
                        "median_step_s": float(np.median(np.diff(times_s))) if len(times_s) > 1 else None}
    return Dataset(times_s, np.column_stack(columns), list(dataset.channels), meta)


def apply_sensor_errors(dataset: Dataset, errors: Sequence[tuple], scenario: Scenario) -> Dataset:
    """The record with sensor errors applied to its (uniformly sampled) true readings.

    ``errors``: tuples ``("thermometer_lag2", τ₁ s, τ₂ s)`` (every surface thermometer through
    :func:`second_order_lag`), ``("thermometer_dead_time", s)``, ``("fixture", k_x, k_y, k_z µm/K, τ₁ min,
    τ₂ min)`` (each displacement probe += k·(room air through a second-order lag − its start value); the
    room air is the scenario's, which the record does not contain), ``("thermometer_in_air", name, share)``
    (one loose thermometer: it reads ``share`` (0…1) of the room air and the rest of its surface).

    Parameters
    ----------
    dataset : Dataset
        The true record (uniformly sampled when a lag is applied).
    errors : sequence of tuple
        The errors, applied in order (see above); an unknown name raises :class:`~twin.errors.TwinInputError`.
    scenario : Scenario
        The record's scenario (machine and room air, °C; used by ``fixture`` and ``thermometer_in_air``).

    Returns
    -------
    Dataset
        The record with the errors applied, listed in its metadata's ``sensor_errors``.
    """
    V = dataset.values.copy()
    for err in errors:
        name, args = err[0], err[1:]
        if name not in _ERRORS:
            raise TwinInputError(f"unknown sensor error {name!r}; errors: {', '.join(_ERRORS)}")
        _ERRORS[name](dataset, V, scenario, *args)
    meta = dict(dataset.metadata)
    meta["sensor_errors"] = [list(e) for e in errors]
    return Dataset(dataset.time_s, V, list(dataset.channels), meta)


def _thermometers(dataset):
    return [j for j, c in enumerate(dataset.channels) if c.kind == "temperature"]


def _room_air(scenario, t):
    room = room_zone(scenario.machine_definition().zones)
    return scenario.zone_ambient(t, [room])[room]


def _thermometer_lag2(dataset, V, scenario, tau1_s, tau2_s):
    cols = _thermometers(dataset)
    V[:, cols] = second_order_lag(dataset.time_s, V[:, cols], tau1_s, tau2_s)


def _thermometer_dead_time(dataset, V, scenario, delay_s):
    cols = _thermometers(dataset)
    V[:, cols] = dead_time(dataset.time_s, V[:, cols], delay_s)


def _fixture(dataset, V, scenario, kx, ky, kz, tau1_min, tau2_min):
    t = dataset.time_s
    air = second_order_lag(t, _room_air(scenario, t), tau1_min * 60.0, tau2_min * 60.0)
    k = {"x": kx, "y": ky, "z": kz}
    for j, c in enumerate(dataset.channels):
        if c.kind == "displacement":
            V[:, j] += k[c.name[0].lower()] * (air - air[0])


def _thermometer_in_air(dataset, V, scenario, name, share):
    j = next((j for j, c in enumerate(dataset.channels) if c.name == name and c.kind == "temperature"), None)
    if j is None:
        raise TwinInputError(f"thermometer_in_air: {name!r} is not a thermometer of the record")
    V[:, j] = (1.0 - share) * V[:, j] + share * _room_air(scenario, dataset.time_s)


_ERRORS = {"thermometer_lag2": _thermometer_lag2, "thermometer_dead_time": _thermometer_dead_time,
           "fixture": _fixture, "thermometer_in_air": _thermometer_in_air}
