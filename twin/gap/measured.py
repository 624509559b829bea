"""Measured data for the gap diagnosis: import, match the channels to the machine's sensors, report what is missing.

A measured record is read through :class:`twin.core.dataset.Dataset` (a twin
dataset with its sidecar, or a measured CSV with ``<name>_<unit>`` columns
or a column map), NaNs kept.  Every channel must be one of the machine's
sensors (``T01_degC``, ``Z_um``, ``FBG1_ue``, air sensors …) or an operating
condition (``spindle_rpm``, ``feed_x_mm_min`` …, ``ambient_<zone>_degC``,
``ambient_gradient_K_m``); anything else is an error that lists the valid
names.  Heat-source powers (``P_*_W``) are ignored: measured data has none.

Sensor NaNs are masked out of the residuals; NaNs in the inputs (spindle,
feeds, air) are filled in time.  Missing sensors, NaN counts and gaps, the
sampling interval and its regularity go into the import report.
"""
from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..core.dataset import ChannelInfo, Dataset, sidecar_path
from ..core.machine import Machine
from ..core.machine_definition import MachineDefinition
from ..core.plausible import check_air_against_surfaces, check_plausible
from ..core.unit_hints import machine_top, other_unit_hint
from ..errors import TwinInputError
from .outages import as_long_as_an_outage

if TYPE_CHECKING:
    from ..core.scenario import Scenario

SENSOR_KINDS = ("temperature", "air", "displacement", "strain")
#: A measured channel whose range differs from the nominal twin's by more than this factor (either way) is
#: taken as a unit error (mm under ``_um``) when the twin predicts a clear signal there.
SCALE_FACTOR = 20.0
#: A spindle speed above this factor × the machine's top speed is a unit error, not an overload.
SPEED_LIMIT_FACTOR = 1.05
#: A logged feed above this factor × the machine's top feed is a unit error: a log holds rapid traverses too,
#: which are faster than the feeds a scenario asks for (typically 2–3 ×).
FEED_LIMIT_FACTOR = 3.0
CONDITION_UNITS = {"spindle": "rpm", "feed_x": "mm_min", "feed_y": "mm_min", "feed_z": "mm_min",
                   "ambient_gradient": "K_m"}


@dataclass
class Record:
    """A measured record matched to a machine (see the module docstring)."""

    time_s: np.ndarray
    names: list                      # sensor channels used in the residuals (machine channel names)
    kinds: list
    values: np.ndarray               # (n, len(names)), NaN where missing
    spindle: np.ndarray | None
    feeds: dict
    gradient: np.ndarray | None
    air: list                        # (name, zone, height above the reference m, values (n,) filled)
    report: dict = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)
    #: the measured operating inputs as read (``spindle_rpm``, ``feed_x_mm_min`` …; NaN where not read), which
    #: :mod:`twin.gap.outages` judges; ``spindle`` and ``feeds`` are them filled in time
    read_inputs: dict = field(default_factory=dict)

    @property
    def mask(self) -> np.ndarray:
        """Where the sensor values are finite: bool ndarray, shape (n_times, len(names))."""
        return np.isfinite(self.values)


def read_measured(data: Dataset | str | Path, column_map: dict[str, str] | None = None) -> Dataset:
    """A :class:`~twin.core.dataset.Dataset` from a path (twin dataset or measured CSV) or a Dataset, NaNs kept.

    Parameters
    ----------
    data : Dataset, str or Path
        A dataset (returned as it is), a twin dataset CSV with its sidecar, or a measured CSV.
    column_map : dict of str to str, optional
        CSV column → ``<name>_<unit>`` for a measured CSV; when given, a sidecar is not used.

    Returns
    -------
    Dataset
        The record, NaNs kept.
    """
    if isinstance(data, Dataset):
        return data
    path = Path(data)
    if not path.exists():
        raise TwinInputError(f"{path}: measured data file not found")
    if column_map is None and sidecar_path(path).exists():
        return Dataset.read(path)
    return Dataset.from_measured_csv(path, column_map=column_map, nan_policy="keep")


def _fill(t, v):
    ok = np.isfinite(v)
    return np.interp(t, t[ok], v[ok])


