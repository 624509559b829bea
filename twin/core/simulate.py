"""Running a scenario on a machine twin: the transient FE run sampled by the virtual sensors.

One thermal solve per time step and one output-operator product per sample,
for the recorded outputs only; no elastic solve and no stored field unless
fields are asked for.  The result is a :class:`~twin.core.dataset.Dataset` in edge
units (°C, µm, µε) with the operating conditions (spindle speed, feeds, zone
ambients, source powers) alongside the sensors, an energy balance of the run
checked against the energy the scenario asks for, and (on request) a
time-step error estimate.
"""
from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import fea
from fea.inputs import interval_means
from fea.transient import step_grid

from .dataset import ChannelInfo, Dataset, project_version
from .machine import Channel, Machine, build_machine, power_input
from .machine_definition import MachineDefinition, room_zone
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


#: Largest energy-balance error (relative to the energy throughput) a run passes with.
ENERGY_TOLERANCE = 1e-6


class ScenarioInputs:
    """The input schedule of a scenario on a machine: ``sample(times)`` and ``means(step_times)`` → (n, n_inputs).

    ``means`` integrates the inputs over each step, split at the scenario's
    breakpoints, so a segment that ends inside a step injects its energy for
    the part of the step it runs.  ``modify`` is an optional hook
    ``modify(conditions) -> inputs`` used to perturb the physics; it must act
    pointwise in time (it is evaluated at the quadrature points).

    Parameters
    ----------
    machine : Machine
        The built machine.
    scenario : Scenario
        The scenario.
    modify : callable, optional
        ``modify(conditions) -> inputs``.
    """

    def __init__(self, machine: Machine, scenario: Scenario, modify: Callable | None = None) -> None:
        self.machine, self.scenario, self.modify = machine, scenario, modify
        self.breakpoints_s = scenario.breakpoints_s(machine.definition.zone_lags_s)

    def conditions(self, times_s: np.ndarray) -> Conditions:
        """The operating conditions and inputs at some times.

        Parameters
        ----------
        times_s : ndarray
            Times, s.

        Returns
        -------
        Conditions
            Speeds (rpm), feeds (mm/min), zone ambients (°C), gradient (K/m) and the inputs (after ``modify``).
        """
        t = np.atleast_1d(np.asarray(times_s, float))
        rpm, feeds = self.scenario.operating(t)
        ambient = self.scenario.zone_ambient(t, self.machine.zones, self.machine.definition.zone_lags_s)
        gradient = np.full(t.shape, self.scenario.ambient.gradient_K_per_m)
        U = self.machine.input_matrix(rpm, feeds, ambient, gradient)
        cond = Conditions(t, rpm, feeds, ambient, gradient, U)
        if self.modify is not None:
            cond.inputs = self.modify(cond)
        return cond

    def sample(self, times_s: np.ndarray) -> np.ndarray:
        """The thermal inputs at some times.

        Parameters
        ----------
        times_s : ndarray, shape (n,)
            Times, s.

        Returns
        -------
        ndarray, shape (n, n_inputs)
            Inputs (°C, K/m, W).
        """
        return self.conditions(times_s).inputs

    def means(self, step_times_s: np.ndarray) -> np.ndarray:
        """Exact mean inputs over each step (see :func:`fea.inputs.interval_means`).

        Parameters
        ----------
        step_times_s : ndarray, shape (k + 1,)
            Step ends, s.

        Returns
        -------
        ndarray, shape (k, n_inputs)
            Mean inputs (°C, K/m, W) over each step.
        """
        return interval_means(self.sample, step_times_s, self.breakpoints_s)


@dataclass
class SimulationResult:
    """What :func:`simulate` returns: the dataset, the machine and scenario, kept fields (°C by time in s),
    the wall time (s) and the energy-balance error (relative to the energy throughput)."""

    dataset: Dataset
    machine: Machine
    scenario: Scenario
    fields: dict = field(default_factory=dict)
    wall_seconds: float = 0.0
    energy_balance_relative_error: float | None = None


