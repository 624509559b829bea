"""Fast simulation of the twin with effects switched on: a parametric reduced model, or the full FE.

Both backends run ``M Ṫ + (A₀ + Σ aᵢ dAᵢ) T = (B₀ + Σ aᵢ dBᵢ) u`` on a
uniform grid with input row k held over step k, (t_{k−1}, t_k] (zero-order
hold; the drive makes the source powers their exact interval means over the
step, :meth:`twin.gap.drive.Drive.step_mean`), from the steady state for an idle
start input plus optional initial-field shapes, and return the FE outputs
(°C, µm, µε; without the operator's constant offset).

:class:`ReducedBackend` (default)
    One Galerkin basis for the whole library (parametric model reduction by
    concatenation): the block-Krylov basis of the nominal system on all
    inputs (machine inputs and the effects' extra columns; via
    :func:`twin.rom.reduction.krylov_basis`), plus small Krylov bases of every
    system term's perturbed system at its parameter bounds, M-orthonormalised
    together.  The reduced matrices are affine in the coefficients, so one
    evaluation costs an r×r eigendecomposition and an exact ZOH recursion in
    modal coordinates (milliseconds).  The basis also maps back to nodes, for
    attribution, candidate sensors and renders.
:class:`FullBackend`
    The assembled FE system, backward Euler or θ-scheme, one factorisation
    per evaluation.  ``--backend fe`` of ``twin gap diagnose``, the reference
    in the tests, and the truth generator of the benchmark.
"""
from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from fea.linsolve import factorize

from ..rom.reduction import krylov_basis, slowest_rate

if TYPE_CHECKING:
    from .structure import Structure

@dataclass(frozen=True)
class Pencil:
    """The thermal system ``M Ṫ + A T = B u`` that :func:`twin.rom.reduction.krylov_basis` and
    :func:`~twin.rom.reduction.slowest_rate` reduce (they read ``n_nodes``, ``mass``, ``stiffness``,
    ``input_matrix``): the structure's nominal system or one perturbed by a system term."""

    mass: object
    stiffness: object
    input_matrix: object

    @property
    def n_nodes(self) -> int:
        """Number of thermal nodes n."""
        return self.mass.shape[0]


#: Default orders: the nominal Krylov basis, and the basis added per system term and bound.
NOMINAL_ORDER = 100
TERM_ORDER = 30


def _factor(matrix):
    return factorize(sp.csc_matrix(matrix), symmetric_positive_definite=True)


def m_orthonormal_union(mass: sp.spmatrix | np.ndarray, blocks: Sequence[np.ndarray],
                        tolerance: float = 1e-7) -> np.ndarray:
    """An M-orthonormal basis of the span of ``blocks`` (the first must be M-orthonormal already).

    Parameters
    ----------
    mass : sparse matrix or ndarray, shape (n, n)
        Mass matrix M, J/K.
    blocks : sequence of ndarray, shape (n, k_i)
        Bases to unite, on thermal nodes.
    tolerance : float, default 1e-7
        Directions of a block whose M-norm after orthogonalisation is below ``tolerance`` times the block's
        largest column M-norm are dropped.

    Returns
    -------
    ndarray, shape (n, r)
        V with Vᵀ M V = I, the first block's columns first.
    """
    V = np.asarray(blocks[0], float)
    for W in blocks[1:]:
        W = np.array(W, float, copy=True)
        ref = np.sqrt(np.maximum(np.einsum("ij,ij->j", W, mass @ W), 1e-300)).max()
        for _ in range(2):
            W -= V @ (V.T @ (mass @ W))
        G = W.T @ (mass @ W)
        lam, Q = np.linalg.eigh((G + G.T) / 2)
        keep = lam > (tolerance * ref) ** 2
        if keep.any():
            V = np.hstack([V, (W @ Q[:, keep]) / np.sqrt(lam[keep])])
    return V


