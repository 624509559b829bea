"""Thermometers at the locations a placement study chose (``twin place``), as outputs of the observer's ROM.

``twin place --out runs/placement`` writes ``chosen_sensors.csv``: per drift axis the chosen set, one row per
location with its ``name`` (``s003549`` a surface node, ``cam199`` a camera spot, ``T18`` an installed
thermometer), ``kind``, ``part`` and position ``x_m``, ``y_m``, ``z_m``.  :func:`read_placement` reads the set
of one axis; :func:`placement_rom` gives the ROM a point-temperature output at each location that is not
already one of its thermometers (:func:`twin.rom.points.with_point_thermometers`).  A camera spot is read with
the S65 camera's noise model (one offset shared by every spot), anything else as a DS18S20 thermometer.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.machine import Machine
from ..errors import TwinInputError
from ..rom.points import with_point_thermometers
from ..rom.reduction import ReducedModel, ROMError

CHOSEN_FILE = "chosen_sensors.csv"
COLUMNS = ("axis", "name", "kind", "x_m", "y_m", "z_m")


@dataclass
class PlacedThermometers:
    """The locations of one axis's chosen set.

    Attributes
    ----------
    names : list of str
        Location names, in the order of choice.
    kinds : list of str
        ``surface``, ``camera`` or ``installed``.
    points : numpy.ndarray
        (k, 3) positions, m.
    source : str
        The file they were read from (for errors).
    """

    names: list
    kinds: list
    points: np.ndarray
    source: str

    @property
    def sensors(self) -> dict:
        """Name → sensor model of the observer: ``S65`` for a camera spot, else ``DS18S20``."""
        return {n: "S65" if k == "camera" else "DS18S20" for n, k in zip(self.names, self.kinds)}


def _rows(path):
    """The rows of a ``chosen_sensors.csv`` as dicts (every column of :data:`COLUMNS` checked present)."""
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
    except OSError as exc:
        raise TwinInputError(f"{path}: cannot read the placement's chosen sensors ({exc.strerror})") from None
    missing = [c for c in COLUMNS if not rows or c not in rows[0]]
    if missing:
        raise TwinInputError(f"{path}: no column {missing[0]!r}; a {CHOSEN_FILE} of `twin place` has "
                             f"{', '.join(COLUMNS)}")
    return rows


def read_placement(path: str | Path, axis: str = "Z") -> PlacedThermometers:
    """The locations chosen for ``axis`` by a placement study.

    Parameters
    ----------
    path : str or Path
        A ``twin place`` result folder or its ``chosen_sensors.csv``.
    axis : str
        The drift axis whose chosen set is read (``Z``, ``Y`` …).

    Returns
    -------
    placed : PlacedThermometers
        Names, points (m) and kinds of the chosen locations.

    Raises
    ------
    TwinInputError
        If the file is missing or malformed (naming file, row, column and value), or has no set for ``axis``.
    """
    path = Path(path)
    if path.is_dir():
        path = path / CHOSEN_FILE
    rows = _rows(path)
    chosen = [r for r in rows if r["axis"] == axis]
    if not chosen:
        axes = sorted({r["axis"] for r in rows})
        raise TwinInputError(f"{path}: no sensor chosen for axis {axis!r}; axes: {', '.join(axes)}")
    points = np.empty((len(chosen), 3))
    for i, row in enumerate(chosen):
        for j, col in enumerate(("x_m", "y_m", "z_m")):
            try:
                points[i, j] = float(row[col])
            except (TypeError, ValueError):
                raise TwinInputError(f"{path}: {row['name']} {col} must be a number (m), got {row[col]!r}") from None
        if not np.all(np.isfinite(points[i])):
            raise TwinInputError(f"{path}: {row['name']} has a position that is not finite: {points[i].tolist()}")
    return PlacedThermometers([r["name"] for r in chosen], [r["kind"] for r in chosen], points, str(path))


def placement_rom(rom: ReducedModel, machine: Machine, placed: PlacedThermometers) -> ReducedModel:
    """``rom`` with a thermometer output at every placed location that is not already a ROM thermometer.

    Parameters
    ----------
    rom : ReducedModel
        A ROM of ``machine`` that keeps its basis (``cached_rom(..., keep_basis=True)``).
    machine : Machine
        The machine (its mesh locates the points).
    placed : PlacedThermometers
        The locations (:func:`read_placement`).

    Returns
    -------
    rom : ReducedModel
        ``rom`` itself if every location is a ROM thermometer already, else a copy with the new outputs.

    Raises
    ------
    TwinInputError
        If a location is off the machine (naming the file, the location and its position).
    """
    new = [i for i, n in enumerate(placed.names) if n not in rom.output_names]
    if not new:
        return rom
    try:
        return with_point_thermometers(rom, machine, [placed.names[i] for i in new], placed.points[new],
                                       [f"{placed.kinds[i]} location chosen by twin place" for i in new])
    except ROMError as exc:
        raise TwinInputError(f"{placed.source}: {exc}") from None
