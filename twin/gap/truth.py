""""Measured" data with effects switched on, for the blind check: not the diagnosis's own model.

:func:`truth_dataset` runs a scenario on a machine (the benchmark uses a
finer mesh than the diagnosis) with the *full* finite-element system, the
scenario's scheme and time step (backward Euler, 20 s for
``gap_blind_24h``, against the diagnosis's reduced model with exact
zero-order hold at 60 s), the effects' *truth variants* (other hidden
constants than the library's), and the scenario's sensor noise (offsets and
quantisation).  The dataset holds what a test rig records: spindle speed,
feeds and the sensors — no true ambient and no source power.

:func:`physics_truth` makes truths by a route that shares nothing with the
library's effect code: it changes the machine's physics in a *copy of the
definition* (:class:`PhysicsChange`: the h of convection groups, the
conductance of joints, extra heat sources, the expansion coefficient of a
part, another mesh, another integrator and step), assembles it (or, when the
change enters the displacement operator, builds the machine anew: adjoint
elastic solves, minutes, then cached) and runs :func:`twin.core.simulate.simulate` (full
FE).  Records are cached under the user cache folder by a content hash of
everything that makes them (machine file, scenario file, change, seed,
project version).
"""
from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from meshes.cachefiles import user_cache_dir

from ..core.dataset import ChannelInfo, Dataset, project_version
from ..core.machine import Machine, build_machine, operator_reusable, reassemble
from ..core.machine_definition import HeatSource, MachineDefinition, load_machine
from ..core.noise import apply_noise
from ..core.scenario import Scenario, load_scenario
from ..core.simulate import simulate
from ..errors import TwinInputError
from ..infra.sweep import cached
from .drive import ScenarioDrive
from .effects import Effect
from .engine import FullBackend
from .model import GapModel
from .signals import uniform_grid
from .structure import build_structure


