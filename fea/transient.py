"""Time integration of a thermal system by the θ-method, and its steady state.

    (M/Δt + θA) Tⁿ⁺¹ = (M/Δt − (1−θ)A) Tⁿ + B ū − θ r(Tⁿ⁺¹) − (1−θ) r(Tⁿ)

with ū the mean of the inputs over the step (:func:`fea.inputs.step_means`),
so each load injects exactly ∫ u dt over the step whatever the grid.
θ = 1 is backward Euler (first order, no overshoot), θ = ½ Crank–Nicolson
(second order; it can ring after a sudden change when the step is long
against the fastest time constants).  :meth:`ThermalSolver.step_error`
estimates the time-discretisation error of a run by step doubling.

The left-hand matrix is
factorised once per distinct step size and kept in a cache, so a run with a
constant step factorises once and a change of step reuses earlier factors.
Full T⁴ radiation (the ``r`` term) is solved per step by chord iterations
with the cached factor, switching to Newton with a fresh tangent if the chord
contracts too slowly.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .energy import EnergyLedger
from .errors import FEAInputError, require_finite
from .inputs import step_means
from .linsolve import factorize

if TYPE_CHECKING:
    from .heat import ThermalSystem
    from .inputs import InputSchedule
    from .outputs import OutputOperator

#: Absolute change (K) below which the radiation iterations stop.
NONLINEAR_TOLERANCE_K = 1e-9
NONLINEAR_MAX_ITERATIONS = 50
#: Most memory (bytes) that temperature snapshots may take while output rows are computed in the background.
DEFERRED_BUFFER_BYTES = 256 * 2**20


@dataclass
class TransientResult:
    """Outputs at the requested times, and any fields that were asked for.

    ``outputs`` has one row per entry of ``times_s`` (the initial state
    included) and one column per output; ``fields`` maps a time in s to the
    temperature on thermal nodes (°C).
    """

    times_s: np.ndarray
    outputs: np.ndarray | None
    output_names: list
    final_temperature: np.ndarray
    fields: dict = field(default_factory=dict)
    factorisations: int = 0
    energy: EnergyLedger | None = None


@dataclass
class StepErrorEstimate:
    """Estimated time-discretisation error (run − exact) of a run's outputs at ``times_s``.

    ``error`` has one row per time and one column per output (the run's
    units); ``method`` says how it was found.
    """

    times_s: np.ndarray
    error: np.ndarray
    output_names: list
    method: str


class ThermalSolver:
    """θ-method and steady-state solver for a :class:`~fea.heat.ThermalSystem`.

    Parameters
    ----------
    system : ThermalSystem
        The assembled system (M in J/K, A in W/K, B per input unit).
    theta : float
        1.0 (backward Euler) or 0.5 (Crank–Nicolson), or any value in [½, 1].
    backend : str, optional
        Sparse direct solver backend (see :mod:`fea.linsolve`).
    """

    def __init__(self, system: ThermalSystem, theta: float = 1.0, backend: str | None = None) -> None:
        if not 0.5 <= float(theta) <= 1.0:
            raise FEAInputError(f"theta must lie in [0.5, 1] for an unconditionally stable scheme, got {theta!r}")
        self.system = system
        self.theta = float(theta)
        self.backend = backend
        n = system.n_nodes
        self.fixed = system.fixed_nodes
        self.free = np.setdiff1d(np.arange(n), self.fixed)
        self._cache = {}
        self._trail = None     # (dt, last states) for the initial guesses of the ``mixed`` backend
        self.factorisations = 0

    # ---------------------------------------------------------------- factors
    def _restrict(self, matrix):
        if len(self.fixed) == 0:
            return sp.csc_matrix(matrix), None
        m = sp.csr_matrix(matrix)
        return sp.csc_matrix(m[self.free][:, self.free]), sp.csr_matrix(m[self.free][:, self.fixed])

    def _factors(self, dt):
        key = "steady" if dt is None else float(np.float64(dt).round(9))
        if key not in self._cache:
            s = self.system
            if dt is None:
                self._check_temperature_level()
                lhs, explicit = s.stiffness, None
            else:
                lhs = s.mass / dt + self.theta * s.stiffness
                explicit = sp.csr_matrix(s.mass / dt - (1.0 - self.theta) * s.stiffness)
            lhs = sp.csr_matrix(lhs)
            lhs_ff, lhs_fd = self._restrict(lhs)
            try:
                solve = factorize(lhs_ff, symmetric_positive_definite=True, backend=self.backend)
            except RuntimeError as exc:  # SuperLU: "Factor is exactly singular"
                raise FEAInputError(
                    "the thermal system is singular: no convection, radiation or fixed temperature "
                    f"sets the temperature level ({exc})") from None
            self.factorisations += 1
            self._cache[key] = (lhs, lhs_ff, lhs_fd, explicit, solve)
        return self._cache[key]

    def _check_temperature_level(self):
        """Raise unless every conducting body has a fixed temperature or a term like h(T_amb − T).

        Without one, the steady matrix is singular; SuperLU without pivoting does not
        always notice and returns a field of order 1e14 °C instead.
        """
        A = sp.csr_matrix(self.system.stiffness)
        n_bodies, body = connected_components(A, directed=False)
        anchored = np.zeros(n_bodies, bool)
        anchored[body[self.fixed]] = True
        level = np.bincount(body, weights=np.asarray(A.sum(axis=1)).ravel(), minlength=n_bodies)
        scale = np.bincount(body, weights=np.abs(A.diagonal()), minlength=n_bodies)
        floating = np.flatnonzero(~anchored & (level <= 1e-12 * scale))
        if len(floating):
            nodes = np.flatnonzero(body == floating[0])
            where = tuple(round(float(v), 6) for v in self.system.points[nodes[0]])
            raise FEAInputError(
                f"the thermal system is singular at steady state: {len(floating)} of {n_bodies} bodies "
                f"(e.g. the one with {len(nodes)} nodes, including node {int(nodes[0])} at {where} m) "
                "have no convection, radiation or fixed temperature to set their temperature level")

    # ---------------------------------------------------------------- one solve
    def _radiation(self, T, u):
        r = np.zeros(self.system.n_nodes)
        for term in self.system.radiation:
            r += term.excess(T, u)
        return r

    def _solve(self, factors, rhs, g_new, weight, u_new, T_guess, guess=None):
        """Solve ``lhs T + weight·r(T) = rhs`` with fixed values ``g_new`` (``guess``: optional start)."""
        lhs, lhs_ff, lhs_fd, _, solve = factors
        if not len(self.fixed) and not self.system.radiation:                 # the common linear case
            x = solve(rhs) if guess is None else solve(rhs, guess)
            return np.asarray(x, dtype=float).reshape(T_guess.shape)
        T = T_guess.copy()
        if len(self.fixed):
            T[self.fixed] = g_new
            rhs_f = rhs[self.free] - lhs_fd @ g_new
        else:
            rhs_f = rhs
        if not self.system.radiation:
            T[self.free] = solve(rhs_f) if guess is None else solve(rhs_f, guess[self.free])
            return T
        previous = np.inf
        tangent_solve = None
        for _ in range(NONLINEAR_MAX_ITERATIONS):
            residual = (lhs @ T + weight * self._radiation(T, u_new) - rhs)[self.free]
            step = (tangent_solve or solve)(residual)
            T[self.free] -= step
            change = float(np.abs(step).max())
            if change < NONLINEAR_TOLERANCE_K:
                return T
            if tangent_solve is None and change > 0.5 * previous:
                tangent = lhs.copy()
                for term in self.system.radiation:
                    tangent = tangent + weight * term.tangent(T, u_new)
                tangent_ff, _ = self._restrict(tangent)
                tangent_solve = factorize(tangent_ff, symmetric_positive_definite=True, backend=self.backend)
            previous = change
        raise FEAInputError(
            f"radiation iterations did not converge in {NONLINEAR_MAX_ITERATIONS} steps "
            f"(last change {change:.2e} K); use a smaller time step")

    # ---------------------------------------------------------------- public API
    def steady_state(self, u: np.ndarray, T_guess: np.ndarray | None = None) -> np.ndarray:
        """The steady temperature for constant inputs.

        Parameters
        ----------
        u : ndarray, shape (n_inputs,)
            Input values (°C, K/m, W as the inputs are).
        T_guess : ndarray, optional
            Start of the Newton iteration with radiation, °C (default: the mean input).

        Returns
        -------
        ndarray, shape (n_nodes,)
            Temperature, °C.
        """
        u = np.asarray(u, dtype=float)
        factors = self._factors(None)
        rhs = self.system.input_matrix @ u
        T0 = np.full(self.system.n_nodes, float(np.mean(u))) if T_guess is None else T_guess
        return self._solve(factors, rhs, self.system.fixed_values(u), 1.0, u, T0)

    def step(self, T: np.ndarray, u_old: np.ndarray | None, u_new: np.ndarray | None, dt: float,
             u_mean: np.ndarray | None = None) -> np.ndarray:
        """Advance the temperature by one θ-scheme step.

        Parameters
        ----------
        T : ndarray, shape (n_nodes,)
            Temperature at the start of the step, °C.
        u_old, u_new : ndarray or None
            Inputs at the start and the end of the step; ``u_new`` sets fixed
            temperatures and, with ``u_old``, the ambient of full radiation
            (both may be None without those).
        dt : float
            Step, s.
        u_mean : ndarray, optional
            Mean input over the step (default θ u_new + (1 − θ) u_old).

        Returns
        -------
        ndarray, shape (n_nodes,)
            Temperature at the end of the step, °C.
        """
        factors = self._factors(dt)
        th = self.theta
        if u_mean is None:
            u_mean = th * u_new + (1.0 - th) * u_old
        rhs = factors[3] @ T + self.system.input_matrix @ u_mean
        if self.system.radiation and th < 1.0:
            rhs -= (1.0 - th) * self._radiation(T, u_old)
        guess = self._extrapolate(T, dt) if getattr(factors[4], "accepts_guess", False) else None
        fixed = self.system.fixed_values(u_new) if len(self.fixed) else None
        T_new = self._solve(factors, rhs, fixed, th, u_new, T, guess)
        if guess is not None:
            self._remember(T, T_new, dt)
        return T_new

    # ---------------------------------------------------------------- initial guesses
    def _extrapolate(self, T, dt):
        """A guess for the next state: polynomial extrapolation of the last steps when ``T`` is the last result.

        Only solvers that refine from a guess (the ``mixed`` backend) use it;
        a poor guess costs iterations, never accuracy.
        """
        trail = self._trail
        if trail is None or trail[0] != dt or trail[1][-1] is not T:
            return T
        states = trail[1]
        if len(states) >= 3:
            return 3.0 * states[-1] - 3.0 * states[-2] + states[-3]
        if len(states) == 2:
            return 2.0 * states[-1] - states[-2]
        return T

    def _remember(self, T, T_new, dt):
        trail = self._trail
        if trail is not None and trail[0] == dt and trail[1][-1] is T:
            self._trail = (dt, (trail[1] + [T_new])[-3:])
        else:
            self._trail = (dt, [T, T_new])

    # Complex: 22 (radon) — four optional recorders (outputs, energy ledger, fields, progress), each tested at
    # the start and at every output time of the one time loop whose state they share; split, the loop's state
    # would have to travel through every piece, on the solver's hot path.
    def run(self, T0: float | np.ndarray, times_s: np.ndarray, schedule: InputSchedule,
            outputs: OutputOperator | None = None, field_times_s: Sequence[float] = (),
            max_step_s: float | None = None, progress: Callable[[int, int], None] | None = None,
            energy: bool = False, substeps: np.ndarray | int | None = None) -> TransientResult:
        """Integrate from ``times_s[0]`` through ``times_s``; record outputs at each time.

        Parameters
        ----------
        T0 : float or ndarray
            Initial temperature on the thermal nodes, °C, or a number for a uniform start.
        times_s : ndarray
            Increasing output times, s; the first is the initial time.
        schedule : InputSchedule
            Or any object with ``sample(times)`` and optionally ``means(step_times)``
            (see :func:`fea.inputs.step_means`).
        outputs : OutputOperator, optional
            Evaluated at every output time; rows that are still computed in the
            background (``build_output_operator(concurrent=True)``) are filled in
            when they arrive, so the run overlaps with their computation.
        field_times_s : sequence of float
            Times whose full temperature field is kept, s.
        max_step_s : float, optional
            Split output intervals into equal sub-steps no longer than this, s.
        progress : callable, optional
            ``progress(done, total)``.
        energy : bool
            Keep an :class:`~fea.energy.EnergyLedger` of the run (``result.energy``).
        substeps : ndarray or int, optional
            Number of equal sub-steps of each output interval, instead of ``max_step_s``.

        Returns
        -------
        TransientResult
            Output history (the outputs' units), final temperature and kept fields (°C), ledger.
        """
        times = _output_times(times_s)
        T = _initial_field(T0, self.system.n_nodes)
        intervals = np.diff(times)
        step_times, at_output = step_grid(times, max_step_s, substeps)
        substeps = np.diff(at_output)
        u_mean = step_means(schedule, step_times, self.theta) if len(times) > 1 else None
        # Point values only where the scheme needs them: fixed temperatures and T⁴ radiation.
        u_point = schedule.sample(step_times) if len(self.fixed) or self.system.radiation else None
        if len(self.fixed):
            T[self.fixed] = self.system.fixed_values(u_point[0])
        wanted = {int(np.argmin(np.abs(times - float(t)))) for t in field_times_s}
        record = outputs is not None
        history = np.empty((len(times), outputs.n_outputs)) if record else None
        recorder = _Recorder(outputs, history) if record else None
        ledger = EnergyLedger(self.system, self.theta, len(times)) if energy else None
        fields = {}
        if record:
            recorder.record(0, T)
        if ledger is not None:
            ledger.record(0, T)
        if 0 in wanted:
            fields[float(times[0])] = T.copy()
        j = 0
        for k, s in enumerate(substeps):
            dt = intervals[k] / s
            for _ in range(s):
                u_old, u_new = (None, None) if u_point is None else (u_point[j], u_point[j + 1])
                T_new = self.step(T, u_old, u_new, dt, u_mean[j])
                if ledger is not None:
                    ledger.step(T, T_new, u_mean[j], dt, u_old, u_new)
                T = T_new
                j += 1
            if record:
                recorder.record(k + 1, T)
            if ledger is not None:
                ledger.record(k + 1, T)
            if k + 1 in wanted:
                fields[float(times[k + 1])] = T.copy()
            if progress is not None:
                progress(k + 1, len(intervals))
        if record:
            recorder.finish()
        return TransientResult(times, history, list(outputs.names) if record else [], T, fields,
                               self.factorisations, ledger)

    def step_error(self, T0: float | np.ndarray, times_s: np.ndarray, schedule: InputSchedule,
                   outputs: OutputOperator, fine: TransientResult, max_step_s: float | None = None) -> StepErrorEstimate:
        """Estimate the time-discretisation error of ``fine`` by step doubling (Richardson extrapolation).

        ``fine`` is the :class:`TransientResult` of :meth:`run` with the same
        arguments.  The run is repeated with steps r ≈ 2 times longer (each
        output interval in half as many sub-steps, or every other output time
        when an interval is one step); with p the order of the scheme (1 for
        backward Euler, 2 for Crank–Nicolson) the fine run's error at the
        common times is ≈ (y_coarse − y_fine) / (rᵖ − 1).  The estimate is
        asymptotic: it holds while the steps resolve the response, i.e. while
        the error is small, which is when one relies on it.

        Parameters
        ----------
        T0, times_s, schedule, outputs, max_step_s
            As given to :meth:`run` for ``fine``.
        fine : TransientResult
            The run whose error is estimated.

        Returns
        -------
        StepErrorEstimate
            The estimated error of ``fine``'s outputs (their units) at the common times (s).
        """
        times = np.asarray(times_s, float)
        _, at_output = step_grid(times, max_step_s)
        substeps = np.diff(at_output)
        if len(times) < 3 and np.all(substeps == 1):
            raise FEAInputError("a step-doubling error estimate needs at least two steps")
        if np.any(substeps == 1) and not np.all(substeps == 1):
            raise FEAInputError("a step-doubling error estimate needs every output interval in one step, "
                                "or every one in two or more")
        h = np.diff(times) / substeps
        if np.all(substeps == 1):
            keep = np.arange(0, len(times), 2)
            first, second = h[0:2 * (len(keep) - 1):2], h[1:2 * (len(keep) - 1):2]
            coarse = self.run(T0, times[keep], schedule, outputs)
            ratio = float(np.min((first + second) / np.maximum(first, second)))
        else:
            keep = np.arange(len(times))
            coarse_substeps = (substeps + 1) // 2
            coarse = self.run(T0, times, schedule, outputs, substeps=coarse_substeps)
            ratio = float(np.min(substeps / coarse_substeps))
        order = 2 if self.theta == 0.5 else 1
        error = (coarse.outputs - fine.outputs[keep]) / (ratio ** order - 1.0)
        scheme = {1.0: "backward Euler", 0.5: "Crank–Nicolson"}.get(self.theta, f"θ = {self.theta:g}")
        return StepErrorEstimate(times[keep], error, list(fine.output_names),
                                 f"step doubling ({scheme}, order {order}, step ratio {ratio:g})")


def step_grid(times: np.ndarray, max_step_s: float | None = None,
              substeps: np.ndarray | int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The solver's step times for output times: each interval split into equal sub-steps.

    Parameters
    ----------
    times : ndarray
        Output times, s.
    max_step_s : float, optional
        Longest sub-step, s.
    substeps : ndarray or int, optional
        Sub-steps of each interval, instead of ``max_step_s``.

    Returns
    -------
    step_times : ndarray
        Step ends, s, from ``times[0]``.
    at_output : ndarray of int
        Per output time, its index in ``step_times``.
    """
    times = np.asarray(times, float)
    intervals = np.diff(times)
    if substeps is not None:
        sub = np.broadcast_to(np.asarray(substeps, int), intervals.shape)
    elif max_step_s is None:
        sub = np.ones(len(intervals), int)
    else:
        sub = np.maximum(1, np.ceil(intervals / float(max_step_s) - 1e-9).astype(int))
    at_output = np.concatenate([[0], np.cumsum(sub)])
    if np.all(sub == 1):
        return times.copy(), at_output
    k = np.repeat(np.arange(len(sub)), sub)                 # interval of each step
    j = np.arange(len(k)) - at_output[k] + 1                # 1..sub within the interval
    return np.concatenate([[times[0]], times[k] + intervals[k] * j / sub[k]]), at_output


class _Recorder:
    """Fills the output history, holding temperatures back for rows still computed in the background.

    While an :class:`~fea.outputs.OutputOperator` has deferred rows (see
    ``build_output_operator(concurrent=True)``), the available outputs are
    recorded at once and the temperature snapshots are kept; as soon as the
    rows arrive the kept snapshots are evaluated in one block product and
    dropped.  If the snapshots would exceed :data:`DEFERRED_BUFFER_BYTES`
    the run waits for the rows instead.
    """

    def __init__(self, outputs, history):
        self.outputs, self.history = outputs, history
        self.rows = outputs.deferred_rows
        self.buffer, self.steps = [], []

    def record(self, k, T):
        if len(self.rows) == 0 or self.outputs.poll():
            self._flush()
            self.history[k] = self.outputs.apply(T)
            return
        self.history[k] = self.outputs.apply_available(T)
        self.buffer.append(T.copy())
        self.steps.append(k)
        if len(self.buffer) * T.nbytes > DEFERRED_BUFFER_BYTES:
            self.outputs.resolve()
            self._flush()

    def _flush(self):
        if self.buffer:
            block = np.column_stack(self.buffer)
            values = self.outputs.matrix[self.rows] @ block + self.outputs.offset[self.rows, None]
            self.history[np.ix_(self.steps, self.rows)] = values.T
            self.buffer, self.steps = [], []

    def finish(self):
        if len(self.rows):
            self.outputs.resolve()
            self._flush()


def _output_times(times_s):
    """``times_s`` as a float array, checked to be 1-D, non-empty and strictly increasing (s)."""
    times = np.asarray(times_s, dtype=float)
    if times.ndim != 1 or len(times) < 1:
        raise FEAInputError("times_s must be a 1-D array with at least the initial time")
    if np.any(np.diff(times) <= 0):
        i = int(np.flatnonzero(np.diff(times) <= 0)[0])
        raise FEAInputError(f"times must increase strictly: t[{i + 1}] = {times[i + 1]} s follows t[{i}] = {times[i]} s")
    return times


def _initial_field(T0, n):
    """The initial temperature (°C) on ``n`` thermal nodes from a number or an array, checked."""
    T = np.full(n, float(T0)) if np.ndim(T0) == 0 else np.array(T0, dtype=float)
    if T.shape != (n,):
        raise FEAInputError(f"initial temperature has shape {T.shape}, the system has {n} nodes")
    require_finite("initial temperature", T)
    return T
