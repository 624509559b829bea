"""Multiple-model observer: is there heat the twin does not know, and how strong might it be?

A few thermometers cannot say where an unread source is, so one filter must either assume there is none
(and attribute its heat to whatever it does estimate: an ambient zone, a feed drive) or assume one always
(and carry its band on every record).  :class:`MultipleModelObserver` runs one
:class:`~twin.live.observer.DriftObserver` per hypothesis on the concentrated source's size σ_P
(:attr:`~twin.live.model.NoiseModel.concentrated_W`, 0 = none) and weighs them by how well each predicted the
readings (multiple-model adaptive estimation, Magill 1965; Maybeck, *Stochastic Models, Estimation and
Control* vol. 2, ch. 10):

    wᵢ(k) ∝ w̃ᵢ(k) · N(νᵢ(k); 0, Sᵢ(k)),     w̃(k) = (1 − ε) w(k−1) + ε/m,   ε = 1 − exp(−Δt/τ)

with νᵢ, Sᵢ each filter's innovation and its covariance.  The leak ε lets a hypothesis that lost come back
when a source switches on or off; τ is the disturbances' correlation time
(:attr:`~twin.live.model.NoiseModel.correlation_time_s`), the time scale on which the model says such things
change.  The estimate is the mixture's mean and its band ±1.96 σ of the mixture (within-model variances plus
the spread of the means).
"""
from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import ArrayLike

from ..errors import TwinInputError
from ..rom.reduction import ReducedModel
from .model import NoiseModel, concentrated_moment
from .observer import (
    NOISE,
    Z95,
    Adaptation,
    DriftObserver,
    Estimate,
    InnovationGate,
    RecordRunner,
    axis_factors,
    unread_time,
)


class MultipleModelObserver(RecordRunner):
    """Observers that differ in the size of an unread concentrated source, weighted by their predictions.

    Parameters
    ----------
    rom : ReducedModel
        The machine's ROM.
    thermometers : list of str
        ROM thermometer outputs that are measured, in the order of the readings.
    concentrated_W : tuple of float
        σ_P of each hypothesis, W (0: no unread source); at least two, distinct.
    noise : NoiseModel, optional
        Every other size of the noise model (its ``concentrated_W`` is replaced by each hypothesis's).
    adaptation : Adaptation, optional
        The NIS-driven widening of each filter.
    sensors : dict, optional
        Thermometer name → sensor model (:class:`~twin.live.observer.DriftObserver`).
    concentrated : numpy.ndarray, optional
        (r, r) second moment of a 1 W source at an unknown cell (default: that of ``rom``, cached).
    band_inflation : array_like, optional
        (3,) factor on the mixture's X, Y, Z band half-width (default 1: its ±1.96 σ); the hypotheses' own
        bands, which the mixture's variance is made of, are not inflated.
    """

    def __init__(self, rom: ReducedModel, thermometers: list[str], concentrated_W: tuple[float, ...],
                 noise: NoiseModel | None = None, adaptation: Adaptation | None = None, sensors: dict | None = None,
                 concentrated: np.ndarray | None = None, band_inflation: ArrayLike | None = None) -> None:
        self.band_inflation = axis_factors(band_inflation)
        sizes = tuple(float(s) for s in concentrated_W)
        if len(sizes) < 2 or len(set(sizes)) != len(sizes) or min(sizes) < 0:
            raise TwinInputError(f"concentrated_W needs two or more distinct sizes ≥ 0 W, got {concentrated_W!r}")
        noise = NOISE if noise is None else noise
        if concentrated is None and max(sizes) > 0:
            concentrated = concentrated_moment(rom)
        self.members = [DriftObserver(rom, thermometers, dataclasses.replace(noise, concentrated_W=s), adaptation,
                                      sensors, concentrated) for s in sizes]
        self.concentrated_W = sizes
        self.switching_time_s = noise.correlation_time_s
        first = self.members[0]
        self.rom, self.thermometers, self.field_names = rom, first.thermometers, first.field_names
        self.weights = np.full(len(sizes), 1.0 / len(sizes))
        self._gate = InnovationGate(len(self.thermometers))
        #: the whole interval between the last two samples, s (:func:`~twin.live.observer.unread_time`)
        self.last_interval_s = None

    @property
    def time_s(self) -> float | None:
        """Machine time of the last sample fused, s (None before the start)."""
        return self.members[0].time_s

    def start(self, time_s: float, room_C: float) -> MultipleModelObserver:
        """Start every hypothesis as :meth:`DriftObserver.start` does (``time_s`` s, room air ``room_C`` °C), with
        equal weights; returns the observer."""
        for member in self.members:
            member.start(time_s, room_C)
        self.weights = np.full(len(self.members), 1.0 / len(self.members))
        self._gate = InnovationGate(len(self.thermometers))
        self.last_interval_s = None
        return self

    def step(self, time_s: float, spindle_rpm: float, room_C: float, temperatures_C: ArrayLike) -> Estimate | None:
        """Fuse one sample in every hypothesis and reweigh them (see :meth:`DriftObserver.step`).

        Parameters
        ----------
        time_s : float
            Machine time of the sample, s; after the previous sample's.
        spindle_rpm, room_C : float
            Spindle speed (rpm) and room air (°C); NaN keeps that input's last reading.
        temperatures_C : array_like
            (p,) thermometer readings, °C (NaN = missing).

        Returns
        -------
        Estimate or None
            The mixture's estimate; None until a room air reading has started the observer.
        """
        previous = self.time_s
        unread = unread_time(self.last_interval_s, previous, time_s)
        if unread:
            self.bridge(previous + unread)
        before = self.time_s
        y = np.asarray(temperatures_C, float).reshape(len(self.thermometers))
        steps = [member.advance(time_s, spindle_rpm, room_C) for member in self.members]
        if not self.members[0].started:
            return None
        if steps[0] is not None:
            self.last_interval_s = float(time_s) - previous
        # one gate for every hypothesis (the likelihoods compare the same readings): a reading is rejected only
        # if even the hypothesis that predicts it best finds it impossible
        rejected = self._gate(np.min([member.innovation_scores(y) for member in self.members], axis=0))
        estimates = [member.fuse(y, dt, rejected) for member, dt in zip(self.members, steps)]
        if estimates[0].used:
            self._weigh(0.0 if before is None else float(time_s) - before)
        return self._mixture(estimates)

    def bridge(self, time_s: float) -> MultipleModelObserver:
        """Predict every hypothesis to ``time_s`` (s) across a time when nobody read the inputs
        (:meth:`DriftObserver.bridge`), the weights leaking towards equal over it; returns the observer."""
        dt = float(time_s) - self.time_s
        for member in self.members:
            member.bridge(time_s)
        self._leak(dt)
        return self

    def _leak(self, dt):
        """Leak the weights towards equal over ``dt`` s (a hypothesis that lost may come back)."""
        leak = -np.expm1(-dt / self.switching_time_s)
        self.weights = (1.0 - leak) * self.weights + leak / len(self.weights)

    def _weigh(self, dt):
        """Leak the weights towards equal over ``dt`` s, then multiply by each filter's likelihood of the readings."""
        self._leak(dt)
        log_likelihood = np.array([member.log_likelihood for member in self.members])
        posterior = self.weights * np.exp(log_likelihood - log_likelihood.max())
        self.weights = posterior / posterior.sum()

    def _mixture(self, estimates):
        w = self.weights
        means = np.array([e.drift_um for e in estimates])
        variances = np.array([e.band_um for e in estimates]) ** 2 / Z95 ** 2
        mean = w @ means
        band = Z95 * np.sqrt(w @ (variances + (means - mean) ** 2)) * self.band_inflation
        return Estimate(estimates[0].time_s, mean, band, w @ np.array([e.temperatures_C for e in estimates]),
                        estimates[0].used, float(w @ [e.inflation for e in estimates]), estimates[0].rejected)

    def expected_readings(self, time_s: float, spindle_rpm: float, room_C: float) -> np.ndarray:
        """The weighted readings the hypotheses predict for the next sample (°C), without changing the observer.

        Parameters
        ----------
        time_s : float
            Machine time of the next sample, s.
        spindle_rpm, room_C : float
            Its spindle speed (rpm) and room air (°C).

        Returns
        -------
        numpy.ndarray
            (p,) readings, °C.
        """
        return self.weights @ np.array([m.expected_readings(time_s, spindle_rpm, room_C) for m in self.members])

    def field(self) -> np.ndarray:
        """The weighted full FE temperature field (°C per thermal node) of the present states.

        Returns
        -------
        field : ndarray, shape (n_thermal_nodes,)
            Temperatures, °C.
        """
        return self.weights @ np.array([member.field() for member in self.members])