def requested_source_energy_J(scenario: Scenario, definition: MachineDefinition) -> dict[str, float]:
    """The energy each heat source must inject over a scenario.

    Segment by segment: the source's power model at the segment's speed and
    feeds times the segment's length, plus the idle machine after the last
    segment.  It uses no time grid, so it is an independent check on what
    the solver injected.

    Parameters
    ----------
    scenario : Scenario
        Its segments (speeds, feeds, lengths).
    definition : MachineDefinition
        Its heat sources' power models.

    Returns
    -------
    dict of str to float
        Source name → energy, J.
    """
    segments = scenario.segments
    idle_s = scenario.duration_s - (segments[-1].end_s if segments else 0.0)
    length = np.array([sg.end_s - sg.start_s for sg in segments] + [idle_s])
    rpm = np.array([sg.spindle_rpm for sg in segments] + [0.0])
    feeds = {a: np.array([sg.feed_mm_min[i] for sg in segments] + [0.0]) for i, a in enumerate("xyz")}
    return {src.name: float(np.sum(src.power_W(rpm, feeds) * length)) for src in definition.sources}


def energy_balance(ledger: fea.energy.EnergyLedger, machine: Machine, scenario: Scenario,
                   modified: bool = False) -> dict:
    """The run's energy balance; ``ok`` is False when heat was lost or created.

    ``stored_vs_loads``: max |ΔE_stored − Σ energy through the loads| over the
    run; ``sources_vs_scenario``: max over the heat sources of |energy
    injected − energy the scenario asks for| (None when ``modified``: the
    inputs were changed on purpose); both relative to ``throughput_J``, the
    gross energy through all loads (at least 10 mK of the whole machine, :data:`fea.energy.ENERGY_FLOOR_K`).

    Parameters
    ----------
    ledger : fea.energy.EnergyLedger
        The run's energy ledger.
    machine : Machine
        The machine run.
    scenario : Scenario
        The scenario run.
    modified : bool
        The inputs were changed on purpose (no check against the scenario).

    Returns
    -------
    dict
        ``relative_error``, ``stored_vs_loads``, ``sources_vs_scenario``,
        ``throughput_J``, ``loads_gross_J`` (the loads' own throughput, J), ``sources_injected_J``, ``sources_requested_J``, ``tolerance``, ``ok``.
    """
    scale = ledger.scale_J()
    injected = {src.name: float(ledger.energy_of(power_input(src.name))[-1]) for src in machine.definition.sources}
    requested = None if modified else requested_source_energy_J(scenario, machine.definition)
    stored_error = ledger.relative_error()
    source_error = None if requested is None else \
        max([abs(injected[n] - requested[n]) / scale for n in injected], default=0.0)
    worst = max(stored_error, source_error or 0.0)
    return {"relative_error": worst, "stored_vs_loads": stored_error, "sources_vs_scenario": source_error,
            "throughput_J": scale, "loads_gross_J": float(ledger.gross_J[-1]), "sources_injected_J": sum(injected.values()),
            "sources_requested_J": None if requested is None else sum(requested.values()),
            "tolerance": ENERGY_TOLERANCE, "ok": bool(worst <= ENERGY_TOLERANCE)}


def recorded_channels(machine: Machine, scenario: Scenario) -> list[int]:
    """The machine's channels a run records (camera spots only when the scenario asks).

    Parameters
    ----------
    machine : Machine
        The machine.
    scenario : Scenario
        The scenario.

    Returns
    -------
    list of int
        Indices into ``machine.channels``.
    """
    return [j for j, c in enumerate(machine.channels) if c.kind != "camera" or scenario.record_camera]


def step_error_summary(estimate: fea.transient.StepErrorEstimate, channels: list[Channel]) -> dict:
    """The largest estimated time-step error per channel kind.

    Parameters
    ----------
    estimate : fea.transient.StepErrorEstimate
        Of the recorded FE channels, in SI.
    channels : list of Channel
        Those channels.

    Returns
    -------
    dict
        ``method`` and ``temperature_K``, ``displacement_um``, ``strain_ue`` where present.
    """
    out = {"method": estimate.method}
    for kind, key in (("temperature", "temperature_K"), ("camera", "temperature_K"),
                      ("displacement", "displacement_um"), ("strain", "strain_ue")):
        cols = [j for j, c in enumerate(channels) if c.kind == kind]
        if cols:
            scale = np.array([channels[j].scale for j in cols])
            value = float(np.abs(estimate.error[:, cols] * scale).max())
            out[key] = max(out.get(key, 0.0), value)
    return out


