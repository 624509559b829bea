"""The full-order twin with room for candidate effects: ``M Ṫ + (A₀ + Σ aᵢ dAᵢ) T = (B₀ + Σ aᵢ dBᵢ) u``.

:func:`build_structure` takes a built machine and a list of effects; each
effect's ``prepare`` registers what it needs:

- extra input columns (``add_input``): the load vector of an unmodelled heat
  source, of a warm air pocket on some facets, of radiation to the walls;
- system terms (``add_system_term``): dA, dB for a unit change of a
  coefficient that enters the matrices linearly (a convection coefficient, a
  joint conductance), found as the difference of two assembled systems, so
  it is exact;
- initial-state fields (``add_field``).

Outputs are the machine's non-camera channels in edge units: FE rows
(thermometers °C, TCP drift µm, strain µε) then air sensors (a feedthrough
of the inputs).  The structure also knows what the effects and the
attribution need about the channels: the region and zone of every
thermometer, the local air a thermometer sees, the region of every node.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from fea.mesh import LOCAL_FACES

from .engine import _factor

#: 4 σ T³ at 20 °C: the linearised radiative coefficient of a black surface, W/(m² K).
RADIATIVE_COEFFICIENT = 4 * 5.670374419e-8 * 293.15 ** 3


def _recorded_rows(machine):
    """``(fe_rows, air_rows)``: the machine's non-camera FE output rows, and its air channels' rows among the
    channels that follow the FE outputs."""
    n_fe = machine.outputs.n_outputs
    fe_rows = [j for j, c in enumerate(machine.channels) if c.kind != "camera" and j < n_fe]
    air_rows = [j - n_fe for j, c in enumerate(machine.channels) if c.kind == "air"]
    return fe_rows, air_rows


class Structure:
    """See the module docstring.  Build with :func:`build_structure`."""

    def __init__(self, machine):
        self.machine = machine
        thermal = machine.thermal
        self.mass = sp.csr_matrix(thermal.mass)
        self.stiffness = sp.csr_matrix(thermal.stiffness)
        self.input_names = list(thermal.input_names)
        self.n_machine_inputs = len(self.input_names)
        self._B = [sp.csc_matrix(thermal.input_matrix)]
        self.system_terms = {}
        self.fields = {}
        self.fe_rows, self.air_rows = _recorded_rows(machine)
        n_fe = machine.outputs.n_outputs
        self.channels = [machine.channels[j] for j in self.fe_rows] + [machine.channels[n_fe + j]
                                                                       for j in self.air_rows]
        assert len(self.channels) == sum(c.kind != "camera" for c in machine.channels)
        scale = np.array([machine.channels[j].scale for j in self.fe_rows])
        self.output_matrix = sp.csr_matrix(machine.outputs.matrix[self.fe_rows].multiply(scale[:, None]))
        self.output_offset = machine.outputs.offset[self.fe_rows] * scale
        self.names = [c.name for c in self.channels]
        self.kinds = [c.kind for c in self.channels]
        self.index = {n: i for i, n in enumerate(self.names)}
        self.thermometers, self.displacements, self.air = (
            [i for i, k in enumerate(self.kinds) if k == kind] for kind in ("temperature", "displacement", "air"))
        self._node_region = None
        self._thermometer_info = None

    # ------------------------------------------------------------------ registration
    @property
    def n_nodes(self):
        return self.mass.shape[0]

    @property
    def n_inputs(self):
        return len(self.input_names)

    @property
    def input_matrix(self):
        B = self._B[0] if len(self._B) == 1 else sp.hstack(self._B).tocsc()
        self._B = [B]
        return B

    def input_index(self, name):
        return self.input_names.index(name)

    def add_input(self, name, column):
        """An extra input column (n,) named ``name`` (e.g. ``gap:belt_drive``, W)."""
        if name in self.input_names:
            return self.input_index(name)
        self._B.append(sp.csc_matrix(np.asarray(column, float).reshape(-1, 1)))
        self.input_names.append(name)
        return len(self.input_names) - 1

    def add_system_term(self, name, dA, dB):
        """A system term: A += a·dA, B += a·dB (dB over the machine's inputs; extra inputs get none)."""
        self.system_terms[name] = (sp.csr_matrix(dA), sp.csc_matrix(dB))

    def system_input_change(self, name):
        """dB of a system term widened to all (machine + extra) inputs."""
        dB = self.system_terms[name][1]
        extra = self.n_inputs - dB.shape[1]
        return sp.hstack([dB, sp.csc_matrix((dB.shape[0], extra))]).tocsc() if extra else dB

    def add_field(self, name, field):
        """An initial-state field shape (n,) on thermal nodes."""
        self.fields[name] = np.asarray(field, float)

    # ------------------------------------------------------------------ outputs
    def air_feedthrough(self):
        """(p_air, n_inputs): the air sensors from the inputs (zero on extra inputs)."""
        D = np.zeros((len(self.air), self.n_inputs))
        D[:, : self.n_machine_inputs] = self.machine.feedthrough[self.air_rows] * \
            np.array([self.channels[i].scale for i in self.air])[:, None]
        return D

    def channel_values(self, fe_values, U):
        """All channels (k, p) from FE outputs in edge units without offset (k, p_fe) and inputs (k, m)."""
        return np.hstack([fe_values + self.output_offset, U @ self.air_feedthrough().T])

    # ------------------------------------------------------------------ geometry of sensors and nodes
    @property
    def node_region(self):
        """Region name of every thermal node (the part of a tetrahedron using it)."""
        if self._node_region is None:
            mesh, thermal = self.machine.mesh, self.machine.thermal
            region = np.empty(self.n_nodes, dtype=np.int64)
            region[thermal.tets.ravel()] = np.repeat(mesh.regions, 4)
            self._node_region = np.array([mesh.region_names[r] for r in region])
        return self._node_region

    @property
    def region_names(self):
        mesh = self.machine.mesh
        return [mesh.region_names[r] for r in sorted(mesh.region_names)]

    def thermometer_info(self):
        """Per surface thermometer: position (m), part, the zone and height of the air at its surface."""
        if self._thermometer_info is None:
            pos = np.array([self.channels[i].position for i in self.thermometers], float)
            self._thermometer_info = point_info(self, pos, [self.names[i] for i in self.thermometers])
        return self._thermometer_info

    def local_air_matrix(self, zones, heights):
        """(k, n_inputs): the ambient seen at k points of given zones and heights above the reference."""
        L = np.zeros((len(zones), self.n_inputs))
        for i, (z, h) in enumerate(zip(zones, heights)):
            L[i, self.input_index(f"ambient:{z}")] = 1.0
            L[i, self.input_index("ambient_gradient")] = h
        return L


def facet_table(machine):
    """All convection facets: (thermal node ids (k, 3), centroids (k, 3), areas (k,), group, h, zone)."""
    mesh = machine.mesh
    rules = {r.name: r for r in machine.definition.convection}
    nodes, cents, areas, groups, hs, zones = [], [], [], [], [], []
    for name, rule in rules.items():
        if name not in mesh.facet_groups:
            continue
        tet, local = mesh.facet_group(name)
        c, _, a = mesh.facet_geometry(tet, local)
        nodes.append(machine.thermal.tets[tet[:, None], LOCAL_FACES[local]])
        cents.append(c)
        areas.append(a)
        groups += [name] * len(tet)
        hs.append(np.full(len(tet), rule.coefficient))
        zones += [rule.zone] * len(tet)
    return (np.vstack(nodes), np.vstack(cents), np.concatenate(areas), np.array(groups), np.concatenate(hs),
            np.array(zones))


def lumped_facet_load(machine, mask, coefficient):
    """Load vector (n,) of ``∫ h φ dS`` over the facets of :func:`facet_table` selected by ``mask``.

    Exact for P1 (∫ φᵢ over a flat triangle is its area / 3); ``coefficient``
    is a number (W/(m² K)) or one value per facet.
    """
    nodes, _, areas, _, _, _ = facet_table(machine)
    h = np.broadcast_to(np.asarray(coefficient, float), areas.shape)
    w = (h * areas / 3.0)[mask]
    b = np.zeros(machine.thermal.n_nodes)
    np.add.at(b, nodes[mask].ravel(), np.repeat(w, 3))
    return b


def point_info(structure, positions, names=None):
    """Part, air zone and air height (above the reference) at points on the surface (dict of arrays)."""
    machine = structure.machine
    mesh = machine.mesh
    positions = np.atleast_2d(np.asarray(positions, float))
    tets, _ = mesh.locate(positions, snap_distance=max(machine.definition.snap_distance_m, 0.02), names=names)
    parts = np.array([mesh.region_names[r] for r in mesh.regions[tets]])
    _, cents, _, groups, _, zones = facet_table(machine)
    from scipy.spatial import cKDTree

    _, k = cKDTree(cents).query(positions)
    z_ref = machine.definition.ambient_reference_height_m
    return {"position": positions, "part": parts, "zone": zones[k], "group": groups[k],
            "height": positions[:, 2] - z_ref}


#: Initial-state shapes estimated as nuisance in every model (the start of a measured record is uncertain).
NUISANCE_FIELDS = ("initial_uniform", "initial_residual_heat")


def build_structure(machine, effects=(), nuisance=True):
    """The :class:`Structure` of a machine with every effect's terms registered (see the module docstring).

    With ``nuisance`` it also holds the initial-state shapes of :data:`NUISANCE_FIELDS`: a uniform
    offset of the whole machine, and the heat left by earlier spindle running (the steady rise at the
    sources' reference speed).
    """
    structure = Structure(machine)
    structure.term_bounds = {}
    for effect in effects:
        if effect.applicable(machine):
            effect.prepare(structure)
            if effect.kind == "system":
                params = effect.parameters(machine)
                for bound in ("lower", "upper"):
                    theta = [getattr(p, bound) for p in params]
                    for name, a in effect.coefficients(theta, structure).items():
                        structure.term_bounds.setdefault(name, []).append(a)
    if nuisance:
        structure.add_field("initial_uniform", np.ones(structure.n_nodes))
        d = machine.definition
        spindle = [src for src in d.sources if src.driver == "spindle"]
        if spindle:
            ref = max(src.reference for src in spindle)
            zeros = {a: np.zeros(1) for a in "xyz"}
            u = np.zeros(machine.thermal.n_inputs)
            for src in spindle:
                u[machine.thermal.input_index(f"power:{src.name}")] = src.power_W(np.array([ref]), zeros)[0]

            rise = _factor(machine.thermal.stiffness)(np.asarray(machine.thermal.input_matrix @ u).ravel())
            structure.add_field("initial_residual_heat", rise / max(float(np.abs(rise).max()), 1e-12))
    return structure
