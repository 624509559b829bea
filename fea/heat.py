"""Heat-conduction problems: materials, boundary conditions and sources → a linear thermal system.

The assembled system is the semi-discrete, linear time-invariant model

    M dT/dt + A T = B u(t) − r(T)

with ``M`` the heat-capacity matrix (J/K), ``A`` conduction plus convection,
linearised radiation and joint conductance (W/K), ``B`` the input matrix
whose columns are the load vectors of named inputs (ambient temperatures in
°C, powers in W, flux densities in W/m²) and ``r`` the part of full T⁴
radiation the linearisation misses (zero unless full radiation is asked for).
Fixed temperatures are eliminated.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from skfem import Basis, ElementTetP1, FacetBasis, MeshTet

from . import heat_forms as forms
from .contact import Joint, interface_matrix, joint_facets, split_nodes
from .errors import FEAInputError, require_positive
from .materials import HEAT_PROPERTIES, Material, per_tet, region_materials
from .mesh import LOCAL_FACES, TetMesh

#: Units of each kind of input.
INPUT_UNITS = {
    "ambient": "°C",
    "ambient_gradient": "K/m",
    "power": "W",
    "flux_density": "W/m²",
    "temperature": "°C",
}


@dataclass
class RadiationTerm:
    """Full T⁴ radiation of one facet group, handled as a correction to its linearisation."""

    group: str
    basis: FacetBasis
    emissivity: float
    radiative_coefficient: float
    ambient_column: int

    def _fields(self, T, u):
        return dict(temperature=self.basis.interpolate(T), ambient=float(u[self.ambient_column]),
                    emissivity=self.emissivity, radiative_coefficient=self.radiative_coefficient)

    def excess(self, T: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The part of the radiation its linearisation misses, ∫ [εσ(T⁴ − T_amb⁴) − h_r (T − T_amb)] φ.

        Parameters
        ----------
        T : ndarray
            Temperature on the thermal nodes, °C.
        u : ndarray
            Inputs (the ambient column is read).

        Returns
        -------
        ndarray
            Per thermal node, W.
        """
        return forms.radiation_excess.assemble(self.basis, **self._fields(T, u))

    def tangent(self, T: np.ndarray, u: np.ndarray) -> sp.csr_matrix:
        """The Jacobian of :meth:`excess` with respect to T.

        Parameters
        ----------
        T : ndarray
            Temperature on the thermal nodes, °C.
        u : ndarray
            Inputs.

        Returns
        -------
        scipy.sparse matrix
            W/K.
        """
        return forms.radiation_tangent.assemble(self.basis, **self._fields(T, u))