class SimulationResult:
    """Modal states W (N, r) of one reduced run and the map to outputs; see :meth:`ReducedBackend.simulate`.

    Parameters
    ----------
    outputs : ndarray, shape (N, p_fe)
        FE outputs on the grid in edge units (°C, µm, µε), without the constant output offset.
    W : ndarray, shape (N, r), optional
        Modal states of a reduced run (None for the full FE).
    Q : ndarray, shape (r, r), optional
        Eigenvectors of the reduced stiffness: reduced coordinates = Q · modal states.
    backend : ReducedBackend or FullBackend, optional
        The backend that ran.
    field_outputs : dict of str to ndarray, shape (N, p_fe), optional
        Field name → free response of the outputs per unit field coefficient.
    """

    def __init__(self, outputs: np.ndarray, W: np.ndarray | None = None, Q: np.ndarray | None = None,
                 backend: ReducedBackend | FullBackend | None = None,
                 field_outputs: dict[str, np.ndarray] | None = None):
        self.outputs = outputs
        self.W, self.Q, self.backend = W, Q, backend
        self.field_outputs = field_outputs or {}

    def rows(self, reduced_rows: np.ndarray) -> np.ndarray:
        """Outputs (N, k) of other rows given in the reduced basis (k, r) (e.g. candidate thermometers).

        Parameters
        ----------
        reduced_rows : ndarray, shape (k, r)
            Output rows over thermal nodes times the basis (:meth:`ReducedBackend.reduce_rows`).

        Returns
        -------
        ndarray, shape (N, k)
            The rows' outputs on the grid (°C for rows that pick node temperatures).
        """
        return self.W @ (np.asarray(reduced_rows) @ self.Q).T


