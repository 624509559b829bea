"""A real-time state observer on the ROM: a few thermometers + spindle speed + room air → field and TCP drift.

:class:`DriftObserver` runs a Kalman filter (:class:`models.kalman.KalmanFilter`, with a covariance step
specialised to the model's structure) on :class:`twin.live.model.ObserverModel`: the ROM's plant state space
augmented with the disturbances the nominal twin may get wrong — estimated ones (source powers, zone airs,
thermometer offsets) and considered ones whose uncertainty only widens the band (convection and power-model
errors, the room-air offset, misplaced heat).  Each sample is a prediction over the interval since the
previous one (the sample's inputs held over it) and a measurement update with the thermometers read (NaN
readings are skipped).  The estimated drift is Gaussian: its 95 % band is ±1.96 σ of the posterior.

**Innovation gate.**  Before the update, a reading whose normalised innovation ν²/S exceeds
:data:`INNOVATION_GATE`² is left out (:func:`gated`): a sensor fault, not information — unless half the thermometers
or more (two of two) disagree at once, which says the model is off.  A thermometer a sample lacks is judged by its
latest score (:class:`InnovationGate`), so a server that stamps each node apart is gated as one that does not.

Each input is held on its own: a sample that has the spindle speed but no room air (or the reverse) updates
the one it has.

**Adaptive widening.**  When the thermometers disagree with the model more than its covariance allows, the
model is off in a way its disturbances do not describe.  The normalised innovation squared (NIS, χ² with as
many degrees of freedom as readings) is averaged over a window of machine time (:attr:`Adaptation.window_s`,
exponential forgetting); while that average ā exceeds 1, the process noise of the disturbances is multiplied
by ā^:attr:`Adaptation.power` (covariance matching: a model error the filter does not expect inflates the
uncertainty it propagates), which widens the band and lets the filter follow.  ā = 1 leaves the filter as
designed.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from numbers import Real

import numpy as np
from numpy.typing import ArrayLike

from ..errors import TwinInputError
from ..rom.reduction import ReducedModel
from .filtering import ModalKalmanFilter
from .model import AXES, NoiseModel, ObserverModel

Z95 = 1.959963984540054
#: A reading more than this many standard deviations of its predicted spread from the prediction is rejected
#: (ν²/S > INNOVATION_GATE², far beyond any χ² tail): a glitching sensor (a DS18x20's 85 °C power-on value
#: scores 55σ or more on a machine near 25 °C).  Twice the largest model error of the training records (9.5σ, T09
#: beside the unmodelled 60 W belt drive), since a model error the gate rejected could not be learnt.
INNOVATION_GATE = 20.0
#: Prior probability that the machine stood at rest in the room air before the session, 1: the start prior is a
#: Gaussian sum of "at rest" and "past unknown" (:meth:`DriftObserver.start`), weighed by the first readings.  Even
#: odds: the observer is not told which.
REST_PRIOR_WEIGHT = 0.5
#: A sample interval longer than this many times the one before it, and than :data:`UNREAD_MIN_S`, holds a time when
#: nobody read the inputs (a dropped connection, a stalled logger): the spindle may have run, stopped or changed
#: speed there.  All of it but its last ordinary interval is bridged with the inputs unknown
#: (:meth:`DriftObserver.bridge`), as a resume from a saved state is; holding the new sample's inputs over it
#: instead gave 2.0 µm RMS and a 7.4 µm band where the bridge gives 0.93 µm and 4.0 µm (tests/test_live_resume.py).
UNREAD_FACTOR = 5.0
#: The shortest unread time bridged, s: shorter than the structure's thermal time constants, holding the inputs
#: moves the estimate about as much as a sample's timing does (the gap diagnosis's outage rule, twin.gap.outages).
UNREAD_MIN_S = 600.0


def gated(scores: ArrayLike, recent: ArrayLike | None = None) -> np.ndarray:
    """The readings the innovation gate rejects: ν²/S above :data:`INNOVATION_GATE`², when they are a sensor's fault.

    They are when fewer than half of the thermometers judged fail, or only one of two or more: when more fail
    together, it is the model that is off (a warm start, a long gap, heat it does not know), not the sensors, and
    all are kept, so the filter follows them.  The thermometers judged are this sample's readings and, with
    ``recent``, the latest score of each thermometer this sample lacks (a server that stamps each node apart
    sends one reading a sample: judged alone, it could never be told from the model being off).  A single
    thermometer is never rejected: nothing tells its fault from the model's.

    Parameters
    ----------
    scores : array_like
        (p,) normalised innovations squared ν²/S of the readings, 1 (NaN: missing).
    recent : array_like, optional
        (p,) each thermometer's latest ν²/S over the last few samples, 1 (NaN: none); default: ``scores``.

    Returns
    -------
    numpy.ndarray
        (p,) bool, True for a rejected reading.
    """
    scores = np.asarray(scores, float)
    judged = scores if recent is None else np.where(np.isfinite(scores), scores, np.asarray(recent, float))
    with np.errstate(invalid="ignore"):          # NaN (missing) compares False: never rejected
        out = scores > INNOVATION_GATE ** 2
        failing = int(np.sum(judged > INNOVATION_GATE ** 2))
    n = int(np.isfinite(judged).sum())
    if not out.any() or not (2 * failing < n or failing == 1 < n):
        return np.zeros(len(scores), bool)
    return out


class InnovationGate:
    """:func:`gated` with each thermometer's latest score kept for ``2 (p + 2)`` samples (p thermometers): a server
    that stamps each node apart sends one reading a sample, one round of the nodes in p + 2 samples.

    Parameters
    ----------
    n_readings : int
        p, the thermometers.
    """

    def __init__(self, n_readings: int) -> None:
        self.scores, self.age = np.full(n_readings, np.nan), np.full(n_readings, np.inf)

    def __call__(self, scores: ArrayLike) -> np.ndarray:
        """The readings :func:`gated` rejects, judged with the recent scores; this sample's are kept for the next.

        Parameters
        ----------
        scores : array_like
            (p,) ν²/S of this sample's readings, 1 (NaN: missing).

        Returns
        -------
        numpy.ndarray
            (p,) bool, True for a rejected reading.
        """
        scores = np.asarray(scores, float)
        seen = np.isfinite(scores)
        self.age += 1
        self.scores[seen], self.age[seen] = scores[seen], 0
        return gated(scores, np.where(self.age <= 2 * (len(scores) + 2), self.scores, np.nan))


def unread_time(last_interval_s: float | None, present_s: float | None, time_s: float) -> float:
    """The part of the interval to the sample at ``time_s`` (s) when nobody read the inputs, s, or 0.

    Parameters
    ----------
    last_interval_s : float or None
        The whole interval between the last two samples, s (None before a second sample: nothing to compare with).
    present_s : float or None
        Machine time of the last sample, s.
    time_s : float
        Machine time of the sample, s.

    Returns
    -------
    float
        The interval less ``last_interval_s``, when the interval is longer than :data:`UNREAD_FACTOR` of those
        and :data:`UNREAD_MIN_S`; else 0.  A logger that samples less often from then on is bridged once: the
        next interval is compared with this one.
    """
    if last_interval_s is None or present_s is None:
        return 0.0
    interval = float(time_s) - present_s
    if interval > UNREAD_FACTOR * last_interval_s and interval >= UNREAD_MIN_S:
        return interval - last_interval_s
    return 0.0


def axis_factors(band_inflation: ArrayLike | None) -> np.ndarray:
    """The (3,) X, Y, Z band inflation factors (1 each when None), checked finite and ≥ 1.

    Parameters
    ----------
    band_inflation : array_like or None
        (3,) factors on the 95 % band's half-width, 1.

    Returns
    -------
    numpy.ndarray
        (3,) factors, 1.
    """
    factors = np.ones(3) if band_inflation is None else np.asarray(band_inflation, float).reshape(-1)
    if factors.shape != (3,) or not np.all(np.isfinite(factors)) or np.any(factors < 1.0):
        raise TwinInputError(f"band_inflation needs three finite factors ≥ 1 (X, Y, Z), got {band_inflation!r}")
    return factors


@dataclass(frozen=True)
class Adaptation:
    """The NIS-driven widening of the process noise (see the module docstring).

    Attributes
    ----------
    window_s : float
        Time constant of the exponential average of NIS per reading, s of machine time (0: no adaptation), ≥ 0.
    power : float
        Exponent of the inflation ā^power applied to the disturbances' process noise, 1, ≥ 0.
    limit : float
        Largest inflation factor, 1, ≥ 1.

    Each is a finite number; another value raises a TwinInputError naming the field.
    """

    window_s: float = 0.0
    power: float = 1.0
    limit: float = 1e4

    def __post_init__(self) -> None:
        # the factor min(limit, max(1, ā)^power) only widens the process noise: a limit below 1 or a negative power
        # would narrow it (and a state file saved with such a factor is refused as corrupted)
        for name, rule, holds in (("window_s", "a time ≥ 0 s", lambda w: 0.0 <= w < np.inf),
                                  ("power", "an exponent ≥ 0", lambda p: 0.0 <= p < np.inf),
                                  ("limit", "a factor ≥ 1", lambda f: 1.0 <= f < np.inf)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, Real) or not holds(value):
                raise TwinInputError(f"Adaptation.{name} must be {rule}, finite, got {value!r}")


@dataclass
class Estimate:
    """The observer's estimate at one sample time.

    Attributes
    ----------
    time_s : float
        Machine time, s.
    drift_um : numpy.ndarray
        (3,) X, Y, Z drift, µm.
    band_um : numpy.ndarray
        (3,) half-width of the 95 % band, µm.
    temperatures_C : numpy.ndarray
        (k,) every ROM thermometer (:attr:`DriftObserver.field_names`), °C.
    used : int
        Thermometer readings fused.
    inflation : float
        The adaptive factor on the disturbances' process noise at this sample, 1.
    rejected : numpy.ndarray or None
        (p,) bool: readings the innovation gate left out (:func:`gated`).
    """

    time_s: float
    drift_um: np.ndarray
    band_um: np.ndarray
    temperatures_C: np.ndarray
    used: int
    inflation: float = 1.0
    rejected: np.ndarray | None = None


@dataclass
class FilterState:
    """What a :class:`DriftObserver` knows after a sample: enough to go on from it in another session.

    Attributes
    ----------
    time_s : float
        Machine time of the last sample fused, s.
    last_step_s : float
        The step before it, s: the sample interval, which a resume predicts as an ordinary step.
    spindle_rpm : float
        The last spindle speed read, rpm.
    room_C : float
        The last room air read, °C.
    mean : numpy.ndarray
        (N,) the state's estimate, in the states' units (°C, W, K, 1).
    covariance : numpy.ndarray
        (N, N) its covariance, in their squares.
    nis : float
        The adaptive widening's average NIS per reading, 1.
    inflation : float
        The adaptive factor on the disturbances' process noise, 1.
    """

    time_s: float
    last_step_s: float
    spindle_rpm: float
    room_C: float
    mean: np.ndarray
    covariance: np.ndarray
    nis: float
    inflation: float


class RecordRunner:
    """What every observer of this package shares: filtering a whole record sample by sample with ``step``."""

    def run(self, times_s: ArrayLike, spindle_rpm: ArrayLike, room_C: ArrayLike,
            temperatures_C: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Filter a whole record.

        Parameters
        ----------
        times_s : array_like
            (k,) sample times, s, increasing.
        spindle_rpm, room_C : array_like
            (k,) spindle speed (rpm) and room air (°C).
        temperatures_C : array_like
            (k, p) thermometer readings, °C.

        Returns
        -------
        tuple of numpy.ndarray
            The drift (k, 3) and the half-width of its 95 % band (k, 3), µm.
        """
        T = np.asarray(temperatures_C, float)
        drift, band = np.empty((len(times_s), 3)), np.empty((len(times_s), 3))
        for k, t in enumerate(times_s):
            e = self.step(float(t), float(spindle_rpm[k]), float(room_C[k]), T[k])
            drift[k], band[k] = e.drift_um, e.band_um
        return drift, band


