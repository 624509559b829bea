"""Records of the placement study: scenarios and elementary step responses run through the twin, cached on disk.

Every scenario (training, validation and test) is run through the twin with an
output operator of the candidates and the TCP drift only — no full field is
stored.  The runs are independent tasks of :func:`twin.infra.sweep.run_tasks`
(a local Dask cluster by default); each worker rebuilds the machine from the
on-disk caches and keeps it.  Records are cached on disk (noise-free) keyed by
machine, scenario and candidates.  Sensor noise (DS18S20 thermometers, S65
camera, NCDT probes) is drawn afterwards (:func:`add_noise`), seeded by the
scenario's name (:func:`scenario_seed`).  The step
responses of ``greedy-physics`` (:class:`ResponseTask`) are further tasks of
the same sweep, cached alike.
"""
from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

import fea
from meshes.cachefiles import checked, user_cache_dir, write_checked

from ..core.machine import Machine
from ..core.machine_definition import load_machine
from ..core.noise import apply_noise
from ..core.scenario import Scenario
from ..core.simulate import ScenarioInputs, initial_temperature
from ..core.variants import MachineSpec, as_scenario
from ..errors import TwinInputError
from ..infra.sweep import run_tasks
from .candidates import CandidateSpec

RECORD_CACHE_VERSION = 1
#: Elementary step responses of ``greedy-physics``: each heat source at its reference power, each ambient
#: zone +2 K (a day/night half-swing), the vertical ambient gradient +1 K/m; from rest at 20 °C, 48 h.
RESPONSE_AMBIENT_STEP_K = 2.0
RESPONSE_GRADIENT_STEP_K_PER_M = 1.0
RESPONSE_HORIZON_S = 48 * 3600.0
RESPONSE_INTERVAL_S = 900.0
NOISE = {"surface": "temperature", "camera": "camera", "installed": "temperature"}


@dataclass
class Record:
    """One scenario through the twin: candidate temperatures (°C) and drift (µm) at the record times.

    Attributes
    ----------
    scenario : str
        Scenario name (``step:<input>`` for a step response).
    time_s : ndarray, shape (n,)
        Record times, s.
    temperatures : ndarray, shape (n, k)
        Candidate temperatures, °C.
    drift : dict of str to ndarray
        Axis → TCP drift, µm, shape (n,).
    seconds : float
        Wall time of the run, s.
    from_cache : bool
        True if read from the record cache.
    """

    scenario: str
    time_s: np.ndarray
    temperatures: np.ndarray
    drift: dict
    seconds: float = 0.0
    from_cache: bool = False


def record_interval(scenario: Scenario, record_interval_s: float | None = None) -> float:
    """The interval a scenario is recorded at, s: ``record_interval_s``, or the scenario's own sampling interval
    if that is coarser (or ``record_interval_s`` is None).

    Parameters
    ----------
    scenario : Scenario
        The scenario.
    record_interval_s : float, optional
        Recording interval asked for, s.

    Returns
    -------
    float
        The spacing of :func:`record_times`, s.
    """
    if record_interval_s is None or record_interval_s <= scenario.sample_interval_s:
        return float(scenario.sample_interval_s)
    return float(record_interval_s)


def record_times(scenario: Scenario, record_interval_s: float | None = None) -> np.ndarray:
    """Record times, s: every :func:`record_interval` (the scenario's samples if they are not finer).

    Parameters
    ----------
    scenario : Scenario
        The scenario.
    record_interval_s : float, optional
        Recording interval, s; None (or finer than the scenario's sampling) keeps the scenario's samples.

    Returns
    -------
    ndarray
        Times from 0 to the scenario's end, s.
    """
    step = record_interval(scenario, record_interval_s)
    if step == scenario.sample_interval_s:
        return scenario.times()
    n = round(scenario.duration_s / step)
    grid = np.arange(n + 1) * step
    return grid[grid <= scenario.duration_s + 1e-9]


@dataclass(frozen=True)
class RecordTask:
    """A picklable sweep task: run one scenario, recording candidates and drift only."""

    machine: MachineSpec
    candidates: CandidateSpec
    scenario: object                 # name, path or Scenario
    axes: tuple = ("X", "Y", "Z")
    record_interval_s: float | None = 60.0

    def __call__(self):
        start = time.perf_counter()
        machine = self.machine.build()
        cands = self.candidates.build(machine)
        sc = as_scenario(self.scenario)
        sc.check_machine(machine.definition)
        schedule = ScenarioInputs(machine, sc)
        T0 = initial_temperature(machine, sc, schedule)
        times = record_times(sc, self.record_interval_s)
        run = fea.ThermalSolver(machine.thermal, theta=sc.theta).run(
            T0, times, schedule, _record_operator(machine, cands, self.axes), max_step_s=sc.time_step_s)
        return _run_record(sc.name, times, run, len(cands), self.axes, start)


