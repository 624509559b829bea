"""The Dataset: the contract between the twin, the models, the gap diagnosis and measured data.

A dataset is a time axis in s and named channels with units.  On disk it is
one CSV (``time_s`` then ``<name>_<unit>`` columns) and a JSON sidecar with
the channel descriptions (kind, unit, position) and metadata (machine,
scenario, effects applied, seed, project version).  Floats are written with
17 significant digits, so a write/read round trip is exact.  Both files are
written under temporary names and renamed into place, the sidecar last and
holding the CSV's SHA-256, so an interrupted write never leaves a dataset
that looks complete.

Measured data enters through :meth:`Dataset.from_measured_csv`, which checks
the time column (in s: a header that names hours or minutes is refused, and a
record that looks timed in hours gets a hint), reports gaps and handles NaNs
by an explicit policy.
"""
from __future__ import annotations

import csv
import hashlib
import io
import json
import logging
import re
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np

from ..errors import TwinInputError
from .clock import seconds_since_first_stamp, stamp
from .files import write_text_atomic
from .plausible import PLAUSIBLE, check_plausible

FORMAT = "thermal-twin-dataset"
FORMAT_VERSION = 1

#: Unit tokens used in column names, and how they read.
UNITS = {
    "degC": "°C", "um": "µm", "ue": "µε", "rpm": "rpm", "mm_min": "mm/min", "W": "W", "K_m": "K/m",
    "J": "J", "s": "s",
}
#: Default kind of a channel from its unit, for CSV files without a sidecar.
KIND_OF_UNIT = {"degC": "temperature", "um": "displacement", "ue": "strain", "rpm": "spindle_speed",
                "mm_min": "feed", "W": "power", "K_m": "ambient_gradient", "J": "energy", "s": "time"}
NAN_POLICIES = ("error", "interpolate", "drop", "keep")

log = logging.getLogger("thermal_twin")

#: Words for a time unit other than s in a time column's header, and the unit they name.
OTHER_TIME_UNITS = {"h": "h", "hr": "h", "hrs": "h", "hour": "h", "hours": "h", "min": "min", "mins": "min",
                    "minute": "min", "minutes": "min", "ms": "ms", "msec": "ms", "d": "d", "day": "d", "days": "d"}
#: Seconds in each unit of :data:`OTHER_TIME_UNITS`, for the message that says how to convert.
SECONDS_PER = {"h": 3600.0, "min": 60.0, "ms": 1e-3, "d": 86400.0}
_UNIT_WORD = {"h": "hours", "min": "minutes", "ms": "milliseconds", "d": "days"}
#: A header that names the time in another unit: ``time_h``, ``t [min]``, ``Time (hours)``, ``elapsed_min``,
#: ``hours``. A bare ``t``/``time`` names no unit and is taken as s when mapped to ``time_s``; a capital ``T``
#: alone (``T_min``) is a temperature.
_TIME_IN_OTHER_UNIT = re.compile(r"(?:(?P<word>time|t|elapsed|elapsed_time|runtime|duration)\s*[_\-/ ]?\s*[\[(]?\s*"
                                 r"(?P<unit>[a-z]+)\s*[\])]?|(?P<bare>hours|hrs|minutes|mins))", re.IGNORECASE)
#: A measured record is taken for one timed in hours (a hint, never an error) when it spans under
#: FAST_RECORD_SPAN_S "s" in median steps under FAST_RECORD_STEP_S "s" *and* a temperature it reads changes
#: faster than FAST_HEATING_K_PER_S on average over it (or a displacement faster than FAST_DRIFT_UM_PER_S).
#: A thermal test lasts minutes to days, its slowest time constants are 10 min to hours, and a machine's
#: structure warms at most about 1 K/min at a spindle's run-up (FL_THERMAL: 7 K over its first hour; the
#: default twin at 9000 rpm: 35 µm in 2 h): 8 h logged in hours span 8 "s" with a change of K per "s". A
#: legitimately fast capture (a 10 Hz logger for a minute) moves its temperatures by tenths of a kelvin, far
#: slower than the thresholds, and gets no hint. Minutes (an 8 h test spans 480 "s" in steps of 1) are not
#: told apart from a fast capture by their values: only the header check catches them.
FAST_RECORD_SPAN_S = 200.0
FAST_RECORD_STEP_S = 0.5
FAST_HEATING_K_PER_S = 0.05      # 3 K/min
FAST_DRIFT_UM_PER_S = 0.5        # 1.8 mm/h
#: A measured record is taken for one timed in ms (a hint, never an error) when its median step exceeds
#: SLOW_RECORD_STEP_S and it spans over SLOW_RECORD_SPAN_S: a thermal logger samples every second to every few
#: minutes, a slow one hourly, and a test lasts hours to weeks; 8 h sampled every 60 s, logged in ms, spans 333
#: "days" in steps of 16.7 "h".
SLOW_RECORD_STEP_S = 3600.0
SLOW_RECORD_SPAN_S = 30 * 86400.0
#: Longest stretch, s, that ``nan_policy="interpolate"`` fills without a warning (the straight line's length, from
#: the reading before a run of NaNs to the one after it).  The fastest thermal time constants of a machine tool
#: (spindle housing, ball screw nut) are 10 to 30 min: a straight line over 10 min misses a small part of their
#: drift, one over longer can hide a spindle start or stop.  In time, not rows, since loggers sample every second
#: to every few minutes.  Its first reading held back over longer than this is refused: the first row is the
#: reference of a record's changes.
QUIET_FILL_S = 600.0


