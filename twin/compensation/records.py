"""The clocks and the start of measured records: sampling, long steps, records that continue one another.

A compensation model trains and runs on records whose time stamps come from a
logger: evenly sampled or not (:func:`evenly_sampled`,
:func:`sampling_interval`), with holes (:func:`note_long_steps`), cut into
files that continue one another (:func:`joined_when_contiguous`,
:func:`continued_record`), or starting later than the history they continue
(:func:`bridge_times`, :func:`linear_bridge`); a model that takes a record's
first row as rest needs it to start with the spindle stopped
(:func:`check_starts_at_rest`), which a twin record whose duty cycle starts at
t = 0 gets as an added first row (:func:`with_rest_start`).  A spindle or feed
column that reads like another unit (krpm, Hz, m/min) is warned about
(:func:`note_unit_suspects`).
"""
from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from models.speed import running

from ..core.dataset import Dataset
from ..core.unit_hints import TYPICAL_TOP, other_unit_hint, top_of
from ..errors import TwinInputError
from .record_order import in_canonical_order

if TYPE_CHECKING:
    from ..core.machine import Machine
    from ..core.machine_definition import MachineDefinition

log = logging.getLogger("thermal_twin")


def dataset_label(dataset: Dataset) -> str:
    """The name a dataset goes by in tables and messages: its label, scenario, source file stem, or "dataset".

    Parameters
    ----------
    dataset : Dataset
        A record (twin or measured).

    Returns
    -------
    str
    """
    meta = dataset.metadata
    if meta.get("label"):
        return str(meta["label"])
    if meta.get("scenario"):
        return str(meta["scenario"])
    if meta.get("source"):
        return Path(str(meta["source"])).stem
    return "dataset"


#: steps within this fraction of their median count as even sampling
EVEN_STEP_TOLERANCE = 1e-6
#: a record that starts one sampling interval after another ends, to within this fraction of it (a logger's
#: jitter), continues it
CONTINUES_WITHIN = 0.5


def distinct_labels(datasets: Sequence[Dataset]) -> list[str]:
    """Each record's :func:`dataset_label`, a repeated one followed by ``_2``, ``_3`` … (files of one name
    in two folders).

    Parameters
    ----------
    datasets : sequence of Dataset
        Records in the order given.

    Returns
    -------
    list of str
    """
    return distinct([dataset_label(ds) for ds in datasets])


def distinct(names: Sequence[str]) -> list[str]:
    """``names`` with a repeated one followed by ``_2``, ``_3`` … until it is unlike every name before it.

    Parameters
    ----------
    names : sequence of str
        Names in order.

    Returns
    -------
    list of str
        As many, all different.
    """
    taken: set[str] = set()
    out = []
    for name in names:
        unique, k = name, 2
        while unique in taken:
            unique, k = f"{name}_{k}", k + 1
        taken.add(unique)
        out.append(unique)
    return out


def evenly_sampled(dataset: Dataset) -> bool:
    """Whether every time step of a record is within :data:`EVEN_STEP_TOLERANCE` of their median.

    Parameters
    ----------
    dataset : Dataset
        A record (one row counts as even).

    Returns
    -------
    bool
    """
    steps = np.diff(dataset.time_s)
    return len(steps) == 0 or _even(steps, float(np.median(steps)))


def _even(steps, usual):
    """Whether ``steps`` (s) are all within :data:`EVEN_STEP_TOLERANCE` of ``usual`` (s)."""
    return bool(np.abs(steps - usual).max() <= EVEN_STEP_TOLERANCE * usual)


def sampling_interval(dataset: Dataset, strict: bool = True) -> float:
    """The constant sampling interval of a dataset (s); with ``strict`` an uneven one is an error.

    Parameters
    ----------
    dataset : Dataset
        A record (twin or measured).
    strict : bool, default True
        Refuse uneven steps (:func:`evenly_sampled`).

    Returns
    -------
    float
        The median time step, s.

    Raises
    ------
    TwinInputError
        One row only, or uneven steps with ``strict``.
    """
    steps = np.diff(dataset.time_s)
    if len(steps) == 0:
        raise TwinInputError(f"{dataset_label(dataset)}: a dataset with one row has no sampling interval")
    dt = float(np.median(steps))
    if strict and not _even(steps, dt):
        raise TwinInputError(f"{dataset_label(dataset)}: grey time-series models need evenly sampled data; "
                             f"steps range from {steps.min():g} to {steps.max():g} s (the grey-box model, "
                             "--model greybox, takes the record's own times)")
    return dt