def _fill_steps(t, v):
    """A piecewise-constant input (a speed, a feed) filled where not read: the reading before up to the middle of
    the unread time, the one after from there (a ramp between them would be a speed nobody ran)."""
    ok = np.flatnonzero(np.isfinite(v))
    after = np.clip(np.searchsorted(ok, np.arange(len(t))), 0, len(ok) - 1)
    before = np.clip(after - 1, 0, len(ok) - 1)
    before = np.where(ok[after] == np.arange(len(t)), after, before)
    nearer = np.where(t - t[ok[before]] <= t[ok[after]] - t, ok[before], ok[after])
    return v[nearer]


def _held_at_ends(t: np.ndarray, v: np.ndarray, column: str) -> list[str]:
    """Notes on an operating input not read from the record's start or up to its end for as long as an outage
    (:func:`~twin.gap.outages.as_long_as_an_outage`): :func:`_fill_steps` holds its first or last reading there,
    and no outage is judged (:func:`twin.gap.outages.outage_spans` needs a reading on both sides), so nothing else
    would tell the user.  A shorter unread end (a trailing empty cell) is a sampling irregularity, as between readings.

    Parameters
    ----------
    t : ndarray, shape (n_times,)
        Sample times, s, increasing (clock or epoch times too: the note gives them from the record's start).
    v : ndarray, shape (n_times,)
        The input as the twin takes it (rpm, the spindle's magnitude; mm/min), NaN where not read; read at least
        once.
    column : str
        Its CSV column, for the note.

    Returns
    -------
    list of str
        One note per unread end (none, one or two), naming the column, the span in s from the record's start and
        in h, and the reading held.
    """
    read = np.flatnonzero(np.isfinite(v))
    since = t - t[0]
    ends = ((0, read[0], "from the record's start to its first reading", v[read[0]]),
            (read[-1], len(t) - 1, "from its last reading to the record's end", v[read[-1]]))
    return [f"column {column!r} is not read from {since[a]:.0f} s to {since[b]:.0f} s into the record "
            f"({since[a] / 3600:.2f}–{since[b] / 3600:.2f} h, {side}): the twin holds that reading ({held:g}) there, "
            "and judges no outage without a reading on both sides"
            for a, b, side, held in ends if as_long_as_an_outage(t[b] - t[a], np.median(np.diff(t)))]


def _nan_runs(t, v):
    """Longest run of NaNs (s) in a column."""
    bad = ~np.isfinite(v)
    if not bad.any():
        return 0.0
    edges = np.diff(np.r_[0, bad.astype(int), 0])
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    lengths = [t[min(e + 1, len(t) - 1)] - t[max(s - 1, 0)] for s, e in zip(starts, ends)]
    return float(max(lengths))


def check_operating_range(dataset: Dataset, channel: ChannelInfo, values: np.ndarray,
                          definition: MachineDefinition) -> str | None:
    """Stop with a clear error when a spindle speed or feed lies beyond what the machine can do (a unit error);
    warn when a running spindle peaks where one in Hz or krpm would, or a feed where one in m/min would.

    A spindle speed is taken by its magnitude (reverse rotation is logged negative; the heat does not care).
    A logged feed may include rapid traverses, faster than the largest feed a scenario asks for: it is
    refused only beyond :data:`FEED_LIMIT_FACTOR` × the machine's top feed (µm/min or counts under
    ``_mm_min``).

    Parameters
    ----------
    dataset : Dataset
        The record (its source and times name the bad value).
    channel : ChannelInfo
        ``spindle`` (rpm) or ``feed_x|y|z`` (mm/min).
    values : ndarray, shape (n_times,)
        The channel's values, NaN where missing (ignored); at least one finite.
    definition : MachineDefinition
        The machine, with ``max_spindle_rpm`` and ``max_feed_mm_min``.

    Returns
    -------
    str or None
        A warning for the report when the column runs (peak > 0) but its typical peak (99th percentile of |v|)
        is at or below :data:`~twin.core.unit_hints.SPINDLE_PEAK_TOO_LOW` (spindle: Hz or krpm?) or
        :data:`~twin.core.unit_hints.FEED_PEAK_TOO_LOW` (feed: m/min?) × the machine's top
        (:func:`twin.core.unit_hints.other_unit_hint`); else None.

    Raises
    ------
    TwinInputError
        At the first value beyond the machine's limit.
    """
    source = dataset.metadata.get("source", "the data")
    spindle = channel.name == "spindle"
    top = machine_top(definition, CONDITION_UNITS[channel.name])
    limit = (SPEED_LIMIT_FACTOR if spindle else FEED_LIMIT_FACTOR) * top
    what = "spindle speed (rpm)" if spindle else "feed (mm/min), rapid traverses allowed for,"
    bad = np.flatnonzero(np.abs(values) > limit)
    if bad.size:
        k = bad[0]
        raise TwinInputError(f"{source}: column {channel.column!r} has value {values[k]:g} at "
                             f"t = {dataset.time_s[k]:g} s, beyond the ±{limit:g} {what} of machine "
                             f"{definition.name!r}: is the column in another unit?")
    culprit = "a spindle in Hz or krpm" if spindle else "feeds in m/min"
    consequence = (f", and every heat it drives below is wrong ({culprit} made the search beyond the library "
                   "'discover' 10^4–10^5 W sources)")
    return other_unit_hint(channel.column, channel.unit, values, top, f"machine {definition.name!r}", consequence)