def project_version() -> str:
    """The installed version of the ``thermal-twin`` distribution.

    Returns
    -------
    str
        E.g. ``"0.1.0"``, or ``"unknown"`` when it is not installed.
    """
    try:
        return version("thermal-twin")
    except PackageNotFoundError:  # run from a source tree without ``pip install -e .``
        return "unknown"


@dataclass(frozen=True)
class ChannelInfo:
    """One column: name, unit token (see :data:`UNITS`), kind, label and sensor position (m)."""

    name: str
    unit: str
    kind: str
    label: str = ""
    position: tuple | None = None

    @property
    def column(self) -> str:
        """The CSV column name, ``<name>_<unit>`` (e.g. ``T01_degC``)."""
        return f"{self.name}_{self.unit}"


def name_listing(names: Sequence[str]) -> str:
    """Channel names for a message: comma-separated, a run of numbered names shortened (``cam000…cam524``).

    Parameters
    ----------
    names : sequence of str
        E.g. a dataset's channels.

    Returns
    -------
    str
        ``spindle,T01,…`` with each run of more than three names that differ only in a consecutive number
        (same prefix, same digit count) written as ``first…last``.
    """
    parts, run = [], []

    def close():
        parts.extend([f"{run[0]}…{run[-1]}"] if len(run) > 3 else run)
        run.clear()

    for name in names:
        if run and _follows(run[-1], name):
            run.append(name)
            continue
        close()
        run.append(name)
    close()
    return ",".join(parts)


def _follows(previous, name):
    """Whether ``name`` is ``previous`` with its trailing number one higher, written with as many digits."""
    a, b = re.fullmatch(r"(.*?)(\d+)", previous), re.fullmatch(r"(.*?)(\d+)", name)
    return bool(a and b and a[1] == b[1] and len(a[2]) == len(b[2]) and int(b[2]) == int(a[2]) + 1)


def split_column(column: str) -> tuple[str, str] | None:
    """Split a column name into channel name and unit token; the longest matching unit suffix wins.

    Parameters
    ----------
    column : str
        E.g. ``T01_degC``.

    Returns
    -------
    tuple of str or None
        ``("T01", "degC")``, or ``None`` when the name ends in no known unit (:data:`UNITS`).
    """
    for unit in sorted(UNITS, key=len, reverse=True):
        if column.endswith("_" + unit) and len(column) > len(unit) + 1:
            return column[: -len(unit) - 1], unit
    return None


