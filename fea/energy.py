"""Energy accounting of a θ-method run: the heat each load moves, step by step, exactly as the scheme moves it.

Summing every row of one θ step

    M (Tⁿ⁺¹ − Tⁿ) + Δt (A T_θ + r_θ) = Δt B ū + Δt f,      T_θ = θ Tⁿ⁺¹ + (1 − θ) Tⁿ

(ū the step-mean inputs, r_θ the θ-weighted T⁴ radiation excess, f the
reactions at fixed nodes) gives the stored-energy change as the sum of the
loads' energies: 1ᵀA = Σ r_Tᵀ over the boundary loads (conduction and joints
conserve heat), 1ᵀB = Σ r_uᵀ.  The ledger adds those terms per load, and the
reaction of each fixed-temperature group from its rows, so that

    stored(t) − stored(0) = Σ_loads energy_in(t)

holds to round-off for any grid; a residual larger than that means heat was
lost or created.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

if TYPE_CHECKING:
    from .heat import ThermalSystem

#: Energy below which a balance counts as zero: that of this many kelvin over the whole body's heat capacity
#: (0.01 K, a good thermometer's resolution).  With a relative tolerance of 1e-6 an error then counts from
#: 10 nK of the whole body up.  A 1 µK floor judged the solver's round-off: a cast-iron box held at 30 °C
#: with nothing on for a day drifts by about 1e-12 K, and its balance read 5e-6 against that floor.
ENERGY_FLOOR_K = 1e-2


class EnergyLedger:
    """Cumulative energy (J) into the body by each load, the stored energy, and ∫u dt, at recorded times.

    ``names`` are the keys of :meth:`fea.heat.ThermalSystem.power_in`
    (``convection:<group>``, ``flux:<group>``, ``source:<name>``,
    ``radiation:<group>``, ``fixed:<group>``).  Attributes, one row per
    recorded time: ``stored_J`` (∫ρcT dV relative to 0 °C), ``load_J``
    (energy into the body since the start, per load), ``gross_J`` (Σ over
    steps and loads of |energy|: the throughput) and ``input_integral``
    (∫ u dt per input, e.g. J for a power input).

    Parameters
    ----------
    system : ThermalSystem
        The system integrated.
    theta : float
        The scheme's θ.
    n_records : int
        Number of recorded times.
    """

    def __init__(self, system: ThermalSystem, theta: float, n_records: int) -> None:
        self.system, self.theta = system, float(theta)
        flows = system.heat_flows
        self.names = list(flows) + [f"fixed:{g}" for g in system.fixed_groups]
        self._r_T = sp.csr_matrix(np.array([r_T for r_T, _ in flows.values()]).reshape(len(flows), system.n_nodes))
        self._r_u = np.array([r_u for _, r_u in flows.values()]).reshape(len(flows), system.n_inputs)
        self._radiation = [self.names.index(f"radiation:{term.group}") for term in system.radiation]
        groups = list(system.fixed_groups.values())
        if groups:
            rows = np.repeat(np.arange(len(groups)), [len(g) for g in groups])
            member = sp.csr_matrix((np.ones(len(rows)), (rows, np.concatenate(groups))),
                                   shape=(len(groups), system.n_nodes))
            self._fix_M, self._fix_A = member @ system.mass, member @ system.stiffness
            self._fix_B, self._member = member @ system.input_matrix, member
        self._stored_row = np.asarray(system.mass @ np.ones(system.n_nodes)).ravel()
        self.capacity_J_per_K = float(self._stored_row.sum())
        self.stored_J = np.full(n_records, np.nan)
        self.load_J = np.zeros((n_records, len(self.names)))
        self.gross_J = np.zeros(n_records)
        self.input_integral = np.zeros((n_records, system.n_inputs))
        self._load = np.zeros(len(self.names))
        self._gross = 0.0
        self._inputs = np.zeros(system.n_inputs)

    def step(self, T_old: np.ndarray, T_new: np.ndarray, u_mean: np.ndarray, dt: float,
             u_old: np.ndarray | None = None, u_new: np.ndarray | None = None) -> None:
        """Add one θ step.

        Parameters
        ----------
        T_old, T_new : ndarray
            Temperature before and after the step, °C.
        u_mean : ndarray
            Inputs driving the step.
        dt : float
            Step, s.
        u_old, u_new : ndarray, optional
            Point inputs at the step ends (for radiation).
        """
        th = self.theta
        T_theta = th * T_new + (1.0 - th) * T_old
        n_flows = self._r_T.shape[0]
        energy = np.empty(len(self.names))
        energy[:n_flows] = dt * (self._r_u @ u_mean - self._r_T @ T_theta)
        excess = None
        if self._radiation:
            terms = self.system.radiation
            excess = [th * term.excess(T_new, u_new) + (1.0 - th) * term.excess(T_old, u_old) for term in terms]
            for k, part in zip(self._radiation, excess):
                energy[k] -= dt * float(part.sum())
        if len(self.names) > n_flows:
            reaction = self._fix_M @ (T_new - T_old) + dt * (self._fix_A @ T_theta - self._fix_B @ u_mean)
            if excess is not None:
                reaction = reaction + dt * (self._member @ sum(excess))
            energy[n_flows:] = reaction
        self._load += energy
        self._gross += float(np.abs(energy).sum())
        self._inputs += dt * np.asarray(u_mean, float)

    def record(self, k: int, T: np.ndarray) -> None:
        """Keep the running totals as a recorded row.

        Parameters
        ----------
        k : int
            Row (recorded time).
        T : ndarray
            The temperature reached at that time, °C.
        """
        self.stored_J[k] = float(self._stored_row @ T)
        self.load_J[k] = self._load
        self.gross_J[k] = self._gross
        self.input_integral[k] = self._inputs

    @property
    def residual_J(self) -> np.ndarray:
        """Stored-energy change minus the energy the loads brought in, J, at each recorded time."""
        return self.stored_J - self.stored_J[0] - self.load_J.sum(axis=1)

    def scale_J(self) -> float:
        """The energy a balance error is measured against.

        Returns
        -------
        float
            The gross throughput, at least the energy of :data:`ENERGY_FLOOR_K` over the whole body, J.
        """
        return max(float(self.gross_J[-1]), ENERGY_FLOOR_K * self.capacity_J_per_K)

    def relative_error(self) -> float:
        """The energy-balance error of the run.

        Returns
        -------
        float
            max |residual| over the run relative to :meth:`scale_J`.
        """
        return float(np.nanmax(np.abs(self.residual_J)) / self.scale_J())

    def energy_of(self, input_name: str) -> np.ndarray:
        """The time integral of an input since the start.

        Parameters
        ----------
        input_name : str
            E.g. ``power:front_bearings``.

        Returns
        -------
        ndarray
            ∫ u dt at each recorded time (J for a power input).
        """
        return self.input_integral[:, self.system.input_index(input_name)]
