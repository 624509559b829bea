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

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.dataset import Dataset, sidecar_path
from ..errors import TwinInputError

SENSOR_KINDS = ("temperature", "air", "displacement", "strain")
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

    @property
    def mask(self):
        return np.isfinite(self.values)


def read_measured(data, column_map=None):
    """A :class:`~twin.core.dataset.Dataset` from a path (twin dataset or measured CSV) or a Dataset, NaNs kept."""
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


def _nan_runs(t, v):
    """Longest run of NaNs (s) in a column."""
    bad = ~np.isfinite(v)
    if not bad.any():
        return 0.0
    edges = np.diff(np.r_[0, bad.astype(int), 0])
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    lengths = [t[min(e + 1, len(t) - 1)] - t[max(s - 1, 0)] for s, e in zip(starts, ends)]
    return float(max(lengths))


def match_record(dataset, machine):
    """Match a dataset's channels to a machine; return a :class:`Record` (see the module docstring)."""
    d = machine.definition
    sensors = {c.name: c for c in machine.channels if c.kind in SENSOR_KINDS}
    cameras = {c.name for c in machine.channels if c.kind == "camera"}
    zones = list(d.zones)
    t = np.asarray(dataset.time_s, float)
    if len(t) < 10:
        raise TwinInputError(f"{dataset.metadata.get('source', 'dataset')}: {len(t)} rows are too few "
                             "for a diagnosis (need at least 10)")
    names, kinds, cols = [], [], []
    feeds, air, ignored, empty = {}, [], [], []
    spindle = gradient = None
    z_ref = d.ambient_reference_height_m

    def valid_names():
        return (f"sensors {sorted(sensors)}; conditions {sorted(CONDITION_UNITS)} and "
                f"{['ambient_' + z for z in zones]}")

    for ch in dataset.channels:
        v = np.asarray(dataset[ch.name], float)
        if ch.name in sensors:
            c = sensors[ch.name]
            if ch.unit != c.unit:
                raise TwinInputError(f"channel {ch.name!r} is in {ch.unit!r}, but sensor {ch.name} of machine "
                                     f"{machine.name!r} reads {c.unit!r} (column {ch.name}_{c.unit})")
            if not np.isfinite(v).any():
                empty.append(ch.name)
                continue
            if c.kind == "air":
                sensor = d.sensor(ch.name)
                air.append((ch.name, sensor.zone, sensor.position[2] - z_ref, _fill(t, v)))
            names.append(ch.name)
            kinds.append(c.kind)
            cols.append(v)
        elif ch.name in CONDITION_UNITS:
            if ch.unit != CONDITION_UNITS[ch.name]:
                raise TwinInputError(f"channel {ch.name!r} must be in {CONDITION_UNITS[ch.name]!r}, got {ch.unit!r}")
            if not np.isfinite(v).any():
                empty.append(ch.name)
                continue
            filled = _fill(t, v)
            if ch.name == "spindle":
                spindle = filled
            elif ch.name == "ambient_gradient":
                gradient = filled
            else:
                feeds[ch.name[-1]] = filled
        elif ch.name.startswith("ambient_") and ch.name[len("ambient_"):] in zones and ch.unit == "degC":
            if np.isfinite(v).any():
                air.append((ch.name, ch.name[len("ambient_"):], 0.0, _fill(t, v)))
        elif ch.name.startswith("P_") and ch.unit == "W" or ch.name in cameras:
            ignored.append(ch.name)
        else:
            raise TwinInputError(
                f"channel {ch.name!r} (column {ch.column}) matches no sensor or condition of machine "
                f"{machine.name!r}; valid names: {valid_names()}. Rename it in the CSV or map it with a column "
                "map (--column-map), e.g. {\"" + ch.column + "\": \"T01_degC\"}")
    if not names:
        raise TwinInputError(f"the data has no sensor channel of machine {machine.name!r}; valid names: "
                             f"{valid_names()}")
    values = np.column_stack(cols)
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
        "sensors_missing": sorted(set(sensors) - set(names) - {n for n, *_ in air}),
        "channels_empty": empty,
        "channels_ignored": ignored,
        "nan_counts": {n: int((~np.isfinite(values[:, j])).sum()) for j, n in enumerate(names)
                       if not np.isfinite(values[:, j]).all()},
        "longest_nan_run_s": {n: _nan_runs(t, values[:, j]) for j, n in enumerate(names)
                              if not np.isfinite(values[:, j]).all()},
        "has_spindle": spindle is not None, "feeds": sorted(feeds),
        "air_inputs": [n for n, *_ in air],
    }
    if imported.get("nan_counts"):
        report["input_nan_counts"] = {k: v for k, v in imported["nan_counts"].items() if k not in names}
    return Record(t, names, kinds, values, spindle, feeds, gradient, air, report, dict(dataset.metadata))