class Dataset:
    """Time series of named channels with units and metadata.

    Parameters
    ----------
    time_s : ndarray, shape (n,)
        Strictly increasing times, s.
    values : ndarray, shape (n, n_channels)
        Values in the channels' units (°C, µm, µε, rpm, mm/min, W, …).
    channels : list of ChannelInfo
        One per column of ``values``.
    metadata : dict, optional
        JSON-serialisable facts (source, machine, scenario, seed, …).
    """

    def __init__(self, time_s: np.ndarray, values: np.ndarray, channels: list[ChannelInfo],
                 metadata: dict | None = None) -> None:
        self.time_s = np.asarray(time_s, dtype=float)
        self.values = np.asarray(values, dtype=float).reshape(len(self.time_s), -1)
        self.channels = list(channels)
        self.metadata = dict(metadata or {})
        if self.values.shape[1] != len(self.channels):
            raise TwinInputError(f"dataset has {self.values.shape[1]} value columns for "
                                 f"{len(self.channels)} channels")
        names = [c.name for c in self.channels]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise TwinInputError(f"duplicate channel names {dupes}")
        _check_time(self.time_s, self.metadata.get("source", "dataset"))

    # ---------------------------------------------------------------- access
    @property
    def names(self) -> list[str]:
        """The channel names, in column order."""
        return [c.name for c in self.channels]

    def index(self, name: str) -> int:
        """The column of a channel.

        Parameters
        ----------
        name : str
            Channel name.

        Returns
        -------
        int
            Its column in :attr:`values`.

        Raises
        ------
        TwinInputError
            Unknown name (the message lists the channels).
        """
        names = self.names
        if name in names:
            return names.index(name)
        raise TwinInputError(f"unknown channel {name!r}; available: {name_listing(names)}")

    def info(self, name: str) -> ChannelInfo:
        """The description (unit, kind, label, position) of a channel.

        Parameters
        ----------
        name : str
            Channel name.

        Returns
        -------
        ChannelInfo
            Its description.
        """
        return self.channels[self.index(name)]

    def __getitem__(self, name):
        """Values of one channel (n,) in its unit."""
        return self.values[:, self.index(name)]

    def __contains__(self, name):
        return name in self.names

    def __len__(self):
        return len(self.time_s)

    def matrix(self, names: list[str]) -> np.ndarray:
        """Values of several channels.

        Parameters
        ----------
        names : list of str
            Channel names.

        Returns
        -------
        ndarray, shape (n, k)
            Their values in their units, in the order given.
        """
        return self.values[:, [self.index(n) for n in names]]

    def names_of_kind(self, *kinds: str) -> list[str]:
        """The channels of some kinds.

        Parameters
        ----------
        *kinds : str
            Channel kinds, e.g. ``"temperature"``, ``"displacement"``.

        Returns
        -------
        list of str
            Their names, in column order.
        """
        return [c.name for c in self.channels if c.kind in kinds]

    def select(self, names: list[str]) -> Dataset:
        """A dataset with only some channels.

        Parameters
        ----------
        names : list of str
            Channel names, in the order wanted.

        Returns
        -------
        Dataset
            Same times and metadata.
        """
        idx = [self.index(n) for n in names]
        return Dataset(self.time_s, self.values[:, idx], [self.channels[i] for i in idx], self.metadata)

    def between(self, start_s: float = -np.inf, end_s: float = np.inf) -> Dataset:
        """The rows of a time window.

        Parameters
        ----------
        start_s, end_s : float
            Window, s (inclusive).

        Returns
        -------
        Dataset
            Rows with ``start_s ≤ t ≤ end_s``; a window that leaves out the first row leaves out the
            conditions before it too (``before_start``).
        """
        keep = (self.time_s >= start_s) & (self.time_s <= end_s)
        metadata = self.metadata if keep[:1].all() else {k: v for k, v in self.metadata.items() if k != "before_start"}
        return Dataset(self.time_s[keep], self.values[keep], self.channels, metadata)

    # ---------------------------------------------------------------- files
    def write(self, path: str | Path) -> Path:
        """Write the CSV and its JSON sidecar (channels, metadata, the CSV's SHA-256), each atomically.

        Parameters
        ----------
        path : str or Path
            The CSV; the sidecar is ``<path>.json``.

        Returns
        -------
        Path
            ``path``.
        """
        path = Path(path)
        buffer = io.StringIO()
        header = ["time_s"] + [c.column for c in self.channels]
        buffer.write(",".join(header) + "\n")
        np.savetxt(buffer, np.column_stack([self.time_s, self.values]), delimiter=",", fmt="%.17g")
        text = buffer.getvalue()
        write_text_atomic(path, text)
        sidecar = {
            "format": FORMAT,
            "version": FORMAT_VERSION,
            "csv_sha256": hashlib.sha256(text.encode("utf-8")).hexdigest(),
            "channels": [asdict(c) for c in self.channels],
            "metadata": self.metadata,
        }
        write_text_atomic(sidecar_path(path), json.dumps(sidecar, indent=1, default=json_default))
        return path

    @classmethod
    def read(cls, path: str | Path) -> Dataset:
        """Read a dataset written by :meth:`write`, checking that CSV and sidecar belong together.

        A CSV without a sidecar is imported as measured data (:meth:`from_measured_csv`).

        Parameters
        ----------
        path : str or Path
            The CSV.

        Returns
        -------
        Dataset
            The data with its channels and metadata.

        Raises
        ------
        TwinInputError
            Malformed sidecar, other format version, or a CSV that does not match its sidecar.
        """
        path = Path(path)
        side = sidecar_path(path)
        if not side.exists():
            return cls.from_measured_csv(path)
        try:
            meta = json.loads(side.read_text(encoding="utf-8"))
        except json.JSONDecodeError as exc:
            raise TwinInputError(f"{side}: malformed JSON sidecar ({exc})") from None
        if meta.get("format") != FORMAT or meta.get("version") != FORMAT_VERSION:
            raise TwinInputError(f"{side}: format {meta.get('format')!r} version {meta.get('version')!r} "
                                 f"is not {FORMAT!r} version {FORMAT_VERSION}")
        text = path.read_text(encoding="utf-8")
        if hashlib.sha256(text.encode("utf-8")).hexdigest() != meta.get("csv_sha256"):
            raise TwinInputError(f"{path}: the CSV does not match its sidecar {side.name} (edited or "
                                 "incompletely written)")
        channels = [ChannelInfo(c["name"], c["unit"], c["kind"], c.get("label", ""),
                                tuple(c["position"]) if c.get("position") else None) for c in meta["channels"]]
        header, data, _ = _parse_csv(path, text)
        expected = ["time_s"] + [c.column for c in channels]
        if header != expected:
            raise TwinInputError(f"{path}: columns {header} do not match the sidecar's {expected}")
        return cls(data[:, 0], data[:, 1:], channels, meta.get("metadata", {}))

    @classmethod
    def from_measured_csv(cls, path: str | Path, column_map: dict[str, str] | None = None,
                          time_column: str = "time_s", nan_policy: str = "error",
                          channel_kinds: dict[str, str] | None = None,
                          nan_channels: Sequence[str] | None = None) -> Dataset:
        """Import measured data from a CSV, validating it.

        Parameters
        ----------
        path : str or Path
            The CSV file: a header row, then one row per sample.
        column_map : dict of str to str or None, optional
            ``csv column → "<name>_<unit>"`` (e.g. ``{"t1": "T01_degC"}``), or to None to leave the column
            out (a spare or broken channel); unmapped columns must already be named ``<name>_<unit>`` with a
            unit from :data:`UNITS`.  A column mapped to ``time_s`` is the time column (s).
        time_column : str
            Name of the time column: s, or ISO 8601 date-times (``2026-11-23 14:05:00``, with or without a
            UTC offset), which become s since the first stamp, kept as ``metadata["import"]["time_origin"]``
            (see :mod:`twin.core.clock`).
        nan_policy : str
            ``error`` (default), ``interpolate`` (linear in time, per channel;
            leading/trailing NaNs are held; a filled stretch longer than :data:`QUIET_FILL_S` is warned of, and
            so is a filled first row, refused when held back over longer; counts in the import report's
            ``filled``), ``drop`` (rows with any NaN) or
            ``keep`` (leave them; the caller masks them, as the gap diagnosis does).
        channel_kinds : dict of str to str, optional
            Channel name → kind, overriding the unit-based default.
        nan_channels : sequence of str, optional
            The channels ``nan_policy`` and the plausibility check are about (those a model reads); default
            every channel. NaNs and implausible values in the others are kept (a dead thermometer that nothing
            reads drops no row and stops nothing).

        Returns
        -------
        Dataset
            The data; the import report (gaps, NaN counts, policy) is in ``metadata["import"]``.

        Raises
        ------
        TwinInputError
            One line naming the file, the column and the row of the first bad value; a sensor value outside
            :data:`~twin.core.plausible.PLAUSIBLE` (kelvin under ``_degC``, nm under ``_um``) is one, and so is a
            data row with more or fewer fields than the header (a file cut short).
        """
        path = Path(path)
        if nan_policy not in NAN_POLICIES:
            raise TwinInputError(f"nan_policy must be one of {NAN_POLICIES}, got {nan_policy!r}")
        column_map, time_column = _time_from_map(path, column_map, time_column)
        header, data, origin = _parse_csv(path, _read_utf8(path), time_column)
        unknown_map = sorted(set(column_map) - set(header))
        if unknown_map:
            raise TwinInputError(f"{path}: column map names column(s) {unknown_map} that the file lacks; "
                                 f"columns: {header}")
        t_index, time_s = _time_column(path, header, data, time_column, origin)
        channels, cols = _measured_channels(path, header, t_index, column_map, channel_kinds or {})
        values = data[:, cols]
        report = {"file": str(path), "rows": int(len(time_s)), "nan_policy": nan_policy}
        if origin:
            report["time_origin"] = origin
        nan_counts = {c.name: int(np.isnan(values[:, k]).sum()) for k, c in enumerate(channels)}
        report["nan_counts"] = {k: v for k, v in nan_counts.items() if v}
        about = [k for k, c in enumerate(channels) if nan_channels is None or c.name in set(nan_channels)]
        if any(channels[k].name in report["nan_counts"] for k in about):
            time_s, values = _apply_nan_policy(path, time_s, values, channels, nan_policy, report, about)
        report.update(_sampling_report(time_s))
        dataset = cls(time_s, values, channels, {"source": str(path), "kind": "measured", "import": report})
        read = [channels[k].name for k in about]
        return _noted_time_unit(_checked_sensors(dataset, read), read, time_column)

    def __repr__(self):
        span = f"{self.time_s[0]:g}–{self.time_s[-1]:g} s" if len(self) else "empty"
        return f"Dataset({len(self)} rows, {span}, channels {self.names[:8]}{'…' if len(self.names) > 8 else ''})"


