"""Quasi-static linear thermo-elasticity: supports, solves and adjoint influence operators.

    −∇·σ = 0,  σ = C : (ε(u) − α (T − T_ref) I)

Displacements are in m.  Because the thermal load is linear in T, any linear
output of the displacement, ``y = L u``, is a linear functional of the
temperature: ``y = L K⁻¹ F (T − T_ref) = G (T − T_ref)``.  ``influence``
computes the rows of G by one adjoint solve ``K z = Lᵀ`` per output, so a
transient run needs no elastic solve per step.
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from . import elastic_forms
from .errors import FEAInputError, require_finite
from .lagrange import LagrangeSpace, barycentric_gradients
from .linsolve import blas_threads, factorize
from .materials import ELASTIC_PROPERTIES, Material, per_tet, region_materials

if TYPE_CHECKING:
    from .elastic_forms import ThermalLoadOperator
    from .heat import ThermalSystem
    from .mesh import TetMesh

#: Below this many free dofs a sparse direct factorisation is used, above it AMG.
DIRECT_SOLVE_LIMIT = 20_000
#: Relative residual required of the iterative solves.
AMG_TOLERANCE = 1e-10

AXES = "xyz"


def rigid_body_modes(points: np.ndarray) -> np.ndarray:
    """The six rigid-body displacement fields on some points.

    Parameters
    ----------
    points : ndarray, shape (N, 3)
        Coordinates, m.

    Returns
    -------
    ndarray, shape (3N, 6)
        3 translations (m per m) and 3 rotations about the centroid (m per rad), interleaved dofs.
    """
    c = points - points.mean(axis=0)
    R = np.zeros((len(points), 3, 6))
    R[:, 0, 0] = R[:, 1, 1] = R[:, 2, 2] = 1.0
    R[:, 1, 3], R[:, 2, 3] = -c[:, 2], c[:, 1]      # rotation about x
    R[:, 0, 4], R[:, 2, 4] = c[:, 2], -c[:, 0]      # rotation about y
    R[:, 0, 5], R[:, 1, 5] = -c[:, 1], c[:, 0]      # rotation about z
    return R.reshape(-1, 6)


#: pyamg smoothed-aggregation settings for the elastic stiffness, with the rigid-body modes as the
#: near-null space.  Measured on 37k- and 141k-dof P1 meshes (bench/column_ram.py): Chebyshev
#: smoothing (degree 3) costs far less per CG iteration than the default block Gauss–Seidel;
#: a two-level hierarchy with a sparse LU coarse solve needs ~22 iterations for 1e-10, where a
#: deeper one needs ~30; Jacobi prolongation smoothing without candidate improvement sets up
#: in a third of the time of energy minimisation and costs only a few iterations more.
AMG_OPTIONS = dict(
    symmetry="symmetric",
    smooth=("jacobi", {"omega": 4.0 / 3.0}),
    improve_candidates=None,
    presmoother=("chebyshev", {"degree": 3}),
    postsmoother=("chebyshev", {"degree": 3}),
    max_coarse=3000,
    coarse_solver=("splu", {"permc_spec": "MMD_AT_PLUS_A", "diag_pivot_thresh": 0.0,
                            "options": {"SymmetricMode": True}}),
)


class _StiffnessSolver:
    """Solves K_ff x = b for many right-hand sides with one factorisation or one AMG hierarchy."""

    def __init__(self, K_ff, near_nullspace, backend=None):
        self.n = K_ff.shape[0]
        self.iterations = []
        if self.n <= DIRECT_SOLVE_LIMIT:
            self.kind = "direct"
            self._solve = factorize(K_ff, symmetric_positive_definite=True, backend=backend)
        else:
            import pyamg

            self.kind = "amg"
            self.K = sp.csr_matrix(K_ff)
            with blas_threads(1):
                self.hierarchy = pyamg.smoothed_aggregation_solver(self.K, B=near_nullspace, **AMG_OPTIONS)

    def __call__(self, b, tolerance=AMG_TOLERANCE, initial_guess=None):
        if self.kind == "direct":
            return self._solve(b)
        residuals = []
        with blas_threads(1):
            x = self.hierarchy.solve(b, x0=initial_guess, tol=tolerance, accel="cg", maxiter=1000,
                                     residuals=residuals)
            # pyamg stops silently at maxiter: check the true residual.
            relative = np.linalg.norm(b - self.K @ x) / max(np.linalg.norm(b), 1e-300)
        self.iterations.append(len(residuals) - 1)
        if relative > 100 * tolerance:
            raise RuntimeError(f"AMG-CG stopped at relative residual {relative:.1e} "
                               f"(required {tolerance:.0e}); the elastic solve did not converge")
        return x


class ElasticProblem:
    """Linear thermo-elastic problem on a :class:`~fea.mesh.TetMesh`.

    Parameters
    ----------
    mesh : TetMesh
        The mesh, m.
    materials : dict of int or str to Material
        Region → material (E in Pa, ν, α in 1/K used).
    degree : int
        1 or 2, the displacement element.
    reference_temperature : float
        T_ref, the stress-free temperature, °C.
    backend : str, optional
        Direct solver backend instead of AMG-CG (see :mod:`fea.linsolve`).
    """

    def __init__(self, mesh: TetMesh, materials: dict[int | str, Material], degree: int = 2,
                 reference_temperature: float = 20.0, backend: str | None = None) -> None:
        self.mesh = mesh
        self.space = LagrangeSpace(mesh.points, mesh.tets, degree)
        self.reference_temperature = float(require_finite("reference_temperature", reference_temperature))
        materials = region_materials(mesh, materials, ELASTIC_PROPERTIES, "an elastic problem")
        E = per_tet(mesh, materials, "youngs_modulus")
        nu = per_tet(mesh, materials, "poisson_ratio")
        self.lame_lambda = E * nu / ((1 + nu) * (1 - 2 * nu))
        self.lame_mu = E / (2 * (1 + nu))
        self.thermal_stress_modulus = per_tet(mesh, materials, "thermal_stress_modulus")
        self.backend = backend
        self._constrained = {}     # dof -> description
        self._stiffness = None
        self._solver = None
        self._load_operators = {}
        #: Timings (s) and solver facts of the assembly and solves done so far, for benchmarks.
        self.stats = {}
        self._geometry = None

    @property
    def _grad_lambda(self):
        """∇λ of each tetrahedron (m, 4, 3), computed when first needed (often in a background worker)."""
        if self._geometry is None:
            self._geometry = barycentric_gradients(self.mesh.points, self.mesh.tets)
        return self._geometry[0]

    @property
    def _volumes(self):
        self._grad_lambda
        return self._geometry[1]

    # ---------------------------------------------------------------- supports
    def _constrain(self, nodes, components, label):
        for axis in components:
            if axis not in AXES:
                raise FEAInputError(f"{label}: component {axis!r} is not one of 'x', 'y', 'z'")
            for node in np.atleast_1d(nodes):
                self._constrained[3 * int(node) + AXES.index(axis)] = label
        self._solver = None

    def add_point_support(self, point: np.ndarray, components: str = "xyz", tolerance: float = 1e-6,
                          name: str | None = None) -> int:
        """Fix displacement components at the mesh vertex at a point.

        The vertex must lie within ``tolerance`` of the point, so a support
        never lands silently somewhere else.

        Parameters
        ----------
        point : ndarray, shape (3,)
            Coordinates, m.
        components : str
            Fixed components, e.g. ``"xyz"``.
        tolerance : float
            Largest distance to the vertex, m.
        name : str, optional
            Named in errors.

        Returns
        -------
        int
            The vertex.
        """
        point = np.asarray(require_finite("support point", point), float)
        d = np.linalg.norm(self.mesh.points - point, axis=1)
        node = int(np.argmin(d))
        label = name or f"support at {tuple(point)}"
        if d[node] > tolerance:
            raise FEAInputError(f"{label}: no mesh vertex within {tolerance} m (nearest {d[node]:.3e} m away)")
        self._constrain(node, components, label)
        return node

    def add_kinematic_mount(self, first: np.ndarray, second: np.ndarray, third: np.ndarray,
                            tolerance: float = 1e-6) -> None:
        """A statically determinate 3-2-1 mount on three vertices that leaves free thermal growth unrestrained.

        The line first→second and the plane of the three points must be axis-aligned.

        Parameters
        ----------
        first : ndarray, shape (3,)
            Fixed in x, y, z; m.
        second : ndarray, shape (3,)
            Fixed in the two axes normal to the line first→second; m.
        third : ndarray, shape (3,)
            Fixed in the axis normal to the plane of the three points; m.
        tolerance : float
            Largest distance of each point to its vertex, m.
        """
        p = [np.asarray(x, float) for x in (first, second, third)]
        line = _axis_of(p[1] - p[0], "the line from the first to the second mount point")
        normal = _axis_of(np.cross(p[1] - p[0], p[2] - p[0]), "the normal of the mount plane")
        self.add_point_support(p[0], "xyz", tolerance, "3-2-1 mount point 1")
        self.add_point_support(p[1], AXES.replace(line, ""), tolerance, "3-2-1 mount point 2")
        self.add_point_support(p[2], normal, tolerance, "3-2-1 mount point 3")

    def add_fixed_face(self, group: str, components: str = "xyz") -> None:
        """Fix displacement components on every node of a facet group.

        Parameters
        ----------
        group : str
            A facet group of the mesh.
        components : str
            Fixed components, e.g. ``"xyz"``.
        """
        nodes = self.space.facet_nodes(*self.mesh.facet_group(group))
        self._constrain(nodes, components, f"fixed face {group!r}")

    def add_roller_face(self, group: str) -> None:
        """Fix the normal displacement on a planar, axis-aligned facet group (it may slide in-plane).

        Parameters
        ----------
        group : str
            A facet group of the mesh.
        """
        tet, local = self.mesh.facet_group(group)
        _, normals, _ = self.mesh.facet_geometry(tet, local)
        axis = _axis_of(normals.mean(axis=0), f"roller face {group!r}")
        if np.abs(normals[:, AXES.index(axis)]).min() < 1 - 1e-6:
            raise FEAInputError(f"roller face {group!r} is not planar: its normals vary")
        self._constrain(self.space.facet_nodes(tet, local), axis, f"roller face {group!r}")

    # ---------------------------------------------------------------- assembly
    @property
    def n_dofs(self) -> int:
        """Number of displacement dofs, 3 per node of the space."""
        return 3 * self.space.n_nodes

    @property
    def stiffness(self) -> sp.csr_matrix:
        """The stiffness matrix K (3N × 3N, N/m), assembled once."""
        if self._stiffness is None:
            start = time.perf_counter()
            self._stiffness = elastic_forms.elastic_stiffness(
                self.space, self._grad_lambda, self._volumes, self.lame_lambda, self.lame_mu)
            self.stats["stiffness_s"] = time.perf_counter() - start
        return self._stiffness

    def thermal_load_operator(self, thermal_system: ThermalSystem | None = None) -> ThermalLoadOperator:
        """F with ``F (T − T_ref)`` the thermal load vector.

        Parameters
        ----------
        thermal_system : ThermalSystem, optional
            Whose thermal nodes the temperature is on (default: the mesh nodes).

        Returns
        -------
        ThermalLoadOperator
            F (3N × n_thermal, N/K), applied matrix-free: ``F @ x``, ``F.T @ z``
            (vectors or blocks) and ``tocsr()`` for the assembled matrix.
        """
        key = id(thermal_system)
        if key not in self._load_operators:
            if thermal_system is None:
                tets, n = self.mesh.tets, self.mesh.n_nodes
            else:
                tets, n = thermal_system.tets, thermal_system.n_nodes
            self._load_operators[key] = elastic_forms.ThermalLoadOperator(
                self.space, self._grad_lambda, self._volumes, self.thermal_stress_modulus, tets, n)
        return self._load_operators[key]

    def _check_supports(self):
        """Raise unless every connected body has its six rigid-body motions restrained."""
        if not self._constrained:
            raise FEAInputError("the elastic problem has no support: add a 3-2-1 mount, a fixed face or rollers")
        n_nodes = self.space.n_nodes
        en = self.space.element_nodes
        adjacency = sp.coo_matrix((np.ones(en.size - len(en)),
                                   (np.repeat(en[:, 0], en.shape[1] - 1), en[:, 1:].ravel())),
                                  shape=(n_nodes, n_nodes))
        n_bodies, body = connected_components(adjacency, directed=False)
        dofs = np.fromiter(self._constrained, dtype=np.int64)
        modes = rigid_body_modes(self.space.node_points)
        names = ["translation x", "translation y", "translation z",
                 "rotation about x", "rotation about y", "rotation about z"]
        for b in range(n_bodies):
            mine = dofs[body[dofs // 3] == b]
            nodes = np.flatnonzero(body == b)
            scale = np.ptp(self.space.node_points[nodes], axis=0).max() or 1.0
            R = modes[mine] / np.array([1, 1, 1, scale, scale, scale])
            gram = R.T @ R
            values, vectors = np.linalg.eigh(gram)
            free = values < 1e-10 * max(values.max(), 1.0)
            if free.any():
                motions = sorted({names[int(np.argmax(np.abs(vectors[:, k])))] for k in np.flatnonzero(free)})
                where = f" (body {b + 1} of {n_bodies})" if n_bodies > 1 else ""
                raise FEAInputError(f"the elastic supports are insufficient{where}: {', '.join(motions)} "
                                    "is not restrained")

    def _free_solver(self):
        if self._solver is None:
            self._check_supports()
            fixed = np.fromiter(self._constrained, dtype=np.int64)
            free = np.setdiff1d(np.arange(self.n_dofs), fixed)
            K_ff = sp.csr_matrix(self.stiffness[free][:, free])
            start = time.perf_counter()
            nullspace = rigid_body_modes(self.space.node_points)[free]
            solver = _StiffnessSolver(K_ff, nullspace, self.backend)
            self.stats.update(solver=solver.kind, solver_setup_s=time.perf_counter() - start)
            self._solver = (free, solver)
        return self._solver

    # ---------------------------------------------------------------- solves
    def prepare(self) -> ElasticProblem:
        """Assemble K and factorise it (or set up AMG) now, e.g. in a worker before the loads are known.

        Returns
        -------
        ElasticProblem
            ``self``.
        """
        self._free_solver()
        return self

    def solve_load(self, load: np.ndarray, tolerance: float = AMG_TOLERANCE,
                   initial_guess: np.ndarray | None = None) -> np.ndarray:
        """Displacements for a load, zero at the supports.

        Parameters
        ----------
        load : ndarray, shape (3N,) or (3N, k)
            Load vector(s), N.
        tolerance : float
            Relative residual at which the iterative (AMG-CG) solves stop
            (a direct factorisation ignores it).
        initial_guess : ndarray, shape (3N,), optional
            Start of the iterative solve (one load vector only), m.

        Returns
        -------
        ndarray, shape of ``load``
            Displacements, m.
        """
        free, solver = self._free_solver()
        load = np.asarray(load, dtype=float)
        out = np.zeros(load.shape)
        if load.ndim == 1:
            guess = None if initial_guess is None else np.asarray(initial_guess, float)[free]
            out[free] = solver(load[free], tolerance, guess)
        else:
            for k in range(load.shape[1]):
                out[free, k] = solver(load[free, k], tolerance)
        return out

    def thermal_load(self, temperature: np.ndarray, thermal_system: ThermalSystem | None = None) -> np.ndarray:
        """The load vector of a temperature field.

        Parameters
        ----------
        temperature : ndarray
            Temperature on the thermal nodes, °C.
        thermal_system : ThermalSystem, optional
            Whose thermal nodes the temperature is on (default: the mesh nodes).

        Returns
        -------
        ndarray, shape (3N,)
            Load, N.
        """
        T = require_finite("temperature", temperature)
        return self.thermal_load_operator(thermal_system) @ (T - self.reference_temperature)

    def displacement(self, temperature: np.ndarray, thermal_system: ThermalSystem | None = None) -> np.ndarray:
        """The displacement field of a temperature field, by a forward solve.

        Parameters
        ----------
        temperature : ndarray
            Temperature on the thermal nodes, °C.
        thermal_system : ThermalSystem, optional
            Whose thermal nodes the temperature is on (default: the mesh nodes).

        Returns
        -------
        ndarray, shape (N, 3)
            Displacement, m.
        """
        return self.solve_load(self.thermal_load(temperature, thermal_system)).reshape(-1, 3)

    def stress(self, displacement: np.ndarray, temperature: np.ndarray,
               thermal_system: ThermalSystem | None = None) -> np.ndarray:
        """Element-mean stress tensors.

        Parameters
        ----------
        displacement : ndarray
            Displacement, m (3N values).
        temperature : ndarray
            Temperature on the thermal nodes, °C.
        thermal_system : ThermalSystem, optional
            Whose thermal nodes the temperature is on (default: the mesh nodes).

        Returns
        -------
        ndarray, shape (m, 3, 3)
            Stress, Pa.
        """
        tets = self.mesh.tets if thermal_system is None else thermal_system.tets
        excess = np.asarray(temperature)[tets].mean(axis=1) - self.reference_temperature
        return elastic_forms.element_stress(self.space, self._grad_lambda, np.ravel(displacement), excess,
                                            self.lame_lambda, self.lame_mu, self.thermal_stress_modulus)

    def point_rows(self, points: np.ndarray, components: str | Sequence[str], names: list[str] | None = None,
                   snap_distance: float = 0.0) -> sp.csr_matrix:
        """Sparse rows evaluating displacement components at points.

        Parameters
        ----------
        points : ndarray, shape (k, 3)
            Coordinates, m.
        components : str or sequence of str
            The component (``x``, ``y``, ``z``) of each row.
        names : list of str, optional
            Names of the points, in errors.
        snap_distance : float
            How far outside the mesh a point may lie and be snapped onto it, m.

        Returns
        -------
        scipy.sparse.csr_matrix, shape (k, 3N)
            Row i gives ``components[i]`` of the displacement at ``points[i]``, m per m.
        """
        tet, lam = self.mesh.locate(points, names=names, snap_distance=snap_distance)
        values = self.space.shape_values(lam)                       # (k, nb)
        comp = np.array([AXES.index(c) for c in components])
        cols = 3 * self.space.element_nodes[tet] + comp[:, None]
        rows = np.repeat(np.arange(len(tet)), values.shape[1])
        return sp.csr_matrix((values.ravel(), (rows, cols.ravel())), shape=(len(tet), self.n_dofs))

    def influence(self, rows: sp.spmatrix, thermal_system: ThermalSystem | None = None) -> np.ndarray:
        """Adjoint influence matrix G with ``rows @ u = G @ (T − T_ref)``: one adjoint solve per row.

        Parameters
        ----------
        rows : scipy.sparse matrix, shape (k, 3N)
            Output rows over the displacement dofs.
        thermal_system : ThermalSystem, optional
            Whose thermal nodes the temperature is on (default: the mesh nodes).

        Returns
        -------
        ndarray, shape (k, n_thermal)
            The rows' units per kelvin (m/K for displacement rows).
        """
        rows = sp.csr_matrix(rows)
        free, solver = self._free_solver()
        start = time.perf_counter()
        Z = self.solve_load(rows.T.toarray())                       # K symmetric: adjoint = forward
        G = np.asarray((self.thermal_load_operator(thermal_system).T @ Z).T)
        self.stats.update(influence_solve_s=time.perf_counter() - start,
                          iterations=list(getattr(solver, "iterations", [])))
        return G


def _axis_of(vector, label):
    v = np.asarray(vector, float)
    norm = np.linalg.norm(v)
    if norm == 0:
        raise FEAInputError(f"{label} is degenerate (the points coincide or are collinear)")
    k = int(np.argmax(np.abs(v)))
    if abs(v[k]) < (1 - 1e-9) * norm:
        raise FEAInputError(f"{label} is not aligned with an axis: direction {tuple(np.round(v / norm, 4))}")
    return AXES[k]