def initial_temperature(machine: Machine, scenario: Scenario, schedule: ScenarioInputs) -> float | np.ndarray:
    """The start temperature of a run.

    Parameters
    ----------
    machine : Machine
        The machine.
    scenario : Scenario
        Its ``initial`` table: uniform, or steady state.
    schedule : ScenarioInputs
        The scenario's inputs (the conditions at t = 0).

    Returns
    -------
    float or ndarray
        A uniform temperature (°C; the room ambient unless given), or the
        steady state (°C on the thermal nodes) for the conditions at t = 0
        (or those the scenario names).
    """
    init = scenario.initial
    if init["kind"] == "uniform":
        value = init.get("temperature_C")
        zone = room_zone(machine.zones)
        return float(schedule.conditions([0.0]).ambient_C[zone][0] if value is None else value)
    return fea.ThermalSolver(machine.thermal).steady_state(_idle_conditions(machine, scenario, schedule).inputs[0])


def _idle_conditions(machine, scenario, schedule):
    """The conditions the machine stood in before t = 0 (:meth:`Scenario.idle_start`), as one row, inputs
    without ``modify``."""
    cond = schedule.conditions([0.0])
    rpm, idle, ambient = scenario.idle_start(cond.ambient_C)
    return Conditions(cond.times_s, rpm, idle, ambient, cond.gradient_K_per_m,
                      machine.input_matrix(rpm, idle, ambient, cond.gradient_K_per_m))


def before_start(machine: Machine, scenario: Scenario, schedule: ScenarioInputs) -> dict[str, float]:
    """The operating channels as they stood before t = 0: the spindle stopped (or a steady start's speed), no
    feed, and the heat those give.

    A record's first row holds the conditions at t = 0, where a duty cycle
    usually starts the spindle; the machine's state there is the one it
    reached before (:func:`initial_temperature`). A model that takes a
    record's first row as its rest state reads these instead
    (:func:`twin.compensation.records.with_rest_start`).

    Parameters
    ----------
    machine : Machine
        The machine.
    scenario : Scenario
        The scenario (its ``[initial]`` table).
    schedule : ScenarioInputs
        Its inputs (``modify`` applies to the powers, as in the record).

    Returns
    -------
    dict of str to float
        Channel → value (rpm, mm/min, W) for the spindle, feed and power channels.
    """
    idle = _idle_conditions(machine, scenario, schedule)
    if schedule.modify is not None:
        idle.inputs = schedule.modify(idle)
    infos, columns = machine_condition_channels(machine, idle)
    return {c.name: float(v[0]) for c, v in zip(infos, columns) if c.kind in ("spindle_speed", "feed", "power")}


