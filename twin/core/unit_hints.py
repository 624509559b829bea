"""Operating-condition columns that read like another unit than their header says: a spindle speed in Hz or krpm
under ``_rpm``, feeds in m/min under ``_mm_min``.

Both the gap diagnosis (:func:`twin.gap.measured.check_operating_range`) and the compensation models
(``twin train``/``twin evaluate`` on a measured CSV, :func:`twin.compensation.records.note_unit_suspects`)
warn with :func:`other_unit_hint`, so the rule and its words are the same everywhere; a column is judged
against its machine's top speed or feed (:func:`machine_top`), or a typical machining centre's when no machine
is given (:func:`top_of`).  A warning, never a refusal: a slow warm-up or slow finishing feeds can be true.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .machine_definition import MachineDefinition

#: A running spindle column that peaks (99th percentile of |n|) at or below this fraction of the machine's top
#: speed reads like one in Hz or rev/s (60× too small: 1000 … 12000 rpm read 17 … 200) or in krpm (1000× too
#: small: 12000 rpm reads 12, 0.1 %), and is warned about.  Running: it holds its speed (:func:`_holds_speed`),
#: which a tachometer's noise at standstill (a few rpm, either sign) does not.  A record that truly peaks there
#: is possible (a slow warm-up), so it is warned about, not refused; the warning names both factors.
SPINDLE_PEAK_TOO_LOW = 0.02
#: A feed column whose peak (99th percentile of |f| over the axes' rows) is at or below this fraction of the
#: machine's top feed reads like one in m/min (1000× too small: 30000 mm/min reads 30, 0.1 %, and a log's
#: rapid traverses at most 3× that); a thermal test's real feeds reach far above 1 % of the top feed (300 mm/min
#: on a 30 m/min machine).  Warned about, like the spindle, since a slow finishing record is possible.
FEED_PEAK_TOO_LOW = 0.01
#: The tops a record is judged against when no machine is given (``twin train`` on a measured CSV): a
#: machining centre's spindle (vmc_ram 12000 rpm, machine_a 9000) and the feed a machine definition defaults to
#: (30 m/min); rpm and mm/min, by the column's unit.
TYPICAL_TOP = {"rpm": 12000.0, "mm_min": 30000.0}


def machine_top(definition: MachineDefinition, unit: str) -> float:
    """A machine's top spindle speed (rpm) for a channel in ``rpm``, else its top feed (mm/min).

    Parameters
    ----------
    definition : MachineDefinition
        The machine (``max_spindle_rpm``, ``max_feed_mm_min``).
    unit : str
        The channel's unit: ``rpm`` (a spindle speed) or ``mm_min`` (a feed).

    Returns
    -------
    float
        rpm or mm/min, by ``unit``.
    """
    return definition.max_spindle_rpm if unit == "rpm" else definition.max_feed_mm_min


def top_of(definition: MachineDefinition | None, unit: str) -> tuple[float, str]:
    """The top a channel in ``unit`` is judged against, and whose it is, for :func:`other_unit_hint`.

    Parameters
    ----------
    definition : MachineDefinition, optional
        The machine; without one, :data:`TYPICAL_TOP`.
    unit : str
        ``rpm`` or ``mm_min``.

    Returns
    -------
    tuple of (float, str)
        The top (rpm or mm/min, :func:`machine_top`) and its owner, ``"machine 'vmc_ram'"`` or
        ``"a typical machining centre (no machine given)"``.
    """
    if definition is None:
        return TYPICAL_TOP[unit], "a typical machining centre (no machine given)"
    return machine_top(definition, unit), f"machine {definition.name!r}"


def other_unit_hint(column: str, unit: str, values: np.ndarray, top: float, owner: str,
                    consequence: str = "") -> str | None:
    """A one-line warning when a running spindle column (unit ``rpm``) peaks where one in Hz or krpm would, or a
    feed column (unit ``mm_min``) where one in m/min would; else None.

    Parameters
    ----------
    column : str
        The CSV column, for the message.
    unit : str
        The channel's unit: ``rpm`` (a spindle speed) or ``mm_min`` (a feed); any other: None.
    values : ndarray, shape (n_times,)
        The column's values (rpm or mm/min), NaN where missing (ignored).
    top : float
        The machine's top spindle speed (rpm) or top feed (mm/min).
    owner : str
        Whose top it is, for the message, e.g. ``"machine 'vmc_ram'"``.
    consequence : str, optional
        What a wrong unit does downstream, inserted before "convert it", e.g. ``", and every heat it drives …"``.

    Returns
    -------
    str or None
        The warning, naming the peak (99th percentile of |v|), its share of ``top`` and both factors, when the
        column runs (peak > 0) at or below :data:`SPINDLE_PEAK_TOO_LOW` (spindle) or :data:`FEED_PEAK_TOO_LOW`
        (feed) × ``top``; None otherwise, or for a column of another unit or without a finite value.
    """
    spindle = unit == "rpm"
    if not (spindle or unit == "mm_min"):
        return None
    values = np.asarray(values, float)
    finite = np.abs(values[np.isfinite(values)])
    if not finite.size:
        return None
    peak = float(np.percentile(finite, 99.0))
    if not 0.0 < peak <= (SPINDLE_PEAK_TOO_LOW if spindle else FEED_PEAK_TOO_LOW) * top:
        return None
    if spindle and not _holds_speed(finite, peak):
        return None
    shown, top_name, guess = (                     # the unit as the message writes it
        ("rpm", "top speed", (f"in Hz (rev/s), the speed is {60 * peak:.0f} rpm (× 60); if in krpm, "
                              f"{1000 * peak:.0f} rpm (× 1000)")) if spindle
        else ("mm/min", "top feed", f"in m/min, the feed is {1000 * peak:.0f} mm/min (× 1000)"))
    return (f"column {column!r} peaks at about {peak:.4g} {shown} (99th percentile), "
            f"{100 * peak / top:.2g} % of the {top:g} {shown} {top_name} of {owner}: if it is "
            f"{guess}{consequence}; convert it to {shown}")


def _holds_speed(magnitudes, peak):
    """Whether a spindle column runs: of the consecutive row pairs at or above half its peak (at least 3), at
    least half change by at most 1 % of the peak (a held speed, not a tachometer's noise at rest)."""
    on = magnitudes >= 0.5 * peak
    pairs = on[1:] & on[:-1]
    steady = pairs & (np.abs(np.diff(magnitudes)) <= 0.01 * peak)
    return pairs.sum() >= 3 and steady.sum() >= 0.5 * pairs.sum()