@dataclass
class ThermalSystem:
    """The assembled linear thermal model ``M Ṫ + A T = B u − r(T)`` (see module docstring).

    Temperatures live on *thermal nodes*: the mesh nodes, with those on joint
    interfaces duplicated per side.  ``node_of`` maps each thermal node to
    its mesh node and ``tets`` is the connectivity in thermal numbering.
    """

    mass: sp.csr_matrix
    stiffness: sp.csr_matrix
    input_matrix: sp.csr_matrix
    input_names: list
    input_units: list
    mesh: object
    tets: np.ndarray
    node_of: np.ndarray
    fixed_nodes: np.ndarray
    fixed_matrix: sp.csr_matrix
    radiation: list = field(default_factory=list)
    heat_flows: dict = field(default_factory=dict)
    constant_inputs: dict = field(default_factory=dict)
    fixed_groups: dict = field(default_factory=dict)   # group → its fixed thermal nodes (disjoint)

    @property
    def n_nodes(self) -> int:
        """Number of thermal nodes."""
        return self.mass.shape[0]

    @property
    def n_inputs(self) -> int:
        """Number of inputs (columns of B)."""
        return len(self.input_names)

    @property
    def points(self) -> np.ndarray:
        """Coordinates of the thermal nodes, m."""
        return self.mesh.points[self.node_of]

    def input_index(self, name: str) -> int:
        """The column of an input.

        Parameters
        ----------
        name : str
            Input name, e.g. ``ambient:room``.

        Returns
        -------
        int
            Its column in B.
        """
        try:
            return self.input_names.index(name)
        except ValueError:
            raise FEAInputError(f"unknown input {name!r}; inputs: {self.input_names}") from None

    def fixed_values(self, u: np.ndarray) -> np.ndarray:
        """The temperatures of the fixed nodes.

        Parameters
        ----------
        u : ndarray, shape (n_inputs,)
            Input values.

        Returns
        -------
        ndarray
            Temperature of each fixed node, °C.
        """
        return self.fixed_matrix @ u

    def stored_energy(self, T: np.ndarray) -> float:
        """The heat stored in the body, ∫ ρc T dV.

        Parameters
        ----------
        T : ndarray, shape (n_nodes,)
            Temperature, °C.

        Returns
        -------
        float
            Energy, J (relative to 0 °C).
        """
        return float(np.sum(self.mass @ T))

    def power_in(self, T: np.ndarray, u: np.ndarray, rate: np.ndarray | None = None) -> dict[str, float]:
        """Heat flow into the body through each load, W, keyed by load name.

        Fixed temperatures appear as ``fixed:<group>``: the reaction heat
        flow the boundary must supply to hold them, Σ over the group's nodes
        of (M Ṫ + A T + r(T) − B u).  ``rate`` is Ṫ (K/s on the thermal
        nodes) for the capacity of those nodes in a transient; omit it at
        steady state.  The flows then sum to d/dt ∫ ρcT dV.

        Parameters
        ----------
        T : ndarray, shape (n_nodes,)
            Temperature, °C.
        u : ndarray, shape (n_inputs,)
            Input values.
        rate : ndarray, optional
            Ṫ on the thermal nodes, K/s.

        Returns
        -------
        dict of str to float
            Load name → heat flow into the body, W.
        """
        flows = {name: float(r_u @ u - r_T @ T) for name, (r_T, r_u) in self.heat_flows.items()}
        excess = np.zeros(self.n_nodes)
        for term in self.radiation:
            # heat_flows holds the linearisation h_r (T_amb − T); the rest of εσ(T_amb⁴ − T⁴) is the excess
            part = term.excess(T, u)
            flows[f"radiation:{term.group}"] -= float(part.sum())
            excess += part
        for group, nodes in self.fixed_groups.items():
            balance = self.stiffness[nodes] @ T + excess[nodes] - self.input_matrix[nodes] @ u
            if rate is not None:
                balance = balance + self.mass[nodes] @ rate
            flows[f"fixed:{group}"] = float(np.sum(balance))
        return flows

    def nodal_field(self, T: np.ndarray) -> np.ndarray:
        """A thermal-node field on the mesh nodes (mean over the sides of split joint nodes).

        Parameters
        ----------
        T : ndarray, shape (n_nodes,)
            Temperature on the thermal nodes, °C.

        Returns
        -------
        ndarray, shape (mesh.n_nodes,)
            Temperature on the mesh nodes, °C.
        """
        total = np.bincount(self.node_of, weights=T, minlength=self.mesh.n_nodes)
        count = np.bincount(self.node_of, minlength=self.mesh.n_nodes)
        return total / np.maximum(count, 1)

    def point_weights(self, points: np.ndarray, names: list[str] | None = None,
                      snap_distance: float = 0.0) -> sp.csr_matrix:
        """The matrix giving the P1 temperature at points (barycentric weights).

        Parameters
        ----------
        points : ndarray, shape (k, 3)
            Coordinates, m.
        names : list of str, optional
            Names of the points, in errors.
        snap_distance : float
            How far outside the mesh a point may lie and be snapped onto it, m.

        Returns
        -------
        scipy.sparse.csr_matrix, shape (k, n_nodes)
            Rows summing to 1.
        """
        tet, w = self.mesh.locate(points, names=names, snap_distance=snap_distance)
        rows = np.repeat(np.arange(len(tet)), 4)
        return sp.csr_matrix((w.ravel(), (rows, self.tets[tet].ravel())), shape=(len(tet), self.n_nodes))