def simulate(scenario: str | Path | Scenario, machine: Machine | None = None, mesh_size_m: float | None = None,
             fields: bool | Sequence[float] = False, progress: Callable[[int, int], None] | None = None,
             modify: Callable | None = None, noise: bool = True, seed: int | None = None,
             step_error: bool = False) -> SimulationResult:
    """Run a scenario on a machine: the FE transient, then the virtual sensors.

    Parameters
    ----------
    scenario : str, Path or Scenario
        Scenario name, TOML path or a loaded :class:`Scenario`.
    machine : Machine, optional
        A built :class:`Machine` (default: build the scenario's machine).
    mesh_size_m : float, optional
        Target tetrahedron edge length (m) when the machine is built here.
    fields : bool or sequence of float
        Keep full temperature fields at the scenario's ``fields_at_h`` and
        ``camera_images_at_h`` times (``True``), or at these times in s.
    progress : callable, optional
        ``progress(done, total)``, called as the integration advances.
    modify : callable, optional
        Input hook, see :class:`ScenarioInputs`.
    noise : bool
        Apply the scenario's sensor-noise models.
    seed : int, optional
        Overrides the scenario's seed.
    step_error : bool
        Also estimate the time-step error of the recorded channels by step
        doubling (about half a run more); the largest per kind goes into the
        metadata (``time_step_error``).

    Returns
    -------
    SimulationResult
        The dataset (°C, µm, µε, rpm, mm/min, W), the machine, the kept fields
        (°C) and the wall time (s).
    """
    scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    machine = machine or build_machine(scenario.machine, mesh_size_m, definition=scenario.machine_definition())
    scenario.check_machine(machine.definition)
    start = time.perf_counter()
    schedule = ScenarioInputs(machine, scenario, modify)
    times = scenario.times()
    field_times = _field_times(scenario, fields)
    fe = machine.outputs
    keep = recorded_channels(machine, scenario)
    keep_fe, keep_air = _split_by_source(keep, fe.n_outputs)
    operator = fe.subset([fe.names[j] for j in keep_fe])
    T0 = initial_temperature(machine, scenario, schedule)
    solver = fea.ThermalSolver(machine.thermal, theta=scenario.theta)
    run = solver.run(T0, times, schedule, operator, field_times_s=field_times,
                     max_step_s=scenario.time_step_s, progress=progress, energy=True)
    cond = schedule.conditions(times)
    channels = [machine.channels[j] for j in keep]
    scale = np.array([c.scale for c in channels])
    sensors = np.hstack([run.outputs, cond.inputs @ machine.feedthrough[keep_air].T]) * scale

    balance = energy_balance(run.energy, machine, scenario, modified=modify is not None)
    if not balance["ok"]:
        warnings.warn(f"scenario {scenario.name!r}: the energy balance fails ({balance['relative_error']:.1e} of "
                      f"the energy throughput, tolerance {ENERGY_TOLERANCE:.0e}): heat was lost or created",
                      RuntimeWarning, stacklevel=2)
    step_errors = None
    if step_error:
        estimate = solver.step_error(T0, times, schedule, operator, run, scenario.time_step_s)
        step_errors = step_error_summary(estimate, channels[:len(keep_fe)])

    columns_info, columns = machine_condition_channels(machine, cond)
    seed = scenario.seed if seed is None else seed
    if noise:
        sensors = apply_noise(sensors, [c.kind for c in channels], scenario.noise, seed)
    for j, c in enumerate(channels):
        columns_info.append(ChannelInfo(c.name, c.unit, c.kind, c.label, c.position))
        columns.append(sensors[:, j])
    metadata = _run_metadata(machine, scenario, seed, noise, balance, step_errors)
    metadata["before_start"] = before_start(machine, scenario, schedule)
    dataset = Dataset(times, np.column_stack(columns), columns_info, metadata)
    return SimulationResult(dataset, machine, scenario, run.fields, time.perf_counter() - start,
                            balance["relative_error"])


def _split_by_source(keep, n_fe):
    """Recorded channel indices → (rows of the FE output operator, rows of the air feedthrough)."""
    return [j for j in keep if j < n_fe], [j - n_fe for j in keep if j >= n_fe]


def _field_times(scenario, fields):
    """Times (s) at which :func:`simulate` keeps full temperature fields (see its ``fields``)."""
    if fields is True:
        return sorted(set(scenario.field_times_s) | set(scenario.camera_image_times_s))
    return list(fields) if fields else list(scenario.camera_image_times_s)


def _longest_step(scenario):
    """The longest time step (s) the solver takes: each sampling interval is split into equal steps of at most
    the scenario's ``time_step_s``, so the step taken can be shorter than the one asked for."""
    step_times, _ = step_grid(scenario.times(), scenario.time_step_s)
    return float(np.diff(step_times).max()) if len(step_times) > 1 else scenario.time_step_s


def _run_metadata(machine, scenario, seed, noise, balance, step_errors):
    """The metadata of a synthetic dataset: what was run, on which mesh, and the checks of the integration."""
    return {
        "kind": "synthetic",
        "machine": machine.name,
        "scenario": scenario.name,
        "scenario_file": scenario.source,
        "seed": seed,
        "noise": scenario.noise if noise else "none",
        "effects": [],
        "mesh": {"nodes": machine.mesh.n_nodes, "tetrahedra": machine.mesh.n_tets, "file": str(machine.mesh_path)},
        "time_step_s": _longest_step(scenario),
        "time_step_limit_s": scenario.time_step_s,
        "scheme": "backward Euler" if scenario.theta == 1.0 else "Crank-Nicolson",
        "energy_balance_relative_error": balance["relative_error"],
        "energy_balance": balance,
        "time_step_error": step_errors,
        "project_version": project_version(),
    }