def truth_dataset(scenario: str | Path | Scenario, machine: Machine, active: Sequence[tuple[Effect, np.ndarray]] = (),
                  seed: int | None = None, noise: bool = True, step_s: float | None = None) -> Dataset:
    """A :class:`~twin.core.dataset.Dataset` of ``scenario`` on ``machine`` with ``active`` = [(effect, θ), …] on.

    ``step_s`` overrides the scenario's time step (it must divide the sampling interval).

    Parameters
    ----------
    scenario : str, Path or Scenario
        Scenario name, file or object: conditions, duration, sampling, scheme, initial state and noise.
    machine : Machine
        The built machine of the truth (the benchmark's is finer than the diagnosis's).
    active : sequence of (Effect, ndarray)
        Effects switched on and their parameters θ (in the effects' units); empty: the nominal machine.
    seed : int, optional
        Noise seed (default the scenario's).
    noise : bool, default True
        Add the scenario's sensor noise (offsets and quantisation).
    step_s : float, optional
        Time step of the full-FE run, s (default the scenario's).

    Returns
    -------
    Dataset
        At the scenario's sampling times: spindle speed (rpm), feeds (mm/min) and the machine's channels (°C,
        µm, µε); the metadata holds the effects switched on (the truth), mesh, step (s) and scheme.
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


#: Channel kinds a rig records (no true ambients, no source powers).
RECORDED_KINDS = ("spindle_speed", "feed", "temperature", "air", "displacement", "strain")
SCHEMES = {"backward_euler": 1.0, "crank_nicolson": 0.5}


@dataclass(frozen=True)
class PhysicsChange:
    """A change of the machine's physics for a truth run (all optional; the default is the nominal machine).

    ``convection`` {group: factor on h}; ``joints`` {"partA-partB": factor on the contact conductance};
    ``sources`` tuple of :class:`~twin.core.machine_definition.HeatSource` added; ``source_scale``
    {source: factor on its power}; ``source_exponent`` {source: change of its speed exponent};
    ``zone_lags_h`` {zone: lag of its air behind the room, h}; ``expansion`` {part: factor on its
    expansion coefficient α} (the part gets a material of its own); ``mesh_size_m`` another
    mesh (must be in the mesh cache to be quick); ``scheme`` ``backward_euler``/``crank_nicolson`` and
    ``time_step_s`` another integrator and step; ``output_step_s`` another output sampling (it must divide
    the duration).
    """

    convection: dict = field(default_factory=dict)
    joints: dict = field(default_factory=dict)
    sources: tuple = ()
    source_scale: dict = field(default_factory=dict)
    source_exponent: dict = field(default_factory=dict)
    zone_lags_h: dict = field(default_factory=dict)
    expansion: dict = field(default_factory=dict)
    mesh_size_m: float | None = None
    scheme: str | None = None
    time_step_s: float | None = None
    output_step_s: float | None = None

    def key(self) -> str:
        """The change as sorted JSON (part of the truth cache key).

        ``expansion`` enters only when set, so the truths cached before it existed keep their keys.

        Returns
        -------
        str
            JSON of every field, sorted keys (objects as ``str``).
        """
        fields = asdict(self)
        if not fields["expansion"]:
            del fields["expansion"]
        return json.dumps(fields, sort_keys=True, default=str)


def changed_definition(definition: MachineDefinition, change: PhysicsChange) -> MachineDefinition:
    """A copy of a machine definition with ``change`` (a :class:`PhysicsChange`) applied; unknown names raise.

    Parameters
    ----------
    definition : MachineDefinition
        The nominal definition (not modified).
    change : PhysicsChange
        Factors on convection h, joint conductances and parts' expansion coefficients, sources added, scaled or
        with another speed exponent, air lags of zones (h).

    Returns
    -------
    MachineDefinition
        The changed copy (zone lags in s).

    Raises
    ------
    TwinInputError
        When the change names a convection group, joint, source, lagged zone or part the definition does not have.
    """
    groups = {r.name for r in definition.convection}
    bad = sorted(set(change.convection) - groups)
    if bad:
        raise TwinInputError(f"PhysicsChange.convection: unknown group(s) {bad}; groups: {sorted(groups)}")
    pairs = {f"{a}-{b}": (a, b) for a, b, _ in definition.joints}
    bad = sorted(set(change.joints) - set(pairs))
    if bad:
        raise TwinInputError(f"PhysicsChange.joints: unknown joint(s) {bad}; joints: {sorted(pairs)}")
    names = {src.name for src in definition.sources}
    bad = sorted((set(change.source_scale) | set(change.source_exponent)) - names)
    if bad:
        raise TwinInputError(f"PhysicsChange: unknown source(s) {bad}; sources: {sorted(names)}")
    bad = sorted(set(change.zone_lags_h) - set(definition.zone_lags_s))
    if bad:
        raise TwinInputError(f"PhysicsChange.zone_lags_h: unknown lagged zone(s) {bad}; "
                             f"lagged zones: {sorted(definition.zone_lags_s)}")
    convection = [replace(r, coefficient=r.coefficient * change.convection.get(r.name, 1.0))
                  for r in definition.convection]
    joints = [(a, b, h * change.joints.get(f"{a}-{b}", 1.0)) for a, b, h in definition.joints]
    sources = [replace(src, coefficient_W=src.coefficient_W * change.source_scale.get(src.name, 1.0),
                       exponent=src.exponent + change.source_exponent.get(src.name, 0.0))
               for src in definition.sources]
    sources += [s if isinstance(s, HeatSource) else HeatSource(**s) for s in change.sources]
    lags = {**definition.zone_lags_s, **{z: h * 3600.0 for z, h in change.zone_lags_h.items()}}
    changed = replace(definition, convection=convection, joints=joints, sources=sources, zone_lags_s=lags)
    return _with_expansion(changed, change.expansion) if change.expansion else changed


def _with_expansion(definition, factors):
    """``definition`` whose parts named in ``factors`` each get a copy of their material with α × factor.

    The parts keep their shapes (the mesh is found in the cache); only the material name of each changed part
    differs, so parts that shared the material keep the nominal α.
    """
    parts = {p.name: p for p in definition.geometry.parts}
    bad = sorted(set(factors) - set(parts))
    if bad:
        raise TwinInputError(f"PhysicsChange.expansion: unknown part(s) {bad}; parts: {sorted(parts)}")
    materials, new_parts = dict(definition.materials), []
    for p in definition.geometry.parts:
        if p.name in factors:
            nominal = definition.materials[p.material]
            own = f"{p.material}_{p.name}_expansion_x{factors[p.name]:g}"
            materials[own] = replace(nominal, expansion=nominal.expansion * float(factors[p.name]))
            p = replace(p, material=own)
        new_parts.append(p)
    return replace(definition, materials=materials, geometry=replace(definition.geometry, parts=new_parts))


def changed_scenario(scenario: str | Path | Scenario, change: PhysicsChange) -> Scenario:
    """The scenario with the change's integrator, step and output sampling.

    Parameters
    ----------
    scenario : str, Path or Scenario
        Scenario name, file or object.
    change : PhysicsChange
        Its ``scheme``, ``time_step_s`` (s) and ``output_step_s`` (s) are used, when set.

    Returns
    -------
    Scenario
        A changed copy, or the scenario itself when the change sets none of them.
    """
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    updates = {}
    if change.scheme is not None:
        if change.scheme not in SCHEMES:
            raise TwinInputError(f"PhysicsChange.scheme: {change.scheme!r}; schemes: {list(SCHEMES)}")
        updates["theta"] = SCHEMES[change.scheme]
    if change.time_step_s is not None:
        updates["time_step_s"] = float(change.time_step_s)
    if change.output_step_s is not None:
        updates["sample_interval_s"] = float(change.output_step_s)
    return replace(sc, **updates) if updates else sc


def _content_key(scenario, change, machine, seed, noise):
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    parts = [change.key(), machine, str(seed), str(noise), project_version()]
    for path in (sc.source, _machine_file(machine)):
        p = Path(path) if path else None
        parts.append(p.read_text() if p is not None and p.exists() else str(path))
    return hashlib.sha256("\n".join(parts).encode("utf-8")).hexdigest()[:20]


def _machine_file(machine):
    return load_machine(machine).source


def physics_truth(scenario: str | Path | Scenario, change: PhysicsChange = PhysicsChange(), machine: str = "vmc_ram",
                  seed: int | None = None, noise: bool = True, cache: bool = True) -> Dataset:
    """A "measured" record (rig channels only) of ``scenario`` on a machine whose physics ``change`` alters.

    The full FE of :func:`twin.core.simulate.simulate` on the changed definition copy (reassembled on the
    nominal or the change's mesh).  With ``cache`` the record is read from / written to the user cache
    folder under a content hash (see the module docstring).

    Parameters
    ----------
    scenario : str, Path or Scenario
        Scenario name, file or object.
    change : PhysicsChange, default the nominal machine
        What differs from the nominal machine and scenario.
    machine : str, default "vmc_ram"
        Machine name or TOML path.
    seed : int, optional
        Noise seed (default the scenario's).
    noise : bool, default True
        Add the scenario's sensor noise.
    cache : bool, default True
        Read from and write to the user cache folder.

    Returns
    -------
    Dataset
        The channels of :data:`RECORDED_KINDS` (rpm, mm/min, °C, µm, µε) at the (changed) output times; the
        metadata holds the change and the run time (s).
    """
    path = user_cache_dir() / "gap-truth" / f"truth-{_content_key(scenario, change, machine, seed, noise)}.csv"
    if cache and path.exists():
        try:
            return Dataset.read(path)
        except TwinInputError:
            pass                                   # damaged entry: make it again
    base = cached(("machine", machine, change.mesh_size_m), lambda: build_machine(machine, change.mesh_size_m))
    definition = changed_definition(base.definition, change)
    if definition == base.definition:
        m = base
    elif operator_reusable(base, definition):
        m = reassemble(base, definition)
    else:                           # e.g. a part's α: the displacement operator's adjoint solves are made anew
        m = build_machine(machine, change.mesh_size_m, definition=definition)
    sc = changed_scenario(scenario, change)
    t0 = time.perf_counter()
    data = simulate(sc, machine=m, noise=noise, seed=seed).dataset
    out = data.select([c.name for c in data.channels if c.kind in RECORDED_KINDS])
    out.metadata.update({"kind": "synthetic truth (physics change, full FE)", "change": asdict(change),
                         "truth_seconds": time.perf_counter() - t0})
    if cache:
        path.parent.mkdir(parents=True, exist_ok=True)
        out.write(path)
    return out
