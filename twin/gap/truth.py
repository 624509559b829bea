""""Measured" data with effects switched on, for the blind check: not the diagnosis's own model.

:func:`truth_dataset` runs a scenario on a machine (the benchmark uses a
finer mesh than the diagnosis) with the *full* finite-element system, the
scenario's scheme and time step (backward Euler, 20 s for
``gap_blind_24h``, against the diagnosis's reduced model with exact
zero-order hold at 60 s), the effects' *truth variants* (other hidden
constants than the library's), and the scenario's sensor noise (offsets and
quantisation).  The dataset holds what a test rig records: spindle speed,
feeds and the sensors — no true ambient and no source power.
"""
from __future__ import annotations

import time

import numpy as np

from ..core.dataset import ChannelInfo, Dataset, project_version
from ..core.noise import apply_noise
from ..core.scenario import Scenario, load_scenario
from .drive import ScenarioDrive
from .engine import FullBackend
from .model import GapModel
from .signals import uniform_grid
from .structure import build_structure


def truth_dataset(scenario, machine, active=(), seed=None, noise=True, step_s=None):
    """A :class:`~twin.core.dataset.Dataset` of ``scenario`` on ``machine`` with ``active`` = [(effect, θ), …] on.

    ``step_s`` overrides the scenario's time step (it must divide the sampling interval).
    """
    t0 = time.perf_counter()
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    sc.check_machine(machine.definition)
    effects = [e for e, _ in active]
    structure = build_structure(machine, effects)
    backend = FullBackend(structure, theta=sc.theta)
    h = float(step_s or sc.time_step_s)
    times = sc.times()
    sub = max(1, int(round(sc.sample_interval_s / h)))
    grid = uniform_grid(0.0, sc.duration_s, sc.sample_interval_s / sub)
    drive = ScenarioDrive(sc, machine, grid)
    uniform = sc.initial["kind"] == "uniform"
    model = GapModel(structure, backend, drive, grid, "uniform" if uniform else "steady",
                     initial_temperature=sc.initial.get("temperature_C") if uniform else None)
    pred = model.predict(list(active), nuisance=False, on_grid=True)
    rows = np.clip(np.round(times / (sc.sample_interval_s / sub)).astype(int), 0, len(grid) - 1)
    Y = pred.grid_values[rows]
    kinds = list(structure.kinds)
    if noise:
        Y = apply_noise(Y, kinds, sc.noise, sc.seed if seed is None else seed)
    channels = [ChannelInfo("spindle", "rpm", "spindle_speed", "spindle speed")]
    columns = [drive.spindle_rpm[rows]]
    for axis in "xyz":
        channels.append(ChannelInfo(f"feed_{axis}", "mm_min", "feed", f"{axis.upper()} axis feed"))
        columns.append(drive.feed_mm_min[axis][rows])
    for j, c in enumerate(structure.channels):
        channels.append(ChannelInfo(c.name, c.unit, c.kind, c.label, c.position))
        columns.append(Y[:, j])
    metadata = {
        "kind": "synthetic truth (gap benchmark)", "machine": machine.name, "scenario": sc.name,
        "seed": sc.seed if seed is None else seed, "noise": sc.noise if noise else "none",
        "effects": [{"name": e.name, "params": [float(v) for v in np.atleast_1d(th)], "hidden": e.hidden}
                    for e, th in active],
        "mesh": {"nodes": machine.mesh.n_nodes, "tetrahedra": machine.mesh.n_tets, "file": str(machine.mesh_path)},
        "time_step_s": sc.sample_interval_s / sub, "scheme": "backward Euler" if sc.theta == 1.0 else "Crank-Nicolson",
        "model": "full FE", "wall_seconds": time.perf_counter() - t0, "project_version": project_version(),
    }
    return Dataset(times, np.column_stack(columns), channels, metadata)
