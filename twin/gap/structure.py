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

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from fea.mesh import LOCAL_FACES

from ..core.machine import Machine
from .engine import _factor

if TYPE_CHECKING:
    from .effects import Effect

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
    """See the module docstring.  Build with :func:`build_structure`.

    Parameters
    ----------
    machine : Machine
        The built machine: its thermal system (mass, stiffness, input matrix), output operator and channels.
    """

    def __init__(self, machine: Machine):
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
    def n_nodes(self) -> int:
        """Number of thermal nodes."""
        return self.mass.shape[0]

    @property
    def n_inputs(self) -> int:
        """Number of inputs: the machine's, then the extra columns registered by :meth:`add_input`."""
        return len(self.input_names)

    @property
    def input_matrix(self) -> sp.csc_matrix:
        """B, sparse, shape (n_nodes, n_inputs): nodal heat load per unit of each input (W/K for an ambient,
        W·m/K for the gradient, W/W for a power), machine inputs then extra columns."""
        B = self._B[0] if len(self._B) == 1 else sp.hstack(self._B).tocsc()
        self._B = [B]
        return B

    def input_index(self, name: str) -> int:
        """Column of an input by name.

        Parameters
        ----------
        name : str
            Input name (``ambient:<zone>``, ``ambient_gradient``, ``power:<source>`` or an extra ``gap:…``).

        Returns
        -------
        int
            Its column in :attr:`input_matrix`.
        """
        return self.input_names.index(name)

    def add_input(self, name: str, column: np.ndarray) -> int:
        """An extra input column (n,) named ``name`` (e.g. ``gap:belt_drive``, W).

        Parameters
        ----------
        name : str
            Input name; an existing name is not added again.
        column : ndarray, shape (n_nodes,) or (n_nodes, 1)
            Nodal heat load per unit of the input (W/W for a power, W/K for a temperature).

        Returns
        -------
        int
            The input's column (the existing one when ``name`` is already registered).
        """
        if name in self.input_names:
            return self.input_index(name)
        self._B.append(sp.csc_matrix(np.asarray(column, float).reshape(-1, 1)))
        self.input_names.append(name)
        return len(self.input_names) - 1

    def add_system_term(self, name: str, dA: sp.spmatrix | np.ndarray, dB: sp.spmatrix | np.ndarray) -> None:
        """A system term: A += a·dA, B += a·dB (dB over the machine's inputs; extra inputs get none).

        Parameters
        ----------
        name : str
            Term name (the coefficient ``a`` is given under it, e.g. by an effect's ``coefficients``).
        dA : sparse matrix or ndarray, shape (n_nodes, n_nodes)
            Change of the stiffness per unit of ``a``, W/K.
        dB : sparse matrix or ndarray, shape (n_nodes, n_machine_inputs)
            Change of the input matrix per unit of ``a`` (W per input unit).
        """
        self.system_terms[name] = (sp.csr_matrix(dA), sp.csc_matrix(dB))

    def system_input_change(self, name: str) -> sp.csc_matrix:
        """dB of a system term widened to all (machine + extra) inputs.

        Parameters
        ----------
        name : str
            Term name (see :meth:`add_system_term`).

        Returns
        -------
        scipy.sparse.csc_matrix, shape (n_nodes, n_inputs)
            dB with zero columns for the extra inputs (W per input unit).
        """
        dB = self.system_terms[name][1]
        extra = self.n_inputs - dB.shape[1]
        return sp.hstack([dB, sp.csc_matrix((dB.shape[0], extra))]).tocsc() if extra else dB

    def add_field(self, name: str, field: np.ndarray) -> None:
        """An initial-state field shape (n,) on thermal nodes.

        Parameters
        ----------
        name : str
            Field name (e.g. ``initial_uniform``).
        field : ndarray, shape (n_nodes,)
            Dimensionless shape; the initial state gains coefficient × field, the coefficient in K.
        """
        self.fields[name] = np.asarray(field, float)

    # ------------------------------------------------------------------ outputs
    def air_feedthrough(self) -> np.ndarray:
        """(p_air, n_inputs): the air sensors from the inputs (zero on extra inputs).

        Returns
        -------
        ndarray, shape (p_air, n_inputs)
            Air-sensor reading (°C) per unit of each input.
        """
        D = np.zeros((len(self.air), self.n_inputs))
        D[:, : self.n_machine_inputs] = self.machine.feedthrough[self.air_rows] * \
            np.array([self.channels[i].scale for i in self.air])[:, None]
        return D

    def channel_values(self, fe_values: np.ndarray, U: np.ndarray) -> np.ndarray:
        """All channels (k, p) from FE outputs in edge units without offset (k, p_fe) and inputs (k, m).

        Parameters
        ----------
        fe_values : ndarray, shape (k, p_fe)
            FE outputs in channel units (°C, µm, µε), without the output offset.
        U : ndarray, shape (k, n_inputs)
            Inputs (°C, K/m, W).

        Returns
        -------
        ndarray, shape (k, p)
            Every channel of :attr:`names` in its unit (°C, µm, µε): FE channels then air sensors.
        """
        return np.hstack([fe_values + self.output_offset, U @ self.air_feedthrough().T])

    # ------------------------------------------------------------------ geometry of sensors and nodes
    @property
    def node_region(self) -> np.ndarray:
        """Region name of every thermal node (the part of a tetrahedron using it): ndarray of str, shape (n_nodes,)."""
        if self._node_region is None:
            mesh, thermal = self.machine.mesh, self.machine.thermal
            region = np.empty(self.n_nodes, dtype=np.int64)
            region[thermal.tets.ravel()] = np.repeat(mesh.regions, 4)
            self._node_region = np.array([mesh.region_names[r] for r in region])
        return self._node_region

    @property
    def region_names(self) -> list[str]:
        """The mesh's region (part) names, in the order of their region ids."""
        mesh = self.machine.mesh
        return [mesh.region_names[r] for r in sorted(mesh.region_names)]

    def thermometer_info(self) -> dict[str, np.ndarray]:
        """Per surface thermometer: position (m), part, the zone and height of the air at its surface.

        Returns
        -------
        dict of str to ndarray
            :func:`point_info` of the thermometers (in the order of :attr:`thermometers`), computed once.
        """
        if self._thermometer_info is None:
            pos = np.array([self.channels[i].position for i in self.thermometers], float)
            self._thermometer_info = point_info(self, pos, [self.names[i] for i in self.thermometers])
        return self._thermometer_info

    def local_air_matrix(self, zones: Sequence[str] | np.ndarray, heights: Sequence[float] | np.ndarray) -> np.ndarray:
        """(k, n_inputs): the ambient seen at k points of given zones and heights above the reference.

        Parameters
        ----------
        zones : sequence of str, length k
            Convection zone of each point.
        heights : sequence of float, length k
            Height of each point above the ambient reference height, m.

        Returns
        -------
        ndarray, shape (k, n_inputs)
            Rows L with ``U @ L.T`` the local ambient, °C: 1 on the zone's ambient, the height (m) on the
            gradient (K/m).
        """
        L = np.zeros((len(zones), self.n_inputs))
        for i, (z, h) in enumerate(zip(zones, heights)):
            L[i, self.input_index(f"ambient:{z}")] = 1.0
            L[i, self.input_index("ambient_gradient")] = h
        return L