#: a step this many times the record's median counts as missing rows, and is named
LONG_STEP_FACTOR = 10.0


def note_long_steps(dataset: Dataset) -> None:
    """Name, on the ``thermal_twin`` logger, the steps of a record longer than :data:`LONG_STEP_FACTOR` times its
    median: a model that takes the time holds the inputs over them, which is a guess for a long one.

    Parameters
    ----------
    dataset : Dataset
        A record (twin or measured).
    """
    if len(dataset) < 2:
        return
    steps, usual = np.diff(dataset.time_s), sampling_interval(dataset, strict=False)
    long = np.flatnonzero(steps > LONG_STEP_FACTOR * usual)
    if len(long):
        k = long[np.argmax(steps[long])]
        log.warning("%s: %d step(s) over %g× the usual %g s, the longest %g s after t = %g s; the inputs are held "
                    "over them", dataset_label(dataset), len(long), LONG_STEP_FACTOR, usual, float(steps[k]),
                    float(dataset.time_s[k]))


def note_unit_suspects(dataset: Dataset, machine: Machine | MachineDefinition | None = None) -> None:
    """Warn, on the ``thermal_twin`` logger, of a spindle column that reads like Hz or krpm under ``_rpm``, or a
    feed that reads like m/min under ``_mm_min`` (:func:`twin.core.unit_hints.other_unit_hint`, the gap
    diagnosis's rule), and list those columns in ``dataset.metadata["import"]["unit_suspects"]``.

    A warning, not a refusal: a slow warm-up can be true.  A model trained on such a column takes the header's
    unit, so one trained on krpm misreads every record in rpm (and the grey-box model's spindle never runs).

    Parameters
    ----------
    dataset : Dataset
        A measured record.
    machine : Machine or MachineDefinition, optional
        Its machine (built or only read), whose top spindle speed (rpm) and feed (mm/min) judge the columns;
        without one, the :data:`~twin.core.unit_hints.TYPICAL_TOP` of a machining centre.
    """
    definition = getattr(machine, "definition", machine)
    suspects = []
    for ch in dataset.channels:
        if ch.unit not in TYPICAL_TOP:
            continue
        hint = other_unit_hint(ch.column, ch.unit, dataset[ch.name], *top_of(definition, ch.unit),
                               consequence=", and a model trained or evaluated on it takes it as given")
        if hint is not None:
            log.warning("%s: %s", dataset.metadata.get("source") or dataset_label(dataset), hint)
            suspects.append(ch.column)
    if suspects:
        dataset.metadata.setdefault("import", {})["unit_suspects"] = suspects


def continued_record(first: Dataset, later: Dataset, names: Sequence[str], interval_s: float | None = None
                     ) -> Dataset:
    """``first`` and then ``later`` as one record, in the channels ``names`` (labelled "first + later").

    Parameters
    ----------
    first, later : Dataset
        Records in time order; both have ``names``.
    names : sequence of str
        Channels kept, in ``first``'s units.
    interval_s : float, optional
        A sampling interval, s: the whole intervals missing between the two are filled by
        :func:`linear_bridge` (as ``twin evaluate --gap interpolate`` does).

    Returns
    -------
    Dataset
        The rows of both, and the bridge between them.
    """
    a, b = first.select(list(names)), later.select(list(names))
    bridge_t = np.empty(0) if interval_s is None else bridge_times(a.time_s[-1], b.time_s[0], interval_s)
    bridge = linear_bridge(a.values[-1], b.values[0], len(bridge_t))
    return Dataset(np.r_[a.time_s, bridge_t, b.time_s], np.vstack([a.values, bridge, b.values]), a.channels,
                   {"label": f"{dataset_label(first)} + {dataset_label(later)}"})


def bridge_times(end_s: float, start_s: float, interval_s: float) -> NDArray[np.float64]:
    """Times of the whole sampling intervals missing between a record that ends at ``end_s`` and one that starts
    at ``start_s`` (s; empty when the second follows within about one interval).

    Parameters
    ----------
    end_s, start_s : float
        The first record's last time and the second's first, s.
    interval_s : float
        The sampling interval, s.

    Returns
    -------
    ndarray, shape (n_missing,)
        ``end_s + k·interval_s`` for k = 1 … n_missing, s.
    """
    n_missing = max(round((start_s - end_s) / interval_s) - 1, 0)
    return end_s + interval_s * np.arange(1, n_missing + 1)