#: The unread-source hypotheses ``twin live`` runs (σ_P of each, W): chosen on the training records by the rule
#: of ``python bench/bench_live.py --calibrate`` (docs/live.md, "Calibration protocol").
HYPOTHESES_W = (0.0, 40.0)


#: Factors on the 95 % band's half-width of the X, Y and Z drift that ``twin live`` publishes, 1: X and Y chosen on
#: the training records by the interval score (``python bench/bench_live.py --calibrate-xy``; docs/live.md,
#: "Calibration protocol"); Z is 1, its band calibrated by the choice of :data:`HYPOTHESES_W`.
BAND_INFLATION = (5.0, 1.25, 1.0)


def live_observer(rom: ReducedModel, thermometers: list[str], sensors: dict | None = None,
                  hypotheses_W: tuple[float, ...] | None = None, band_inflation: ArrayLike | None = None,
                  at_rest: bool = False) -> DriftObserver | MultipleModelObserver:
    """The observer ``twin live`` runs: the shipped noise model with the unread-source hypotheses.

    Parameters
    ----------
    rom, thermometers, sensors
        As :class:`MultipleModelObserver`.
    hypotheses_W : tuple of float, optional
        σ_P of each hypothesis, W (default :data:`HYPOTHESES_W`); one gives a single filter.
    band_inflation : array_like, optional
        (3,) factors on the X, Y, Z band's half-width, 1 (default :data:`BAND_INFLATION`; ``(1, 1, 1)``: the
        filter's own ±1.96 σ).
    at_rest : bool
        The machine is known to have stood idle in the room air before the start
        (:attr:`~twin.live.model.NoiseModel.start_at_rest`); default: its past is unknown.

    Returns
    -------
    DriftObserver or MultipleModelObserver
        A new observer, not started.
    """
    sizes = HYPOTHESES_W if hypotheses_W is None else tuple(hypotheses_W)
    inflation = BAND_INFLATION if band_inflation is None else band_inflation
    noise = dataclasses.replace(NOISE, start_at_rest=bool(at_rest))
    if len(sizes) == 1:
        return DriftObserver(rom, thermometers, dataclasses.replace(noise, concentrated_W=sizes[0]), sensors=sensors,
                             band_inflation=inflation)
    return MultipleModelObserver(rom, thermometers, sizes, noise, sensors=sensors, band_inflation=inflation)
