"""Logging outages across which the operating inputs changed: rows whose twin is not known.

A measured record gives the spindle speed and the feeds only at its samples.
Between two ordinary samples a change can lie anywhere within one interval,
and :func:`twin.gap.diagnose.reconstruct_inputs` turns that into the timing
floor.  Across a logging outage (an interval of more than
:data:`OUTAGE_FACTOR` typical ones) the spindle may have run, stopped or
changed speed several times: what the machine did there is unknown, and its
heat shows in every sensor for hours after.  Rows logged with the input left
empty are the same (its outage runs from the last row that read it to the
next).  Such an interval, when an input differs across it, is an *outage*; it is left out of the timing floor (it would
swamp the floor of every other change and hide a real gap), and the rows
after it on which the twin depends on when the change happened are left out
of the fits and of the evidence: the twin with the change at the outage's
start and at its end differ there by more than the channel's scale.  The
diagnosis says so in its verdict, rather than judging the twin on inputs
nobody recorded.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import TwinInputError

#: An interval longer than this many typical (median) intervals and than :data:`OUTAGE_MIN_S`, with an input that
#: differs across it, is an outage; a shorter one is a sampling irregularity, which the timing floor covers.
OUTAGE_FACTOR = 5.0
#: The shortest outage, s: shorter than the structure's thermal time constants (tens of minutes and more), an
#: unlogged interval moves the twin about as much as a sample of timing does.
OUTAGE_MIN_S = 600.0
#: The fewest fit and held-out rows a diagnosis keeps once the rows after outages are left out.
MIN_ROWS = 10
#: The largest hold-out fraction the diagnosis takes (:func:`twin.gap.diagnose.diagnose`).
MAX_HOLDOUT = 0.8


@dataclass
class UnknownInputs:
    """Outages and the rows they leave out.

    Attributes
    ----------
    outages : list of (float, float, str)
        Start and end of each outage, s, and what changed across it (e.g. ``spindle 0 → 10000 rpm``).
    rows : ndarray of bool, shape (n_times,)
        Rows left out of the fits and the evidence.
    """

    outages: list
    rows: np.ndarray

    def as_dict(self) -> dict[str, object]:
        """The outages (``start_s``, ``end_s``, ``change``) and the number of rows left out, for JSON."""
        return {"outages": [{"start_s": a, "end_s": b, "change": what} for a, b, what in self.outages],
                "rows_left_out": int(self.rows.sum())}

    def sentence(self, time_s: np.ndarray) -> str:
        """What the verdict opens with, or '' without outages.

        Parameters
        ----------
        time_s : ndarray, shape (n_times,)
            The record's sample times, s.
        """
        if not self.outages:
            return ""
        spans = _spans(self.outages)
        left = time_s[self.rows]
        until = (f"the {int(self.rows.sum())} rows from {left[0] / 3600:.2f} to {left[-1] / 3600:.2f} h, where the "
                 "twin depends on when the change happened, are left out of the fits and the evidence"
                 if left.size else "no row depends on it beyond the channels' scales")
        return (f"INPUTS UNKNOWN: the operating inputs changed during logging outages, {spans}; {until}; "
                "what follows judges the other rows: ")


def _spans(outages):
    return "; ".join(f"{a / 3600:.2f}–{b / 3600:.2f} h ({what})" for a, b, what in outages)


def as_long_as_an_outage(span_s: np.ndarray | float, typical_s: float) -> np.ndarray | bool:
    """Whether a time without readings of an input, ``span_s`` (s), is long enough to be an outage: more than
    :data:`OUTAGE_FACTOR` typical (median) sample intervals ``typical_s`` (s) and at least :data:`OUTAGE_MIN_S`.

    Parameters
    ----------
    span_s : float or ndarray
        Times without a reading, s.
    typical_s : float
        The record's median sample interval, s.

    Returns
    -------
    bool or ndarray of bool
        Elementwise.
    """
    return (np.asarray(span_s) > OUTAGE_FACTOR * typical_s) & (np.asarray(span_s) >= OUTAGE_MIN_S)


def outage_spans(time_s: np.ndarray, inputs: dict[str, np.ndarray]) -> dict[str, list[tuple[int, int]]]:
    """Each input's outages (see the module docstring): ``(a, b)``, two consecutive rows that read it.

    An input that is not read (NaN) on rows that were logged is as unknown there as across an interval without
    rows: its outage runs from the last row that read it to the next, over every interval between.

    Parameters
    ----------
    time_s : ndarray, shape (n_times,)
        Sample times, s, increasing.
    inputs : dict of str to ndarray, shape (n_times,)
        Measured operating inputs by name (spindle in rpm, feeds in mm/min); NaN where not read.

    Returns
    -------
    dict of str to list of (int, int)
        Input name → its outages, rows a < b, with the input read at both and different.
    """
    t = np.asarray(time_s, float)
    typical = np.median(np.diff(t))
    spans = {}
    for name, values in inputs.items():
        v = np.asarray(values, float)
        read = np.flatnonzero(np.isfinite(v))
        a, b = read[:-1], read[1:]
        span = t[b] - t[a]
        hit = as_long_as_an_outage(span, typical) & ~np.isclose(v[b], v[a], rtol=1e-6, atol=1e-9)
        spans[name] = list(zip(a[hit].tolist(), b[hit].tolist()))
    return spans


def outage_intervals(time_s: np.ndarray, spans: dict[str, list[tuple[int, int]]]) -> np.ndarray:
    """Which sample intervals lie in some input's outage.

    Parameters
    ----------
    time_s : ndarray, shape (n_times,)
        Sample times, s.
    spans : dict
        :func:`outage_spans`.

    Returns
    -------
    ndarray of bool, shape (n_times - 1,)
    """
    out = np.zeros(len(time_s) - 1, bool)
    for a, b in (span for each in spans.values() for span in each):
        out[a:b] = True
    return out


def describe(time_s: np.ndarray, inputs: dict[str, np.ndarray], spans: dict[str, list[tuple[int, int]]]) -> list:
    """(start s, end s, what changed) of each outage, in time order; the inputs whose outages span the same rows
    are named together (``spindle_rpm 0 → 10000, feed_x_mm_min 0 → 5000``)."""
    changes = {}
    for name, each in spans.items():
        v = np.asarray(inputs[name], float)
        for a, b in each:
            changes.setdefault((a, b), []).append(f"{name} {v[a]:g} → {v[b]:g}")
    return [(float(time_s[a]), float(time_s[b]), ", ".join(what)) for (a, b), what in sorted(changes.items())]


def held_across(values: np.ndarray, spans: list[tuple[int, int]], side: str) -> np.ndarray:
    """An input with each of its outages' changes moved to the outage's ``side``: its rows inside an outage hold
    the value after it (``"start"``: the change came first) or before it (``"end"``).

    Parameters
    ----------
    values : ndarray, shape (n_times,)
        The input as filled in time (a step at each unread run's middle).
    spans : list of (int, int)
        The input's outages (:func:`outage_spans`).
    side : {"start", "end"}
        Where the change goes.

    Returns
    -------
    ndarray, shape (n_times,)
        A copy; each change then lies in its outage's first (``start``) or last (``end``) interval.
    """
    out = np.array(values, float)
    for a, b in spans:
        out[a + 1:b] = out[b] if side == "start" else out[a]
    return out


def unknown_rows(time_s: np.ndarray, start_s: float, spread: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Rows after the first outage's start where the twin's spread over the outages' change times exceeds the scale.

    Parameters
    ----------
    time_s : ndarray, shape (n_times,)
        Sample times, s.
    start_s : float
        Start of the first outage, s.
    spread : ndarray, shape (n_times, n_channels)
        The twin with every outage's change at its end minus at its start, channel units (NaN where not read).
    scale : ndarray, shape (n_channels,)
        Each channel's scale (its tolerance, noise or timing floor), channel units.

    Returns
    -------
    ndarray of bool, shape (n_times,)
        Every row from the first to the last at which some channel's |spread| exceeds its scale.
    """
    over = np.flatnonzero(np.any(np.abs(np.nan_to_num(spread)) > scale, axis=1) & (time_s > start_s))
    rows = np.zeros(len(time_s), bool)
    if over.size:
        rows[over[0]:over[-1] + 1] = True
    return rows


def check_rows_left(fit_rows: np.ndarray, hold_rows: np.ndarray, unknown: UnknownInputs, time_s: np.ndarray,
                    source: str) -> None:
    """Refuse a record whose outages leave too few fit or held-out rows (:data:`MIN_ROWS`).

    Raises
    ------
    TwinInputError
        Naming the record, the outages and the rows left.
    """
    fit, hold = int((fit_rows & ~unknown.rows).sum()), int((hold_rows & ~unknown.rows).sum())
    if min(fit, hold) >= MIN_ROWS or not unknown.rows.any():
        return
    first, last = time_s[unknown.rows][[0, -1]]
    # the split at 70 % of the way to the first outage: the fit part keeps most rows before it, the held-out the rest
    fraction = 1.0 - 0.7 * (unknown.outages[0][0] - time_s[0]) / (time_s[-1] - time_s[0])
    move = (f"or hold out the last {fraction:.2f} (--holdout {fraction:.2f}), which judges the twin on the rows "
            "before the outage" if fraction <= MAX_HOLDOUT else "and the rows before the outage are too few to "
            "judge the twin on")
    raise TwinInputError(
        f"{source}: the operating inputs changed during logging outages ({_spans(unknown.outages)}), and the rows "
        f"where the twin depends on when ({first / 3600:.2f}–{last / 3600:.2f} h) leave {fit} fit and {hold} "
        f"held-out rows (at least {MIN_ROWS} of each are needed): the record cannot tell whether the twin has a "
        f"gap there; give a record without the outage (or with the inputs logged through it), {move}")