def linear_bridge(before: ArrayLike, after: ArrayLike, n_rows: int) -> NDArray[np.float64]:
    """``n_rows`` evenly spaced rows on the straight line from ``before`` to ``after`` (both left out).

    Parameters
    ----------
    before, after : array-like, shape (k,)
        The rows either side of the gap, in their channels' units.
    n_rows : int
        Rows missing between them.

    Returns
    -------
    ndarray, shape (n_rows, k)
    """
    weight = (np.arange(1, n_rows + 1) / (n_rows + 1))[:, None]
    return (1.0 - weight) * np.asarray(before, float) + weight * np.asarray(after, float)


def joined_when_contiguous(datasets: Sequence[Dataset], names: Sequence[str]) -> list[Dataset]:
    """Records that continue one another (each starts one sampling interval after another ends, with the same
    channels and units) joined into one, in the channels ``names``; the others as they are; all in the canonical
    order of :mod:`twin.compensation.record_order`, whatever order they were given in.

    A record cut into files (a day per file) is one history: the second file starts warm, so neither a
    time-series model nor a zero reference at its own start fits it alone. The files are found to continue
    one another by their clocks, not by the order they were given in. Where the clocks leave it open (two
    records end one interval before a third starts, e.g. a file whose clock restarts at 0 beside the first
    day, or two start one interval after a third ends) nothing is guessed: the records are refused.

    Parameters
    ----------
    datasets : sequence of Dataset
        Records in any order.
    names : sequence of str
        The model's channels (inputs and target).

    Returns
    -------
    list of Dataset
        As many as there are runs of contiguous records, in the canonical order of their first records.

    Raises
    ------
    TwinInputError
        A record that starts with rows of another again (the same file twice, or files that overlap), or
        records whose continuation is ambiguous (naming the files and their times).
    """
    ordered = in_canonical_order(datasets, names)
    _check_no_repeats(ordered, names)
    successor = _successors(ordered, names)
    continuing = set(successor.values())
    joined = []
    for k, record in enumerate(ordered):
        if k in continuing:
            continue                     # joined to the record it continues
        while k in successor:
            k, earlier = successor[k], ordered[k]
            log.info("%s continues %s: trained on as one record", dataset_label(ordered[k]), dataset_label(earlier))
            record = continued_record(record, ordered[k], names)
        joined.append(record)
    return joined


def _successors(ordered, names):
    """``{i: j}``: record ``j`` continues record ``i`` (:func:`_continues`; indices into ``ordered``); refuses
    ambiguous clocks."""
    pairs = [(i, j) for i, first in enumerate(ordered) for j, later in enumerate(ordered)
             if i != j and len(later) and _continues(first, later, names)]
    # which of two records a third continues, or which of two continues one, would be a guess, and a wrong one
    # joins unrelated states
    _refuse_shared(ordered, [(j, i) for i, j in pairs], 0,
                   "each end one sampling interval before {} starts (t = {:.10g} s), so which of them it continues")
    _refuse_shared(ordered, pairs, -1,
                   "each start one sampling interval after {} ends (t = {:.10g} s), so which of them continues it")
    return dict(pairs)


def _refuse_shared(ordered, links, row, meeting):
    """Refuse a record ``k`` that two or more others meet (``links``: ``(k, other)`` index pairs into ``ordered``),
    naming them, ``k`` and its time at ``row`` (0: its start, -1: its end) in the ``meeting`` sentence."""
    for k in sorted({k for k, _ in links}):
        others = [ordered[other] for m, other in links if m == k]
        if len(others) > 1:
            record = ordered[k]
            raise TwinInputError(f"{_with_span(others)} {meeting.format(_record_file(record), record.time_s[row])} "
                                 f"is ambiguous; {_HOW_TO_RESOLVE}")


_HOW_TO_RESOLVE = ("give a history cut into files as one file, or shift the clock (time_s) of a record that "
                   "does not continue it so that it no longer meets it")


