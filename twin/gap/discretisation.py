"""The twin's discretisation floor: how far its prediction moves on a second, coarser discretisation.

The group scales carry a model tolerance (:data:`twin.gap.fit.GROUP_FLOOR`:
0.05 K, 0.1 µm, 0.3 µε) that covers what a twin's mesh and reduced model
typically get wrong.  One sensor can sit where the mesh matters far more: a
thermometer on a small motor housing beside a concentrated heat source, whose
temperature depends on how many facets carry that source.  On a densely
sampled record of a finer mesh's truth (where the timing floor of ± half a
sample is small) such a sensor read 6 σ off a twin with no gap.

The floor is measured, not assumed: the nominal twin's residual is recomputed
with the same drive on the machine meshed :data:`COARSENING` times coarser,
by the twin's own backend and options (the reduced model of the same order, or
the full FE with the same scheme; the coarse reduced basis is built without the
library's effect terms, so the floor holds that basis change too); the
floor of a sensor is the held-out RMS of the change, after each model's own
offsets and initial-state nuisance.  It estimates the twin's own error where
the error shrinks with the mesh size, it does not bound it (a coarsening of 1.5
moves the prediction by half the twin's error at order 1, by 1.25 times it at
order 2).  It widens the sensors' σ_j only: a group's scale keeps its
tolerance, which the independent benchmark judges, so one sensor's mesh
sensitivity does not blunt a whole group.  Where it widens σ_j, an effect of
that size at that sensor alone is not told from the mesh either: the verdict
names such sensors (:func:`twin.gap.verdict.mesh_limited`).
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..core.machine import Machine, build_machine
from ..infra.sweep import cached
from .engine import FullBackend, ReducedBackend
from .fit import Evaluator, FitResult
from .model import GapModel
from .structure import Structure

#: Mesh size of the second discretisation, relative to the twin's.
COARSENING = 1.5


def coarser_machine(machine: Machine) -> Machine:
    """The machine meshed :data:`COARSENING` times coarser, built once per process.

    Parameters
    ----------
    machine : Machine
        The nominal machine (its ``mesh_size_m`` is known when it was made by
        :func:`~twin.core.machine.build_machine`).

    Returns
    -------
    Machine
        The same definition on a coarser mesh (from the mesh cache when it was built before).
    """
    size = COARSENING * (machine.mesh_size_m or machine.definition.geometry.mesh_size_m)
    # the memo holds the nominal machine too, so its id (the key) cannot pass to another machine
    return cached(("coarser-machine", id(machine), round(size, 9)),
                  lambda: (machine, build_machine(machine.name, size, definition=machine.definition)))[1]


def discretisation_floor(model: GapModel, nominal: FitResult, evaluator: Evaluator,
                         engine: Callable[..., tuple[Structure, ReducedBackend | FullBackend]]) -> np.ndarray:
    """Per-sensor held-out RMS change of the nominal residual on a coarser mesh, channel units.

    Parameters
    ----------
    model : GapModel
        The nominal twin (its drive and initial state are reused).
    nominal : FitResult
        Its residual on the record.
    evaluator : Evaluator
        The record's evaluator (fit and held-out rows, offsets, nuisance).
    engine : callable
        ``engine(machine, effects)`` → (structure, backend): :func:`twin.gap.diagnose.engine` with the nominal
        twin's backend and options.

    Returns
    -------
    ndarray, shape (n_channels,)
        The floor per evaluated channel, in its unit (K, µm, µε); 0 where a channel has no held-out value.
    """
    coarse = coarser_machine(model.structure.machine)
    structure, backend = engine(coarse, [])
    twin = GapModel(structure, backend, model.drive, model.times_s, model.initial, model.initial_temperature)
    change = evaluator.residual(twin.predict()).R - nominal.residual.R
    held = change[evaluator.hold_rows]
    counted = np.isfinite(held).sum(axis=0)
    return np.sqrt(np.nansum(held ** 2, axis=0) / np.maximum(counted, 1))
