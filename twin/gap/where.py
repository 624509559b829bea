"""Where the twin misses: residuals by sensor, drift axis, operating phase and frequency band.

Phases come from the measured spindle speed and ambient: a thermal-load
proxy p(t) = lag((n / n_max)^1.3, 1 h) against its target (n / n_max)^1.3
separates *heating* (running, p below 85 % of its target), *steady*
(running, within ±15 %), *cooling* (stopped, or slowed down, with p still
above its target), *ambient-driven* (idle, the room changing faster than
0.3 K/h or a door zone departing more than 1 K from the room) and *idle*.
"""
from __future__ import annotations

import numpy as np

from .drive import Drive
from .fit import Evaluator, Residual
from .signals import BANDS, band_split, lag

PHASES = ("heating", "steady", "cooling", "ambient-driven", "idle")


def phases(drive: Drive, times_s: np.ndarray) -> np.ndarray:
    """Phase label of every measured time (array of str), from a drive on the twin grid.

    Parameters
    ----------
    drive : Drive
        Operating conditions on the twin grid (spindle speed, rpm; room and zone ambients, °C).
    times_s : ndarray, shape (n,)
        Measured times, s; each takes the label of the first grid point at or after it.

    Returns
    -------
    ndarray of str, shape (n,)
        One of :data:`PHASES` per time.
    """
    rpm = np.abs(drive.spindle_rpm)
    n_max = max(float(rpm.max()), 1.0)
    target = (rpm / n_max) ** 1.3
    proxy = lag(target, drive.step_s, 3600.0)
    running = rpm > 0.01 * n_max
    room = lag(drive.room(), drive.step_s, 900.0)
    rate = np.abs(np.gradient(room, drive.step_s)) * 3600.0
    amb = drive.zone_ambient()
    door = np.zeros(len(drive.grid), bool)
    for z, v in amb.items():
        if z != drive.room_zone and not drive.lags_s.get(z):
            dev = v - drive.room()
            door |= np.abs(dev - np.median(dev)) > 1.0
    label = np.full(len(drive.grid), "idle", dtype=object)
    busy = proxy > 0.05 * max(float(proxy.max()), 1e-9)
    label[~running & ((rate > 0.3) | door)] = "ambient-driven"
    label[~running & busy] = "cooling"
    label[running & (proxy < 0.85 * target)] = "heating"
    label[running & (proxy >= 0.85 * target) & (proxy <= 1.15 * target)] = "steady"
    label[running & (proxy > 1.15 * target)] = "cooling"
    k = np.clip(np.searchsorted(drive.grid, times_s), 0, len(drive.grid) - 1)
    return label[k].astype(str)


def _rms_entry(R, evaluator, groups, names, entry=None):
    """RMS of the finite residuals R (n, p) per channel group and per drift axis, into ``entry``."""
    entry = {} if entry is None else entry
    for g, idx in groups.items():
        entry[g] = _rms(R[:, idx])
    for j, n in enumerate(names):
        if evaluator.kinds[j] == "displacement":
            entry[n] = _rms(R[:, j])
    return entry


def _rms(r):
    r = r[np.isfinite(r)]
    return float(np.sqrt(np.mean(r ** 2))) if r.size else float("nan")


def phase_table(residual: Residual, evaluator: Evaluator, labels: np.ndarray,
                names: list[str]) -> dict[str, dict[str, float | int | None]]:
    """RMS residual per phase: per group, and per drift axis, over all rows (dict phase → {key: (rms, n)}).

    Parameters
    ----------
    residual : Residual
        Residuals ``R``, shape (n, p), in channel units.
    evaluator : Evaluator
        Gives the channel groups and kinds.
    labels : ndarray of str, shape (n,)
        Phase of every row (:func:`phases`).
    names : list of str
        Channel names, length p.

    Returns
    -------
    dict
        Phase (those with rows only) → {``"rows"``: number of rows (int), ``"hours"``: None, group or
        drift-axis name: RMS (float, K for temperature and air, µm for displacement, µε for strain; NaN
        without finite residuals)}.
    """
    out = {}
    groups = evaluator.groups()
    for ph in PHASES:
        rows = labels == ph
        if not rows.any():
            continue
        out[ph] = _rms_entry(residual.R[rows], evaluator, groups, names,
                             {"rows": int(rows.sum()), "hours": None})
    return out


def band_table(residual: Residual, evaluator: Evaluator, times_s: np.ndarray,
               names: list[str]) -> dict[str, dict[str, float]]:
    """RMS residual per frequency band (:data:`~twin.gap.signals.BANDS`): per group and per drift axis.

    Parameters
    ----------
    residual : Residual
        Residuals ``R``, shape (n, p), in channel units.
    evaluator : Evaluator
        Gives the channel groups and kinds.
    times_s : ndarray, shape (n,)
        Measured times of the rows, s.
    names : list of str
        Channel names, length p.

    Returns
    -------
    dict
        Band name → {group or drift-axis name: RMS (K for temperature and air, µm for displacement, µε for
        strain; NaN without finite residuals)}, over the rows where the residual is finite.
    """
    parts = band_split(times_s, residual.R)
    groups = evaluator.groups()
    return {band: _rms_entry(np.where(np.isfinite(residual.R), part, np.nan), evaluator, groups, names)
            for (band, _, _), part in zip(BANDS, parts)}
