"""Running a scenario on a machine twin: the transient FE run sampled by the virtual sensors.

One thermal solve per time step and one output-operator product per sample;
no elastic solve and no stored field unless fields are asked for.  The
result is a :class:`~twin.dataset.Dataset` in edge units (°C, µm, µε) with the
operating conditions (spindle speed, feeds, zone ambients, source powers)
alongside the sensors, and an energy-balance check of the run.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

import fea

from .dataset import ChannelInfo, Dataset, project_version
from .machine import Machine, build_machine
from .machine_definition import room_zone
from .noise import apply_noise
from .scenario import Scenario, load_scenario


@dataclass
class Conditions:
    """Operating conditions of a scenario on a time grid, and the thermal inputs they give."""

    times_s: np.ndarray
    spindle_rpm: np.ndarray
    feed_mm_min: dict
    ambient_C: dict
    gradient_K_per_m: np.ndarray
    inputs: np.ndarray


class ScenarioInputs:
    """The input schedule of a scenario on a machine (``sample(times) -> (n, n_inputs)``).

    ``modify`` is an optional hook ``modify(conditions) -> inputs`` used to
    perturb the physics (e.g. the gap diagnosis's candidate effects).
    """

    def __init__(self, machine: Machine, scenario: Scenario, modify=None):
        self.machine, self.scenario, self.modify = machine, scenario, modify

    def conditions(self, times_s):
        t = np.atleast_1d(np.asarray(times_s, float))
        rpm, feeds = self.scenario.operating(t)
        ambient = self.scenario.zone_ambient(t, self.machine.zones, self.machine.definition.zone_lags_s)
        gradient = np.full(t.shape, self.scenario.ambient.gradient_K_per_m)
        U = self.machine.input_matrix(rpm, feeds, ambient, gradient)
        cond = Conditions(t, rpm, feeds, ambient, gradient, U)
        if self.modify is not None:
            cond.inputs = self.modify(cond)
        return cond

    def sample(self, times_s):
        return self.conditions(times_s).inputs


@dataclass
class SimulationResult:
    dataset: Dataset
    machine: Machine
    scenario: Scenario
    fields: dict = field(default_factory=dict)
    wall_seconds: float = 0.0
    energy_balance_relative_error: float | None = None


def energy_rows(machine):
    """Rows over T giving stored energy (J) and Σ r_T·T (W), and r_u (W per input) for the power in."""
    system = machine.thermal
    stored = system.mass @ np.ones(system.n_nodes)
    r_T = sum((rt for rt, _ in system.heat_flows.values()), np.zeros(system.n_nodes))
    r_u = sum((ru for _, ru in system.heat_flows.values()), np.zeros(system.n_inputs))
    return sp.csr_matrix(np.vstack([stored, r_T])), r_u


def initial_temperature(machine, scenario, schedule):
    """Uniform start, or the steady state for the conditions at t = 0 (or those the scenario names)."""
    init = scenario.initial
    if init["kind"] == "uniform":
        value = init.get("temperature_C")
        zone = room_zone(machine.zones)
        return float(schedule.conditions([0.0]).ambient_C[zone][0] if value is None else value)
    cond = schedule.conditions([0.0])
    # The machine stands idle before the test unless the scenario names a speed.
    rpm = np.array([init.get("spindle_rpm") or 0.0])
    idle = {a: np.zeros(1) for a in "xyz"}
    ambient = cond.ambient_C if init.get("ambient_C") is None else \
        {z: np.array([init["ambient_C"]]) for z in machine.zones}
    u = machine.input_matrix(rpm, idle, ambient, cond.gradient_K_per_m)[0]
    return fea.ThermalSolver(machine.thermal).steady_state(u)


def simulate(scenario, machine=None, mesh_size_m=None, fields=False, progress=None, modify=None,
             noise=True, seed=None):
    """Run ``scenario`` (name, path or :class:`Scenario`) and return a :class:`SimulationResult`.

    Parameters
    ----------
    machine : a built :class:`Machine` (default: build the scenario's machine)
    mesh_size_m : mesh size when the machine is built here
    fields : keep full temperature fields at the scenario's ``fields_at_h`` and
        ``camera_images_at_h`` times (``True``), or at an explicit list of times in s
    progress : optional callable ``progress(done, total)``
    modify : optional input hook, see :class:`ScenarioInputs`
    noise : apply the scenario's sensor-noise models
    seed : overrides the scenario's seed
    """
    scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    machine = machine or build_machine(scenario.machine, mesh_size_m)
    scenario.check_machine(machine.definition)
    start = time.perf_counter()
    schedule = ScenarioInputs(machine, scenario, modify)
    times = scenario.times()
    if fields is True:
        field_times = sorted(set(scenario.field_times_s) | set(scenario.camera_image_times_s))
    else:
        field_times = list(fields) if fields else list(scenario.camera_image_times_s)
    energy, r_u = energy_rows(machine)
    fe = machine.outputs
    extended = fea.OutputOperator(fe.names + ["__stored_energy", "__boundary_loss"], fe.units + ["J", "W"],
                                  sp.vstack([fe.matrix, energy]).tocsr(), np.r_[fe.offset, 0.0, 0.0])
    T0 = initial_temperature(machine, scenario, schedule)
    solver = fea.ThermalSolver(machine.thermal, theta=scenario.theta)
    run = solver.run(T0, times, schedule, extended, field_times_s=field_times,
                     max_step_s=scenario.time_step_s, progress=progress)
    cond = schedule.conditions(times)
    fe_values = run.outputs[:, : fe.n_outputs]
    stored, loss = run.outputs[:, -2], run.outputs[:, -1]
    sensors = machine.channel_values(fe_values, cond.inputs)

    balance = None
    if scenario.time_step_s == scenario.sample_interval_s:
        power = cond.inputs @ r_u - loss
        dt = np.diff(times)
        th = scenario.theta
        expected = dt * (th * power[1:] + (1 - th) * power[:-1])
        change = np.diff(stored)
        scale = max(np.abs(change).max(), np.abs(expected).max(), 1e-300)
        balance = float(np.abs(change - expected).max() / scale)

    channels, columns = machine_condition_channels(machine, cond)
    kinds = [c.kind for c in machine.channels]
    keep = [j for j, c in enumerate(machine.channels) if c.kind != "camera" or scenario.record_camera]
    if noise:
        sensors = apply_noise(sensors, kinds, scenario.noise, scenario.seed if seed is None else seed)
    for j in keep:
        c = machine.channels[j]
        channels.append(ChannelInfo(c.name, c.unit, c.kind, c.label, c.position))
        columns.append(sensors[:, j])
    metadata = {
        "kind": "synthetic",
        "machine": machine.name,
        "scenario": scenario.name,
        "scenario_file": scenario.source,
        "seed": scenario.seed if seed is None else seed,
        "noise": scenario.noise if noise else "none",
        "effects": [],
        "mesh": {"nodes": machine.mesh.n_nodes, "tetrahedra": machine.mesh.n_tets, "file": str(machine.mesh_path)},
        "time_step_s": scenario.time_step_s,
        "scheme": "backward Euler" if scenario.theta == 1.0 else "Crank-Nicolson",
        "energy_balance_relative_error": balance,
        "project_version": project_version(),
    }
    dataset = Dataset(times, np.column_stack(columns), channels, metadata)
    return SimulationResult(dataset, machine, scenario, run.fields, time.perf_counter() - start, balance)


def condition_channels(cond, zones, sources, input_names, inputs):
    """Dataset channels and columns of the operating conditions.

    ``cond`` has ``spindle_rpm``, ``feed_mm_min``, ``ambient_C`` and
    ``gradient_K_per_m``; ``sources`` lists ``(name, label)`` of the heat
    sources whose powers are read from ``inputs`` (n, len(input_names)).
    """
    channels = [ChannelInfo("spindle", "rpm", "spindle_speed", "spindle speed")]
    columns = [cond.spindle_rpm]
    for axis in "xyz":
        channels.append(ChannelInfo(f"feed_{axis}", "mm_min", "feed", f"{axis.upper()} axis feed"))
        columns.append(cond.feed_mm_min[axis])
    for zone in zones:
        channels.append(ChannelInfo(f"ambient_{zone}", "degC", "ambient", f"ambient of zone {zone} (true)"))
        columns.append(cond.ambient_C[zone])
    channels.append(ChannelInfo("ambient_gradient", "K_m", "ambient_gradient", "vertical ambient gradient"))
    columns.append(cond.gradient_K_per_m)
    for name, label in sources:
        channels.append(ChannelInfo(f"P_{name}", "W", "power", label))
        columns.append(inputs[:, list(input_names).index(f"power:{name}")])
    return channels, columns


def machine_condition_channels(machine, cond):
    """:func:`condition_channels` for a built machine."""
    return condition_channels(cond, machine.zones, [(s.name, s.label) for s in machine.definition.sources],
                              machine.thermal.input_names, cond.inputs)