def _checked_sensors(dataset, names):
    """The dataset, once the sensor channels ``names`` (those a command reads) hold values plausible for their
    kind: a unit error stops here, a spare or broken channel that nothing reads does not."""
    for channel in dataset.channels:
        if channel.kind in PLAUSIBLE and channel.name in names:
            check_plausible(dataset, channel, channel.kind, dataset[channel.name])
    return dataset


def time_unit_in_name(column: str) -> str | None:
    """The time unit other than s that a column's header names (``"h"``, ``"min"``, ``"ms"``, ``"d"``), or None.

    Parameters
    ----------
    column : str
        A CSV header, e.g. ``time_h``, ``t [min]``, ``Time (hours)``, ``hours``.

    Returns
    -------
    str or None
        A key of :data:`SECONDS_PER`; None for a header in s (``time_s``, ``t [s]``) or one that names no unit.
    """
    match = _TIME_IN_OTHER_UNIT.fullmatch(column.strip())
    if match is None or match["word"] == "T":   # a capital T is a temperature's letter (T_min, T_h)
        return None
    return OTHER_TIME_UNITS.get((match["unit"] or match["bare"]).lower())


def other_time_unit_text(column: str) -> str | None:
    """Why a time column headed ``column`` is refused, when the header names another unit than s
    (:func:`time_unit_in_name`): the twin counts time in s and converts nothing on import (as a column map renames
    and does not convert a channel).  One wording for a measured CSV and a scenario's ambient CSV; each caller
    raises its own error with it.

    Parameters
    ----------
    column : str
        The time column's header.

    Returns
    -------
    str or None
        ``"says hours (h); the twin reads time in s and does not convert it: write the column in s (× 3600) as
        time_s"`` (what the header does, to follow "its header"); None for a header in s or one that names no unit.
    """
    unit = time_unit_in_name(column)
    if unit is None:
        return None
    return (f"says {_UNIT_WORD[unit]} ({unit}); the twin reads time in s and does not convert it: write the column "
            f"in s (× {SECONDS_PER[unit]:g}) as time_s")


