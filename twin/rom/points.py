"""Thermometers at arbitrary points of a ROM: the output rows of point temperatures, projected on the ROM's basis.

A point temperature is a row of the FE output operator: the barycentric weights w (n,) of the point in its
tetrahedron (:meth:`fea.heat.ThermalSystem.point_weights`, as :mod:`fea.outputs` builds the machine's own
thermometers).  On a ROM with the M-orthonormal basis V (T ≈ V z) the row is wᵀV: exact for the ROM's
field, with the same reduction error as any other thermometer.  This is how the locations a placement study
chose (``twin place``: surface nodes ``s003549``, camera spots) become outputs the observer can fuse.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from fea.errors import FEAInputError

from ..core.machine import Machine
from .reduction import ReducedModel, ROMError


def point_rows(rom: ReducedModel, machine: Machine, names: list[str], points: np.ndarray,
               snap_distance_m: float | None = None) -> np.ndarray:
    """The ROM output rows (k, r) of the temperatures at ``points``, °C per unit of the modal state.

    Parameters
    ----------
    rom : ReducedModel
        A ROM of ``machine`` that keeps its basis (``cached_rom(..., keep_basis=True)``).
    machine : Machine
        The built machine the ROM reduces (its mesh locates the points).
    names : list of str
        The points' names, for errors.
    points : numpy.ndarray
        (k, 3) positions, m.
    snap_distance_m : float, optional
        How far off the mesh a point may lie and be snapped onto it, m (default: the machine's
        ``snap_distance_m``, the tolerance of its own sensors).

    Returns
    -------
    numpy.ndarray
        (k, r) rows over the modal state, °C per unit of state.

    Raises
    ------
    ROMError
        If the ROM has no basis, it is not a ROM of ``machine``, or a point is off the machine.
    """
    if rom.basis is None:
        raise ROMError("point thermometers need the ROM's basis: build or load it with keep_basis=True")
    if rom.basis.shape[0] != machine.thermal.n_nodes:
        raise ROMError(f"the ROM's basis has {rom.basis.shape[0]} nodes, the machine {machine.name!r} "
                       f"{machine.thermal.n_nodes}: not a ROM of this machine")
    snap = machine.definition.snap_distance_m if snap_distance_m is None else float(snap_distance_m)
    points = np.atleast_2d(np.asarray(points, float))
    if points.shape != (len(names), 3) or not np.all(np.isfinite(points)):
        raise ROMError(f"point thermometers need one finite (x, y, z) position in m per name; got {points.shape} "
                       f"positions for {len(names)} names")
    try:
        weights = machine.thermal.point_weights(points, names=list(names), snap_distance=snap)
    except FEAInputError as exc:
        raise ROMError(f"point thermometer {exc} of {machine.name!r}") from None
    return np.asarray(weights @ rom.basis)


def with_point_thermometers(rom: ReducedModel, machine: Machine, names: list[str], points: np.ndarray,
                            labels: list[str] | None = None, snap_distance_m: float | None = None) -> ReducedModel:
    """A copy of ``rom`` with a ``temperature`` output (°C) at each point, after its own outputs.

    Parameters
    ----------
    rom, machine, names, points, snap_distance_m
        As :func:`point_rows`; ``names`` must differ from the ROM's outputs.
    labels : list of str, optional
        A description per point (default ``"point thermometer"``); the position is appended.

    Returns
    -------
    ReducedModel
        The same state space with k more output rows (no feedthrough, no offset).

    Raises
    ------
    ROMError
        As :func:`point_rows`, or if a name is already an output of the ROM or given twice.
    """
    names = list(names)
    taken = sorted((set(names) & set(rom.output_names)) | {n for n in names if names.count(n) > 1})
    if taken:
        raise ROMError(f"point thermometer name {taken[0]!r} is already an output of the ROM or given twice")
    rows = point_rows(rom, machine, names, points, snap_distance_m)
    points = np.atleast_2d(np.asarray(points, float))
    labels = labels or ["point thermometer"] * len(names)
    where = [f"{lab} at ({', '.join(f'{v:.4g}' for v in p)}) m" for lab, p in zip(labels, points)]
    return dataclasses.replace(
        rom, output_matrix=np.vstack([rom.output_matrix, rows]),
        feedthrough=np.vstack([rom.feedthrough, np.zeros((len(names), rom.n_inputs))]),
        offset=np.r_[rom.offset, np.zeros(len(names))], output_names=[*rom.output_names, *names],
        output_units=[*rom.output_units, *["degC"] * len(names)],
        output_kinds=[*rom.output_kinds, *["temperature"] * len(names)],
        output_labels=[*(rom.output_labels or [""] * rom.n_outputs), *where], info=dict(rom.info))
