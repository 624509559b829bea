"""Reduced-order real-time model (ROM) of a machine's thermal twin.

The full model is the LTI system of the finite-element twin

    M Ṫ + A T = B u,        y = C T + D u + c

(M, A symmetric positive definite; u = zone ambients °C, vertical ambient
gradient K/m, heat-source powers W; y = the machine's channels in edge units:
°C, µm, µε).  A ROM is a Galerkin projection T ≈ V x with an M-orthonormal
basis V (Vᵀ M V = I):

    ẋ = −Aᵣ x + Bᵣ u,       Aᵣ = Vᵀ A V (symmetric positive definite),  Bᵣ = Vᵀ B,  Cᵣ = C V

which is stable and passive by construction.  Two bases are offered:

``krylov`` (default)
    Block Krylov moment matching: block Arnoldi on the pencil at expansion
    points s₀ = 0 (steady state, exact DC gain) and a few positive points
    (moments of (A + sⱼM)⁻¹ B).  The uniform field 1 (= A⁻¹ Σ_zones B_ambient)
    is put first into the basis so that a uniform start temperature and every
    steady state for any constant input are represented exactly.
``modal``
    Modal truncation: the r slowest modes of A φ = λ M φ (shift-invert
    ``eigsh``), for comparison; no exact DC gain, no exact uniform state.

Whatever the basis, the reduced pencil is diagonalised once (Aᵣ = Q Λ Qᵀ), so
the ROM lives in *reduced modal coordinates* z: ż = −Λ z + B_z u, y = C_z z + D u + c.
Each coordinate is a first-order filter, so the zero-order-hold step is
exact for any step size h: z ← e^{−λh} z + (1 − e^{−λh})/λ · B_z u — no
matrix exponential is needed and a change of step size costs r exponentials.
The same θ-scheme as the FE solver is offered for like-for-like comparisons
(the error report uses it).

Inputs at the edges (operating conditions) map to u through the machine's
power models P = c·(n/n_ref)^b; the ROM stores those models, so it needs no
mesh at run time (:meth:`ReducedModel.inputs_from_conditions`).

A ROM saves to a versioned ``.npz`` (no pickle) and is cached under the
user cache folder keyed by a digest of the machine's matrices
(:func:`machine_digest`), so a change of mesh, materials, sources or output
operator (e.g. P1 → P2 elasticity) builds a new one, and a renamed copy of a
machine reuses it.  The cached file's SHA-256 is checked before it is read
(:mod:`meshes.cachefiles`); a corrupt one is reported and built again.
"""
from __future__ import annotations

import functools
import hashlib
import json
import time
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from numpy.typing import ArrayLike, NDArray

from fea.inputs import interval_means
from fea.linsolve import factorize
from fea.transient import step_grid
from meshes.cachefiles import checked, user_cache_dir, write_checked

from ..core.dataset import ChannelInfo, Dataset, json_default, project_version
from ..core.machine_definition import room_zone
from ..core.scenario import Scenario, load_scenario
from ..core.simulate import condition_channels
from ..errors import TwinInputError

if TYPE_CHECKING:
    from fea.heat import ThermalSystem

    from ..core.machine import Machine

FORMAT = "thermal-twin-rom"
FORMAT_VERSION = 1
METHODS = ("krylov", "modal")
DEFAULT_ORDER = 80
#: Expansion points (1/s) of the Krylov basis besides s = 0, chosen per machine from its slowest
#: time constant τ₁ unless given: s = 0, 1/τ₁·{10, 100, 1000} spread the order over the hours to
#: seconds range of machine-tool thermal dynamics.
DEFAULT_POINT_FACTORS = (0.0, 10.0, 100.0, 1000.0)
DEFAULT_N_POINTS = len(DEFAULT_POINT_FACTORS)
#: Relative M-norm below which a new Krylov direction counts as linearly dependent (deflated).
DEFLATION_TOLERANCE = 1e-9
DEFAULT_KINDS = ("temperature", "air", "displacement", "strain")


class ROMError(TwinInputError):
    """A reduced model cannot be built or used as asked (order too high, Krylov breakdown, bad input)."""


# ----------------------------------------------------------------------------- helpers
def machine_digest(machine: Machine) -> str:
    """SHA-256 (16 hex) of everything the ROM depends on: M, A, B, C, c, D, names and power models.

    Parameters
    ----------
    machine : Machine
        A built machine.

    Returns
    -------
    str
        16 hex digits.
    """
    h = hashlib.sha256()
    system = machine.thermal
    for m in (system.mass, system.stiffness, system.input_matrix, machine.outputs.matrix):
        m = sp.csr_matrix(m)
        for a in (m.indptr, m.indices, m.data, np.array(m.shape)):
            h.update(np.ascontiguousarray(a).tobytes())
    h.update(np.ascontiguousarray(machine.outputs.offset, float).tobytes())
    h.update(np.ascontiguousarray(machine.feedthrough, float).tobytes())
    h.update(json.dumps([system.input_names, [c.name for c in machine.channels],
                         [c.scale for c in machine.channels], _source_models(machine)]).encode())
    h.update(f"rom-format-{FORMAT_VERSION}".encode())
    return h.hexdigest()[:16]


def _source_models(machine):
    return [dict(name=s.name, driver=s.driver, coefficient_W=float(s.coefficient_W),
                 reference=float(s.reference), exponent=float(s.exponent))
            for s in machine.definition.sources]


def _check_lti(system):
    if system.radiation:
        raise ROMError("the thermal system has T⁴ radiation, which is nonlinear: no LTI reduced model")
    if len(system.fixed_nodes):
        raise ROMError("the thermal system has fixed-temperature nodes; the ROM supports convection-"
                       "anchored systems only (no Dirichlet lifting)")


def _start_vector(n):
    """A seeded start vector for ARPACK: without one it draws its own, and a rebuilt ROM differs in the last digits."""
    return np.random.default_rng(0).standard_normal(n)


def _spd_factor(matrix):
    return factorize(sp.csc_matrix(matrix), symmetric_positive_definite=True)


class _MOrthonormalBasis:
    """An M-orthonormal basis grown block by block (classical Gram–Schmidt, twice, plus deflation)."""

    def __init__(self, mass, capacity):
        self.M = mass
        self.n = mass.shape[0]
        self.V = np.empty((self.n, capacity))
        self.MV = np.empty((self.n, capacity))
        self.k = 0

    def add(self, W, limit):
        """M-orthonormalise the columns of W against the basis; append at most ``limit`` new ones.

        Returns the appended block (n, j), j ≤ limit (0 when W lies in the span).
        """
        W = np.array(W, dtype=float, copy=True).reshape(self.n, -1)
        MW = self.M @ W
        norms0 = np.sqrt(np.maximum(np.einsum("ij,ij->j", W, MW), 0.0))
        added = []
        for j in range(W.shape[1]):
            if len(added) >= limit:
                break
            w = W[:, j]
            ref = norms0[j]
            if ref == 0.0:
                continue
            for _ in range(2):
                if self.k:
                    w = w - self.V[:, :self.k] @ (self.MV[:, :self.k].T @ w)
            mw = self.M @ w
            norm = float(np.sqrt(max(w @ mw, 0.0)))
            if norm <= DEFLATION_TOLERANCE * ref:
                continue
            self.V[:, self.k] = w / norm
            self.MV[:, self.k] = mw / norm
            self.k += 1
            added.append(self.k - 1)
        return self.V[:, added]

    @property
    def basis(self):
        return self.V[:, :self.k]