class DriftObserver(RecordRunner):
    """Kalman observer of the ROM driven by spindle speed and room air, fusing a few thermometers.

    Parameters
    ----------
    rom : ReducedModel
        The machine's ROM (its thermometer outputs may include placement points,
        :func:`twin.rom.points.with_point_thermometers`).
    thermometers : list of str
        Names of the ROM thermometer outputs that are measured (``T18`` …), in the order of the readings.
    noise : NoiseModel
        Sizes of the noise model (default: :data:`NOISE`).
    adaptation : Adaptation
        The NIS-driven widening (default: :data:`ADAPTATION`).
    sensors : dict, optional
        Thermometer name → sensor model (``DS18S20``, the default, or ``S65`` for thermal-camera spots), which
        sets its offset prior and reading noise (:class:`~twin.live.model.ObserverModel`).
    concentrated : numpy.ndarray, optional
        (r, r) second moment of a 1 W source at an unknown cell of the machine
        (:func:`~twin.live.model.concentrated_moment`); default: that of ``rom``, built once and cached.
    band_inflation : array_like, optional
        (3,) factor on the X, Y, Z band's half-width (1: the posterior's ±1.96 σ, the default); ``twin live``
        runs :data:`~twin.live.multiple_model.BAND_INFLATION`.
    """

    def __init__(self, rom: ReducedModel, thermometers: list[str], noise: NoiseModel | None = None,
                 adaptation: Adaptation | None = None, sensors: dict | None = None,
                 concentrated: np.ndarray | None = None, band_inflation: ArrayLike | None = None) -> None:
        self.band_inflation = axis_factors(band_inflation)
        self.model = ObserverModel(rom, thermometers, NOISE if noise is None else noise, sensors, concentrated)
        self.adaptation = ADAPTATION if adaptation is None else adaptation
        self.rom, self.thermometers = rom, self.model.thermometers
        self.field_names = self.model.field_names
        self._power, self._kf = {}, None
        self._room = np.r_[self.model.plant_inputs(0.0, 1.0)[0] - self.model.plant_inputs(0.0, 0.0)[0], 0.0]
        self.time_s, self._rpm, self._rest = None, 0.0, None
        #: the last prediction step, s: the sample interval (None until a second sample came)
        self.last_step_s = None
        #: the whole interval between the last two samples, s, a bridged time included (:func:`unread_time`)
        self.last_interval_s = None
        #: the weight the first readings gave the at-rest start prior (NaN until they came; :meth:`start`)
        self.rest_weight = np.nan
        self._gate = InnovationGate(len(self.thermometers))

    # ------------------------------------------------------------------ filtering
    def start(self, time_s: float, room_C: float) -> DriftObserver:
        """Start from the idle steady state in the room air ``room_C`` (°C) at ``time_s`` (s), its past unknown.

        Unless the noise model says the machine stood at rest (:attr:`~twin.live.model.NoiseModel.start_at_rest`),
        the prior is a Gaussian sum: at rest or with an unknown past (:meth:`~twin.live.model.ObserverModel.prior`),
        weighed :data:`REST_PRIOR_WEIGHT` and by how well each predicts the first thermometer readings, then
        collapsed to one Gaussian (:meth:`_weigh_start`).  The
        first readings of a warm machine rule out the rest; those of a machine at rest favour it, and their sensor
        offsets are not taken for heat.

        Parameters
        ----------
        time_s : float
            Machine time of the start, s.
        room_C : float
            Room air, °C.

        Returns
        -------
        self : DriftObserver
            The observer, started.
        """
        model = self.model
        x0, P0 = model.prior(room_C)
        #: the at-rest prior's covariance, carried beside the unknown past's until the first readings weigh them
        self._rest = None if model.noise.start_at_rest else P0
        if self._rest is not None:
            P0 = model.prior(room_C, unknown_past=True)[1]
        F, _, G, Q = model.matrices(1.0)
        self._kf = ModalKalmanFilter(self.rom.order, F, G, model.H, model.J, Q, model.R, model.consider,
                                     model.couplings).reset(x0, P0)
        self.time_s, self._u = float(time_s), np.r_[model.plant_inputs(0.0, room_C)[0], 1.0]
        self._rpm, self._air, self._prepared, self.last_step_s = 0.0, float(room_C), None, None
        self.last_interval_s = None
        self._nis, self.inflation = 1.0, 1.0
        self._gate = InnovationGate(len(self.thermometers))
        return self

    def step(self, time_s: float, spindle_rpm: float, room_C: float, temperatures_C: ArrayLike) -> Estimate | None:
        """Fuse one sample: thermometer readings (°C, NaN = missing) in the order of :attr:`thermometers`.

        Parameters
        ----------
        time_s : float
            Machine time of the sample, s; must be after the previous sample's.
        spindle_rpm : float
            Spindle speed, rpm (NaN: keep the last speed read).
        room_C : float
            Room air, °C (NaN: keep the last room air read).
        temperatures_C : array_like
            (p,) thermometer readings, °C.

        Returns
        -------
        Estimate or None
            None until a room air reading has started the observer.  The inputs over the interval since the
            previous sample are this sample's readings, held (a record of the twin holds left limits: the
            speed over the interval that ends at the sample); each input is held on its own, so a sample with
            only one of them updates that one.  An interval that holds a time nobody read the inputs
            (:func:`unread_time`) is bridged with them unknown up to its last ordinary interval.  Readings the innovation gate rejects (:func:`gated`) are not
            fused (:attr:`Estimate.rejected`).

        Raises
        ------
        TwinInputError
            If the sample is not later than the previous one.
        """
        y = np.asarray(temperatures_C, float).reshape(len(self.thermometers))
        previous = self.time_s
        unread = unread_time(self.last_interval_s, previous, time_s)
        if unread:
            self.bridge(previous + unread)
        dt = self.advance(time_s, spindle_rpm, room_C)
        if not self.started:
            return None
        if dt is not None:
            self.last_interval_s = float(time_s) - previous
        return self.fuse(y, dt, self._gate(self.innovation_scores(y)))

    @property
    def started(self) -> bool:
        """Whether a room air reading has started the filter."""
        return self._kf is not None

    def advance(self, time_s: float, spindle_rpm: float, room_C: float) -> float | None:
        """Predict to the sample at ``time_s`` (s) with its inputs (rpm, °C; NaN keeps that input), or start.

        Parameters
        ----------
        time_s : float
            Machine time of the sample, s.
        spindle_rpm, room_C : float
            Its spindle speed (rpm) and room air (°C).

        Returns
        -------
        float or None
            The prediction step, s; None when this sample started the observer or nothing could (no room air).

        Raises
        ------
        TwinInputError
            If the sample is not later than the previous one.
        """
        if not self.started:
            # a speed read before the first room air is held for the start (a speed reported only on change may
            # not come again for hours)
            rpm = self._rpm = float(spindle_rpm) if np.isfinite(spindle_rpm) else self._rpm
            if not np.isfinite(room_C):
                return None                    # no room air yet: nothing to start from
            self.start(time_s, room_C)
            self._rpm = rpm
            dt = None
        elif time_s <= self.time_s:
            raise TwinInputError(f"observer: sample time {time_s} s is not after the previous {self.time_s} s")
        else:
            dt = self.last_step_s = float(time_s) - self.time_s
            self._rpm, self._air, self._u = self._inputs(spindle_rpm, room_C)
            self._predict(dt)
            self.time_s = float(time_s)
        model = self.model
        H, self._L, self._Lf = model.output_rows(model.excitations(self._kf.x, self._u)) if model.feeds else (
            model.H, model.L, model.Lf)
        self._kf.H = H
        return dt

    def innovation_scores(self, temperatures_C: ArrayLike) -> np.ndarray:
        """Each reading's normalised innovation squared ν²/S against the present prediction (χ², 1 degree of freedom).

        Parameters
        ----------
        temperatures_C : array_like
            (p,) thermometer readings, °C (NaN = missing).

        Returns
        -------
        numpy.ndarray
            (p,) ν²/S per reading, 1; NaN for a missing one.
        """
        y = np.asarray(temperatures_C, float)
        scores = np.full(len(y), np.nan)
        if np.isfinite(y).any():
            # kept for the update that follows (the same readings unless the gate rejects one)
            self._prepared = self._kf.innovations(y, self._u)
            seen, innovation, _, S = self._prepared
            scores[seen] = innovation ** 2 / np.diagonal(S)
        return scores

    def fuse(self, temperatures_C: ArrayLike, dt: float | None, rejected: np.ndarray) -> Estimate:
        """Update with the readings but the ``rejected`` ones, after :meth:`advance` over ``dt`` s.

        Parameters
        ----------
        temperatures_C : array_like
            (p,) thermometer readings, °C (NaN = missing).
        dt : float or None
            The step :meth:`advance` returned, s (None: the sample that started the observer).
        rejected : numpy.ndarray
            (p,) bool, readings left out.

        Returns
        -------
        Estimate
            The estimate at the sample.
        """
        y = np.asarray(temperatures_C, float)
        prepared, self._prepared = self._prepared, None
        if rejected.any():
            y, prepared = np.where(rejected, np.nan, y), None
        used = int(np.isfinite(y).sum())
        if used and self._rest is not None:
            nis = self._weigh_start(y, prepared)
        else:
            nis = self._kf.update(y, self._u, prepared)
        if dt is not None and used:
            self._adapt(nis / used, dt)
        return self._estimate(used, rejected)

    def _weigh_start(self, y, prepared):
        """Update both start priors with the first readings ``y`` (°C), weigh them by :data:`REST_PRIOR_WEIGHT` and
        their likelihoods, and keep the mixture's mean and covariance (moment matching); returns the NIS of the
        unknown past's update.  The filter's log-likelihood becomes the mixture's (the hypotheses' weights)."""
        kf, u = self._kf, self._u
        x, rest, self._rest = kf.x, self._rest, None
        nis = kf.update(y, u, prepared)
        parts = [(kf.x, kf.P, np.log1p(-REST_PRIOR_WEIGHT) + kf.log_likelihood)]
        kf.x, kf.P = x, rest
        kf.update(y, u)
        parts.append((kf.x, kf.P, np.log(REST_PRIOR_WEIGHT) + kf.log_likelihood))
        logs = np.array([part[2] for part in parts])
        w = np.exp(logs - logs.max())
        kf.log_likelihood = float(logs.max() + np.log(w.sum()))
        w /= w.sum()
        mean = sum(wi * xi for wi, (xi, _, _) in zip(w, parts))
        P = sum(wi * (Pi + np.outer(xi - mean, xi - mean)) for wi, (xi, Pi, _) in zip(w, parts))
        kf.x, kf.P = mean, 0.5 * (P + P.T)
        self.rest_weight = float(w[1])
        return nis

    # ------------------------------------------------------------------ across sessions
    def state(self) -> FilterState | None:
        """What the observer knows now, to go on from it in another session (:meth:`restore`).

        Returns
        -------
        FilterState or None
            None before the first readings weighed the start priors (until then it knows nothing the start prior
            would not give again) or before a second sample (no sample interval yet).
        """
        if not self.started or self._rest is not None or self.last_step_s is None:
            return None
        kf = self._kf
        return FilterState(self.time_s, self.last_step_s, self._rpm, self._air, kf.x.copy(), kf.P.copy(), self._nis,
                           self.inflation)

    def restore(self, state: FilterState) -> DriftObserver:
        """Go on from ``state`` (:meth:`state`, of an observer of the same model) as if its samples had been fused
        here.  The innovation gate's memory of the last few samples' scores starts afresh.

        Parameters
        ----------
        state : FilterState
            The state to go on from.

        Returns
        -------
        self : DriftObserver
            The observer at ``state.time_s``.
        """
        self.start(state.time_s, state.room_C)
        self._rest = None
        self._kf.x, self._kf.P = np.array(state.mean, float), np.array(state.covariance, float)
        self._rpm, self._nis, self.inflation = float(state.spindle_rpm), float(state.nis), float(state.inflation)
        self.last_step_s = self.last_interval_s = float(state.last_step_s)
        return self

    def bridge(self, time_s: float) -> DriftObserver:
        """Predict to ``time_s`` (s) across a time when nobody read the inputs (the twin was not running).

        The ordinary prediction with the last inputs held — so the considered errors that scale with the physics
        (a power model, a film coefficient) act as they did when the machine was last seen — with the held load's
        response replaced by that of the inputs nobody read (:meth:`~twin.live.model.ObserverModel.unknown_inputs`):
        the last speed's load forgotten at the correlation time, the load and the room air unknown about it, more
        so the longer the time.  The thermometer offsets, constant, are kept as they were.

        Parameters
        ----------
        time_s : float
            Machine time to predict to, s; after the present one.

        Returns
        -------
        self : DriftObserver
            The observer at ``time_s``.

        Raises
        ------
        TwinInputError
            If ``time_s`` is not after the present time.
        """
        if not time_s > self.time_s:
            raise TwinInputError(f"observer: cannot bridge to {time_s} s, not after the present {self.time_s} s")
        dt, n = float(time_s) - self.time_s, self.model.n
        self._u, idle = self._inputs(self._rpm, self._air)[2], self._inputs(0.0, self._air)[2]
        self._predict(dt)
        mean, covariance = self.model.unknown_inputs(dt, self._rpm)
        # the held load's response out (the ordinary prediction's), the forgotten load's in
        self._kf.x[:n] += mean - self.model.matrices(dt)[2][:n] @ (self._u - idle)
        self._kf.P[:n, :n] += covariance
        if self._rest is not None:      # the at-rest start prior, not yet weighed, did not see that time either
            self._rest[:n, :n] += covariance
        self.time_s = float(time_s)
        return self

    def expected_readings(self, time_s: float, spindle_rpm: float, room_C: float) -> np.ndarray:
        """The thermometer readings the model predicts for the next sample, without changing the observer.

        Parameters
        ----------
        time_s : float
            Machine time of the next sample, s (after the present one).
        spindle_rpm, room_C : float
            Its spindle speed (rpm) and room air (°C), held over the interval up to it.

        Returns
        -------
        numpy.ndarray
            (p,) readings, °C, offsets included.
        """
        model, u = self.model, self._inputs(spindle_rpm, room_C)[2]
        F, G, _ = self._transition(float(time_s) - self.time_s, u)
        x = F @ self._kf.x + G @ u
        return model.output_rows(model.excitations(x, u))[0] @ x + model.J @ u

    def _transition(self, dt, u):
        """``(F, G, Q)`` of the step of ``dt`` s with the inputs ``u`` from the present estimate (its excitations)."""
        model = self.model
        n, q = model.n, model.q
        F0, dF, G, Q = model.matrices(dt)
        F = F0.copy()
        F[:n, n:n + q] = dF * model.excitations(self._kf.x, u)
        return F, G, Q

    def _predict(self, dt):
        """The prediction over ``dt`` s, with the disturbances' process noise widened by the NIS."""
        kf, n, q = self._kf, self.model.n, self.model.q
        F, G, Q = self._transition(dt, self._u)
        if self.inflation != 1.0:
            Q = Q.copy()
            Q[n:n + q, n:n + q] *= self.inflation
        kf.F, kf.G, kf.Q = F, G, Q
        if self._rest is not None:
            # no reading yet: the at-rest prior's covariance follows the same dynamics (the means are one)
            x, P = kf.x, kf.P
            kf.P = self._rest
            self._rest = kf.predict(self._u).P
            kf.x, kf.P = x, P
        kf.predict(self._u)

    def _adapt(self, nis_per_reading, dt):
        """Average the NIS per reading over the window and set the inflation of the next prediction."""
        a = self.adaptation
        if a.window_s <= 0:
            return
        keep = np.exp(-dt / a.window_s)
        self._nis = keep * self._nis + (1.0 - keep) * nis_per_reading
        self.inflation = float(min(a.limit, max(1.0, self._nis) ** a.power))

    def _inputs(self, spindle_rpm, room_C):
        """``(speed rpm, room °C, [u, 1])`` of a sample, each input that is NaN at its last reading: servers stamp
        the nodes apart or report the speed only when it changes, so a sample may carry one input and not the
        other.  The power part is cached per speed (machines run at a few speeds)."""
        rpm = float(spindle_rpm) if np.isfinite(spindle_rpm) else self._rpm
        room = float(room_C) if np.isfinite(room_C) else self._air
        power = self._power.get(rpm)
        if power is None:
            if len(self._power) > 4096:
                self._power.clear()
            power = self._power[rpm] = np.r_[self.model.plant_inputs(rpm, 0.0)[0], 1.0]
        return rpm, room, power + room * self._room

    def _estimate(self, used, rejected):
        kf, u, model, L = self._kf, self._u, self.model, self._L
        sd = np.sqrt(np.maximum(((L @ kf.P) * L).sum(axis=1), 0.0))
        return Estimate(self.time_s, L @ kf.x + model.M @ u, Z95 * sd * self.band_inflation,
                        self._Lf @ kf.x + model.Mf @ u, used,
                        self.inflation, rejected)

    @property
    def log_likelihood(self) -> float:
        """ln N(ν; 0, S) of the last readings fused: how well the model predicted them (:class:`~twin.live.multiple_model.MultipleModelObserver`)."""
        return self._kf.log_likelihood

    def field(self) -> np.ndarray:
        """The full FE temperature field (°C per thermal node) of the present state.

        Returns
        -------
        field : ndarray, shape (n_thermal_nodes,)
            Temperatures, °C.

        Raises
        ------
        TwinInputError
            If the ROM was built without its basis (``keep_basis=True`` in :func:`twin.rom.reduction.build_rom`).
        """
        if self.rom.basis is None:
            raise TwinInputError("this ROM has no basis (build it with keep_basis=True) to map the state to the "
                                 "full field; Estimate.temperatures_C has the ROM thermometers")
        return self.rom.basis @ self._kf.x[:self.rom.order]


