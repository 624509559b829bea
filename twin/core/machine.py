"""A machine's thermal twin: its mesh, thermal system, inputs and virtual-sensor outputs.

``build_machine("vmc_ram")`` meshes the definition (or reads the cached mesh),
assembles the thermal system once, and precomputes every sensor as a linear
output ``y = C T + D u + c``: surface thermometers and camera spots by
barycentric rows, tool-centre-point drift and strain lines by adjoint
influence rows, and air thermometers as a feedthrough of the ambient inputs.

The output operator is cached on disk (``outputs-<key>.npz`` in
``meshes/cache`` or the user cache, with a SHA-256 sidecar checked before it is
read; see :mod:`meshes.cachefiles`).  The key (:func:`operator_cache_key`)
holds exactly what the operator is computed from:

- the mesh content (points, tetrahedra, region ids and names);
- the joint *pairs*: they split the thermal nodes on the joint facets, which
  numbers the operator's columns (conductance values do not enter);
- each part's elastic properties (Young's modulus, Poisson ratio, expansion
  coefficient), the elastic degree, the supports and the stress-free
  reference temperature;
- the output specifications (names, kinds and positions of thermometers,
  camera spots, TCP probes and strain lines) and the point snap distance;
- :data:`OUTPUT_CACHE_VERSION`.

Not in the key: the machine's name, conductivities, densities, heat
capacities, convection, heat sources and joint conductances; none of them
enters the operator, so renaming a machine or changing its powers,
convection or joint conductances reuses it.  Building it takes minutes on
the full machine; progress goes to the ``thermal_twin`` logger.

Inputs u (one column of the thermal system each):
- ``ambient:<zone>``   ambient temperature of a convection zone, °C
- ``ambient_gradient`` vertical ambient gradient, K/m, about the reference height
- ``power:<source>``   heat-source power, W
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

import fea
from meshes.builder import build_mesh, duration_text
from meshes.cachefiles import find_cached, log, user_cache_dir, write_checked
from meshes.tomlspec import DefinitionError

from .machine_definition import MachineDefinition, load_machine

#: Bump when the way outputs are computed changes, to invalidate cached operators.
OUTPUT_CACHE_VERSION = 1
GRADIENT_INPUT = "ambient_gradient"


def ambient_input(zone: str) -> str:
    """The thermal-system input name of a zone's ambient temperature (°C).

    Parameters
    ----------
    zone : str
        Convection zone.

    Returns
    -------
    str
        ``ambient:<zone>``.
    """
    return f"ambient:{zone}"


def power_input(source: str) -> str:
    """The thermal-system input name of a heat source's power (W).

    Parameters
    ----------
    source : str
        Heat-source name.

    Returns
    -------
    str
        ``power:<source>``.
    """
    return f"power:{source}"


@dataclass(frozen=True)
class Channel:
    """A recorded quantity: name, kind, unit at the edges, scale from SI, position and description."""

    name: str
    kind: str            # temperature | air | camera | displacement | strain
    unit: str            # degC | um | ue
    scale: float         # multiply the SI value by this to get ``unit``
    label: str = ""
    position: tuple | None = None


@dataclass
class Machine:
    """A built twin: ``outputs`` (FE outputs, SI) then air sensors, described by ``channels``."""

    definition: MachineDefinition
    mesh: fea.TetMesh
    thermal: fea.ThermalSystem
    outputs: fea.OutputOperator
    feedthrough: np.ndarray          # (n_air, n_inputs): air sensors from the inputs
    channels: list
    mesh_seconds: float
    operator_seconds: float
    mesh_path: Path
    operator_path: Path
    mesh_size_m: float | None = None  # the target edge length the mesh was made with, m (None: not known)

    @property
    def name(self) -> str:
        """The machine's name."""
        return self.definition.name

    @property
    def zones(self) -> list[str]:
        """The convection zones, sorted; each has an ambient input."""
        return self.definition.zones

    def channel(self, name: str) -> Channel:
        """A recorded channel by name.

        Parameters
        ----------
        name : str
            Channel name (sensor, drift axis, strain line or camera spot).

        Returns
        -------
        Channel
            Its kind, unit, scale from SI and position (m).

        Raises
        ------
        DefinitionError
            Unknown name (the message lists the channels).
        """
        for c in self.channels:
            if c.name == name:
                return c
        raise DefinitionError(f"{self.definition.source}: unknown channel {name!r}; "
                              f"channels: {[c.name for c in self.channels if c.kind != 'camera']} "
                              f"and {sum(c.kind == 'camera' for c in self.channels)} camera spots")

    def input_matrix(self, spindle_rpm: np.ndarray, feed_mm_min: dict[str, np.ndarray],
                     ambient_C: dict[str, np.ndarray], gradient_K_per_m: float | np.ndarray = 0.0,
                     source_scale: dict[str, float] | None = None, source_exponent: dict[str, float] | None = None,
                     extra_power_W: dict[str, np.ndarray] | None = None) -> np.ndarray:
        """Input values of the thermal system from operating conditions on a time grid.

        Parameters
        ----------
        spindle_rpm : ndarray, shape (n,)
            Spindle speed, rpm.
        feed_mm_min : dict of str to ndarray
            Axis (``x``, ``y``, ``z``) → feed, mm/min.
        ambient_C : dict of str to ndarray
            Zone → ambient temperature, °C (every zone is required).
        gradient_K_per_m : float or ndarray
            Vertical ambient gradient, K/m.
        source_scale, source_exponent : dict of str to float, optional
            Per source name: factor on its power and replacement of its speed exponent.
        extra_power_W : dict of str to ndarray, optional
            Input name → power added to it, W.

        Returns
        -------
        ndarray, shape (n, n_inputs)
            In the order of ``thermal.input_names`` (°C, K/m, W).
        """
        names = self.thermal.input_names
        n = len(np.atleast_1d(spindle_rpm))
        U = np.zeros((n, len(names)))
        for zone in self.zones:
            if zone not in ambient_C:
                raise DefinitionError(f"no ambient given for zone {zone!r}; zones: {self.zones}")
            U[:, names.index(ambient_input(zone))] = ambient_C[zone]
        U[:, names.index(GRADIENT_INPUT)] = gradient_K_per_m
        for src in self.definition.sources:
            scale = (source_scale or {}).get(src.name, 1.0)
            exponent = (source_exponent or {}).get(src.name)
            U[:, names.index(power_input(src.name))] = src.power_W(spindle_rpm, feed_mm_min, scale, exponent)
        for name, values in (extra_power_W or {}).items():
            U[:, self.thermal.input_index(name)] += values
        return U

    def channel_values(self, fe_outputs: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        """Channel values in edge units from FE outputs and inputs.

        Parameters
        ----------
        fe_outputs : ndarray, shape (k, p_fe)
            FE outputs in SI (°C, m, strain).
        inputs : ndarray, shape (k, n_inputs)
            Thermal-system inputs (feed the air sensors).

        Returns
        -------
        ndarray, shape (k, p)
            Every channel in its unit (°C, µm, µε).
        """
        air = np.atleast_2d(inputs) @ self.feedthrough.T
        values = np.concatenate([np.atleast_2d(fe_outputs), air], axis=1)
        return values * np.array([c.scale for c in self.channels])


def _facet_groups(definition, mesh):
    """Partition the boundary into the convection rules' groups (first match wins)."""
    tet, local = mesh.boundary_facets()
    centroids, normals, area = mesh.facet_geometry(tet, local)
    part_of = np.array([mesh.region_names[r] for r in mesh.regions[tet]])
    shapes = {p.name: p.shape for p in definition.geometry.parts}
    claimed = np.zeros(len(tet), bool)
    groups = {}
    for rule in definition.convection:
        match = np.isin(part_of, rule.parts) & ~claimed
        if rule.facing is not None:
            d = np.asarray(rule.facing, float)
            match &= normals @ (d / np.linalg.norm(d)) >= np.cos(np.radians(30.0))
        in_cavity = np.zeros(len(tet), bool)
        for name in rule.parts:
            cavity = getattr(shapes[name], "cavity", None)
            if cavity is not None:
                b = np.asarray(cavity).reshape(3, 2)
                in_cavity |= (part_of == name) & np.all((centroids >= b[:, 0] - 1e-3) &
                                                        (centroids <= b[:, 1] + 1e-3), axis=1)
        match &= in_cavity if rule.inside else ~in_cavity
        if match.any():
            mesh.set_facet_group(rule.name, tet[match], local[match])
            groups[rule.name] = rule
            claimed |= match
    return groups, float(area[~claimed].sum())


def materials_by_region(definition: MachineDefinition, mesh: fea.TetMesh) -> dict[int, fea.Material]:
    """The material of each mesh region, from its part.

    Parameters
    ----------
    definition : MachineDefinition
        The machine.
    mesh : fea.TetMesh
        Its labelled mesh (region names are part names).

    Returns
    -------
    dict of int to fea.Material
        Region id → material.
    """
    return {rid: definition.part_material(name) for rid, name in mesh.region_names.items()}


def _thermal_system(definition, mesh, groups):
    materials = materials_by_region(definition, mesh)
    problem = fea.HeatProblem(mesh, materials)
    for name, rule in groups.items():
        problem.add_convection(name, rule.coefficient, ambient=ambient_input(rule.zone),
                               ambient_gradient=GRADIENT_INPUT,
                               reference_height=definition.ambient_reference_height_m)
    for src in definition.sources:
        selector = fea.Box(src.box[0::2], src.box[1::2]) if src.box is not None else None
        try:
            tets = mesh.select_tets(selector, region=src.part)
        except fea.FEAInputError:
            raise DefinitionError(f"{definition.source}: source {src.name!r}: its box {src.box} holds no "
                                  f"tetrahedron of part {src.part!r} at this mesh size") from None
        problem.add_volumetric_source(src.name, tets, power=power_input(src.name))
    for a, b, h_c in definition.joints:
        problem.add_contact(a, b, h_c)
    return problem.assemble(), materials


def _output_specs(definition):
    d = definition
    specs, channels = [], []
    for s in d.sensors:
        if s.kind == "temperature":
            specs.append(fea.PointTemperature(s.name, s.position))
            channels.append(Channel(s.name, "temperature", "degC", 1.0, s.label, s.position))
    if d.camera is not None:
        for i, p in enumerate(d.camera.spots()):
            name = f"cam{i:03d}"
            specs.append(fea.PointTemperature(name, tuple(p)))
            channels.append(Channel(name, "camera", "degC", 1.0, f"camera spot {i}", tuple(p)))
    tool, work = np.asarray(d.tool_point), np.asarray(d.workpiece_point)
    for axis in "xyz":
        name = axis.upper()
        specs.append(fea.RelativeDisplacement(name, tuple(tool), tuple(work), axis))
        channels.append(Channel(name, "displacement", "um", 1e6, f"TCP drift {name} (tool − table)", tuple(tool)))
    top = tuple(tool + np.asarray(d.tilt_probe_offset))
    specs.append(fea.RelativeDisplacement("Y_top", top, tuple(work), "y"))
    channels.append(Channel("Y_top", "displacement", "um", 1e6,
                            "Y drift of the upper test-bar probe (tilt = Y_top − Y)", top))
    for s in d.sensors:
        if s.kind == "strain":
            specs.append(fea.AxialStrain(s.name, s.start, s.end))
            channels.append(Channel(s.name, "strain", "ue", 1e6, s.label, s.start))
    return specs, channels


def operator_cache_key(definition: MachineDefinition, mesh: fea.TetMesh, specs: list) -> str:
    """The cache key of the output operator: a hash of what it is computed from (see the module docstring).

    Parameters
    ----------
    definition : MachineDefinition
        The machine (elastic properties, supports, joint pairs, snap distance).
    mesh : fea.TetMesh
        Its mesh (hashed by content).
    specs : list
        The output specifications (``fea.PointTemperature``, ``fea.RelativeDisplacement``, …).

    Returns
    -------
    str
        First 16 hex digits of a SHA-256.
    """
    payload = {**_operator_inputs(definition, mesh, specs), "mesh": mesh_content_digest(mesh)}
    return hashlib.sha256(json.dumps(payload, sort_keys=True, default=float).encode()).hexdigest()[:16]


def _operator_inputs(definition, mesh, specs):
    """What the output operator is computed from, but the mesh content (see the module docstring)."""
    d = definition
    elastic = [[name, *_elastic_properties(d.part_material(name))] for _, name in sorted(mesh.region_names.items())]
    return {
        "version": OUTPUT_CACHE_VERSION, "elastic": elastic,
        "degree": d.elastic_degree, "supports": d.support_points, "reference_temperature": d.reference_temperature_C,
        "joint_pairs": sorted({tuple(sorted((a, b))) for a, b, _ in d.joints}), "snap": d.snap_distance_m,
        "outputs": [[type(s).__name__, dataclasses.astuple(s)] for s in specs],
    }


def operator_reusable(machine: Machine, definition: MachineDefinition) -> bool:
    """Whether ``machine``'s output operator is also that of ``definition`` on the same mesh.

    True when nothing the operator is computed from changes (elastic properties such as a part's expansion
    coefficient, supports, reference temperature, joint pairs, sensors); convection, heat sources and joint
    conductances may.  Compares the inputs of :func:`operator_cache_key` without hashing the mesh.

    Parameters
    ----------
    machine : Machine
        The built machine.
    definition : MachineDefinition
        A changed definition of it.

    Returns
    -------
    bool
        True: :func:`reassemble` may reuse the operator; False: build the machine anew (:func:`build_machine`).
    """
    def inputs(d):
        return json.dumps(_operator_inputs(d, machine.mesh, _output_specs(d)[0]), sort_keys=True, default=float)

    return inputs(definition) == inputs(machine.definition)


def _elastic_properties(material):
    """E, ν, α as floats; ``None`` for a missing one (the elastic problem then says which)."""
    values = (getattr(material, a) for a in ("youngs_modulus", "poisson_ratio", "expansion"))
    return [None if v is None else float(v) for v in values]


def mesh_content_digest(mesh: fea.TetMesh) -> str:
    """Hash of the mesh itself (fTetWild is not reproducible, so the definition's hash is not enough).

    Parameters
    ----------
    mesh : fea.TetMesh
        Points, tetrahedra, regions and region names are hashed.

    Returns
    -------
    str
        SHA-256, 64 hex digits.
    """
    h = hashlib.sha256()
    for array in (mesh.points, mesh.tets, mesh.regions):
        h.update(np.ascontiguousarray(array).tobytes())
    h.update(json.dumps(sorted(mesh.region_names.items())).encode())
    return h.hexdigest()


#: Output-operator build time ≈ seconds per (elastic dof × adjoint solve), the assembly and AMG
#: set-up counted as ``OPERATOR_SETUP_SOLVES`` solves.  vmc_ram at 45 mm (P2, 257,097 dofs, 7
#: solves) took about 6 min on a quiet 2-core VM and 16 min with the cores shared (load 6).
OPERATOR_S_PER_DOF_SOLVE = 1.6e-4
OPERATOR_SETUP_SOLVES = 2


def _build_outputs(definition, mesh, thermal, materials):
    """The output operator (from the checked cache, or built and cached), the channels and the cache file."""
    specs, channels = _output_specs(definition)
    name = f"outputs-{operator_cache_key(definition, mesh, specs)}.npz"
    cache = find_cached(name)
    if cache is not None:
        with np.load(cache, allow_pickle=False) as data:
            matrix = sp.csr_matrix((data["data"], data["indices"], data["indptr"]), shape=tuple(data["shape"]))
            operator = fea.OutputOperator([str(n) for n in data["names"]], [str(u) for u in data["units"]],
                                          matrix, data["offset"])
        return operator, channels, cache
    operator = _compute_outputs(definition, mesh, thermal, materials, specs)
    m = operator.matrix
    cache = write_checked(user_cache_dir() / name, lambda tmp: np.savez(
        tmp, data=m.data, indices=m.indices, indptr=m.indptr, shape=np.array(m.shape),
        names=np.array(operator.names), units=np.array(operator.units), offset=operator.offset))
    return operator, channels, cache


def elastic_problem(definition: MachineDefinition, mesh: fea.TetMesh,
                    materials: dict[int, fea.Material] | None = None) -> fea.ElasticProblem:
    """The machine's thermo-elastic problem.

    Parameters
    ----------
    definition : MachineDefinition
        Elastic degree, stress-free reference temperature (°C) and support points (m).
    mesh : fea.TetMesh
        Its mesh.
    materials : dict of int to fea.Material, optional
        Region id → material (default :func:`materials_by_region`).

    Returns
    -------
    fea.ElasticProblem
        With the 3-2-1 kinematic mount on the support points (5 mm tolerance).
    """
    materials = materials or materials_by_region(definition, mesh)
    if definition.elastic_degree not in (1, 2):
        raise DefinitionError(f"{definition.source}: machine.elastic_degree must be 1 or 2, "
                              f"got {definition.elastic_degree}")
    elastic = fea.ElasticProblem(mesh, materials, degree=definition.elastic_degree,
                                 reference_temperature=definition.reference_temperature_C)
    elastic.add_kinematic_mount(*definition.support_points, tolerance=5e-3)
    return elastic


def _compute_outputs(definition, mesh, thermal, materials, specs):
    """Thermometer rows at once, then one adjoint elastic solve per drift or strain output, reporting progress."""
    snap = definition.snap_distance_m
    temps = [s for s in specs if isinstance(s, fea.PointTemperature)]
    with _named_in_file(definition):
        blocks = [fea.build_output_operator(temps, thermal, snap_distance=snap)]
    mech = [s for s in specs if not isinstance(s, fea.PointTemperature)]
    if mech:
        elastic = elastic_problem(definition, mesh, materials)
        estimate = OPERATOR_S_PER_DOF_SOLVE * elastic.n_dofs * (len(mech) + OPERATOR_SETUP_SOLVES)
        log.info("building the output operator of %s: %d elastic solves (P%d, %s dofs), roughly %s on a "
                 "2-core machine", definition.name, len(mech), definition.elastic_degree,
                 f"{elastic.n_dofs:,}", duration_text(estimate))
        start = time.perf_counter()
        for k, spec in enumerate(mech, 1):      # one at a time: the factorisation is kept, progress is shown
            with _named_in_file(definition):
                blocks.append(fea.build_output_operator([spec], thermal, elastic, snap_distance=snap))
            if estimate > 60:
                log.info("output operator of %s: %d/%d elastic solves done (%s)", definition.name, k, len(mech),
                         duration_text(time.perf_counter() - start))
    whole = fea.OutputOperator([n for b in blocks for n in b.names], [u for b in blocks for u in b.units],
                               sp.vstack([b.matrix for b in blocks]), np.concatenate([b.offset for b in blocks]))
    return whole.subset([s.name for s in specs])


@contextmanager
def _named_in_file(definition):
    """Turn the solver's "<output> at (x, y, z) m lies outside the mesh" into an error naming the machine file and
    the field that placed the point (the outputs' names are the twin's, not the file's)."""
    try:
        yield
    except fea.FEAInputError as exc:
        if "lies outside the mesh" not in str(exc):
            raise
        label = str(exc).split(" at (", 1)[0]
        raise DefinitionError(f"{definition.source}: {_point_field(definition, label)}: {exc}") from None


def _point_field(definition, label):
    """The machine-file field of an output point's label (``T05``, ``X reference``, ``FBG1 end``, ``cam012``)."""
    name, _, end = label.partition(" ")
    if name in {s.name for s in definition.sensors}:
        return f"sensors (name = {name!r}).{end or 'position'}"     # a strain line's end or start
    if name.startswith("cam"):
        return "camera (its spots)"
    if end == "reference":
        return "tcp.workpiece_point"
    if name == "Y_top":
        return f"tcp.tool_point + tcp.tilt_probe_offset {tuple(definition.tilt_probe_offset)} m (the upper Y probe)"
    return "tcp.tool_point"


def _air_feedthrough(definition, thermal):
    """Rows over the inputs giving the air sensors' readings (their zone's ambient at their height), and the sensors."""
    air = [s for s in definition.sensors if s.kind == "air"]
    feedthrough = np.zeros((len(air), thermal.n_inputs))
    for i, s in enumerate(air):
        feedthrough[i, thermal.input_index(ambient_input(s.zone))] = 1.0
        feedthrough[i, thermal.input_index(GRADIENT_INPUT)] = s.position[2] - definition.ambient_reference_height_m
    return feedthrough, air


def build_machine(machine: str | Path = "vmc_ram", mesh_size_m: float | None = None,
                  definition: MachineDefinition | None = None) -> Machine:
    """Build (or load from caches) the twin of a machine definition.

    Parameters
    ----------
    machine : str or Path
        Machine name or path to its TOML file.
    mesh_size_m : float, optional
        Target tetrahedron edge length, m (default: the definition's).
    definition : MachineDefinition, optional
        An already-loaded definition (skips reading the file).

    Returns
    -------
    Machine
        Mesh, thermal system, output operator and channels, with the meshing and operator times (s).
    """
    definition = definition or load_machine(machine)
    mesh_size_m = definition.geometry.mesh_size_m if mesh_size_m is None else mesh_size_m
    mesh, info = build_mesh(definition.geometry, mesh_size_m)
    groups, _ = _facet_groups(definition, mesh)
    thermal, materials = _thermal_system(definition, mesh, groups)
    start = time.perf_counter()
    outputs, channels, operator_path = _build_outputs(definition, mesh, thermal, materials)
    feedthrough, air = _air_feedthrough(definition, thermal)
    channels += [Channel(s.name, "air", "degC", 1.0, s.label, s.position) for s in air]
    return Machine(definition, mesh, thermal, outputs, feedthrough, channels, info.seconds,
                   time.perf_counter() - start, info.path, operator_path, float(mesh_size_m))


def reassemble(machine: Machine, definition: MachineDefinition) -> Machine:
    """The machine with its thermal system reassembled for a changed definition; mesh and output operator reused.

    For definitions that differ from ``machine.definition`` in convection
    coefficients, heat sources and joint *conductances* only: the joint pairs
    (which fix the thermal node numbering) and the parts must be the same,
    so the output operator's rows over thermal nodes stay valid and no
    elastic solve is needed (about 1 s instead of minutes).  Used by the gap
    diagnosis to switch candidate effects on.

    Parameters
    ----------
    machine : Machine
        The built machine.
    definition : MachineDefinition
        The changed definition.

    Returns
    -------
    Machine
        A new machine sharing mesh and output operator.

    Raises
    ------
    DefinitionError
        The joint pairs or the thermal numbering differ, or anything the output operator is computed from
        (elastic properties such as a part's expansion coefficient, supports, sensors): reusing the operator
        would then give silently wrong drift.
    """
    pairs = [(a, b) for a, b, _ in definition.joints]
    if pairs != [(a, b) for a, b, _ in machine.definition.joints]:
        raise DefinitionError(f"{definition.source}: reassemble keeps the joint pairs of the machine "
                              f"({[(a, b) for a, b, _ in machine.definition.joints]}); got {pairs}")
    if not operator_reusable(machine, definition):
        raise DefinitionError(f"{definition.source}: reassemble reuses the output operator, but the definition "
                              "changes what it is computed from (elastic properties, supports, reference "
                              "temperature, sensors); build the machine anew with build_machine")
    groups, _ = _facet_groups(definition, machine.mesh)
    thermal, _ = _thermal_system(definition, machine.mesh, groups)
    if thermal.n_nodes != machine.thermal.n_nodes or not np.array_equal(thermal.node_of, machine.thermal.node_of):
        raise DefinitionError(f"{definition.source}: the reassembled thermal numbering differs from the machine's")
    feedthrough, _ = _air_feedthrough(definition, thermal)
    return Machine(definition, machine.mesh, thermal, machine.outputs, feedthrough, list(machine.channels),
                   machine.mesh_seconds, machine.operator_seconds, machine.mesh_path, machine.operator_path,
                   machine.mesh_size_m)


def convection_summary(machine: Machine) -> tuple[list[tuple[str, float, float, str]], float]:
    """Area, coefficient and zone of each convection group, and the adiabatic remainder.

    Parameters
    ----------
    machine : Machine
        A built machine.

    Returns
    -------
    rows : list of tuple
        ``(group, area m², coefficient W/(m² K), zone)`` per group.
    adiabatic_m2 : float
        Boundary area in no group, m².
    """
    groups, adiabatic = _facet_groups(machine.definition, machine.mesh)
    rows = [(name, machine.mesh.facet_group_area(name), rule.coefficient, rule.zone)
            for name, rule in groups.items()]
    return rows, adiabatic