def krylov_basis(system: ThermalSystem, order: int, points: Sequence[float], uniform: bool = True
                 ) -> NDArray[np.float64]:
    """M-orthonormal block-Krylov basis (n, order) of the pencil (A + sM)⁻¹ at the expansion ``points``.

    The blocks are taken round-robin over the points: the first block of each
    point, then the second of each, … so that every point contributes about
    order/len(points) directions.  Raises :class:`ROMError` when the order
    exceeds the number of unknowns or the Krylov spaces of all points are
    exhausted (breakdown: an invariant subspace smaller than the order).

    Parameters
    ----------
    system : ThermalSystem
        The FE thermal system (M, A, B).
    order : int
        Number of basis vectors r.
    points : sequence of float
        Expansion points s ≥ 0, 1/s.
    uniform : bool, default True
        Put the uniform field 1 first.

    Returns
    -------
    ndarray, shape (n_nodes, order)
        V with Vᵀ M V = I.
    """
    n = system.n_nodes
    A, M = sp.csr_matrix(system.stiffness), sp.csr_matrix(system.mass)
    B = np.asarray(system.input_matrix.todense()) if sp.issparse(system.input_matrix) else np.asarray(
        system.input_matrix, float)
    if order > n:
        raise ROMError(f"ROM order {order} exceeds the {n} thermal unknowns of this mesh; "
                       f"choose an order ≤ {n}")
    basis = _MOrthonormalBasis(M, order)
    if uniform:
        basis.add(np.ones(n), 1)
    solvers = [_spd_factor(A + s * M) if s else _spd_factor(A) for s in points]
    blocks = [np.asarray(solve(B)).reshape(n, -1) for solve in solvers]
    alive = [True] * len(points)
    while basis.k < order:
        if not any(alive):
            raise ROMError(f"the Krylov space broke down at dimension {basis.k} < order {order} "
                           f"(expansion points {list(points)}): the inputs reach no more directions; "
                           f"choose an order ≤ {basis.k}")
        for i, solve in enumerate(solvers):
            if not alive[i] or basis.k >= order:
                continue
            new = basis.add(blocks[i], order - basis.k)
            if new.shape[1] == 0:
                alive[i] = False
                continue
            blocks[i] = np.asarray(solve(M @ new)).reshape(n, -1)
    return basis.basis


def modal_basis(system: ThermalSystem, order: int) -> NDArray[np.float64]:
    """The ``order`` slowest M-orthonormal modes of A φ = λ M φ (shift-invert about 0).

    Parameters
    ----------
    system : ThermalSystem
        The FE thermal system.
    order : int
        Number of modes, < n_nodes − 1.

    Returns
    -------
    ndarray, shape (n_nodes, order)
        Modes, slowest first, M-orthonormal to machine precision.
    """
    n = system.n_nodes
    if order >= n - 1:
        raise ROMError(f"modal ROM order {order} is too high for the {n} thermal unknowns of this mesh "
                       f"(eigsh needs order < n − 1 = {n - 1})")
    A, M = sp.csc_matrix(system.stiffness), sp.csc_matrix(system.mass)
    solve = _spd_factor(A)
    OPinv = sla.LinearOperator(A.shape, matvec=lambda x: solve(np.asarray(x, float)), dtype=float)
    lam, phi = sla.eigsh(A, k=order, M=M, sigma=0.0, which="LM", OPinv=OPinv, tol=1e-10, v0=_start_vector(n))
    idx = np.argsort(lam)
    phi = phi[:, idx]
    # eigsh returns M-orthonormal vectors to its tolerance; re-orthonormalise to machine precision.
    G = phi.T @ (M @ phi)
    L = np.linalg.cholesky((G + G.T) / 2)
    return np.linalg.solve(L, phi.T).T


def slowest_rate(system: ThermalSystem) -> float:
    """Smallest eigenvalue λ₁ (1/s) of A φ = λ M φ: 1/λ₁ is the slowest thermal time constant.

    Parameters
    ----------
    system : ThermalSystem
        The FE thermal system.

    Returns
    -------
    float
        λ₁, 1/s.
    """
    A, M = sp.csc_matrix(system.stiffness), sp.csc_matrix(system.mass)
    solve = _spd_factor(A)
    OPinv = sla.LinearOperator(A.shape, matvec=lambda x: solve(np.asarray(x, float)), dtype=float)
    lam = sla.eigsh(A, k=1, M=M, sigma=0.0, which="LM", OPinv=OPinv, tol=1e-8, return_eigenvectors=False,
                    v0=_start_vector(A.shape[0]))
    return float(lam[0])