class HeatProblem:
    """Collects materials, loads and boundary conditions, then assembles a :class:`ThermalSystem`.

    Every time-varying quantity is a named *input*; its value over time is
    supplied when the system is solved (see :mod:`fea.inputs`).  Numbers
    given where an input name is expected are constant inputs.

    Example
    -------
    >>> problem = HeatProblem(mesh, {0: CAST_IRON})          # doctest: +SKIP
    >>> problem.add_convection("outside", 8.0, ambient="room")
    >>> problem.add_heat_flux("bearing", power="bearing_W")
    >>> system = problem.assemble()

    Parameters
    ----------
    mesh : TetMesh
        The mesh (m) with its regions and facet groups.
    materials : dict of int or str to Material
        Region id or name → material (conductivity W/(m K), density kg/m³, specific heat J/(kg K)).
    """

    def __init__(self, mesh: TetMesh, materials: dict[int | str, Material]) -> None:
        self.mesh = mesh
        materials = region_materials(mesh, materials, HEAT_PROPERTIES, "a heat problem")
        self.conductivity = per_tet(mesh, materials, "conductivity")
        self.heat_capacity = per_tet(mesh, materials, "volumetric_heat_capacity")
        self._inputs = {}
        self._constants = {}
        self._convection = []
        self._fluxes = []
        self._volume_sources = []
        self._fixed = []
        self._radiation = []
        self._joints = []

    # ---------------------------------------------------------------- inputs
    def _input(self, name_or_value, kind, owner):
        if isinstance(name_or_value, str):
            name = name_or_value
        else:
            value = float(name_or_value)
            if not np.isfinite(value):
                raise FEAInputError(f"{owner}: value must be finite, got {name_or_value!r}")
            name = f"const:{owner}"
            self._constants[name] = value
        known = self._inputs.get(name)
        if known is not None and known != kind:
            raise FEAInputError(f"input {name!r} is used as {known} and as {kind}")
        self._inputs[name] = kind
        return name

    def _check_group(self, group):
        self.mesh.facet_group(group)
        return group

    # ---------------------------------------------------------------- loads
    def add_convection(self, group: str, convection_coefficient: float, ambient: str | float = "ambient",
                       ambient_gradient: str | float | None = None, reference_height: float = 0.0) -> None:
        """Convection ``h (T_amb − T)`` into the body on a facet group.

        With a gradient the ambient is stratified vertically:
        ``T_amb(z) = ambient + gradient · (z − reference_height)``.

        Parameters
        ----------
        group : str
            A facet group of the mesh.
        convection_coefficient : float
            h, W/(m² K).
        ambient : str or float
            Input giving the ambient temperature (°C), or a constant.
        ambient_gradient : str or float, optional
            Input giving the vertical gradient, K/m.
        reference_height : float
            Height where the ambient is ``ambient``, m.
        """
        h = require_positive(f"convection coefficient on {group!r}", convection_coefficient)
        self._check_group(group)
        amb = self._input(ambient, "ambient", f"ambient of {group}")
        grad = None if ambient_gradient is None else self._input(ambient_gradient, "ambient_gradient",
                                                                 f"gradient of {group}")
        self._convection.append((group, h, amb, grad, float(reference_height)))

    def add_heat_flux(self, group: str, power: str | float | None = None,
                      flux_density: str | float | None = None) -> None:
        """Heat into the body over a facet group; give exactly one of ``power`` and ``flux_density``.

        Parameters
        ----------
        group : str
            A facet group of the mesh.
        power : str or float, optional
            Input (or constant) giving the total power, W, spread by area.
        flux_density : str or float, optional
            Input (or constant) giving the flux density, W/m².
        """
        if (power is None) == (flux_density is None):
            raise FEAInputError(f"heat flux on {group!r}: give exactly one of power (W) or flux_density (W/m²)")
        self._check_group(group)
        if power is not None:
            self._fluxes.append((group, self._input(power, "power", f"power on {group}"), True))
        else:
            self._fluxes.append((group, self._input(flux_density, "flux_density", f"flux on {group}"), False))

    def add_volumetric_source(self, name: str, tets: np.ndarray, power: str | float) -> None:
        """Heat generated in some tetrahedra, spread uniformly by volume.

        Parameters
        ----------
        name : str
            The source's name (its heat-flow ledger entry is ``source:<name>``).
        tets : ndarray of int
            Tetrahedron indices.
        power : str or float
            Input (or constant) giving the total power, W.
        """
        tets = np.asarray(tets, dtype=np.int64)
        if tets.size == 0:
            raise FEAInputError(f"volumetric source {name!r} covers no tetrahedron")
        self._volume_sources.append((name, tets, self._input(power, "power", f"source {name}")))

    def add_fixed_temperature(self, group: str, temperature: str | float) -> None:
        """Prescribe the temperature on a facet group's nodes.

        Parameters
        ----------
        group : str
            A facet group of the mesh.
        temperature : str or float
            Input (or constant) giving the temperature, °C.
        """
        self._check_group(group)
        self._fixed.append((group, self._input(temperature, "temperature", f"fixed T on {group}")))

    def add_radiation(self, group: str, emissivity: float, ambient: str | float = "ambient",
                      linearise_about: float | None = None) -> None:
        """Radiation to surroundings at the ambient temperature on a facet group.

        With ``linearise_about`` (°C) the exchange is the linear
        ``h_r (T − T_amb)``, h_r = 4εσ(T₀ + 273.15)³.  Without it the full
        ``εσ (T⁴ − T_amb⁴)`` (kelvin) is solved by Newton iterations that
        start from that linearisation about 20 °C.

        Parameters
        ----------
        group : str
            A facet group of the mesh.
        emissivity : float
            ε, in (0, 1].
        ambient : str or float
            Input (or constant) giving the surroundings' temperature, °C.
        linearise_about : float, optional
            Temperature of the linearisation, °C.
        """
        eps = require_positive(f"emissivity on {group!r}", emissivity)
        if eps > 1.0:
            raise FEAInputError(f"emissivity on {group!r} must be at most 1, got {emissivity!r}")
        self._check_group(group)
        amb = self._input(ambient, "ambient", f"radiation ambient of {group}")
        full = linearise_about is None
        T0 = 20.0 if full else float(linearise_about)
        h_r = 4.0 * eps * forms.STEFAN_BOLTZMANN * (T0 + forms.KELVIN) ** 3
        self._radiation.append((group, eps, amb, h_r, full))

    def add_contact(self, region_a: int, region_b: int, conductance: float) -> None:
        """A joint between two regions: their interface nodes are split and coupled by a contact conductance.

        Parameters
        ----------
        region_a, region_b : int
            Region ids.
        conductance : float
            h_c, W/(m² K).
        """
        self._joints.append(Joint(region_a, region_b, conductance))

    # ---------------------------------------------------------------- assembly
    # Long: one loop per load kind (convection, fluxes, sources, radiation), each adding its matrix, its input
    # column and its heat-flow ledger entry to shared state; together they show the column order of B.
    def assemble(self) -> ThermalSystem:
        """Assemble M, A, B once and return the :class:`ThermalSystem`.

        Returns
        -------
        ThermalSystem
            Capacity matrix M (J/K), conductance matrix A (W/K), input matrix B
            (W per input unit: °C, K/m or W), on the thermal nodes.
        """
        mesh = self.mesh
        pairs = joint_facets(mesh, self._joints)
        if pairs:
            tets, node_of = split_nodes(mesh, pairs)
        else:
            tets, node_of = mesh.tets, np.arange(mesh.n_nodes)
        n = len(node_of)
        skmesh = MeshTet(np.ascontiguousarray(mesh.points[node_of].T), np.ascontiguousarray(tets.T))
        element = ElementTetP1()
        # P1 gradients and the conductivity are constant per tetrahedron: one point integrates
        # conduction exactly; the consistent mass needs the degree-2 rule.
        centroid = Basis(skmesh, element, intorder=1)
        cell = Basis(skmesh, element, intorder=2)
        K = forms.conduction.assemble(centroid, conductivity=np.repeat(
            self.conductivity[:, None], centroid.X.shape[1], 1))
        M = forms.capacity.assemble(cell, heat_capacity=np.repeat(self.heat_capacity[:, None], cell.X.shape[1], 1))
        A = K + interface_matrix(mesh, pairs, tets, n)

        names = list(self._inputs)
        col = {name: i for i, name in enumerate(names)}
        B = np.zeros((n, len(names)))
        flows = {}

        def add_flow(key, r_T, r_u):
            # Loads of one kind on one group (or sources of one name) share a key: sum them.
            r_T_old, r_u_old = flows.get(key, (0.0, 0.0))
            flows[key] = (r_T_old + r_T, r_u_old + r_u)

        used = [g[0] for g in self._convection] + [g[0] for g in self._fluxes] + [g[0] for g in self._radiation]
        facets = _FacetForms(mesh, skmesh, tets, element, used, n)
        facet_basis, lift = facets.basis, facets.lift

        for group, h, amb, grad, z_ref in self._convection:
            fb = facet_basis(group)
            H = lift(forms.convection.assemble(fb, convection_coefficient=h))
            A = A + H
            b = lift(forms.weighted_load.assemble(fb, weight=h))
            B[:, col[amb]] += b
            r_u = np.zeros(len(names))
            r_u[col[amb]] = b.sum()
            if grad is not None:
                bz = lift(forms.weighted_load.assemble(fb, weight=h * (np.asarray(fb.global_coordinates())[2] - z_ref)))
                B[:, col[grad]] += bz
                r_u[col[grad]] = bz.sum()
            add_flow(f"convection:{group}", np.asarray(H.sum(axis=0)).ravel(), r_u)

        for group, name, total in self._fluxes:
            fb = facet_basis(group)
            b = lift(forms.unit_load.assemble(fb))
            if total:
                b = b / b.sum()
            B[:, col[name]] += b
            r_u = np.zeros(len(names))
            r_u[col[name]] = b.sum()
            add_flow(f"flux:{group}", np.zeros(n), r_u)

        for name, sel, power in self._volume_sources:
            b = forms.unit_load.assemble(Basis(skmesh, element, elements=sel, intorder=2))
            B[:, col[power]] += b / b.sum()
            r_u = np.zeros(len(names))
            r_u[col[power]] = 1.0
            add_flow(f"source:{name}", np.zeros(n), r_u)

        radiation = []
        for group, eps, amb, h_r, full in self._radiation:
            fb = facet_basis(group)
            H = lift(forms.convection.assemble(fb, convection_coefficient=h_r))
            A = A + H
            b = lift(forms.weighted_load.assemble(fb, weight=h_r))
            B[:, col[amb]] += b
            if full:
                radiation.append(RadiationTerm(group, facets.full_basis(group), eps, h_r, col[amb]))
            r_u = np.zeros(len(names))
            r_u[col[amb]] = b.sum()
            add_flow(f"radiation:{group}", np.asarray(H.sum(axis=0)).ravel(), r_u)

        nodes, cols, fixed_groups = _fixed_nodes(mesh, tets, self._fixed, col)
        fixed_matrix = sp.csr_matrix((np.ones(len(nodes)), (np.arange(len(nodes)), cols)),
                                     shape=(len(nodes), len(names)))
        return ThermalSystem(
            mass=sp.csr_matrix(M), stiffness=sp.csr_matrix(A), input_matrix=sp.csr_matrix(B),
            input_names=names, input_units=[INPUT_UNITS[self._inputs[k]] for k in names],
            mesh=mesh, tets=tets, node_of=node_of, fixed_nodes=nodes, fixed_matrix=fixed_matrix,
            radiation=radiation, heat_flows=flows, constant_inputs=dict(self._constants),
            fixed_groups=fixed_groups,
        )