def facet_table(machine: Machine) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """All convection facets: (thermal node ids (k, 3), centroids (k, 3), areas (k,), group, h, zone).

    Parameters
    ----------
    machine : Machine
        The built machine; facets of every convection rule with a facet group in the mesh.

    Returns
    -------
    nodes : ndarray of int, shape (k, 3)
        Thermal node ids of each facet.
    centroids : ndarray, shape (k, 3)
        Facet centroids, m.
    areas : ndarray, shape (k,)
        Facet areas, m².
    groups : ndarray of str, shape (k,)
        Convection group (rule name) of each facet.
    h : ndarray, shape (k,)
        Convection coefficient, W/(m²·K).
    zones : ndarray of str, shape (k,)
        Ambient zone of each facet.
    """
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


def lumped_facet_load(machine: Machine, mask: np.ndarray, coefficient: float | np.ndarray) -> np.ndarray:
    """Load vector (n,) of ``∫ h φ dS`` over the facets of :func:`facet_table` selected by ``mask``.

    Exact for P1 (∫ φᵢ over a flat triangle is its area / 3); ``coefficient``
    is a number (W/(m² K)) or one value per facet.

    Parameters
    ----------
    machine : Machine
        The built machine.
    mask : ndarray of bool, shape (k,)
        Facets of :func:`facet_table` to include.
    coefficient : float or ndarray, shape (k,)
        h, W/(m²·K): one value or one per facet (of all k facets, before ``mask``).

    Returns
    -------
    ndarray, shape (n_nodes,)
        Nodal load per kelvin of the temperature driving it, W/K.
    """
    nodes, _, areas, _, _, _ = facet_table(machine)
    h = np.broadcast_to(np.asarray(coefficient, float), areas.shape)
    w = (h * areas / 3.0)[mask]
    b = np.zeros(machine.thermal.n_nodes)
    np.add.at(b, nodes[mask].ravel(), np.repeat(w, 3))
    return b


def point_info(structure: Structure, positions: np.ndarray,
               names: Sequence[str] | None = None) -> dict[str, np.ndarray]:
    """Part, air zone and air height (above the reference) at points on the surface (dict of arrays).

    Parameters
    ----------
    structure : Structure
        Gives the machine.
    positions : ndarray, shape (k, 3) or (3,)
        Points, m (snapped onto the mesh within ``max(snap_distance_m, 0.02)`` m).
    names : sequence of str, optional
        Point names, for the error message of a point outside the mesh.

    Returns
    -------
    dict of str to ndarray
        ``position`` (k, 3) m; ``part`` (k,) the region containing it; ``zone`` and ``group`` (k,) of the
        nearest convection facet (by centroid); ``height`` (k,) above the ambient reference height, m.
    """
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


def build_structure(machine: Machine, effects: Sequence[Effect] = (), nuisance: bool = True) -> Structure:
    """The :class:`Structure` of a machine with every effect's terms registered (see the module docstring).

    With ``nuisance`` it also holds the initial-state shapes of :data:`NUISANCE_FIELDS`: a uniform
    offset of the whole machine, and the heat left by earlier spindle running (the steady rise at the
    sources' reference speed).

    Parameters
    ----------
    machine : Machine
        The built machine.
    effects : sequence of Effect
        Candidate effects; those applicable to ``machine`` register their terms, and system effects their
        coefficients at the parameter bounds in ``term_bounds``.
    nuisance : bool, default True
        Register the initial-state shapes of :data:`NUISANCE_FIELDS` (both dimensionless, max 1).

    Returns
    -------
    Structure
        With ``term_bounds``: system term name → its coefficients at the lower and upper parameter bounds.
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