# ----------------------------------------------------------------------------- the model
@dataclass
class StateSpace:
    """ẋ = A x + B u, y = C x + D u + offset (continuous time); x0 for a uniform 1 °C start.

    Attributes
    ----------
    A, B, C, D : ndarray
        Continuous-time matrices (A in 1/s); outputs in their units (°C, µm, µε).
    offset : ndarray, shape (p,)
        Output offset.
    uniform_state : ndarray
        State of a uniform 1 °C start.
    input_names, output_names, output_units : list of str
        Names of u and y, and y's units.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    offset: np.ndarray
    uniform_state: np.ndarray
    input_names: list
    output_names: list
    output_units: list

    def initial_state(self, temperature_C: float) -> NDArray[np.float64]:
        """State of a uniform start at ``temperature_C`` (exact for a Krylov ROM).

        Parameters
        ----------
        temperature_C : float
            Uniform temperature, °C.

        Returns
        -------
        ndarray
            The state.
        """
        return float(temperature_C) * self.uniform_state


@dataclass
class ReducedModel:
    """A reduced model in reduced modal coordinates: ż = −λ ⊙ z + B u, y = C z + D u + offset.

    ``outputs`` are channels in edge units (°C, µm, µε) named ``output_names``;
    inputs are the thermal system's inputs ``input_names`` (ambients °C,
    gradient K/m, powers W).  ``basis`` (n, r), when kept, maps z back to the
    temperature field: T ≈ basis @ z.
    """

    method: str
    eigenvalues: np.ndarray          # λ (r,), 1/s
    input_matrix: np.ndarray         # (r, m)
    output_matrix: np.ndarray        # (p, r)
    feedthrough: np.ndarray          # (p, m)
    offset: np.ndarray               # (p,)
    uniform_state: np.ndarray        # (r,): coordinates of T ≡ 1 °C (its M-projection for modal)
    input_names: list
    output_names: list
    output_units: list
    output_kinds: list
    zones: list
    sources: list                    # power models, see machine_definition.HeatSource
    limits: dict                     # max_spindle_rpm, max_feed_mm_min
    machine: str
    digest: str
    info: dict = field(default_factory=dict)
    basis: np.ndarray | None = None
    zone_lags_s: dict = field(default_factory=dict)   # zones whose air lags the room (s), as the machine says
    output_labels: list = field(default_factory=list)  # per output: the sensor's label and position (text)

    # ------------------------------------------------------------------ shape
    @property
    def order(self) -> int:
        """Number of states r."""
        return len(self.eigenvalues)

    @property
    def n_inputs(self) -> int:
        """Number of thermal inputs m."""
        return len(self.input_names)

    @property
    def n_outputs(self) -> int:
        """Number of outputs p."""
        return len(self.output_names)

    def output_index(self, name: str) -> int:
        """Position of an output channel.

        Parameters
        ----------
        name : str
            Channel name (``Z``, ``T05`` …).

        Returns
        -------
        int

        Raises
        ------
        ROMError
            For an unknown name (the message lists the outputs).
        """
        try:
            return self.output_names.index(name)
        except ValueError:
            raise ROMError(f"unknown ROM output {name!r}; outputs: {self.output_names}") from None

    def __repr__(self):
        return (f"ReducedModel({self.method}, order {self.order}, {self.n_inputs} inputs, "
                f"{self.n_outputs} outputs, machine {self.machine!r})")

    # ------------------------------------------------------------------ state space
    def state_space(self) -> StateSpace:
        """Continuous-time ``StateSpace`` (A, B, C, D, offset) on the thermal inputs u, in modal coordinates.

        Returns
        -------
        StateSpace
            Copies; A = −diag λ (1/s).
        """
        return StateSpace(-np.diag(self.eigenvalues), self.input_matrix.copy(), self.output_matrix.copy(),
                          self.feedthrough.copy(), self.offset.copy(), self.uniform_state.copy(),
                          list(self.input_names), list(self.output_names), list(self.output_units))

    def uniform(self, temperature_C: float) -> NDArray[np.float64]:
        """State of a uniform temperature field (°C); exact for a Krylov ROM (1 is in its basis).

        Parameters
        ----------
        temperature_C : float
            Uniform temperature, °C.

        Returns
        -------
        ndarray, shape (r,)
        """
        return float(temperature_C) * self.uniform_state

    def steady_state(self, u: ArrayLike) -> NDArray[np.float64]:
        """Steady state for a constant input vector ``u`` (exact DC gain for a Krylov ROM).

        Parameters
        ----------
        u : array_like, shape (m,)
            Thermal inputs (°C, K/m, W).

        Returns
        -------
        ndarray, shape (r,)
        """
        return (self.input_matrix @ np.asarray(u, float)) / self.eigenvalues

    def project(self, T: ArrayLike, mass: sp.spmatrix | NDArray[np.float64]) -> NDArray[np.float64]:
        """State of a temperature field T (n,) by M-orthogonal projection (needs the kept ``basis``).

        Parameters
        ----------
        T : array_like, shape (n,)
            Nodal temperatures, °C.
        mass : sparse matrix or ndarray, shape (n, n)
            The FE capacity matrix M.

        Returns
        -------
        ndarray, shape (r,)

        Raises
        ------
        ROMError
            If the ROM has no basis.
        """
        if self.basis is None:
            raise ROMError("this ROM was saved without its basis; it cannot project temperature fields")
        return self.basis.T @ (mass @ np.asarray(T, float))

    def outputs(self, z: ArrayLike, u: ArrayLike) -> NDArray[np.float64]:
        """Outputs (p,) or (k, p) for states z (r,)/(k, r) and inputs u (m,)/(k, m).

        Parameters
        ----------
        z : array_like, shape (r,) or (k, r)
            States.
        u : array_like, shape (m,) or (k, m)
            Thermal inputs (°C, K/m, W).

        Returns
        -------
        ndarray, shape (p,) or (k, p)
            Outputs in their units (°C, µm, µε).
        """
        z, u = np.asarray(z, float), np.asarray(u, float)
        return z @ self.output_matrix.T + u @ self.feedthrough.T + self.offset

    # ------------------------------------------------------------------ operating conditions → u
    def inputs_from_conditions(self, spindle_rpm: ArrayLike, feed_mm_min: dict[str, ArrayLike] | None,
                               ambient_C: dict[str, ArrayLike] | ArrayLike,
                               gradient_K_per_m: ArrayLike = 0.0) -> NDArray[np.float64]:
        """Thermal inputs (k, m) from operating conditions, as :meth:`twin.core.machine.Machine.input_matrix`.

        ``spindle_rpm`` (k,), ``feed_mm_min`` dict axis → (k,), ``ambient_C``
        dict zone → (k,) (or a number/array for every zone), ``gradient_K_per_m``.

        Parameters
        ----------
        spindle_rpm : array_like, shape (k,)
            Spindle speed, rpm.
        feed_mm_min : dict of str to array_like, or None
            Axis (``x``, ``y``, ``z``) → feed, mm/min; a missing axis is 0.
        ambient_C : dict of str to array_like, or array_like
            Zone → air temperature, °C, or one value for every zone.
        gradient_K_per_m : array_like, default 0.0
            Vertical ambient gradient, K/m.

        Returns
        -------
        ndarray, shape (k, m)
            Columns as :attr:`input_names` (°C, K/m, W).

        Raises
        ------
        ROMError
            For a zone without an ambient.
        """
        rpm = np.atleast_1d(np.asarray(spindle_rpm, float))
        k = len(rpm)
        feeds = {a: np.broadcast_to(np.asarray((feed_mm_min or {}).get(a, 0.0), float), (k,)) for a in "xyz"}
        if not isinstance(ambient_C, dict):
            ambient_C = {z: ambient_C for z in self.zones}
        U = np.zeros((k, self.n_inputs))
        for zone in self.zones:
            if zone not in ambient_C:
                raise ROMError(f"no ambient given for zone {zone!r}; zones: {self.zones}")
            U[:, self.input_names.index(f"ambient:{zone}")] = ambient_C[zone]
        U[:, self.input_names.index("ambient_gradient")] = gradient_K_per_m
        for src in self.sources:
            U[:, self.input_names.index(f"power:{src['name']}")] = source_power(src, rpm, feeds)
        return U

    # ------------------------------------------------------------------ time integration
    def simulate(self, times_s: ArrayLike, inputs: ArrayLike, z0: ArrayLike, scheme: Literal["zoh", "theta"] = "zoh",
                 theta: float = 1.0) -> NDArray[np.float64]:
        """Outputs (k, p) at ``times_s`` from inputs (k, m) and the initial state ``z0``.

        ``scheme="zoh"``: exact for inputs held piecewise constant — ``inputs[i]``
        acts over [tᵢ, tᵢ₊₁) (the last row is not used by the state).  The output
        at tᵢ (i ≥ 1) uses the input last applied, ``inputs[i−1]``, as an FMU
        reports it after ``doStep``; at t₀ it uses ``inputs[0]``.

        ``scheme="theta"``: the FE solver's θ-method on the same grid with
        inputs sampled at the step ends (θ = 1 backward Euler); outputs at tᵢ use ``inputs[i]``.

        Parameters
        ----------
        times_s : array_like, shape (k,)
            Strictly increasing times, s.
        inputs : array_like, shape (k, m)
            Thermal inputs (°C, K/m, W).
        z0 : array_like, shape (r,)
            State at ``times_s[0]``.
        scheme : {"zoh", "theta"}, default "zoh"
            Time stepping (above).
        theta : float, default 1.0
            θ of the θ-method.

        Returns
        -------
        ndarray, shape (k, p)
            Outputs in their units (°C, µm, µε).
        """
        z, Z = self.states(times_s, inputs, z0, scheme, theta)
        U = np.asarray(inputs, float)
        if scheme == "zoh":
            U = np.vstack([U[:1], U[:-1]])
        return self.outputs(Z, U)

    def states(self, times_s: ArrayLike, inputs: ArrayLike | None, z0: ArrayLike,
               scheme: Literal["zoh", "theta"] = "zoh", theta: float = 1.0,
               means: ArrayLike | None = None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Final state and the states (k, r) at ``times_s`` (see :meth:`simulate`).

        ``means`` (k − 1, m), when given, are the inputs driving each step
        instead of ``inputs``: their mean over the step (held over it by
        ``zoh``, or as the θ-method's ū), so each step gets exactly ∫ u dt.

        Parameters
        ----------
        times_s : array_like, shape (k,)
            Strictly increasing times, s.
        inputs : array_like, shape (k, m), or None
            Thermal inputs (°C, K/m, W); not used when ``means`` is given.
        z0 : array_like, shape (r,)
            State at ``times_s[0]``.
        scheme : {"zoh", "theta"}, default "zoh"
            Time stepping.
        theta : float, default 1.0
            θ of the θ-method.
        means : array_like, shape (k - 1, m), optional
            Step means of the inputs.

        Returns
        -------
        final : ndarray, shape (r,)
            The state at the last time.
        states : ndarray, shape (k, r)
            The states at ``times_s``.

        Raises
        ------
        ROMError
            An unknown scheme, a row count that does not match the times, non-finite inputs, or times that
            do not increase.
        """
        t = np.asarray(times_s, float)
        if scheme not in ("zoh", "theta"):
            raise ROMError(f"unknown scheme {scheme!r}; use 'zoh' or 'theta'")
        U = np.asarray(inputs if means is None else means, float).reshape(-1, self.n_inputs)
        if len(U) != len(t) - (means is not None):
            raise ROMError(f"{len(U)} rows of ROM inputs for {len(t)} times")
        if not np.all(np.isfinite(U)):
            raise ROMError("ROM inputs contain NaN or infinite values")
        if np.any(np.diff(t) <= 0):
            raise ROMError("ROM times must increase strictly")
        W = U @ self.input_matrix.T                       # (k, r) forcing per coordinate
        Z = np.empty((len(t), self.order))
        Z[0] = z0
        if len(t) == 1:
            return Z[0], Z
        dt = np.diff(t)
        uniform = np.allclose(dt, dt[0], rtol=1e-12, atol=0.0)
        if means is not None:
            forcing = W
        elif scheme == "zoh":
            forcing = W[:-1]
        else:
            forcing = theta * W[1:] + (1.0 - theta) * W[:-1]
        if uniform:
            a, g = self._step_coefficients(dt[0], scheme, theta)
            from scipy.signal import lfilter

            for i in range(self.order):
                Z[1:, i] = lfilter([g[i]], [1.0, -a[i]], forcing[:, i], zi=[a[i] * Z[0, i]])[0]
        else:
            z = np.array(z0, float)
            for k, h in enumerate(dt):
                a, g = self._step_coefficients(h, scheme, theta)
                z = a * z + g * forcing[k]
                Z[k + 1] = z
        return Z[-1], Z

    def _step_coefficients(self, h, scheme="zoh", theta=1.0):
        lam = self.eigenvalues
        if scheme == "zoh":
            return np.exp(-lam * h), -np.expm1(-lam * h) / lam
        denom = 1.0 / h + theta * lam
        return (1.0 / h - (1.0 - theta) * lam) / denom, 1.0 / denom

    def discretize(self, step_s: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Exact ZOH discretisation for step h: (Φ, Γ) diagonal/dense with z⁺ = Φ z + Γ u.

        Parameters
        ----------
        step_s : float
            Step h, s.

        Returns
        -------
        Phi : ndarray, shape (r, r)
            Diagonal e^{−λh}.
        Gamma : ndarray, shape (r, m)
        """
        a, g = self._step_coefficients(float(step_s))
        return np.diag(a), g[:, None] * self.input_matrix

    # ------------------------------------------------------------------ plant inputs: zone lags as states
    @property
    def lagged_zones(self) -> list[str]:
        """Zones whose air follows the room through a first-order lag (``[[zones]] lag_h``), in zone order."""
        return [z for z in self.zones if float(self.zone_lags_s.get(z, 0.0)) > 0.0]

    @property
    def measured_zones(self) -> list[str]:
        """Zones whose ambient is a plant input (every zone but the lagged ones)."""
        return [z for z in self.zones if z not in self.lagged_zones]

    @property
    def plant_input_names(self) -> list[str]:
        """Inputs of the plant model: :attr:`input_names` without the lagged zones' ambients."""
        lagged = {f"ambient:{z}" for z in self.lagged_zones}
        return [n for n in self.input_names if n not in lagged]

    def _plant_layout(self):
        """(columns of the plant inputs in u, columns of the lagged ambients in u, the room's column in u_p)."""
        room = room_zone(self.zones)
        if room in self.lagged_zones:
            raise ROMError(f"zone {room!r} is the room, which the lagged zones follow; it cannot lag itself")
        plant = [self.input_names.index(n) for n in self.plant_input_names]
        lagged = [self.input_names.index(f"ambient:{z}") for z in self.lagged_zones]
        return plant, lagged, self.plant_input_names.index(f"ambient:{room}")

    def plant_inputs_from_conditions(self, spindle_rpm: ArrayLike, feed_mm_min: dict[str, ArrayLike] | None,
                                     ambient_C: dict[str, ArrayLike] | ArrayLike,
                                     gradient_K_per_m: ArrayLike = 0.0) -> NDArray[np.float64]:
        """Plant inputs (k, m_p) (:attr:`plant_input_names`) from conditions.

        As :meth:`inputs_from_conditions`, with ``ambient_C`` over :attr:`measured_zones` only.

        Parameters
        ----------
        spindle_rpm : array_like, shape (k,)
            Spindle speed, rpm.
        feed_mm_min : dict of str to array_like, or None
            Axis → feed, mm/min.
        ambient_C : dict of str to array_like, or array_like
            Measured zone → air temperature, °C (the lagged zones take the room's value here; they are
            dropped from the result), or one value for every zone.
        gradient_K_per_m : array_like, default 0.0
            Vertical ambient gradient, K/m.

        Returns
        -------
        ndarray, shape (k, m_p)
            Columns as :attr:`plant_input_names`.
        """
        if isinstance(ambient_C, dict):
            room = ambient_C.get(room_zone(self.zones))
            ambient_C = {**{z: room for z in self.lagged_zones}, **ambient_C}
        U = self.inputs_from_conditions(spindle_rpm, feed_mm_min, ambient_C, gradient_K_per_m)
        return U[:, self._plant_layout()[0]]

    def _full_inputs(self, Up, lag_air):
        """Thermal inputs u (k, m) from plant inputs (k, m_p) and the lagged zones' air (k, l)."""
        plant, lagged, _ = self._plant_layout()
        Up = np.atleast_2d(np.asarray(Up, float))
        U = np.zeros((len(Up), self.n_inputs))
        U[:, plant] = Up
        U[:, lagged] = np.atleast_2d(lag_air)
        return U

    def plant_state_space(self) -> StateSpace:
        """Continuous ``StateSpace`` on the plant inputs; states x = [z (r), lagged zone air (l), °C].

        ż = −λ ⊙ z + B_z u,  ẇ_l = (u_room − w_l)/τ_l,  y = C_z z + D u + offset, where u is
        the thermal input with each lagged zone's ambient replaced by its state w_l.  A, B, C, D
        are dense; ``uniform_state`` is the state of a uniform 1 °C machine in 1 °C air.

        Returns
        -------
        StateSpace
            On :attr:`plant_input_names`, r + l states.
        """
        plant, lagged, room = self._plant_layout()
        r, l = self.order, len(lagged)
        mu = np.array([1.0 / float(self.zone_lags_s[z]) for z in self.lagged_zones])
        A = np.zeros((r + l, r + l))
        A[:r, :r] = -np.diag(self.eigenvalues)
        A[:r, r:] = self.input_matrix[:, lagged]
        A[r:, r:] = -np.diag(mu)
        B = np.zeros((r + l, len(plant)))
        B[:r] = self.input_matrix[:, plant]
        B[r:, room] = mu
        C = np.hstack([self.output_matrix, self.feedthrough[:, lagged]])
        return StateSpace(A, B, C, self.feedthrough[:, plant].copy(), self.offset.copy(),
                          np.r_[self.uniform_state, np.ones(l)], self.plant_input_names, list(self.output_names),
                          list(self.output_units))

    def plant_uniform(self, temperature_C: float, room_C: float | None = None) -> NDArray[np.float64]:
        """Plant state of a uniform machine at ``temperature_C``, the lagged air at ``room_C`` (default the same).

        Parameters
        ----------
        temperature_C : float
            Machine temperature, °C.
        room_C : float, optional
            Air temperature of the lagged zones, °C.

        Returns
        -------
        ndarray, shape (r + l,)
        """
        room_C = temperature_C if room_C is None else room_C
        return np.r_[self.uniform(temperature_C), np.full(len(self.lagged_zones), float(room_C))]

    def plant_steady_state(self, u_plant: ArrayLike) -> NDArray[np.float64]:
        """Plant state in equilibrium with constant plant inputs (the lagged air at the room's).

        Parameters
        ----------
        u_plant : array_like, shape (m_p,)
            Plant inputs (°C, K/m, W).

        Returns
        -------
        ndarray, shape (r + l,)
        """
        u_plant = np.asarray(u_plant, float)
        w = np.full(len(self.lagged_zones), u_plant[self._plant_layout()[2]])
        return np.r_[self.steady_state(self._full_inputs(u_plant, w)[0]), w]

    def plant_outputs(self, x: ArrayLike, u_plant: ArrayLike) -> NDArray[np.float64]:
        """Outputs (p,) or (k, p) for plant states x (r + l,)/(k, ·) and plant inputs (m_p,)/(k, m_p).

        Parameters
        ----------
        x : array_like, shape (r + l,) or (k, r + l)
            Plant states.
        u_plant : array_like, shape (m_p,) or (k, m_p)
            Plant inputs.

        Returns
        -------
        ndarray, shape (p,) or (k, p)
            Outputs in their units (°C, µm, µε).
        """
        x = np.asarray(x, float)
        U = self._full_inputs(u_plant, np.atleast_2d(x)[:, self.order:])
        y = self.outputs(np.atleast_2d(x)[:, :self.order], U)
        return y if x.ndim == 2 else y[0]

    def plant_step_coefficients(self, h: float) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                         NDArray[np.float64], NDArray[np.float64]]:
        """Exact ZOH coefficients of the plant model for a step ``h`` (s): (a, g, e, E).

        a = e^{−λh}, g = (1 − e^{−λh})/λ per mode; e = e^{−h/τ} per lagged zone; E (r, l) =
        ∫₀ʰ e^{−λ(h−s)} e^{−s/τ} ds = (e^{−h/τ} − e^{−λh})/(λ − 1/τ), evaluated without
        cancellation.

        Parameters
        ----------
        h : float
            Step, s.

        Returns
        -------
        a, g : ndarray, shape (r,)
        e : ndarray, shape (l,)
        E : ndarray, shape (r, l)
        """
        lam = self.eigenvalues
        mu = np.array([1.0 / float(self.zone_lags_s[z]) for z in self.lagged_zones])
        a, g = self._step_coefficients(float(h))
        d = lam[:, None] - mu[None, :]
        slow = np.minimum(lam[:, None], mu[None, :])
        with np.errstate(invalid="ignore", divide="ignore"):
            E = np.where(d == 0.0, h, -np.expm1(-np.abs(d) * h) / np.abs(d)) * np.exp(-slow * h)
        return a, g, np.exp(-mu * h), E

    def plant_states(self, times_s: ArrayLike, inputs: ArrayLike, x0: ArrayLike) -> NDArray[np.float64]:
        """States (k, r + l) at ``times_s`` for plant inputs (k, m_p), row i held over [tᵢ, tᵢ₊₁) (exact ZOH).

        The lagged zones' air w follows the held room value u_room exactly,
        w ← u_room + (w − u_room) e^{−h/τ}, and drives the modes through the cross term E.

        Parameters
        ----------
        times_s : array_like, shape (k,)
            Strictly increasing times, s.
        inputs : array_like, shape (k, m_p)
            Plant inputs (°C, K/m, W).
        x0 : array_like, shape (r + l,)
            Plant state at ``times_s[0]``.

        Returns
        -------
        ndarray, shape (k, r + l)

        Raises
        ------
        ROMError
            A row count that does not match the times, non-finite inputs, or times that do not increase.
        """
        t = np.asarray(times_s, float)
        Up = np.atleast_2d(np.asarray(inputs, float))
        if len(Up) != len(t):
            raise ROMError(f"{len(Up)} rows of plant inputs for {len(t)} times")
        if not np.all(np.isfinite(Up)):
            raise ROMError("ROM inputs contain NaN or infinite values")
        if np.any(np.diff(t) <= 0):
            raise ROMError("ROM times must increase strictly")
        _, lagged, room = self._plant_layout()
        r = self.order
        X = np.empty((len(t), r + len(lagged)))
        X[0] = x0
        Bl = self.input_matrix[:, lagged]
        cache = {}
        for k, h in enumerate(np.diff(t)):
            if h not in cache:
                cache[h] = self.plant_step_coefficients(h)
            a, g, e, E = cache[h]
            z, w = X[k, :r], X[k, r:]
            u_room = Up[k, room]
            W = self.input_matrix @ self._full_inputs(Up[k], np.full(len(lagged), u_room))[0]
            X[k + 1, :r] = a * z + g * W + (E * Bl) @ (w - u_room)
            X[k + 1, r:] = u_room + (w - u_room) * e
        return X

    # ------------------------------------------------------------------ persistence
    def save(self, path: Path | str, keep_basis: bool = False) -> Path:
        """Write a versioned ``.npz`` (no pickle); the basis only with ``keep_basis``.

        Written to a temporary file beside ``path`` and renamed (atomic); the folder is created.

        Parameters
        ----------
        path : Path or str
            The ``.npz`` file.
        keep_basis : bool, default False
            Also store V (n, r).

        Returns
        -------
        Path
            ``path``.
        """
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = dict(format=FORMAT, version=FORMAT_VERSION, method=self.method, input_names=self.input_names,
                    output_names=self.output_names, output_units=self.output_units,
                    output_kinds=self.output_kinds, zones=self.zones, zone_lags_s=self.zone_lags_s,
                    sources=self.sources, limits=self.limits, output_labels=self.output_labels,
                    machine=self.machine, digest=self.digest, info=self.info)
        arrays = dict(eigenvalues=self.eigenvalues, input_matrix=self.input_matrix,
                      output_matrix=self.output_matrix, feedthrough=self.feedthrough, offset=self.offset,
                      uniform_state=self.uniform_state, meta=np.array(json.dumps(meta, default=json_default)))
        if keep_basis and self.basis is not None:
            arrays["basis"] = self.basis
        tmp = path.with_name(path.name + ".partial.npz")
        np.savez(tmp, **arrays)
        tmp.replace(path)
        return path

    @classmethod
    def load(cls, path: Path | str) -> ReducedModel:
        """Read a ROM written by :meth:`save`; raise :class:`ROMError` on another format or version.

        Parameters
        ----------
        path : Path or str
            The ``.npz`` file.

        Returns
        -------
        ReducedModel

        Raises
        ------
        ROMError
            A missing, empty, truncated or foreign file, or another format or version.
        """
        path = Path(path)
        try:
            data = np.load(path, allow_pickle=False)
            meta = json.loads(str(data["meta"]))
        # missing/unreadable (OSError), empty (EOFError), not an npz or pickled or bad JSON (ValueError),
        # no "meta" in it (LookupError), a truncated or corrupt archive (BadZipFile)
        except (OSError, EOFError, ValueError, LookupError, zipfile.BadZipFile) as exc:
            raise ROMError(f"{path}: not a readable ROM file ({exc})") from None
        if meta.get("format") != FORMAT or meta.get("version") != FORMAT_VERSION:
            raise ROMError(f"{path}: ROM format {meta.get('format')!r} version {meta.get('version')!r}; "
                           f"this program reads {FORMAT!r} version {FORMAT_VERSION}")
        return cls(meta["method"], data["eigenvalues"], data["input_matrix"], data["output_matrix"],
                   data["feedthrough"], data["offset"], data["uniform_state"], meta["input_names"],
                   meta["output_names"], meta["output_units"], meta["output_kinds"], meta["zones"],
                   meta["sources"], meta["limits"], meta["machine"], meta["digest"], meta["info"],
                   data["basis"] if "basis" in data.files else None, meta.get("zone_lags_s", {}),
                   meta.get("output_labels", []))


