"""thermal-twin: a thermal digital twin of a CNC machine tool — the public API.

::

    import twin

    machine = twin.build_machine("vmc_ram")
    result = twin.simulate("heat_cool_9000", machine)          # result.dataset: °C, µm, µε
    twin.run_scenario("heat_cool_9000", out_dir="runs/hc")    # what `twin run` writes

The subpackages mirror the command line: :mod:`twin.core` (machine, scenario, simulation, dataset),
:mod:`twin.run` (``run``, ``mesh``, ``report``), :mod:`twin.compensation` (``train``, ``evaluate``,
``study``), :mod:`twin.placement` (``place``), :mod:`twin.rom` (``rom``), :mod:`twin.fmu` (``fmu``),
:mod:`twin.gap` (``gap``), and :mod:`twin.infra` (sweeps, output folders, plots, renders, tables).
"""
import importlib

from .errors import TwinInputError  # noqa: F401 (public API: in __all__)

#: Public name → the module that defines it.
_API = {
    "build_machine": "twin.core.machine", "Machine": "twin.core.machine",
    "load_machine": "twin.core.machine_definition", "MachineDefinition": "twin.core.machine_definition",
    "load_scenario": "twin.core.scenario", "available_scenarios": "twin.core.scenario",
    "Scenario": "twin.core.scenario",
    "simulate": "twin.core.simulate", "SimulationResult": "twin.core.simulate",
    "Dataset": "twin.core.dataset", "ChannelInfo": "twin.core.dataset",
    "run_scenario": "twin.run.workflows", "mesh_machine": "twin.run.workflows", "report_dataset": "twin.run.workflows",
    "load_dataset": "twin.compensation.train", "train": "twin.compensation.train",
    "evaluate": "twin.compensation.train", "physics_prediction": "twin.compensation.train",
    "CompensationModel": "twin.compensation.store",
    "cross_condition_study": "twin.compensation.studies", "thesis_protocol_study": "twin.compensation.studies",
    "hybrid_study": "twin.compensation.studies",
    "placement_study": "twin.placement.study",
    "build_rom": "twin.rom.reduction", "cached_rom": "twin.rom.reduction", "simulate_rom": "twin.rom.reduction",
    "ReducedModel": "twin.rom.reduction", "error_report": "twin.rom.report",
    "export_fmu": "twin.fmu.export", "FMUSession": "twin.fmu.session",
    "diagnose": "twin.gap.diagnose", "Diagnosis": "twin.gap.diagnose",
    "run_tasks": "twin.infra.sweep",
}

__all__ = sorted(["TwinInputError", *_API])


def __getattr__(name):
    """Import a public name on first use (PEP 562).

    Lazy because ``import twin.cli`` runs this file first, and ``twin --help`` must answer without
    loading numpy or scipy (tests/test_cli_startup.py).
    """
    if name not in _API:
        raise AttributeError(f"module 'twin' has no attribute {name!r}")
    value = getattr(importlib.import_module(_API[name]), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_API))