def check_scale(record: Record, predicted: np.ndarray, columns: Mapping[str, str]) -> None:
    """Stop when a sensor's measured range differs from the nominal twin's by more than :data:`SCALE_FACTOR`
    (mm written under ``_um``), where the twin predicts a clear signal; ``predicted`` (n, p) at the record's
    times, ``columns`` the record's CSV column names.

    A clear signal: a predicted range (max − min over the rows with a measured value) of at least 0.5 K for a
    thermometer or air sensor, 2 µm for a displacement, 5 µε for a strain.

    Parameters
    ----------
    record : Record
        The matched record.
    predicted : ndarray, shape (n_times, len(record.names))
        The nominal twin's values of the record's sensors at its times (°C, µm, µε).
    columns : mapping of str to str
        Sensor name → the record's CSV column (for the message; the name when absent).

    Raises
    ------
    TwinInputError
        When a sensor's measured range is more than :data:`SCALE_FACTOR` times larger or smaller than predicted,
        or it is constant (a dead channel) where the twin predicts a clear signal.
    """
    floor = {"temperature": 0.5, "air": 0.5, "displacement": 2.0, "strain": 5.0}
    for j, (name, kind) in enumerate(zip(record.names, record.kinds)):
        v = record.values[:, j]
        ok = np.isfinite(v)
        expected = float(np.ptp(predicted[ok, j])) if ok.sum() > 1 else 0.0
        if expected < floor[kind]:
            continue
        seen = float(np.ptp(v[ok]))
        source, column = record.report.get("source", "the data"), columns.get(name, name)
        if seen == 0.0:
            raise TwinInputError(
                f"{source}: column {column!r} ({name}) is constant at {v[ok][0]:g} {GROUP_UNITS[kind]} over the "
                f"record where the nominal twin predicts a range of {expected:.4g} {GROUP_UNITS[kind]}: a dead "
                f"channel? map it to null with --column-map '{{\"{column}\": null}}'")
        ratio = seen / expected
        if ratio < 1.0 / SCALE_FACTOR or ratio > SCALE_FACTOR:
            raise TwinInputError(
                f"{source}: column {column!r} ({name}) spans "
                f"{seen:.4g} {GROUP_UNITS[kind]} but the nominal twin predicts {expected:.4g} {GROUP_UNITS[kind]} "
                f"there ({ratio:.3g} ×): a unit error (mm under _um, µm under _um × 1000?); fix the column's unit")


GROUP_UNITS = {"temperature": "degC", "air": "degC", "displacement": "um", "strain": "ue"}