def _refuse_other_time_unit(path, column, mapped):
    """Refuse a measured CSV's time column whose header names another unit than s (:func:`other_time_unit_text`)."""
    text = other_time_unit_text(column)
    if text is not None:
        as_time = "is the time column (mapped to time_s)" if mapped else "looks like the time column"
        raise TwinInputError(f"{path}: column {column!r} {as_time}, and its header {text}")


def _time_from_map(path, column_map, time_column):
    """``(column map without its time entry, time column)``: a map entry ``{"Time": "time_s"}`` names the time
    column (in s; a header that names another unit is refused by :func:`_refuse_other_time_unit`)."""
    column_map = dict(column_map or {})
    mapped = [k for k, v in column_map.items() if v == "time_s"]
    if len(mapped) > 1 or (mapped and time_column not in ("time_s", mapped[0])):
        raise TwinInputError(f"{path}: the column map maps {mapped} to time_s, and the time column is "
                             f"{time_column!r}: map one column to time_s")
    for k in mapped:
        del column_map[k]
    return column_map, mapped[0] if mapped else time_column


def ms_hint(dataset: Dataset, column: str = "time_s") -> str | None:
    """A one-line hint that a measured record's time is in ms, not s, or None (thresholds and why:
    :data:`SLOW_RECORD_STEP_S`).

    Parameters
    ----------
    dataset : Dataset
        A measured record (its ``metadata["source"]`` names the file).
    column : str, default "time_s"
        The time column's header, for the message.

    Returns
    -------
    str or None
        Naming the file, the column, its span (days) and median step (h).
    """
    if len(dataset) < 2:
        return None
    span_s, step_s = _span_and_step(dataset)
    if step_s <= SLOW_RECORD_STEP_S or span_s <= SLOW_RECORD_SPAN_S:
        return None
    return (f"{dataset.metadata.get('source', 'the data')}: column {column!r} spans {span_s / 86400:.4g} days in "
            f"steps of {step_s / 3600:.3g} h, too slow and too long for a thermal record: is the time in ms "
            f"(÷ 1000 to s: {span_s / 3600e3:.3g} h in steps of {step_s / 1e3:g} s)? The twin reads it in s")


def _span_and_step(dataset):
    """``(span, median step)`` of a record's time, s: what a time-unit hint judges it by."""
    return float(dataset.time_s[-1] - dataset.time_s[0]), float(np.median(np.diff(dataset.time_s)))


def _noted_time_unit(dataset, names, column):
    """The dataset, once a hint that its time is in hours (:func:`hours_hint`) or ms (:func:`ms_hint`) is logged
    and kept in its import report as ``time_unit_hint``: a hint, not an error, since a real record can look
    alike."""
    hint = hours_hint(dataset, names, column) or ms_hint(dataset, column)
    if hint is not None:
        log.warning("%s", hint)
        dataset.metadata["import"]["time_unit_hint"] = hint
    return dataset


def _time_column(path, header, data, time_column, origin):
    """``(index, time in s)`` of a measured CSV's time column, present, complete and strictly increasing; a
    header that names another unit (:func:`time_unit_in_name`) is refused."""
    _refuse_other_time_unit(path, time_column, mapped=time_column != "time_s")
    if time_column not in header:
        for column in header:
            _refuse_other_time_unit(path, column, mapped=False)
        raise TwinInputError(f"{path}: no time column {time_column!r}; columns: {header}")
    t_index = header.index(time_column)
    time_s = data[:, t_index]
    if np.isnan(time_s).any():
        row = int(np.flatnonzero(np.isnan(time_s))[0])
        raise TwinInputError(f"{path}: {time_column} is empty or NaN at data row {row + 1}")
    _check_time(time_s, str(path), time_column, origin)
    return t_index, time_s