class _FacetForms:
    """Facet bases for the boundary forms of :meth:`HeatProblem.assemble`, and the map back to thermal nodes.

    The facet forms are assembled on a mesh of only the tetrahedra under the
    facet groups used, with its own compact node numbering: scikit-fem then
    finds the facets of a few thousand elements instead of the whole mesh.
    :meth:`lift` maps the results back.
    """

    def __init__(self, mesh, skmesh, tets, element, used_groups, n):
        self.mesh, self.skmesh, self.tets, self.element = mesh, skmesh, tets, element
        self.n = n                  # thermal nodes (joint facets split mesh nodes)
        self._bases = {}
        if used_groups:
            under = np.unique(np.concatenate([mesh.facet_group(g)[0] for g in used_groups]))
            self.facet_nodes, local_tets = np.unique(tets[under], return_inverse=True)
            self.facet_mesh = MeshTet(np.ascontiguousarray(skmesh.p[:, self.facet_nodes]),
                                      np.ascontiguousarray(local_tets.reshape(-1, 4).T))
            element_of = np.full(len(tets), -1)
            element_of[under] = np.arange(len(under))
            self._facet_index = _skfem_facets(self.facet_mesh, mesh, tets, element_of, self.facet_nodes)

    def basis(self, group):
        """The (cached) facet basis of a boundary group on the facet mesh."""
        if group not in self._bases:
            self._bases[group] = FacetBasis(self.facet_mesh, self.element, intorder=2,
                                            facets=self._facet_index(*self.mesh.facet_group(group)))
        return self._bases[group]

    def lift(self, local):
        """A facet-mesh vector or matrix in the thermal node numbering."""
        n, facet_nodes = self.n, self.facet_nodes
        if sp.issparse(local):
            local = local.tocoo()
            return sp.csr_matrix((local.data, (facet_nodes[local.row], facet_nodes[local.col])), shape=(n, n))
        out = np.zeros(n)
        out[facet_nodes] = local
        return out

    def full_basis(self, group):
        """A facet basis on the whole mesh, for terms evaluated on thermal-node fields later."""
        return FacetBasis(self.skmesh, self.element, intorder=2,
                          facets=_skfem_facets(self.skmesh, self.mesh, self.tets)(*self.mesh.facet_group(group)))