class ReducedBackend:
    """See the module docstring.  ``structure`` is a :class:`~twin.gap.structure.Structure`.

    Parameters
    ----------
    structure : Structure
        The full-order twin with the library's inputs, system terms and fields.
    nominal_order : int, default :data:`NOMINAL_ORDER`
        Order of the nominal block-Krylov basis (at most n_nodes − 1).
    term_order : int, default :data:`TERM_ORDER`
        Order of the basis added per system term and bound.
    keep_basis : bool, default True
        Keep the basis V (n_nodes, r) for :meth:`reduce_rows`.
    """

    name = "rom"

    def __init__(self, structure: Structure, nominal_order: int = NOMINAL_ORDER, term_order: int = TERM_ORDER,
                 keep_basis: bool = True):
        start = time.perf_counter()
        s = structure
        M, A0, B0 = s.mass, s.stiffness, s.input_matrix
        lam1 = slowest_rate(Pencil(M, A0, B0))
        points = [0.0, 10 * lam1, 100 * lam1, 1000 * lam1]
        order = min(nominal_order, s.n_nodes - 1)
        blocks = [krylov_basis(Pencil(M, A0, B0), order, points)]
        for name, param_values in self._term_values(s):
            dA, dB = s.system_terms[name][0], s.system_input_change(name)
            for a in param_values:
                blocks.append(krylov_basis(Pencil(M, A0 + a * dA, B0 + a * dB),
                                           min(term_order, s.n_nodes - 1), points[:2], uniform=False))
        for f in s.fields.values():
            blocks.append(f[:, None])
        V = m_orthonormal_union(M, blocks)
        self.order = V.shape[1]
        self.Ar0 = V.T @ (A0 @ V)
        self.dAr = {n: V.T @ (dA @ V) for n, (dA, _) in s.system_terms.items()}
        self.Br0 = np.asarray((B0.T @ V).T)
        self.dBr = {n: np.asarray((s.system_input_change(n).T @ V).T) for n in s.system_terms}
        self.Cr = np.asarray(s.output_matrix @ V)
        self.fields = {n: V.T @ (M @ f) for n, f in s.fields.items()}
        self.basis = V if keep_basis else None
        self.mass = M
        self.structure = s
        self.build_seconds = time.perf_counter() - start

    @staticmethod
    def _term_values(structure):
        """For each system term: the coefficients a at which its perturbed system is added to the basis."""
        out = []
        for name in structure.system_terms:
            bounds = structure.term_bounds.get(name, (-0.7, 2.0))
            out.append((name, [b for b in bounds if abs(b) > 1e-12]))
        return out

    def reduce_rows(self, rows: np.ndarray | sp.spmatrix) -> np.ndarray:
        """Rows over thermal nodes (k, n) in the reduced basis (k, r).

        Parameters
        ----------
        rows : ndarray or sparse matrix, shape (k, n_nodes)
            Output rows over thermal nodes.

        Returns
        -------
        ndarray, shape (k, r)
            The rows times the basis.

        Raises
        ------
        RuntimeError
            The backend was built with ``keep_basis=False``.
        """
        if self.basis is None:
            raise RuntimeError("the reduced backend was built without its basis")
        return np.asarray(sp.csr_matrix(rows) @ self.basis) if sp.issparse(rows) else np.asarray(rows) @ self.basis

    def simulate(self, U: np.ndarray, step_s: float, coefficients: Mapping[str, float] | None = None,
                 u0: np.ndarray | None = None, fields: Mapping[str, float] | None = None,
                 field_responses: Sequence[str] = ()) -> SimulationResult:
        """Outputs (N, p_fe) for inputs U (N, m) on a uniform grid of step ``step_s``.

        ``u0`` (m,): the steady start input (default U[0]); ``fields`` {name: coefficient}
        adds initial-field shapes to the start; ``field_responses`` names fields whose
        free responses (N, p_fe) per unit coefficient are returned too.

        Parameters
        ----------
        U : ndarray, shape (N, m)
            Inputs on the grid in the structure's input order (ambients °C, gradient K/m, powers W); row k is
            held over step k.
        step_s : float
            Grid step, s.
        coefficients : mapping of str to float, optional
            System term → coefficient a (A₀ + a dA, B₀ + a dB).
        u0 : ndarray, shape (m,), optional
            Input of the steady initial state.
        fields : mapping of str to float, optional
            Initial-field name → coefficient, K (times the field's shape), added to the start.
        field_responses : sequence of str, default ()
            Fields whose free responses are returned.

        Returns
        -------
        SimulationResult
            ``outputs`` (N, p_fe) in edge units (°C, µm, µε) without offset, the modal states, and
            ``field_outputs``.
        """
        coefficients = coefficients or {}
        Ar, Br = self.Ar0.copy(), self.Br0.copy()
        for name, a in coefficients.items():
            if a:
                Ar += a * self.dAr[name]
                Br += a * self.dBr[name]
        lam, Q = np.linalg.eigh((Ar + Ar.T) / 2)
        lam = np.maximum(lam, 1e-14)
        Bm = Q.T @ Br
        u0 = U[0] if u0 is None else u0
        w = (Bm @ u0) / lam
        for name, c in (fields or {}).items():
            w = w + c * (Q.T @ self.fields[name])
        F = U @ Bm.T
        e = np.exp(-lam * step_s)
        g = -np.expm1(-lam * step_s) / lam
        W = np.empty((len(U), len(lam)))
        W[0] = w
        gF = F * g
        for k in range(1, len(U)):
            w = e * w + gF[k]
            W[k] = w
        Cm = self.Cr @ Q
        out = W @ Cm.T
        responses = {}
        if field_responses:
            decay = np.exp(-np.outer(np.arange(len(U)) * step_s, lam))
            for name in field_responses:
                responses[name] = (decay * (Q.T @ self.fields[name])) @ Cm.T
        return SimulationResult(out, W, Q, self, responses)