def _measured_channels(path, header, t_index, column_map, channel_kinds):
    """The channels of a measured CSV's value columns and their column indices, from the names or the map."""
    channels, cols = [], []
    for j, col in enumerate(header):
        if j == t_index or (col in column_map and column_map[col] is None):    # mapped to null: left out
            continue
        parts = split_column(column_map.get(col, col))
        if parts is None:
            stem = col.rsplit("_", 1)[0]
            raise TwinInputError(
                f"{path}: column {col!r} is not named <name>_<unit> with a known unit {sorted(UNITS)}; rename it "
                f"or give a column map, e.g. {{{col!r}: '{stem}_<unit>'}} (a map renames, it does not convert: "
                "convert values in another unit first)")
        name, unit = parts
        channels.append(ChannelInfo(name, unit, channel_kinds.get(name, KIND_OF_UNIT[unit])))
        cols.append(j)
    return channels, cols


def _apply_nan_policy(path, time_s, values, channels, nan_policy, report, about):
    """(time_s, values) after the NaN policy on the columns ``about`` (``values`` is changed in place by
    ``interpolate``); notes it in ``report``."""
    counts = {channels[k].name: report["nan_counts"].get(channels[k].name, 0) for k in about}
    if nan_policy == "error":
        k = next(k for k in about if counts[channels[k].name])
        row = int(np.flatnonzero(np.isnan(values[:, k]))[0])
        raise TwinInputError(
            f"{path}: column {channels[k].column!r} is NaN/empty at t = {time_s[row]} s (data row "
            f"{row + 1}); {sum(counts.values())} NaNs in {sum(v > 0 for v in counts.values())} "
            "column(s); choose nan_policy='interpolate' or 'drop'")
    if nan_policy == "drop":
        keep = ~np.isnan(values[:, about]).any(axis=1)
        if not keep.any():
            raise TwinInputError(f"{path}: every row has a NaN in {', '.join(c for c, n in counts.items() if n)}; "
                                 "nan_policy='drop' leaves none")
        report["dropped_rows"] = int((~keep).sum())
        return time_s[keep], values[keep]
    if nan_policy == "interpolate":
        report["filled"] = {channels[k].name: _interpolated(path, time_s, values[:, k], channels[k].column)
                            for k in about if counts[channels[k].name]}
    return time_s, values


def _interpolated(path, time_s, column, name):
    """Fill the NaNs of ``column`` (one channel's values, changed in place) linearly in time, holding its first
    and last readings beyond them; warn of a run longer than :data:`QUIET_FILL_S` and of a first row filled.

    Returns ``{"values": filled, "longest_run_rows": rows, "longest_run_s": s}`` for the import report."""
    bad = np.isnan(column)
    if bad.all():
        raise TwinInputError(f"{path}: column {name!r} holds no value at all")
    runs = _nan_runs(time_s, bad)
    if runs[0][0] == 0:
        _check_reference_fill(path, time_s, name, runs[0])
    column[bad] = np.interp(time_s[bad], time_s[~bad], column[~bad])
    for start, stop, span_s in runs[1 if runs[0][0] == 0 else 0:]:   # the first rows' fill is checked above
        if span_s > QUIET_FILL_S:
            how = "with a straight line" if stop < len(bad) else "by holding its last reading"
            log.warning("%s: column %r: nan_policy='interpolate' filled %d rows in a row %s over %.2g h (t = %g … "
                        "%g s; %d values filled in all): the drift in a gap that long is a guess", path, name,
                        stop - start, how, span_s / 3600.0, time_s[start], time_s[stop - 1], bad.sum())
    start, stop, span_s = max(runs, key=lambda run: run[2])
    return {"values": int(bad.sum()), "longest_run_rows": stop - start, "longest_run_s": span_s}


def _nan_runs(time_s, bad):
    """``[(first row, row after the last, s bridged), …]`` of the runs of True in ``bad``: s from the reading
    before the run to the one after it (from the first row, or to the last, at the record's ends)."""
    edges = np.diff(np.concatenate(([0], bad.astype(np.int8), [0])))
    last = len(time_s) - 1
    return [(int(a), int(b), float(time_s[min(b, last)] - time_s[max(a - 1, 0)]))
            for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1))]


def _check_reference_fill(path, time_s, name, run):
    """Filling a channel's first rows holds its first reading back to the record's first row, the reference its
    changes are taken from (an extrapolation): warned of up to :data:`QUIET_FILL_S` or one median sampling
    interval, whichever is longer (a 15-min logger that missed its first reading), refused beyond."""
    _, first, span_s = run
    where = f"{path}: column {name!r} has no reading before t = {time_s[first]:g} s ({first} rows, {span_s:g} s)"
    if span_s > max(QUIET_FILL_S, float(np.median(np.diff(time_s)))):
        raise TwinInputError(f"{where}: nan_policy='interpolate' would hold that reading back to the first row, "
                             "the reference of the record's changes, over more than one sampling interval and "
                             f"{QUIET_FILL_S:g} s; cut the record to start at its first reading or drop the "
                             "incomplete rows (--nan-policy drop; nan_policy='drop' in Python)")
    log.warning("%s: nan_policy='interpolate' holds that reading back to the first row, the reference of the "
                "record's changes", where)