def source_power(src: dict, spindle_rpm: ArrayLike, feed_mm_min: dict[str, ArrayLike]) -> NDArray[np.float64]:
    """Power (W) of a source model dict (see :class:`twin.core.machine_definition.HeatSource`).

    ``P = coefficient_W · (n / reference)^exponent`` with n the |speed| of the source's driver (the spindle,
    the fastest of the x/y or x/y/z feeds, or one axis), or the constant ``coefficient_W``.

    Parameters
    ----------
    src : dict
        ``driver``, ``coefficient_W`` (W), ``reference`` (rpm or mm/min), ``exponent``.
    spindle_rpm : array_like, shape (k,)
        Spindle speed, rpm.
    feed_mm_min : dict of str to array_like
        Axis → feed, mm/min (the axes the driver needs).

    Returns
    -------
    ndarray, shape (k,)
        Power, W.
    """
    rpm = np.asarray(spindle_rpm, float)
    driver = src["driver"]
    if driver == "constant":
        return src["coefficient_W"] * np.ones_like(rpm)
    if driver == "spindle":
        n = np.abs(rpm)
    elif driver == "feed_xy":
        n = np.maximum(np.abs(feed_mm_min["x"]), np.abs(feed_mm_min["y"]))
    elif driver == "feed_xyz":
        n = np.maximum.reduce([np.abs(feed_mm_min[a]) for a in "xyz"])
    else:
        n = np.abs(np.asarray(feed_mm_min[driver[-1]], float))
    return src["coefficient_W"] * (n / src["reference"]) ** src["exponent"]


