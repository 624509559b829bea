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
the time column, reports gaps and handles NaNs by an explicit policy.
"""
from __future__ import annotations

import hashlib
import io
import json
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..errors import TwinInputError

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


def project_version():
    try:
        from importlib.metadata import version

        return version("thermal-twin")
    except Exception:  # not installed (e.g. run from a source tree)
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
    def column(self):
        return f"{self.name}_{self.unit}"


def _atomic_write_text(path, text):
    path = Path(path)
    tmp = path.with_name(f".{path.name}.partial")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def split_column(column):
    """``T01_degC`` → (``T01``, ``degC``); the longest matching unit suffix wins."""
    for unit in sorted(UNITS, key=len, reverse=True):
        if column.endswith("_" + unit) and len(column) > len(unit) + 1:
            return column[: -len(unit) - 1], unit
    return None


class Dataset:
    """Time series of named channels with units and metadata.

    Parameters
    ----------
    time_s : (n,) strictly increasing times in s
    values : (n, n_channels) values in the channels' units
    channels : list of :class:`ChannelInfo`
    metadata : JSON-serialisable dict
    """

    def __init__(self, time_s, values, channels, metadata=None):
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
    def names(self):
        return [c.name for c in self.channels]

    def index(self, name):
        names = self.names
        if name in names:
            return names.index(name)
        raise TwinInputError(f"unknown channel {name!r}; available: {names}")

    def info(self, name):
        return self.channels[self.index(name)]

    def __getitem__(self, name):
        """Values of one channel (n,) in its unit."""
        return self.values[:, self.index(name)]

    def __contains__(self, name):
        return name in self.names

    def __len__(self):
        return len(self.time_s)

    def matrix(self, names):
        """Values of several channels (n, k), in the order given."""
        return self.values[:, [self.index(n) for n in names]]

    def names_of_kind(self, *kinds):
        return [c.name for c in self.channels if c.kind in kinds]

    def select(self, names):
        """A dataset with only the named channels."""
        idx = [self.index(n) for n in names]
        return Dataset(self.time_s, self.values[:, idx], [self.channels[i] for i in idx], self.metadata)

    def between(self, start_s=-np.inf, end_s=np.inf):
        """Rows with start_s ≤ t ≤ end_s."""
        keep = (self.time_s >= start_s) & (self.time_s <= end_s)
        return Dataset(self.time_s[keep], self.values[keep], self.channels, self.metadata)

    # ---------------------------------------------------------------- files
    def write(self, path):
        """Write ``path`` (CSV) and ``path.json`` (sidecar), atomically."""
        path = Path(path)
        buffer = io.StringIO()
        header = ["time_s"] + [c.column for c in self.channels]
        buffer.write(",".join(header) + "\n")
        np.savetxt(buffer, np.column_stack([self.time_s, self.values]), delimiter=",", fmt="%.17g")
        text = buffer.getvalue()
        _atomic_write_text(path, text)
        sidecar = {
            "format": FORMAT,
            "version": FORMAT_VERSION,
            "csv_sha256": hashlib.sha256(text.encode("utf-8")).hexdigest(),
            "channels": [asdict(c) for c in self.channels],
            "metadata": self.metadata,
        }
        _atomic_write_text(sidecar_path(path), json.dumps(sidecar, indent=1, default=json_default))
        return path

    @classmethod
    def read(cls, path):
        """Read a dataset written by :meth:`write` (CSV + sidecar), checking they belong together."""
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
        header, data = _parse_csv(path, text)
        expected = ["time_s"] + [c.column for c in channels]
        if header != expected:
            raise TwinInputError(f"{path}: columns {header} do not match the sidecar's {expected}")
        return cls(data[:, 0], data[:, 1:], channels, meta.get("metadata", {}))

    @classmethod
    def from_measured_csv(cls, path, column_map=None, time_column="time_s", nan_policy="error",
                          channel_kinds=None):
        """Import measured data from a CSV, validating it.

        Parameters
        ----------
        column_map : optional dict ``csv column → "<name>_<unit>"`` (e.g.
            ``{"t1": "T01_degC"}``); unmapped columns must already be named
            ``<name>_<unit>`` with a unit from :data:`UNITS`
        time_column : name of the time column, in s
        nan_policy : ``error`` (default), ``interpolate`` (linear in time,
            per channel; leading/trailing NaNs are held) or ``drop`` (rows
            with any NaN) or ``keep`` (leave them; the caller masks them, as the gap
            diagnosis does)
        channel_kinds : optional dict name → kind overriding the unit-based default

        The import report (gaps, NaN counts, policy) is stored in
        ``metadata["import"]``.
        """
        path = Path(path)
        if nan_policy not in NAN_POLICIES:
            raise TwinInputError(f"nan_policy must be one of {NAN_POLICIES}, got {nan_policy!r}")
        header, data = _parse_csv(path, path.read_text(encoding="utf-8"))
        column_map = dict(column_map or {})
        unknown_map = sorted(set(column_map) - set(header))
        if unknown_map:
            raise TwinInputError(f"{path}: column map names column(s) {unknown_map} that the file lacks; "
                                 f"columns: {header}")
        if time_column not in header:
            raise TwinInputError(f"{path}: no time column {time_column!r}; columns: {header}")
        t_index = header.index(time_column)
        channels, cols = [], []
        for j, col in enumerate(header):
            if j == t_index:
                continue
            target = column_map.get(col, col)
            parts = split_column(target)
            if parts is None:
                raise TwinInputError(
                    f"{path}: column {col!r} is not named <name>_<unit> with a known unit "
                    f"{sorted(UNITS)}; give a column map, e.g. {{{col!r}: 'T01_degC'}}")
            name, unit = parts
            kind = (channel_kinds or {}).get(name, KIND_OF_UNIT[unit])
            channels.append(ChannelInfo(name, unit, kind))
            cols.append(j)
        time_s = data[:, t_index]
        values = data[:, cols]
        if np.isnan(time_s).any():
            row = int(np.flatnonzero(np.isnan(time_s))[0])
            raise TwinInputError(f"{path}: {time_column} is empty or NaN at data row {row + 1}")
        _check_time(time_s, str(path), time_column)
        report = {"file": str(path), "rows": int(len(time_s)), "nan_policy": nan_policy}
        nan_counts = {c.name: int(np.isnan(values[:, k]).sum()) for k, c in enumerate(channels)}
        report["nan_counts"] = {k: v for k, v in nan_counts.items() if v}
        if report["nan_counts"]:
            if nan_policy == "error":
                first = next(iter(report["nan_counts"]))
                k = [c.name for c in channels].index(first)
                row = int(np.flatnonzero(np.isnan(values[:, k]))[0])
                raise TwinInputError(
                    f"{path}: column {channels[k].column!r} is NaN/empty at t = {time_s[row]} s (data row "
                    f"{row + 1}); {sum(report['nan_counts'].values())} NaNs in {len(report['nan_counts'])} "
                    "column(s); choose nan_policy='interpolate' or 'drop'")
            if nan_policy == "drop":
                keep = ~np.isnan(values).any(axis=1)
                report["dropped_rows"] = int((~keep).sum())
                time_s, values = time_s[keep], values[keep]
            elif nan_policy == "interpolate":
                for k in range(values.shape[1]):
                    bad = np.isnan(values[:, k])
                    if bad.all():
                        raise TwinInputError(f"{path}: column {channels[k].column!r} holds no value at all")
                    if bad.any():
                        values[bad, k] = np.interp(time_s[bad], time_s[~bad], values[~bad, k])
        steps = np.diff(time_s)
        if len(steps):
            typical = float(np.median(steps))
            gaps = np.flatnonzero(steps > 1.5 * typical)
            report["sampling_interval_s"] = typical
            report["gaps"] = [{"after_s": float(time_s[g]), "length_s": float(steps[g])} for g in gaps[:100]]
            report["n_gaps"] = int(len(gaps))
        return cls(time_s, values, channels, {"source": str(path), "kind": "measured", "import": report})

    def __repr__(self):
        span = f"{self.time_s[0]:g}–{self.time_s[-1]:g} s" if len(self) else "empty"
        return f"Dataset({len(self)} rows, {span}, channels {self.names[:8]}{'…' if len(self.names) > 8 else ''})"


def sidecar_path(path):
    path = Path(path)
    return path.with_name(path.name + ".json")


def json_default(value):
    """``json.dumps`` fallback for numpy arrays and scalars (as lists and Python numbers) and paths (as text).

    Anything else raises ``TypeError``, as ``json`` itself would: metadata
    that cannot be written faithfully is an error, not a string.
    """
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {value!r}")


def _parse_csv(path, text):
    """Header and float matrix of a CSV; empty cells and NaN/NA become NaN."""
    import pandas as pd

    # pandas ≥ 3 parses floats exactly by default; older versions need round_trip.
    exact = {} if int(pd.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"}
    try:
        frame = pd.read_csv(io.StringIO(text), skipinitialspace=True, **exact)
    except pd.errors.EmptyDataError:
        raise TwinInputError(f"{path}: the file is empty") from None
    except pd.errors.ParserError as exc:
        raise TwinInputError(f"{path}: not a well-formed CSV ({exc})") from None
    header = [str(h).strip() for h in frame.columns]
    if len(frame) == 0:
        raise TwinInputError(f"{path}: the file has a header but no data rows")
    for j, column in enumerate(frame.columns):
        numeric = pd.to_numeric(frame[column], errors="coerce")
        bad = numeric.isna() & frame[column].notna()
        if bad.any():
            i = int(np.flatnonzero(bad.to_numpy())[0])
            raise TwinInputError(f"{path}: column {header[j]!r}, data row {i + 1}: "
                                 f"{frame[column].iloc[i]!r} is not a number")
        frame[column] = numeric
    data = frame.to_numpy(dtype=float)
    if np.isinf(data).any():
        i, j = np.argwhere(np.isinf(data))[0]
        raise TwinInputError(f"{path}: column {header[j]!r}, data row {i + 1} is infinite")
    return header, data


def _check_time(time_s, source, column="time_s"):
    if time_s.ndim != 1:
        raise TwinInputError(f"{source}: time must be one-dimensional")
    steps = np.diff(time_s)
    if np.any(steps <= 0):
        k = int(np.flatnonzero(steps <= 0)[0])
        raise TwinInputError(f"{source}: {column} must increase strictly, but row {k + 2} has {time_s[k + 1]} s "
                             f"after {time_s[k]} s")