def _record_operator(machine, cands, axes):
    """Output operator of a record: the candidates (°C) followed by the drift ``axes`` (m)."""
    drift = machine.outputs.subset(list(axes))
    return fea.OutputOperator(list(cands.names) + list(axes), ["°C"] * len(cands) + ["m"] * len(axes),
                              sp.vstack([cands.rows, drift.matrix]).tocsr(),
                              np.r_[np.zeros(len(cands)), drift.offset])


def _run_record(name, times, run, k, axes, start):
    """A :class:`Record` from a run through :func:`_record_operator` (``k`` candidates; drift in µm)."""
    return Record(name, times, run.outputs[:, :k].copy(),
                  {a: run.outputs[:, k + j] * 1e6 for j, a in enumerate(axes)}, time.perf_counter() - start)


def elementary_inputs(machine: Machine) -> list[tuple[str, int, float]]:
    """``(input name, index, step)`` of every thermal input of ``machine``: source powers at their reference
    power (W), ambient zones +:data:`RESPONSE_AMBIENT_STEP_K`, the gradient +:data:`RESPONSE_GRADIENT_STEP_K_PER_M`.

    Parameters
    ----------
    machine : Machine
        A built machine.

    Returns
    -------
    list of (str, int, float)
        Input name, its column in ``machine.thermal.input_names``, and the step (W, K or K/m).
    """
    names = machine.thermal.input_names
    power = {f"power:{s.name}": float(s.coefficient_W) for s in machine.definition.sources}
    out = []
    for j, name in enumerate(names):
        if name in power:
            step = power[name]
        elif name.startswith("ambient:"):
            step = RESPONSE_AMBIENT_STEP_K
        elif name == "ambient_gradient":
            step = RESPONSE_GRADIENT_STEP_K_PER_M
        else:                                       # pragma: no cover - an input kind this study does not know
            continue
        out.append((name, j, step))
    return out


class _StepSchedule:
    """Inputs at rest (every ambient zone at ``base_C``, no gradient, no power) plus a step of one input at t > 0."""

    def __init__(self, names, index, step, base_C=20.0):
        self.base = np.array([base_C if n.startswith("ambient:") else 0.0 for n in names])
        self.index, self.step = index, step

    def sample(self, times_s):
        t = np.atleast_1d(np.asarray(times_s, float))
        U = np.tile(self.base, (len(t), 1))
        U[t > 0, self.index] += self.step
        return U


@dataclass(frozen=True)
class ResponseTask:
    """A picklable sweep task: the twin's response to a step of one thermal input, from rest at 20 °C.

    Records the candidates and the drift every ``interval_s`` for ``horizon_s`` (the
    machine's slowest responses take about a day).  The step sizes are those of
    :func:`elementary_inputs`.  The result is a :class:`Record` named ``step:<input>``.
    """

    machine: MachineSpec
    candidates: CandidateSpec
    input_name: str
    axes: tuple = ("X", "Y", "Z")
    horizon_s: float = RESPONSE_HORIZON_S
    interval_s: float = RESPONSE_INTERVAL_S
    max_step_s: float = 300.0

    @property
    def scenario(self) -> str:
        """The record's name, ``step:<input>``."""
        return f"step:{self.input_name}"

    def __call__(self):
        start = time.perf_counter()
        machine = self.machine.build()
        cands = self.candidates.build(machine)
        steps = {name: (j, step) for name, j, step in elementary_inputs(machine)}
        if self.input_name not in steps:
            raise TwinInputError(f"no thermal input {self.input_name!r}; inputs: {sorted(steps)}")
        j, step = steps[self.input_name]
        times = np.arange(0.0, self.horizon_s + 1e-9, self.interval_s)
        schedule = _StepSchedule(machine.thermal.input_names, j, step)
        run = fea.ThermalSolver(machine.thermal).run(20.0, times, schedule, _record_operator(machine, cands, self.axes),
                                                     max_step_s=self.max_step_s)
        return _run_record(self.scenario, times, run, len(cands), self.axes, start)


def _file_digest(path):
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]
    except OSError:
        return "none"