class _Channels:
    """The channels of a dataset sorted into sensors, operating conditions, air inputs and ignored ones."""

    def __init__(self, dataset, machine):
        self.dataset, self.machine = dataset, machine
        self.d = machine.definition
        self.sensors = {c.name: c for c in machine.channels if c.kind in SENSOR_KINDS}
        self.cameras = {c.name for c in machine.channels if c.kind == "camera"}
        self.zones = list(self.d.zones)
        self.t = np.asarray(dataset.time_s, float)
        self.names, self.kinds, self.cols = [], [], []
        self.feeds, self.air, self.ignored, self.empty = {}, [], [], []
        self.empty_columns, self.warnings = {}, []    # condition → its empty column; notes for the report
        self.spindle = self.gradient = None
        self.read_inputs = {}                          # operating inputs as read, NaN where not (Record.read_inputs)
        self.air_columns = []                          # (CSV column, values °C with NaNs) of the air inputs
        self.unit_suspects = []                        # condition columns warned about as in another unit

    def valid_names(self):
        return (f"sensors {sorted(self.sensors)}; conditions {sorted(CONDITION_UNITS)} and "
                f"{['ambient_' + z for z in self.zones]}")

    def add(self, ch):
        v = np.asarray(self.dataset[ch.name], float)
        if ch.name in self.sensors:
            self.sensor(ch, v)
        elif ch.name in CONDITION_UNITS:
            self.condition(ch, v)
        elif ch.name.startswith("ambient_") and ch.name[len("ambient_"):] in self.zones and ch.unit == "degC":
            if np.isfinite(v).any():
                check_plausible(self.dataset, ch, "air", v)
                self.air_columns.append((ch.column, v))
                self.air.append((ch.name, ch.name[len("ambient_"):], 0.0, _fill(self.t, v)))
        elif ch.name.startswith("P_") and ch.unit == "W" or ch.name in self.cameras:
            self.ignored.append(ch.name)
        else:
            raise TwinInputError(
                f"channel {ch.name!r} (column {ch.column}) matches no sensor or condition of machine "
                f"{self.machine.name!r}; valid names: {self.valid_names()}. Rename it in the CSV or map it with a "
                "column map (--column-map), e.g. {\"" + ch.column + "\": \"T01_degC\"}")

    def sensor(self, ch, v):
        c = self.sensors[ch.name]
        if ch.unit != c.unit:
            raise TwinInputError(f"channel {ch.name!r} is in {ch.unit!r}, but sensor {ch.name} of machine "
                                 f"{self.machine.name!r} reads {c.unit!r} (column {ch.name}_{c.unit})")
        if not np.isfinite(v).any():
            self.empty.append(ch.name)
            return
        check_plausible(self.dataset, ch, c.kind, v)
        if c.kind == "air":
            sensor = self.d.sensor(ch.name)
            self.air_columns.append((ch.column, v))
            self.air.append((ch.name, sensor.zone, sensor.position[2] - self.d.ambient_reference_height_m,
                             _fill(self.t, v)))
        self.names.append(ch.name)
        self.kinds.append(c.kind)
        self.cols.append(v)

    def condition(self, ch, v):
        if ch.unit != CONDITION_UNITS[ch.name]:
            raise TwinInputError(f"channel {ch.name!r} must be in {CONDITION_UNITS[ch.name]!r}, got {ch.unit!r}")
        if not np.isfinite(v).any():
            self.empty.append(ch.name)
            self.empty_columns[ch.name] = ch.column
            return
        if ch.name == "ambient_gradient":
            self.gradient = _fill(self.t, v)
            return
        warning = check_operating_range(self.dataset, ch, v, self.d)
        if warning:
            self.warnings.append(warning)
            self.unit_suspects.append(ch.column)
        if ch.name == "spindle":
            lowest = np.nanmin(v)
            if lowest < 0.0:
                self.warnings.append(f"column {ch.column!r} reads down to {lowest:g} rpm: its magnitude is "
                                     "the spindle speed (reverse rotation, a tachometer's noise at rest)")
            v = np.abs(v)
            self.read_inputs["spindle_rpm"] = v
            self.spindle = _fill_steps(self.t, v)
        else:
            self.read_inputs[f"{ch.name}_mm_min"] = v
            self.feeds[ch.name[-1]] = _fill_steps(self.t, v)
        # after the spindle's magnitude is taken: the note quotes the reading held
        self.warnings += _held_at_ends(self.t, v, ch.column)