# ----------------------------------------------------------------------------- building
def default_points(system: ThermalSystem, n_points: int = DEFAULT_N_POINTS) -> list[float]:
    """Expansion points 0 and λ₁·{10, 100, 1000, …} (1/s) with λ₁ the slowest thermal rate.

    Parameters
    ----------
    system : ThermalSystem
        The FE thermal system.
    n_points : int, default :data:`DEFAULT_N_POINTS` (4)
        Points taken from :data:`DEFAULT_POINT_FACTORS`.

    Returns
    -------
    list of float
        Points, 1/s.
    """
    lam1 = slowest_rate(system)
    return [f * lam1 for f in DEFAULT_POINT_FACTORS[:n_points]]


def compute_basis(machine: Machine, order: int, method: Literal["krylov", "modal"] = "krylov",
                  points: Sequence[float] | None = None) -> tuple[NDArray[np.float64], list[float]]:
    """The projection basis V (n, order) and the expansion points used (Krylov) or [] (modal).

    Bases are nested: the first r columns of an order-R basis are the order-r basis
    (the construction is sequential), which :func:`twin.rom.report.error_report` uses.

    Parameters
    ----------
    machine : Machine
        A built machine.
    order : int
        Number of basis vectors, ≥ 1.
    method : {"krylov", "modal"}, default "krylov"
        Reduction method.
    points : sequence of float, optional
        Krylov expansion points, 1/s (default :func:`default_points`).

    Returns
    -------
    V : ndarray, shape (n_nodes, order)
        M-orthonormal basis.
    points : list of float
        The Krylov points used, 1/s ([] for modal).

    Raises
    ------
    ROMError
        An unknown method, an order < 1 or too high, negative points, or a nonlinear system.
    """
    if method not in METHODS:
        raise ROMError(f"unknown ROM method {method!r}; methods: {list(METHODS)}")
    order = int(order)
    if order < 1:
        raise ROMError(f"ROM order must be a positive integer, got {order}")
    system = machine.thermal
    _check_lti(system)
    if method == "modal":
        return modal_basis(system, order), []
    points = [float(p) for p in (default_points(system) if points is None else points)]
    if any(p < 0 for p in points) or not points:
        raise ROMError(f"Krylov expansion points must be ≥ 0 (1/s), got {points}")
    return krylov_basis(system, order, points), points