def hours_hint(dataset: Dataset, names: Sequence[str], column: str = "time_s") -> str | None:
    """A one-line hint that a measured record's time is in hours, not s, or None (thresholds and why:
    :data:`FAST_RECORD_SPAN_S`).

    Parameters
    ----------
    dataset : Dataset
        A measured record (its ``metadata["source"]`` names the file).
    names : sequence of str
        The channels a command reads: their temperatures (°C) and displacements (µm) are the evidence; a
        spare column's noise is none.
    column : str, default "time_s"
        The time column's header, for the message.

    Returns
    -------
    str or None
        Naming the file, the column, its span and median step (s) and the fastest change per s.
    """
    if len(dataset) < 2:
        return None
    span_s, step_s = _span_and_step(dataset)
    if span_s >= FAST_RECORD_SPAN_S or step_s >= FAST_RECORD_STEP_S:
        return None
    limits = {"degC": (FAST_HEATING_K_PER_S, "K"), "um": (FAST_DRIFT_UM_PER_S, "µm")}
    for name in names:
        unit = dataset.info(name).unit
        values = dataset[name][np.isfinite(dataset[name])]
        if unit not in limits or len(values) < 2:
            continue
        limit, shown = limits[unit]
        rate = float(np.ptp(values)) / span_s
        if rate > limit:
            return (f"{dataset.metadata.get('source', 'the data')}: column {column!r} spans {span_s:g} s in steps "
                    f"of {step_s:g} s while {name} changes by {np.ptp(values):.3g} {shown} ({rate:.3g} {shown}/s, "
                    f"over {limit:g}), too fast for a thermal record: is the time in hours (× 3600 to s) or "
                    "minutes (× 60)? The twin reads it in s")
    return None


def _sampling_report(time_s):
    """Typical sampling interval (s, the median step) and the gaps longer than 1.5 of it (first 100 listed)."""
    steps = np.diff(time_s)
    if not len(steps):
        return {}
    typical = float(np.median(steps))
    gaps = np.flatnonzero(steps > 1.5 * typical)
    return {"sampling_interval_s": typical,
            "gaps": [{"after_s": float(time_s[g]), "length_s": float(steps[g])} for g in gaps[:100]],
            "n_gaps": int(len(gaps))}


def sidecar_path(path: str | Path) -> Path:
    """The JSON sidecar of a dataset CSV.

    Parameters
    ----------
    path : str or Path
        The CSV.

    Returns
    -------
    Path
        ``<path>.json``.
    """
    path = Path(path)
    return path.with_name(path.name + ".json")


