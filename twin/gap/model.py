"""The twin of one record with any effects switched on: inputs → backend → sensor models → measured times.

:class:`GapModel` binds a structure (machine + library terms), a backend
(reduced or full FE), the drive of the record (operating conditions on the
twin's uniform grid) and the measured sample times.  :meth:`GapModel.predict`
takes ``[(effect, θ), …]`` and returns every channel at the measured times,
with the free responses of the initial-state nuisance shapes.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .signals import Interpolator
from .structure import NUISANCE_FIELDS


@dataclass
class Prediction:
    """Channels at the measured times (n, p), nuisance responses {name: (n, p)}, and the run on the grid."""

    values: np.ndarray
    nuisance: dict
    grid_values: np.ndarray
    run: object
    inputs: np.ndarray


class GapModel:
    """See the module docstring.  ``initial`` is ``"steady"`` (idle, steady state at t₀) or ``"uniform"``."""

    def __init__(self, structure, backend, drive, times_s, initial="steady", initial_temperature=None):
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

    def inputs(self, active, drive=None):
        """Input matrix (N, m) and system coefficients with the effects ``active`` = [(effect, θ), …] on."""
        drive = drive or self.drive
        U = (self.U0 if drive is self.drive else self.U0_idle).copy()
        coefficients = {}
        for effect, theta in active:
            for name, delta in effect.input_changes(theta, drive, self.structure).items():
                U[:, self.structure.input_index(name)] += delta
            for name, a in effect.coefficients(theta, self.structure).items():
                coefficients[name] = coefficients.get(name, 0.0) + a
        return U, coefficients

    def predict(self, active=(), nuisance=True, on_grid=False):
        """Channels (see :class:`Prediction`) with the effects ``active`` = [(effect, θ), …] switched on."""
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

    def sensor_models(self, active, Y, U, additive=True):
        """Apply the output effects (mounting, then lag, then fixture drift) to channel values on the grid."""
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


def output_effects(active):
    """The output effects among ``active`` = [(effect, θ), …], in the order they apply (:data:`SENSOR_ORDER`)."""
    return sorted([(e, th) for e, th in active if e.kind == "output"],
                  key=lambda p: SENSOR_ORDER.index(p[0].name) if p[0].name in SENSOR_ORDER else len(SENSOR_ORDER))