class FullBackend:
    """The full FE system (see the module docstring); ``theta`` 1 = backward Euler, ½ = Crank–Nicolson.

    Parameters
    ----------
    structure : Structure
        The full-order twin with the library's inputs, system terms and fields.
    theta : float, default 1.0
        Implicitness of the θ-scheme.
    """

    name = "fe"

    def __init__(self, structure: Structure, theta: float = 1.0):
        self.structure = structure
        self.theta = float(theta)
        self.build_seconds = 0.0

    def system(self, coefficients: Mapping[str, float] | None) -> tuple[sp.csr_matrix, sp.csc_matrix]:
        """The system matrices with the system terms' coefficients applied.

        Parameters
        ----------
        coefficients : mapping of str to float or None
            System term → coefficient a.

        Returns
        -------
        A : scipy.sparse.csr_matrix, shape (n_nodes, n_nodes)
            A₀ + Σ aᵢ dAᵢ, W/K.
        B : scipy.sparse.csc_matrix, shape (n_nodes, m)
            B₀ + Σ aᵢ dBᵢ (maps the inputs to nodal heat flows, W).
        """
        s = self.structure
        A, B = s.stiffness, s.input_matrix
        for name, a in (coefficients or {}).items():
            if a:
                A = A + a * s.system_terms[name][0]
                B = B + a * s.system_input_change(name)
        return sp.csr_matrix(A), sp.csc_matrix(B)

    def simulate(self, U: np.ndarray, step_s: float, coefficients: Mapping[str, float] | None = None,
                 u0: np.ndarray | None = None, fields: Mapping[str, float] | None = None,
                 field_responses: Sequence[str] = ()) -> SimulationResult:
        """As :meth:`ReducedBackend.simulate`.

        Parameters
        ----------
        U : ndarray, shape (N, m)
            Inputs on the grid (ambients °C, gradient K/m, powers W).
        step_s : float
            Grid step, s.
        coefficients : mapping of str to float, optional
            System term → coefficient a.
        u0 : ndarray, shape (m,), optional
            Input of the steady initial state (default U[0]).
        fields : mapping of str to float, optional
            Initial-field name → coefficient, K, added to the start.
        field_responses : sequence of str, default ()
            Fields whose free responses are returned.

        Returns
        -------
        SimulationResult
            ``outputs`` (N, p_fe) in edge units without offset and ``field_outputs``; no modal states.
        """
        s = self.structure
        A, B = self.system(coefficients)
        M = s.mass
        th, h = self.theta, float(step_s)
        u0 = U[0] if u0 is None else u0
        T = _factor(A)(np.asarray(B @ u0).ravel())
        for name, c in (fields or {}).items():
            T = T + c * s.fields[name]
        names = list(field_responses)
        X = np.column_stack([T] + [s.fields[n] for n in names])
        lhs = _factor(M / h + th * A)
        explicit = sp.csr_matrix(M / h - (1 - th) * A)
        BU = np.asarray((B @ U.T).T) if sp.issparse(B) else U @ B.T
        C = s.output_matrix
        out = np.empty((len(U), C.shape[0]))
        resp = {n: np.empty((len(U), C.shape[0])) for n in names}

        def record(k):
            Y = np.asarray(C @ X)
            out[k] = Y[:, 0]
            for j, n in enumerate(names):
                resp[n][k] = Y[:, j + 1]

        record(0)
        for k in range(1, len(U)):
            rhs = explicit @ X
            rhs[:, 0] += th * BU[k] + (1 - th) * BU[k - 1]
            X = np.asarray(lhs(rhs)).reshape(X.shape)
            record(k)
        return SimulationResult(out, backend=self, field_outputs=resp)


def make_backend(structure: Structure, backend: str = "rom",
                 **options: int | float | bool) -> ReducedBackend | FullBackend:
    """A backend by name: ``rom`` (the parametric reduced model) or ``fe`` (full finite elements).

    Parameters
    ----------
    structure : Structure
        The full-order twin.
    backend : str, default "rom"
        ``rom`` (the reduced model) or ``fe`` (the full FE).
    **options : int, float or bool
        ``nominal_order``, ``term_order``, ``keep_basis`` (rom) or ``theta`` (fe); others are ignored.

    Returns
    -------
    ReducedBackend or FullBackend
        The backend, built.
    """
    if backend not in ("rom", "fe"):
        raise ValueError(f"unknown gap backend {backend!r}; use 'rom' or 'fe'")
    if backend == "rom":
        return ReducedBackend(structure, **{k: v for k, v in options.items()
                                            if k in ("nominal_order", "term_order", "keep_basis")})
    return FullBackend(structure, **{k: v for k, v in options.items() if k == "theta"})
