"""The twin of one record with any effects switched on: inputs → backend → sensor models → measured times.

:class:`GapModel` binds a structure (machine + library terms), a backend
(reduced or full FE), the drive of the record (operating conditions on the
twin's uniform grid) and the measured sample times.  :meth:`GapModel.predict`
takes ``[(effect, θ), …]`` and returns every channel at the measured times,
with the free responses of the initial-state nuisance shapes.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .drive import Drive, IdleDrive
from .effects import Effect
from .engine import FullBackend, ReducedBackend
from .signals import Interpolator
from .structure import NUISANCE_FIELDS, Structure


@dataclass
class Prediction:
    """Channels at the measured times (n, p), nuisance responses {name: (n, p)}, and the run on the grid."""

    values: np.ndarray
    nuisance: dict
    grid_values: np.ndarray
    run: object
    inputs: np.ndarray


class GapModel:
    """See the module docstring.  ``initial`` is ``"steady"`` (idle, steady state at t₀) or ``"uniform"``.

    Parameters
    ----------
    structure : Structure
        The machine with the effects' terms registered.
    backend : ReducedBackend or FullBackend
        Simulates the structure.
    drive : Drive
        Operating conditions of the record on the twin's uniform grid (step ``drive.step_s``, s).
    times_s : ndarray, shape (n,)
        Measured sample times, s.
    initial : str, default "steady"
        ``"steady"``: the steady state of the idle machine at the first grid input; ``"uniform"``: every
        node at ``initial_temperature``.
    initial_temperature : float, optional
        Start temperature for ``"uniform"``, °C; default the room ambient at the first grid point.
    """

    def __init__(self, structure: Structure, backend: ReducedBackend | FullBackend, drive: Drive,
                 times_s: np.ndarray, initial: str = "steady", initial_temperature: float | None = None):
        self.structure, self.backend, self.drive = structure, backend, drive
        self.times_s = np.asarray(times_s, float)
        self.initial = initial
        self.initial_temperature = initial_temperature
        self.effects = []
        s = structure
        n_extra = s.n_inputs - s.n_machine_inputs
        self.U0 = drive.inputs(s.machine, n_extra)
        idle = drive.idle()
        self.idle_drive = idle
        self.U0_idle = idle.inputs(s.machine, n_extra)
        self.interp = Interpolator(drive.grid, self.times_s)
        info = s.thermometer_info()
        self.thermometer_air = s.local_air_matrix(info["zone"], info["height"])
        self.axes = [s.channels[i].name[0].lower() if s.channels[i].name[:1] in "XYZ" else "z"
                     for i in s.displacements]
        self.nuisance_names = [n for n in NUISANCE_FIELDS if n in s.fields]

    def inputs(self, active: Sequence[tuple[Effect, np.ndarray]],
               drive: Drive | IdleDrive | None = None) -> tuple[np.ndarray, dict[str, float]]:
        """Input matrix (N, m) and system coefficients with the effects ``active`` = [(effect, θ), …] on.

        Parameters
        ----------
        active : sequence of (Effect, ndarray)
            Effects and their parameters θ (units of :attr:`Effect.params`).
        drive : Drive or IdleDrive, optional
            The model's drive (default) or its idle copy ``idle_drive``; any other drive starts from the
            idle nominal inputs.

        Returns
        -------
        U : ndarray, shape (N, m)
            Thermal inputs on the grid (N points), machine then extra inputs (W, °C, K/m, K).
        coefficients : dict of str to float
            System term → coefficient a (A += a·dA, B += a·dB), dimensionless.
        """
        drive = drive or self.drive
        U = (self.U0 if drive is self.drive else self.U0_idle).copy()
        coefficients = {}
        for effect, theta in active:
            for name, delta in effect.input_changes(theta, drive, self.structure).items():
                U[:, self.structure.input_index(name)] += delta
            for name, a in effect.coefficients(theta, self.structure).items():
                coefficients[name] = coefficients.get(name, 0.0) + a
        return U, coefficients

    def predict(self, active: Sequence[tuple[Effect, np.ndarray]] = (), nuisance: bool = True,
                on_grid: bool = False) -> Prediction:
        """Channels (see :class:`Prediction`) with the effects ``active`` = [(effect, θ), …] switched on.

        Parameters
        ----------
        active : sequence of (Effect, ndarray)
            Effects and their parameters θ; empty for the nominal twin.
        nuisance : bool, default True
            Also simulate the free responses of the nuisance initial-state fields.
        on_grid : bool, default False
            Values on the twin's grid (N points) instead of at the measured times (n).

        Returns
        -------
        Prediction
            Channel values, shape (n, p) (or (N, p) with ``on_grid``), in channel units (°C, µm, µε);
            nuisance responses per unit coefficient; the values on the grid, the backend's run and the
            inputs (N, m).
        """
        s = self.structure
        U, coefficients = self.inputs(active)
        if self.initial == "steady":
            u0 = self.inputs(active, self.idle_drive)[0][0]
            fields = None
        else:
            u0 = np.zeros(U.shape[1])
            start = self.drive.room()[0] if self.initial_temperature is None else self.initial_temperature
            fields = {"initial_uniform": float(start)}
        run = self.backend.simulate(U, self.drive.step_s, coefficients, u0=u0, fields=fields,
                                    field_responses=self.nuisance_names if nuisance else ())
        Y = s.channel_values(run.outputs, U)
        responses = {}
        for name, R in run.field_outputs.items():
            full = np.zeros_like(Y)
            full[:, : R.shape[1]] = R
            responses[name] = full
        Y = self.sensor_models(active, Y, U)
        for name in responses:
            responses[name] = self.sensor_models(active, responses[name], np.zeros_like(U), additive=False)
        if on_grid:
            return Prediction(Y, responses, Y, run, U)
        return Prediction(self.interp(Y), {k: self.interp(v) for k, v in responses.items()}, Y, run, U)

    def sensor_models(self, active: Sequence[tuple[Effect, np.ndarray]], Y: np.ndarray, U: np.ndarray,
                      additive: bool = True) -> np.ndarray:
        """Apply the output effects (mounting, then lag, then fixture drift) to channel values on the grid.

        Parameters
        ----------
        active : sequence of (Effect, ndarray)
            Effects and their parameters θ; only the output effects act.
        Y : ndarray, shape (N, p)
            True channel values on the grid (°C, µm, µε).
        U : ndarray, shape (N, m)
            Thermal inputs on the grid (give the air at the thermometers, °C).
        additive : bool, default True
            Also apply the displacement changes (fixture drift); False for responses per unit
            coefficient, which take only the linear thermometer models.

        Returns
        -------
        ndarray, shape (N, p)
            Channel readings (Y itself when no output effect is active).
        """
        s = self.structure
        outputs = output_effects(active)
        if not outputs:
            return Y
        Y = Y.copy()
        T = Y[:, s.thermometers]
        air = U @ self.thermometer_air.T
        for effect, theta in outputs:
            T = effect.thermometer_change(theta, T, air, self.drive.step_s)
        Y[:, s.thermometers] = T
        if additive and s.displacements:
            D = Y[:, s.displacements]
            for effect, theta in outputs:
                D = effect.displacement_change(theta, D, self.axes, self.drive)
            Y[:, s.displacements] = D
        return Y


#: Order in which the output effects apply to a reading (the others, after them, in their given order).
SENSOR_ORDER = ("sensor_mounting", "sensor_lag")


def output_effects(active: Sequence[tuple[Effect, np.ndarray]]) -> list[tuple[Effect, np.ndarray]]:
    """The output effects among ``active`` = [(effect, θ), …], in the order they apply (:data:`SENSOR_ORDER`).

    Parameters
    ----------
    active : sequence of (Effect, ndarray)
        Effects and their parameters θ.

    Returns
    -------
    list of (Effect, ndarray)
        The pairs with ``kind == "output"``, sorted (stable) by :data:`SENSOR_ORDER`.
    """
    return sorted([(e, th) for e, th in active if e.kind == "output"],
                  key=lambda p: SENSOR_ORDER.index(p[0].name) if p[0].name in SENSOR_ORDER else len(SENSOR_ORDER))