#: The noise model's sizes (:class:`~twin.live.model.NoiseModel`): set from the physics, but for the misplaced
#: heat κ = 0.05, chosen on the training records (docs/live.md, "Calibration protocol").  The concentrated
#: source's σ_P is that of each hypothesis ``twin live`` weighs (:data:`twin.live.multiple_model.HYPOTHESES_W`).
NOISE = NoiseModel(discrepancy=0.05, concentrated_W=0.0)
#: The adaptive widening (:class:`Adaptation`): a 1 h window, chosen with κ on the training records.
ADAPTATION = Adaptation(window_s=3600.0)
#: :data:`NOISE` for a machine known to stand at rest in the room air at the start (the model runs of
#: :func:`choose_thermometers` start so, and its choice does not depend on the start prior).
AT_REST = dataclasses.replace(NOISE, start_at_rest=True)


def choose_thermometers(rom: ReducedModel, k: int = 6, axis: str = "Z", candidates: list[str] | None = None,
                        step_s: float = 300.0, horizon_s: float = 4 * 3600.0) -> list[str]:
    """Greedy choice of ``k`` ROM thermometers that minimise the observer's posterior std of ``axis``.

    Model-based (no record is used, so no scenario is favoured): for each candidate added to the set
    chosen so far, the observer (started at rest, :data:`AT_REST`) runs for ``horizon_s`` at ``step_s`` at full
    spindle speed in 20 °C air, reading what the nominal model predicts (so the innovations are zero and the
    covariance follows the model); the candidate giving the smallest final drift std is kept.

    Parameters
    ----------
    rom : ReducedModel
        The ROM; placement points added with :func:`twin.rom.points.with_point_thermometers` are candidates too.
    k : int
        How many thermometers to choose.
    axis : str
        ``X``, ``Y`` or ``Z``.
    candidates : list of str, optional
        ROM thermometer outputs to choose among (default: every one).
    step_s, horizon_s : float
        Sample interval and length of the model run, s.

    Returns
    -------
    list of str
        The names in order of choice.
    """
    names = [n for n, kd in zip(rom.output_names, rom.output_kinds) if kd == "temperature"] \
        if candidates is None else list(candidates)
    if axis not in AXES:
        raise TwinInputError(f"axis must be one of {', '.join(AXES)}, got {axis!r}")
    if not 0 < k <= len(names):
        raise TwinInputError(f"cannot choose {k} thermometers among {len(names)} candidates")
    rpm, chosen = float(rom.limits["max_spindle_rpm"]), []
    j = AXES.index(axis)
    for _ in range(k):
        best = None
        for name in names:
            if name in chosen:
                continue
            band = _final_band(DriftObserver(rom, chosen + [name], AT_REST), rpm, step_s, horizon_s)[j]
            if best is None or band < best[0]:
                best = (band, name)
        chosen.append(best[1])
    return chosen


def _final_band(observer, rpm, step_s, horizon_s):
    """The 95 % half-band (3,) after running ``observer`` on the readings its model expects, µm."""
    e = observer.step(0.0, rpm, 20.0, np.full(len(observer.thermometers), np.nan))
    for step in range(1, int(horizon_s / step_s) + 1):
        t = step * step_s
        e = observer.step(t, rpm, 20.0, observer.expected_readings(t, rpm, 20.0))
    return e.band_um