def finite_or_none(value: object) -> object:
    """``value`` with every float that is NaN or infinite (e.g. a correlation of a constant series) as None,
    through dicts, lists and tuples: ``json`` would write it as ``NaN``, which is not JSON.

    Parameters
    ----------
    value : object
        A JSON-ready document.

    Returns
    -------
    object
        The same document, its non-finite floats None.
    """
    if isinstance(value, dict):
        return {k: finite_or_none(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite_or_none(v) for v in value]
    if isinstance(value, float | np.floating) and not np.isfinite(value):
        return None
    return value


def json_default(value: object) -> object:
    """``json.dumps`` fallback for numpy arrays and scalars (as lists and Python numbers) and paths (as text).

    Anything else raises ``TypeError``, as ``json`` itself would: metadata
    that cannot be written faithfully is an error, not a string.

    Parameters
    ----------
    value : object
        What ``json`` could not serialise.

    Returns
    -------
    object
        A list, a Python number or a string.
    """
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {value!r}")


def _read_utf8(path):
    """The file's text; one that is not UTF-8 (a spreadsheet's "ANSI" export) is refused by name."""
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise TwinInputError(f"{path}: not UTF-8 text (byte {exc.object[exc.start]:#04x} at offset {exc.start}); "
                             "save the CSV as UTF-8") from None


def other_separator_text(header: Sequence[str]) -> str | None:
    """What is wrong with a CSV header read as one column holding semicolons or tabs (a spreadsheet's export in
    another separator), or None.

    Parameters
    ----------
    header : sequence of str
        The column names as a comma-separated reader found them.

    Returns
    -------
    str or None
        ``"the header '…' is separated by ';'; the twin reads comma-separated files …"``.
    """
    other = next((sep for sep in (";", "\t") if len(header) == 1 and sep in header[0]), None)
    if other is None:
        return None
    return (f"the header {header[0]!r} is separated by {other!r}; the twin reads comma-separated files with '.' as "
            "the decimal mark: export the file so")


def _check_header_once(path, text):
    """Refuse a header that names a column twice (pandas would rename the second ``X.1`` and read both), or that
    is one column holding semicolons or tabs (a spreadsheet's export in another separator)."""
    named = [h.strip() for h in next(csv.reader(io.StringIO(text)), [])]
    other = other_separator_text(named)
    if other is not None:
        raise TwinInputError(f"{path}: {other}")
    twice = next((h for i, h in enumerate(named) if h in named[:i]), None)
    if twice is not None:
        where = [i + 1 for i, h in enumerate(named) if h == twice]
        raise TwinInputError(f"{path}: column {twice!r} appears {len(where)} times (columns "
                             f"{', '.join(map(str, where))}); give each channel once")


def _check_row_lengths(path, text):
    """Refuse a data row with fewer or more fields than the header: pandas fills a row cut short (the last one of a
    file copied while the logger wrote it) with NaNs, read as missing or, cut mid-number, as a wrong value; a
    trailing comma on each row would make it take the time column as the index. Rows are split as pandas splits
    them (spaces after a comma skipped); a blank line, or one of spaces, is skipped, as pandas skips it. The file
    is read as a stream: only the first bad row is kept (a week of 1 Hz logging is 600 000 rows)."""
    reader = csv.reader(io.StringIO(text), skipinitialspace=True)
    expected, bad, data_rows, trailing_comma = None, None, 0, True
    for row in reader:
        n = len(row)
        if n <= 1 and not (row and row[0].strip()):    # a blank line, or one of spaces
            continue
        if expected is None:
            expected = n
            continue
        data_rows += 1
        if trailing_comma and (n != expected + 1 or row[-1].strip()):
            trailing_comma = False
        if bad is None and n != expected:
            bad = (data_rows, reader.line_num, row)
    if bad is None:
        return
    number, line, row = bad
    hint = (" (a trailing comma on each row? remove it)" if trailing_comma else
            " (cut short? it is the file's last row)" if number == data_rows and len(row) < expected else "")
    raise TwinInputError(f"{path}: data row {number} (line {line}, {','.join(row)[:60]!r}) has {len(row)} fields, "
                         f"the header {expected}{hint}")


def _parse_csv(path, text, time_column=None):
    """Header, float matrix and time origin of a CSV; empty cells and NaN/NA become NaN.

    A ``time_column`` of ISO 8601 date-times becomes s since its first stamp, the origin returned
    (:mod:`twin.core.clock`); it is ``""`` when the time column is in s.
    """
    import pandas as pd

    # pandas ≥ 3 parses floats exactly by default; older versions need round_trip.
    exact = {} if int(pd.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"}
    _check_header_once(path, text)
    _check_row_lengths(path, text)
    try:
        frame = pd.read_csv(io.StringIO(text), skipinitialspace=True, **exact)
    except pd.errors.EmptyDataError:
        raise TwinInputError(f"{path}: the file is empty") from None
    except pd.errors.ParserError as exc:
        raise TwinInputError(f"{path}: not a well-formed CSV ({exc})") from None
    header = [str(h).strip() for h in frame.columns]
    if len(frame) == 0:
        raise TwinInputError(f"{path}: the file has a header but no data rows")
    origin = ""
    for j, column in enumerate(frame.columns):
        numeric = pd.to_numeric(frame[column], errors="coerce")
        bad = numeric.isna() & frame[column].notna()
        if bad.any() and header[j] == time_column and bad[frame[column].first_valid_index()]:   # stamps, not s
            numeric, origin = seconds_since_first_stamp(path, header[j], frame[column].astype(object))
        elif bad.any():
            i = int(np.flatnonzero(bad.to_numpy())[0])
            raise TwinInputError(f"{path}: column {header[j]!r}, data row {i + 1}: "
                                 f"{frame[column].iloc[i]!r} is not a number")
        frame[column] = numeric
    data = frame.to_numpy(dtype=float)
    if np.isinf(data).any():
        i, j = np.argwhere(np.isinf(data))[0]
        raise TwinInputError(f"{path}: column {header[j]!r}, data row {i + 1} is infinite")
    return header, data, origin


def _check_time(time_s, source, column="time_s", origin=""):
    """Refuse time that does not increase strictly, by row (as stamps when it was read from ``origin``)."""
    if time_s.ndim != 1:
        raise TwinInputError(f"{source}: time must be one-dimensional")
    steps = np.diff(time_s)
    if np.any(steps <= 0):
        k = int(np.flatnonzero(steps <= 0)[0])
        if origin:
            raise TwinInputError(f"{source}: {column} must increase strictly, but row {k + 2} has "
                                 f"{stamp(origin, time_s[k + 1])} after {stamp(origin, time_s[k])} (a clock set "
                                 "back, such as a daylight-saving change? stamps with their UTC offset are read "
                                 "in UTC)")
        raise TwinInputError(f"{source}: {column} must increase strictly, but row {k + 2} has {time_s[k + 1]} s "
                             f"after {time_s[k]} s")