def _record_file(dataset):
    """A record's file name for messages (its label when it has no file)."""
    source = dataset.metadata.get("source")
    return Path(str(source)).name if source else dataset_label(dataset)


def _with_span(datasets):
    """``"a.csv (0–29985 s) and b.csv (0–29985 s)"``: records with their time spans."""
    return " and ".join(f"{_record_file(ds)} ({ds.time_s[0]:.10g}–{ds.time_s[-1]:.10g} s)" for ds in datasets)


def _check_no_repeats(ordered, names):
    """Refuse a record (in canonical order, so by start time) that starts inside an earlier one with the same
    times and readings (:func:`repeats`)."""
    for k, later in enumerate(ordered):
        for first in ordered[:k]:
            if (len(first) and len(later) and first.time_s[0] <= later.time_s[0] <= first.time_s[-1]
                    and _same_channels(first, later, names) and _first_row_is_a_row_of(first, later, names)
                    and repeats(first, later, names)):
                raise TwinInputError(f"{dataset_label(later)} starts with a row of {dataset_label(first)} again "
                                     f"(t = {later.time_s[0]:g} s, the same readings): the same file twice, or "
                                     "files that overlap; give each row once")


def _first_row_is_a_row_of(first, later, names):
    """Whether ``later``'s first row is a row of ``first`` (same time, same readings of ``names``): the cheap
    test before :func:`repeats` compares every row, as records whose clocks each start at 0 all share times."""
    at = int(np.searchsorted(first.time_s, later.time_s[0]))
    return bool(at < len(first) and first.time_s[at] == later.time_s[0] and all(
        first[n][at] == later[n][0] or (np.isnan(first[n][at]) and np.isnan(later[n][0])) for n in names))


def _same_channels(first, later, names):
    """Whether both records hold ``names`` in the same units."""
    return all(n in first and n in later and first.info(n).unit == later.info(n).unit for n in names)


def _continues(first, later, names):
    """Whether ``later`` starts one sampling interval of ``first`` after ``first`` ends (to within
    :data:`CONTINUES_WITHIN` of it), with the same channels in the same units."""
    if len(first) < 2 or not _same_channels(first, later, names):
        return False
    dt = sampling_interval(first, strict=False)
    return abs(later.time_s[0] - first.time_s[-1] - dt) <= CONTINUES_WITHIN * dt


def repeats(first: Dataset, later: Dataset, names: Sequence[str]) -> bool:
    """Whether ``later``'s rows up to ``first``'s end are rows of ``first`` again (same times, same readings of
    ``names``): a file given twice, or files cut with rows in both. A record whose clock restarts shares times
    with another, not readings.

    Parameters
    ----------
    first, later : Dataset
        Two records, ``later`` given after ``first``.
    names : sequence of str
        The channels compared.

    Returns
    -------
    bool
    """
    inside = later.time_s <= first.time_s[-1]
    at = np.minimum(np.searchsorted(first.time_s, later.time_s[inside]), len(first) - 1)
    return bool(inside[0] and np.array_equal(first.time_s[at], later.time_s[inside]) and np.array_equal(
        first.matrix(list(names))[at], later.matrix(list(names))[inside], equal_nan=True))