def _fixed_nodes(mesh, tets, fixed, col):
    """(thermal nodes, input column of each, group → its nodes) of the fixed-temperature groups ``fixed``.

    A node on two fixed groups takes the value (and belongs to the group) of the last one given.
    """
    fixed_rows, fixed_cols, fixed_of = [], [], []
    for k, (group, name) in enumerate(fixed):
        tet, loc = mesh.facet_group(group)
        nodes = np.unique(tets[tet[:, None], LOCAL_FACES[loc]])
        fixed_rows.append(nodes)
        fixed_cols.append(np.full(len(nodes), col[name]))
        fixed_of.append(np.full(len(nodes), k))
    if not fixed_rows:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), {}
    nodes = np.concatenate(fixed_rows)
    cols = np.concatenate(fixed_cols)
    nodes, last = np.unique(nodes[::-1], return_index=True)
    cols = cols[::-1][last]
    owner = np.concatenate(fixed_of)[::-1][last]
    fixed_groups = {}
    for k, (group, _) in enumerate(fixed):
        fixed_groups[group] = np.union1d(fixed_groups.get(group, []), nodes[owner == k]).astype(np.int64)
    return nodes, cols, fixed_groups


def _skfem_facets(skmesh, mesh, thermal_tets, element_of=None, node_of=None):
    """Return a function mapping our (tet, local face) pairs to scikit-fem facet indices.

    When ``skmesh`` holds only some of our tetrahedra, ``element_of`` maps our
    tetrahedra to its elements and ``node_of`` its nodes to thermal nodes.
    """
    t2f = skmesh.t2f
    facets = np.sort(skmesh.facets if node_of is None else node_of[skmesh.facets], axis=0)

    def index(tet, local):
        ours = np.sort(thermal_tets[tet[:, None], LOCAL_FACES[local]], axis=1)
        cand = t2f[:, tet if element_of is None else element_of[tet]]      # (4, k)
        match = np.all(facets[:, cand].transpose(1, 2, 0) == ours[None], axis=2)  # (4, k)
        if not match.any(axis=0).all():
            raise FEAInputError("internal: a boundary facet has no scikit-fem facet")
        return cand[np.argmax(match, axis=0), np.arange(len(tet))]

    return index