def record_cache_key(task: RecordTask | ResponseTask) -> str:
    """The record cache's key of a task: machine file, scenario file (or step input), candidates, axes.

    Parameters
    ----------
    task : RecordTask or ResponseTask

    Returns
    -------
    str
        20 hex digits of a SHA-256 of the payload.
    """
    definition = load_machine(task.machine.name)
    payload = {"v": RECORD_CACHE_VERSION, "machine": repr(task.machine), "machine_file": _file_digest(
        definition.source), "candidates": repr(task.candidates), "axes": task.axes}
    if isinstance(task, ResponseTask):
        payload.update(response=[task.input_name, task.horizon_s, task.interval_s, task.max_step_s,
                                 RESPONSE_AMBIENT_STEP_K, RESPONSE_GRADIENT_STEP_K_PER_M])
    else:
        sc = as_scenario(task.scenario)
        payload.update(scenario=repr(sc) if not Path(str(sc.source)).exists() else [sc.name, _file_digest(sc.source)],
                       record=task.record_interval_s)
    return hashlib.sha256(json.dumps(payload, sort_keys=True, default=str).encode()).hexdigest()[:20]


def _cache_dir():
    d = user_cache_dir() / "placement-records"
    d.mkdir(parents=True, exist_ok=True)
    return d


def _load_record(path):
    with np.load(path, allow_pickle=False) as data:
        axes = [str(a) for a in data["axes"]]
        return Record(str(data["scenario"]), data["time_s"], data["temperatures"],
                      {a: data[f"drift_{a}"] for a in axes}, float(data["seconds"]), True)


def _save_record(path, rec):
    write_checked(path, lambda tmp: np.savez(
        tmp, scenario=rec.scenario, time_s=rec.time_s, temperatures=rec.temperatures, axes=np.array(list(rec.drift)),
        seconds=rec.seconds, **{f"drift_{a}": v for a, v in rec.drift.items()}))


def run_records(tasks: list, scheduler: object = "local", use_cache: bool = True,
                progress: Callable[[int, int], None] | None = None) -> list[Record]:
    """Records of :class:`RecordTask` s and :class:`ResponseTask` s, from the disk cache where possible, the rest
    through the sweep (``scheduler``: see :func:`twin.infra.sweep.run_tasks`).

    Parameters
    ----------
    tasks : list of RecordTask or ResponseTask
        The runs.
    scheduler : str or distributed.Client, default "local"
        See :func:`twin.infra.sweep.run_tasks`.
    use_cache : bool, default True
        Read and write the record cache in the user cache; False runs every task and stores nothing.
    progress : callable, optional
        ``progress(done, total)`` of the runs not cached.

    Returns
    -------
    list of Record
        Noise-free, in the order of ``tasks``.
    """
    keys = [record_cache_key(t) for t in tasks] if use_cache else [None] * len(tasks)
    out = [None] * len(tasks)
    todo = []
    for i, key in enumerate(keys):
        path = _cache_dir() / f"{key}.npz" if key else None
        if path is not None and path.exists() and checked(path) is not None:    # a corrupt record is redone
            out[i] = _load_record(path)
            continue
        todo.append(i)
    results = run_tasks([tasks[i] for i in todo], scheduler=scheduler, progress=progress)
    for i, rec in zip(todo, results):
        out[i] = rec
        if keys[i]:
            _save_record(_cache_dir() / f"{keys[i]}.npz", rec)
    return out


def scenario_seed(name: str, base: int = 0) -> int:
    """A noise seed from a scenario's name (a stable hash, the same in every run and process; not ``hash()``).

    The same scenario gets the same noise whatever its role or position in a study.

    Parameters
    ----------
    name : str
        The scenario's name.
    base : int, default 0
        Mixed into the hash (another noise draw).

    Returns
    -------
    int
        A seed in 0 .. 2³¹ − 1.
    """
    digest = hashlib.sha256(f"{int(base)}:{name}".encode()).digest()
    return int.from_bytes(digest[:4], "little") & 0x7FFFFFFF


def add_noise(record: Record, kinds: list[str], seed: int) -> Record:
    """Measured-like copy of a record: DS18S20 thermometers, S65 camera spots, NCDT drift probes.

    ``kinds`` are the candidates' kinds (``surface``, ``camera``, ``installed``); the drift noise is drawn
    from ``seed + 7919``, the temperatures' from ``seed``.

    Parameters
    ----------
    record : Record
        A noise-free record.
    kinds : list of str
        One kind per candidate.
    seed : int
        Noise seed (see :func:`scenario_seed`).

    Returns
    -------
    Record
        A new record (°C, µm); ``record`` is unchanged.
    """
    temp_kinds = [NOISE[k] for k in kinds]
    settings = {"temperature": "DS18S20", "camera": "S65", "displacement": "NCDT"}
    temps = apply_noise(record.temperatures, temp_kinds, settings, seed)
    axes = list(record.drift)
    drift = apply_noise(np.column_stack([record.drift[a] for a in axes]), ["displacement"] * len(axes), settings,
                        seed + 7919)
    return Record(record.scenario, record.time_s, temps, {a: drift[:, j] for j, a in enumerate(axes)},
                  record.seconds, record.from_cache)