def condition_channel_infos(zones: list[str], sources: list[tuple[str, str]]) -> list[ChannelInfo]:
    """The dataset channels of the operating conditions, in the order :func:`condition_channels` writes them.

    Parameters
    ----------
    zones : list of str
        Convection zones (one ambient channel each).
    sources : list of tuple of str
        ``(name, label)`` of the heat sources.

    Returns
    -------
    list of ChannelInfo
        Spindle (rpm), feeds (mm/min), ambients (°C), gradient (K/m), powers (W).
    """
    return ([ChannelInfo("spindle", "rpm", "spindle_speed", "spindle speed")]
            + [ChannelInfo(f"feed_{axis}", "mm_min", "feed", f"{axis.upper()} axis feed") for axis in "xyz"]
            + [ChannelInfo(f"ambient_{zone}", "degC", "ambient", f"ambient of zone {zone} (true)") for zone in zones]
            + [ChannelInfo("ambient_gradient", "K_m", "ambient_gradient", "vertical ambient gradient")]
            + [ChannelInfo(f"P_{name}", "W", "power", label) for name, label in sources])


def condition_channels(cond: Conditions, zones: list[str], sources: list[tuple[str, str]],
                       input_names: list[str], inputs: np.ndarray) -> tuple[list[ChannelInfo], list[np.ndarray]]:
    """Dataset channels and columns of the operating conditions.

    Parameters
    ----------
    cond : Conditions
        Has ``spindle_rpm``, ``feed_mm_min``, ``ambient_C`` and ``gradient_K_per_m``.
    zones : list of str
        Convection zones (one ambient column each).
    sources : list of tuple of str
        ``(name, label)`` of the heat sources.
    input_names : list of str
        The columns of ``inputs``.
    inputs : ndarray, shape (n, len(input_names))
        Where the source powers (W) are read.

    Returns
    -------
    channels : list of ChannelInfo
        As :func:`condition_channel_infos`.
    columns : list of ndarray
        Their values.
    """
    columns = ([cond.spindle_rpm] + [cond.feed_mm_min[axis] for axis in "xyz"]
               + [cond.ambient_C[zone] for zone in zones] + [cond.gradient_K_per_m]
               + [inputs[:, list(input_names).index(f"power:{name}")] for name, _ in sources])
    return condition_channel_infos(zones, sources), columns


def _machine_sources(machine: Machine) -> list[tuple[str, str]]:
    """``(name, label)`` of a built machine's heat sources."""
    return [(s.name, s.label) for s in machine.definition.sources]


def record_channel_names(machine: Machine, camera: bool = False) -> list[str]:
    """The channel names of a record :func:`simulate` makes on ``machine``: conditions, then sensors.

    Parameters
    ----------
    machine : Machine
        A built machine.
    camera : bool, default False
        With the camera spots (recorded when a scenario asks, :func:`recorded_channels`).

    Returns
    -------
    list of str
        E.g. ``spindle``, ``ambient_<zone>``, ``P_<source>``, ``T01``, ``Z``.
    """
    return ([c.name for c in condition_channel_infos(machine.zones, _machine_sources(machine))]
            + [c.name for c in machine.channels if c.kind != "camera" or camera])


def machine_condition_channels(machine: Machine,
                               cond: Conditions) -> tuple[list[ChannelInfo], list[np.ndarray]]:
    """:func:`condition_channels` for a built machine.

    Parameters
    ----------
    machine : Machine
        Gives the zones, heat sources and input names.
    cond : Conditions
        The conditions on a time grid.

    Returns
    -------
    channels : list of ChannelInfo
        As :func:`condition_channels`.
    columns : list of ndarray
        Their values.
    """
    return condition_channels(cond, machine.zones, _machine_sources(machine),
                              machine.thermal.input_names, cond.inputs)