def build_rom(machine: Machine, order: int = DEFAULT_ORDER, method: Literal["krylov", "modal"] = "krylov",
              points: Sequence[float] | None = None, kinds: Sequence[str] = DEFAULT_KINDS,
              keep_basis: bool = False) -> ReducedModel:
    """Reduce a built :class:`~twin.core.machine.Machine` to a :class:`ReducedModel` of ``order`` states.

    Parameters
    ----------
    order : number of states r (Krylov: includes the uniform field)
    method : ``"krylov"`` (block moment matching) or ``"modal"`` (modal truncation)
    points : Krylov expansion points in 1/s (default :func:`default_points`)
    kinds : channel kinds kept as outputs (``"camera"`` adds the 525 camera spots)
    keep_basis : keep V (n, r) in the model to project or reconstruct temperature fields

    Returns
    -------
    ReducedModel
        With ``info`` (build times, time constants, basis quality, points).
    """
    start = time.perf_counter()
    V, points = compute_basis(machine, order, method, points)
    basis_seconds = time.perf_counter() - start
    rom = reduce_with_basis(machine, V, method, kinds, keep_basis)
    rom.info.update(points_per_s=points, basis_seconds=basis_seconds, build_seconds=time.perf_counter() - start)
    return rom


def _reduced_outputs(machine, Vq, keep):
    """``(C, D, offset)`` of the kept channels (rows ``keep`` of the machine's channels) in modal coordinates.

    FE outputs read the modes (C); air channels feed through from the inputs (D); each row is scaled to its
    channel's unit.
    """
    n_fe = machine.outputs.n_outputs
    scale = np.array([machine.channels[j].scale for j in keep])
    rows_fe = [j for j in keep if j < n_fe]
    rows_air = [j - n_fe for j in keep if j >= n_fe]
    C = np.zeros((len(keep), Vq.shape[1]))
    D = np.zeros((len(keep), machine.thermal.n_inputs))
    c = np.zeros(len(keep))
    n_kept_fe = len(rows_fe)
    if rows_fe:
        C[:n_kept_fe] = np.asarray(sp.csr_matrix(machine.outputs.matrix)[rows_fe] @ Vq)
        c[:n_kept_fe] = machine.outputs.offset[rows_fe]
    if rows_air:
        D[n_kept_fe:] = machine.feedthrough[rows_air]
    return C * scale[:, None], D * scale[:, None], c * scale


