"""Machine variants for sweeps: a picklable recipe of a (possibly perturbed) machine, and helpers shared by studies.

A :class:`MachineSpec` is what a sweep task carries instead of a machine: the
machine's name, its mesh size and an optional perturbation of heat-source
powers and convection coefficients (the "real" machine of a sim-to-real
study).  A worker rebuilds the machine from the on-disk mesh and operator
caches once per process and keeps it.

Used by :mod:`twin.placement` and :mod:`twin.compensation` alike.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import numpy as np

from ..errors import TwinInputError
from .machine import Machine, build_machine
from .machine_definition import MachineDefinition, load_machine
from .scenario import Scenario, load_scenario


@dataclass(frozen=True)
class MachineSpec:
    """What a worker needs to rebuild a machine: its name, mesh size and an optional perturbation.

    Attributes
    ----------
    name : str
        Machine name (a file of ``meshes/machines``).
    mesh_size_m : float or None
        Target element size, m; None for the machine's default.
    source_scale : tuple of (str, float) or float
        Scales heat-source powers: ``((source, factor), …)`` or one factor for every source (-).
    convection_scale : float
        Scales every convection coefficient (-).

    Both scales enter the assembled thermal system only, so the cached mesh and
    output operator are reused.
    """

    name: str = "vmc_ram"
    mesh_size_m: float | None = None
    source_scale: tuple | float = 1.0
    convection_scale: float = 1.0

    @property
    def perturbed(self) -> bool:
        """True if the spec scales any source power or convection coefficient."""
        return self.source_scale != 1.0 or self.convection_scale != 1.0

    def build(self) -> Machine:
        """The machine, built once per process and kept (a sweep worker reuses it for every task).

        Returns
        -------
        Machine
            The built (possibly perturbed) machine.
        """
        return _built_machine(self)


@functools.cache
def _built_machine(spec: MachineSpec) -> Machine:
    if not spec.perturbed:
        return build_machine(spec.name, spec.mesh_size_m)
    return build_machine(spec.name, spec.mesh_size_m, definition=perturbed_definition(
        load_machine(spec.name), spec.source_scale, spec.convection_scale))


def perturbed_definition(definition: MachineDefinition, source_scale: tuple | float = 1.0,
                         convection_scale: float = 1.0) -> MachineDefinition:
    """A copy of a machine definition with scaled source powers and convection coefficients.

    Parameters
    ----------
    definition : MachineDefinition
        The nominal machine.
    source_scale : tuple of (str, float), dict or float
        Power factor per named source (others unchanged), or one factor for every source (-).
    convection_scale : float
        Factor on every convection coefficient (-).

    Returns
    -------
    MachineDefinition
        The perturbed copy; its description says how it was perturbed.

    Raises
    ------
    TwinInputError
        If ``source_scale`` names a source the machine does not have.
    """
    scales = dict(source_scale) if isinstance(source_scale, (tuple, list, dict)) else {}
    names = {s.name for s in definition.sources}
    unknown = sorted(set(scales) - names)
    if unknown:
        raise TwinInputError(f"source_scale names unknown source(s) {unknown}; sources: {sorted(names)}")
    common = 1.0 if scales else float(source_scale)
    sources = [replace(s, coefficient_W=s.coefficient_W * scales.get(s.name, common)) for s in definition.sources]
    convection = [replace(c, coefficient=c.coefficient * float(convection_scale)) for c in definition.convection]
    out = replace(definition, sources=sources, convection=convection)
    out.description = (definition.description + f" [perturbed: sources {source_scale}, convection "
                       f"×{convection_scale}]")
    return out


def as_scenario(scenario: Scenario | str) -> Scenario:
    """A :class:`~twin.core.scenario.Scenario` from itself, a scenario name or a TOML path.

    Parameters
    ----------
    scenario : Scenario or str
        A scenario, or the name or TOML path of one.

    Returns
    -------
    Scenario
        The scenario (loaded if given by name or path).
    """
    return scenario if isinstance(scenario, Scenario) else load_scenario(scenario)


def zero_referenced(values: np.ndarray) -> np.ndarray:
    """``values`` minus their first row: the change since the start of a record (same unit as ``values``).

    Parameters
    ----------
    values : numpy.ndarray
        (n, …) a time-ordered record, first axis time.

    Returns
    -------
    numpy.ndarray
        Same shape and unit, first row zero.
    """
    return values - values[:1]