def match_record(dataset: Dataset, machine: Machine, scenario: Scenario | str | None = None) -> Record:
    """Match a dataset's channels to a machine; return a :class:`Record` (see the module docstring).

    Parameters
    ----------
    dataset : Dataset
        The measured record (at least 10 rows).
    machine : Machine
        The built machine whose sensors and operating conditions the channels must name.
    scenario : Scenario or str, optional
        The scenario that supplies what the record lacks (only named in the report's ``assumed_inputs``,
        :func:`feed_assumptions`).

    Returns
    -------
    Record
        Sensor values (NaN where missing), filled inputs and the import report.

    Raises
    ------
    TwinInputError
        On too few rows, a channel that matches nothing of the machine, a wrong unit, an implausible value, or no
        sensor channel at all.
    """
    t = np.asarray(dataset.time_s, float)
    if len(t) < 10:
        raise TwinInputError(f"{dataset.metadata.get('source', 'dataset')}: {len(t)} rows are too few "
                             "for a diagnosis (need at least 10)")
    m = _Channels(dataset, machine)
    for ch in dataset.channels:
        m.add(ch)
    if not m.names:
        raise TwinInputError(f"the data has no sensor channel of machine {machine.name!r}; valid names: "
                             f"{m.valid_names()}")
    check_air_against_surfaces(dataset.metadata.get("source", "the data"), m.air_columns,
                               [v for v, kind in zip(m.cols, m.kinds) if kind == "temperature"])
    values = np.column_stack(m.cols)
    report = _import_report(dataset, m, t, values)
    report["assumed_inputs"] = feed_assumptions(m.feeds, scenario)
    return Record(t, m.names, m.kinds, values, m.spindle, m.feeds, m.gradient, m.air, report,
                  dict(dataset.metadata), m.read_inputs)


def feed_assumptions(measured_axes: Collection[str], scenario: Scenario | str | None = None) -> list[str]:
    """What the twin takes for the axis feeds a record lacks, in words for the verdict and the report (a record
    without feed columns was diagnosed with feeds of 0 mm/min, and nothing but a note said so).

    Parameters
    ----------
    measured_axes : collection of str
        The axes (``x``, ``y``, ``z``) whose feed (mm/min) the record holds.
    scenario : Scenario or str, optional
        The scenario that supplies the missing feeds (its name, or the scenario); without one they are 0 mm/min.

    Returns
    -------
    list of str
        One phrase naming the missing ``feed_<axis>`` columns and what they are taken as; empty when every axis
        is measured.
    """
    missing = [f"feed_{a}" for a in "xyz" if a not in measured_axes]
    if not missing:
        return []
    taken = "0 mm/min" if scenario is None else f"those of scenario {getattr(scenario, 'name', scenario)!r}"
    return [f"axis feeds not measured (no {'/'.join(missing)} column): taken as {taken}"]


def _import_report(dataset, m, t, values):
    """What the record has and lacks: rows, sampling, gaps, missing and empty channels, NaNs, inputs."""
    names, air = m.names, m.air
    steps = np.diff(t)
    typical = float(np.median(steps))
    gaps = np.flatnonzero(steps > 1.5 * typical)
    imported = dict(dataset.metadata.get("import", {}))
    report = {
        "source": dataset.metadata.get("source", dataset.metadata.get("scenario", "dataset")),
        "rows": int(len(t)), "span_h": float((t[-1] - t[0]) / 3600.0),
        "sampling_interval_s": typical,
        "sampling_regular": bool(np.allclose(steps, typical, rtol=0.01)),
        "gaps": [{"after_s": float(t[g]), "length_s": float(steps[g])} for g in gaps[:50]],
        "n_gaps": int(len(gaps)),
        "sensors_used": names,
        "sensors_missing": sorted(set(m.sensors) - set(names) - {n for n, *_ in air}),
        "channels_empty": m.empty,
        "empty_columns": m.empty_columns,
        "warnings": m.warnings,
        "unit_suspects": m.unit_suspects,
        "channels_ignored": m.ignored,
        "nan_counts": {n: int((~np.isfinite(values[:, j])).sum()) for j, n in enumerate(names)
                       if not np.isfinite(values[:, j]).all()},
        "longest_nan_run_s": {n: _nan_runs(t, values[:, j]) for j, n in enumerate(names)
                              if not np.isfinite(values[:, j]).all()},
        "has_spindle": m.spindle is not None, "feeds": sorted(m.feeds),
        "air_inputs": [n for n, *_ in air],
    }
    if imported.get("nan_counts"):
        report["input_nan_counts"] = {k: v for k, v in imported["nan_counts"].items() if k not in names}
    report["columns"] = {ch.name: ch.column for ch in dataset.channels if ch.name in names}
    return report