def _basis_quality(M, V, Vq):
    """``(uniform state, uniform residual, orthonormality error)`` of an M-orthonormal basis.

    The uniform state holds the modal coordinates of a uniform 1 °C field; the residual is the M-norm of
    what the basis misses of it, relative; the orthonormality error is max |VᵀMV − I|.
    """
    ones = np.ones(M.shape[0])
    uniform = Vq.T @ (M @ ones)
    gap = ones - Vq @ uniform
    residual = float(np.sqrt((gap @ (M @ gap)) / (ones @ (M @ ones))))
    orth = float(np.abs(V.T @ (M @ V) - np.eye(V.shape[1])).max())
    return uniform, residual, orth


def reduce_with_basis(machine: Machine, V: NDArray[np.float64], method: str = "krylov",
                      kinds: Sequence[str] = DEFAULT_KINDS, keep_basis: bool = False) -> ReducedModel:
    """The :class:`ReducedModel` of a machine for an M-orthonormal basis V (n, r).

    Parameters
    ----------
    machine : Machine
        A built machine.
    V : ndarray, shape (n_nodes, r)
        M-orthonormal basis.
    method : str, default "krylov"
        Recorded in the model.
    kinds : sequence of str
        Channel kinds kept as outputs.
    keep_basis : bool, default False
        Keep the basis (rotated to modal coordinates) in the model.

    Returns
    -------
    ReducedModel

    Raises
    ------
    ROMError
        If the reduced stiffness is not positive definite (no heat path to an ambient).
    """
    start = time.perf_counter()
    system = machine.thermal
    A = sp.csr_matrix(system.stiffness)
    Ar = V.T @ (A @ V)
    Ar = (Ar + Ar.T) / 2
    lam, Q = np.linalg.eigh(Ar)
    if lam[0] <= 0:
        raise ROMError(f"reduced stiffness is not positive definite (λ_min = {lam[0]:.3e}); "
                       "the thermal system has no heat path to an ambient")
    Vq = V @ Q
    B = sp.csr_matrix(system.input_matrix)
    Bz = np.asarray((B.T @ Vq).T)
    keep = [j for j, c in enumerate(machine.channels) if c.kind in kinds]
    C, D, c = _reduced_outputs(machine, Vq, keep)
    uniform, residual, orth = _basis_quality(sp.csr_matrix(system.mass), V, Vq)
    seconds = time.perf_counter() - start
    info = dict(n_nodes=int(system.n_nodes), build_seconds=seconds, points_per_s=[],
                slowest_time_constant_s=float(1.0 / lam[0]), fastest_time_constant_s=float(1.0 / lam[-1]),
                uniform_residual=residual, orthonormality_error=orth)
    definition = machine.definition
    limits = dict(max_spindle_rpm=float(definition.max_spindle_rpm),
                  max_feed_mm_min=float(definition.max_feed_mm_min))
    channels = [machine.channels[j] for j in keep]
    return ReducedModel(method, lam, Bz, C, D, c, uniform, list(system.input_names),
                        [ch.name for ch in channels], [ch.unit for ch in channels], [ch.kind for ch in channels],
                        list(machine.zones), _source_models(machine), limits, machine.name,
                        machine_digest(machine), info, Vq if keep_basis else None,
                        dict(getattr(definition, "zone_lags_s", {}) or {}), channel_labels(machine, channels))


def channel_labels(machine: Machine, channels: Sequence | None = None) -> list[str]:
    """``"<label> at (x, y, z) m"`` per channel (default: every channel of the machine), for descriptions.

    Parameters
    ----------
    machine : Machine
        A built machine.
    channels : sequence of Channel, optional
        Channels to label (default: all of the machine's).

    Returns
    -------
    list of str
        One per channel (no position part for a channel without a position).
    """
    out = []
    for c in machine.channels if channels is None else channels:
        where = "" if c.position is None else " at ({}) m".format(", ".join(f"{float(v):.4g}" for v in c.position))
        out.append(f"{c.label}{where}")
    return out


def rom_cache_path(machine: Machine, order: int, method: str = "krylov", points: Sequence[float] | None = None,
                   kinds: Sequence[str] = DEFAULT_KINDS, keep_basis: bool = False) -> Path:
    """Where :func:`cached_rom` keeps the ROM of these settings: ``rom-<method>-r<order>-<key>[-basis].npz`` in the
    user cache.

    Parameters
    ----------
    machine : Machine
        A built machine.
    order, method, points, kinds
        As for :func:`build_rom`; with the machine digest they make the key.
    keep_basis : bool, default False
        The file of the ROM that keeps its basis V (a file of its own).

    Returns
    -------
    Path
    """
    key = hashlib.sha256(json.dumps([machine_digest(machine), int(order), method,
                                     None if points is None else [float(p) for p in points],
                                     sorted(kinds)]).encode()).hexdigest()[:16]
    return user_cache_dir() / f"rom-{method}-r{int(order)}-{key}{'-basis' if keep_basis else ''}.npz"


def cached_rom(machine: Machine, order: int = DEFAULT_ORDER, method: Literal["krylov", "modal"] = "krylov",
               points: Sequence[float] | None = None, kinds: Sequence[str] = DEFAULT_KINDS,
               rebuild: bool = False, keep_basis: bool = False) -> ReducedModel:
    """:func:`build_rom`, or the ROM saved earlier for the same machine matrices and settings.

    A ROM read from the cache takes the machine's name and channel labels (they are not in the key);
    ``info["from_cache"]`` is the file read, or None for one built (and saved) now.

    Parameters
    ----------
    machine : Machine
        A built machine.
    order, method, points, kinds
        As for :func:`build_rom`.
    rebuild : bool, default False
        Build (and save) even if cached.
    keep_basis : bool, default False
        Keep (and cache, in a file of its own) the basis V (n, r), e.g. to add point thermometers
        (:func:`twin.rom.points.with_point_thermometers`).

    Returns
    -------
    ReducedModel
    """
    path = rom_cache_path(machine, order, method, points, kinds, keep_basis)
    if path.exists() and not rebuild and checked(path) is not None:
        rom = ReducedModel.load(path)
        rom.machine = machine.name          # not in the key: a renamed copy of a machine reuses the ROM
        labels = dict(zip([c.name for c in machine.channels], channel_labels(machine)))
        rom.output_labels = [labels.get(n, "") for n in rom.output_names]   # nor are labels: text only
        rom.info["from_cache"] = str(path)
        return rom
    rom = build_rom(machine, order, method, points, kinds, keep_basis)
    write_checked(path, lambda target: rom.save(target, keep_basis))
    rom.info["from_cache"] = None
    return rom


# ----------------------------------------------------------------------------- scenarios
@dataclass
class ScenarioConditions:
    """A scenario's operating conditions at some times.

    Attributes
    ----------
    times_s : ndarray, shape (k,)
        Times, s.
    spindle_rpm : ndarray, shape (k,)
        Spindle speed, rpm.
    feed_mm_min : dict of str to ndarray
        Axis → feed, mm/min.
    ambient_C : dict of str to ndarray
        Zone → air temperature, °C.
    gradient_K_per_m : ndarray, shape (k,)
        Vertical ambient gradient, K/m.
    """

    times_s: np.ndarray
    spindle_rpm: np.ndarray
    feed_mm_min: dict
    ambient_C: dict
    gradient_K_per_m: np.ndarray