def with_rest_start(dataset: Dataset, names: Sequence[str] | None = None, reference_samples: int = 1) -> Dataset:
    """The record with the state it started from as a first row, when the record says the machine stood in
    other operating conditions before its first row (a twin record whose spindle starts at t = 0).

    A twin run starts from a state the machine reached standing idle
    (``metadata["before_start"]``, :func:`twin.core.simulate.before_start`),
    while its first row already holds the duty cycle's first speed. The added
    row, one sampling interval before the first, holds those earlier
    conditions (spindle, feeds, powers) and every other channel as read at
    the first row, which is the state then: a model that takes a record's
    first row as rest (the zero reference, the grey-box model's equilibrium)
    then starts from rest, and the first row's speed is held from the first
    row on, as the twin ran it. A measured record has no such metadata and is
    returned as it is, as is a twin record whose conditions do not change at
    its start in the channels a model reads.

    Parameters
    ----------
    dataset : Dataset
        A record.
    names : sequence of str, optional
        The channels a model reads (default: every channel): a model that reads none of those that change
        at the start (a model on temperatures) gets the record as it is.
    reference_samples : int, default 1
        Rows the model's zero reference averages: more than one would average the rest row with running
        rows, and is refused when a rest row is added.

    Returns
    -------
    Dataset
        ``dataset``, or a copy with the rest row first (``metadata["rest_row_s"]``: its time, s; no
        ``before_start`` any more, so a second call adds nothing).

    Raises
    ------
    TwinInputError
        A rest row is needed and ``reference_samples`` is above 1.
    """
    before = {name: value for name, value in dataset.metadata.get("before_start", {}).items() if name in dataset}
    read = before if names is None else [name for name in before if name in names]
    if len(dataset) < 2 or all(dataset[name][0] == before[name] for name in read):
        return dataset
    if reference_samples > 1:
        changed = next(name for name in read if dataset[name][0] != before[name])
        raise TwinInputError(f"{dataset_label(dataset)}: the record's {changed} changes at its first row (the "
                             f"twin run starts its duty cycle there), so its rest state is one row, and "
                             f"--reference-samples {reference_samples} would average it with running rows; use "
                             "--reference-samples 1")
    rest = dataset.values[0].copy()
    for name, value in before.items():
        rest[dataset.index(name)] = value
    t_rest = 2.0 * dataset.time_s[0] - dataset.time_s[1]
    metadata = {k: v for k, v in dataset.metadata.items() if k != "before_start"} | {"rest_row_s": float(t_rest)}
    return Dataset(np.r_[t_rest, dataset.time_s], np.vstack([rest, dataset.values]), list(dataset.channels),
                   metadata)


def starts_running(dataset: Dataset, speed: str) -> bool:
    """Whether the spindle runs at the record's first row (:func:`models.speed.running`: above 5 % of its top
    speed and above :data:`models.speed.STANDSTILL_RPM`, as a measured standstill reads a few rpm).

    Parameters
    ----------
    dataset : Dataset
        A record with the speed channel.
    speed : str
        The speed channel (rpm).

    Returns
    -------
    bool
    """
    return bool(running(dataset[speed])[0])


def check_starts_at_rest(dataset: Dataset, speed: str, model_name: str) -> None:
    """Refuse a record whose first row has the spindle running (:func:`starts_running`), for a model that
    takes its first row as rest.

    Parameters
    ----------
    dataset : Dataset
        A record with the speed channel.
    speed : str
        The speed channel (rpm).
    model_name : str
        Names the model in the error.

    Raises
    ------
    TwinInputError
        The record starts with the spindle running.
    """
    if starts_running(dataset, speed):
        raise TwinInputError(f"{dataset_label(dataset)}: the record starts with the spindle running ({speed} "
                             f"{dataset[speed][0]:g} rpm at t = {dataset.time_s[0]:g} s), and {model_name} takes a "
                             "record's first row as rest (the spindle stopped, the machine in equilibrium): train "
                             "on a record that starts at rest, and evaluate one that continues the training "
                             "record with --reference train")


def check_complete(dataset: Dataset, names: Sequence[str], may_miss: Sequence[str] = (), reference_rows: int = 1
                   ) -> None:
    """Refuse a missing (NaN) reading in ``names``, but for the channels ``may_miss`` (an observer's
    thermometers) outside their first ``reference_rows`` rows (the reference of their change).

    Parameters
    ----------
    dataset : Dataset
        A record with the channels.
    names : sequence of str
        The channels a model reads.
    may_miss : sequence of str, default ()
        Those of them that may miss readings.
    reference_rows : int, default 1
        Rows that are the zero reference.

    Raises
    ------
    TwinInputError
        Naming the record, the channel, the first time without a reading and how many rows miss one.
    """
    for name in names:
        missing = np.flatnonzero(~np.isfinite(dataset[name]))
        if len(missing) and name not in may_miss:
            raise TwinInputError(f"{dataset_label(dataset)}: {name} has no reading at t = "
                                 f"{dataset.time_s[missing[0]]:g} s ({len(missing)} rows); only the thermometers "
                                 f"a model observes may miss readings ({', '.join(may_miss) or 'it observes none'})")
        if len(missing) and missing[0] < reference_rows:
            raise TwinInputError(f"{dataset_label(dataset)}: {name} has no reading at t = "
                                 f"{dataset.time_s[missing[0]]:g} s, one of the first {reference_rows} row(s), "
                                 "which are the reference of its change")