def scenario_conditions(scenario: Scenario, zones: Sequence[str], times: ArrayLike,
                        lags_s: dict[str, float] | None = None) -> ScenarioConditions:
    """Operating conditions of a scenario at ``times`` (as :class:`twin.core.simulate.ScenarioInputs` gives them).

    Parameters
    ----------
    scenario : Scenario
    zones : sequence of str
        The machine's ambient zones.
    times : array_like
        Times, s.
    lags_s : dict of str to float, optional
        Zone → lag of its air behind the room, s.

    Returns
    -------
    ScenarioConditions
    """
    t = np.atleast_1d(np.asarray(times, float))
    rpm, feeds = scenario.operating(t)
    ambient = scenario.zone_ambient(t, zones, lags_s) if lags_s else scenario.zone_ambient(t, zones)
    return ScenarioConditions(t, rpm, feeds, ambient, np.full(t.shape, scenario.ambient.gradient_K_per_m))


def initial_state(rom: ReducedModel, scenario: Scenario) -> NDArray[np.float64]:
    """The scenario's initial state: uniform (its temperature, or the t = 0 ambient) or steady.

    A steady start is in equilibrium with the scenario's idle conditions at t = 0 (:meth:`Scenario.idle_start`).

    Parameters
    ----------
    rom : ReducedModel
    scenario : Scenario

    Returns
    -------
    ndarray, shape (r,)
    """
    init = scenario.initial
    cond = scenario_conditions(scenario, rom.zones, [0.0], rom.zone_lags_s)
    if init["kind"] == "uniform":
        value = init.get("temperature_C")
        return rom.uniform(cond.ambient_C[room_zone(rom.zones)][0] if value is None else value)
    rpm, idle, ambient = scenario.idle_start(cond.ambient_C)
    u = rom.inputs_from_conditions(rpm, idle, ambient, cond.gradient_K_per_m)[0]
    return rom.steady_state(u)


def held_conditions(scenario: Scenario, zones: Sequence[str], times: ArrayLike,
                    lags_s: dict[str, float] | None = None) -> ScenarioConditions:
    """Conditions held over each step [tᵢ, tᵢ₊₁): the scenario's value at tᵢ₊₁ (left limit).

    This is the scenario module's convention (a step ending when the spindle
    stops still carries the running power) and the table an FMU master feeds:
    row i is applied at tᵢ for the step to tᵢ₊₁.  The last row repeats the
    value at the last time.

    Parameters
    ----------
    scenario : Scenario
    zones : sequence of str
        The machine's ambient zones.
    times : array_like, shape (k,)
        Step times, s.
    lags_s : dict of str to float, optional
        Zone → lag of its air behind the room, s.

    Returns
    -------
    ScenarioConditions
        At ``times`` shifted by one step (its ``times_s`` are those sampled, not ``times``).
    """
    t = np.asarray(times, float)
    return scenario_conditions(scenario, zones, np.r_[t[1:], t[-1]], lags_s)


@functools.lru_cache(maxsize=1)
def _project_version():
    return project_version()


def scenario_step_means(rom: ReducedModel, scenario: Scenario, step_times: ArrayLike) -> NDArray[np.float64]:
    """Mean ROM inputs over each step (len − 1, m), as the FE run takes them (see ``ScenarioInputs``).

    Parameters
    ----------
    rom : ReducedModel
    scenario : Scenario
    step_times : array_like, shape (k,)
        Step times, s.

    Returns
    -------
    ndarray, shape (k - 1, m)
        Thermal inputs (°C, K/m, W).
    """
    def inputs_at(t):
        c = scenario_conditions(scenario, rom.zones, t, rom.zone_lags_s)
        return rom.inputs_from_conditions(c.spindle_rpm, c.feed_mm_min, c.ambient_C, c.gradient_K_per_m)

    return interval_means(inputs_at, step_times, scenario.breakpoints_s(rom.zone_lags_s))


def simulate_rom(rom: ReducedModel, scenario: Scenario | Path | str, scheme: Literal["zoh", "theta"] = "zoh",
                 theta: float | None = None, sample_times: ArrayLike | None = None,
                 inputs: Literal["mean", "held"] = "mean") -> Dataset:
    """Run a scenario (name, path or Scenario) on a ROM; return a :class:`~twin.core.dataset.Dataset`.

    Channels as in :func:`twin.core.simulate.simulate` (conditions, then the ROM's
    outputs, no noise).  ``scheme="zoh"``: exact for the inputs held over
    each step; ``"theta"``: the FE's θ-method on its step grid (like-for-like
    with the full model).  ``inputs="mean"`` drives each step by the mean of
    the inputs over it, as the FE run does, so every segment injects its
    energy whatever the grid; ``inputs="held"`` holds the conditions at the
    step's end instead (left limits, :func:`held_conditions`): what an FMU
    master feeds from :func:`twin.fmu.export.input_table`, equal to the mean for
    duty cycles on the step grid and a constant ambient.

    Parameters
    ----------
    rom : ReducedModel
    scenario : Scenario, Path or str
        The scenario (name, TOML path or object).
    scheme : {"zoh", "theta"}, default "zoh"
        Time stepping.
    theta : float, optional
        θ of the θ-method (default the scenario's).
    sample_times : array_like, optional
        Output times, s (default the scenario's samples).
    inputs : {"mean", "held"}, default "mean"
        How each step is driven (above).

    Returns
    -------
    Dataset
        Conditions (rpm, mm/min, °C, K/m, W) and the ROM's outputs (°C, µm, µε), ``metadata["model"]``
        naming the ROM.
    """
    if inputs not in ("mean", "held"):
        raise ROMError(f"unknown inputs {inputs!r}; use 'mean' or 'held'")
    scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    start = time.perf_counter()
    times = scenario.times() if sample_times is None else np.asarray(sample_times, float)
    steps, at_output = step_grid(times, scenario.time_step_s)
    z0 = initial_state(rom, scenario)
    theta = scenario.theta if theta is None else theta
    if inputs == "mean":
        _, Z = rom.states(steps, None, z0, scheme, theta, means=scenario_step_means(rom, scenario, steps))
    else:
        cond = scenario_conditions(scenario, rom.zones, steps, rom.zone_lags_s)
        U = rom.inputs_from_conditions(cond.spindle_rpm, cond.feed_mm_min, cond.ambient_C, cond.gradient_K_per_m)
        if scheme == "zoh":      # held over [tᵢ, tᵢ₊₁): the value at tᵢ₊₁ (held_conditions), i.e. the next row
            _, Z = rom.states(steps, np.vstack([U[1:], U[-1:]]), z0, "zoh")
        else:
            _, Z = rom.states(steps, U, z0, "theta", theta)
    out = scenario_conditions(scenario, rom.zones, times, rom.zone_lags_s)
    U_out = rom.inputs_from_conditions(out.spindle_rpm, out.feed_mm_min, out.ambient_C, out.gradient_K_per_m)
    Y = rom.outputs(Z[at_output], U_out)
    channels, columns = condition_channels(out, rom.zones, [(src["name"], src["name"]) for src in rom.sources],
                                           rom.input_names, U_out)
    for j, name in enumerate(rom.output_names):
        channels.append(ChannelInfo(name, rom.output_units[j], rom.output_kinds[j]))
        columns.append(Y[:, j])
    metadata = {"kind": "synthetic", "machine": rom.machine, "scenario": scenario.name,
                "scenario_file": scenario.source, "noise": "none", "effects": [],
                "model": f"ROM {rom.method} r={rom.order} ({scheme}, {inputs} inputs)", "rom_digest": rom.digest,
                "time_step_s": scenario.time_step_s, "wall_seconds": time.perf_counter() - start,
                "project_version": _project_version()}
    return Dataset(times, np.column_stack(columns), channels, metadata)
