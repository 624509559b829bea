"""A real-time state observer on the ROM: a few thermometers + spindle speed + room air → field and TCP drift.

The model is the ROM's plant state space (:meth:`twin.rom.reduction.ReducedModel.plant_state_space`:
reduced modal coordinates z plus the air of the lagged zones, e.g. the enclosure), augmented for
what the nominal twin does not know::

    x = [ z (r) | w lagged air (l), °C | d input disturbances (m_d) | b thermometer offsets (p), °C ]

    ż = −Λ z + B (u + E d),  ẇ = (u_room − w)/τ + ν_w,  ḋ = −d/τ_d + ν_d,  ḃ = 0
    y_T = C_T [z, w] + D_T (u + E d) + c_T + b + v,     drift = C_XYZ [z, w] + D_XYZ (u + E d) + c_XYZ

u are the plant inputs made from what the machine publishes: spindle speed (rpm → the power of the
spindle-driven sources through the ROM's power models), the feeds (0 unless given) and the room air
(°C, for every zone that does not lag).  It is discretised exactly (ZOH for the inputs, Van Loan for
the process noise, :func:`models.kalman.discretize`) for each sample interval met, and filtered with
:class:`models.kalman.KalmanFilter` (NaN readings are skipped).  Covariances, and where they come from:

* thermometer offsets b: DS18S20 accuracy ±0.5 °C uniform (:data:`twin.core.noise.MODELS`) → prior
  variance 0.5²/3 K², constant in time: the filter learns each offset against the model while the
  machine is near its known start state, instead of treating a constant offset as white noise;
* R (per thermometer): the DS18S20 resolution 0.0625 °C as quantisation noise 0.0625²/12 K², plus
  the ROM's reduction error against the full FE, 2.43e-3 K worst over the shipped scenarios
  (docs/rom_fmu.md, r = 80), as a variance; plus :data:`MODEL_ERROR_K` for thermometer-level model
  error not carried by the input disturbances below (a chosen value, not fitted);
* d: one first-order Gauss–Markov process ḋ = −d/τ_d + ν (stationary σ, correlation time
  :data:`DISTURBANCE_TIME_S`, intensity 2σ²/τ_d) per zone ambient (σ = :data:`AMBIENT_SIGMA_K`) and
  per heat source (σ = :data:`POWER_SIGMA_FRACTION` of its reference power): the unmodelled effects
  of the gap diagnosis (wrong convection, air pockets, wrong power models) act like slowly varying
  biased inputs; bounded (not random walks), so directions the thermometers cannot see keep a finite
  band and the gain settles;
* lagged air w: σ = :data:`AMBIENT_SIGMA_K` about its first-order lag (intensity 2σ²/τ of the lag).

The estimated drift is Gaussian: its 95 % band is ±1.96 σ.  Everything is arrays after construction.
A step costs the covariance recursion of the ~100-state model (block-structured, see
:class:`_ModalKalmanFilter`) until the gain settles, then a few matrix–vector products.  The sizes above
give the noise model's shape; its size is one common factor on every covariance,
:data:`COVARIANCE_SCALE`, fitted on training records for 95 % Z coverage (it changes the band, not the
estimates; docs/live.md has the rule and the held-out coverage).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from models.kalman import KalmanFilter, discretize

from ..core.noise import MODELS
from ..errors import TwinInputError

AXES = ("X", "Y", "Z")
Z95 = 1.959963984540054
#: Thermometer accuracy, resolution (°C) of the DS18S20 model the twin's records use.
OFFSET_C = MODELS["DS18S20"]["offset_per_sensor"]
RESOLUTION_C = MODELS["DS18S20"]["resolution"]
#: Worst ROM (r = 80) − FE thermometer error over the shipped scenarios, K (docs/rom_fmu.md).
ROM_ERROR_K = 2.43e-3
#: Thermometer-level error of the nominal twin against a machine with unmodelled effects, K (rms).
MODEL_ERROR_K = 0.05
#: Standard deviation of each unmodelled zone-ambient error (and of the lagged air about its lag), K.
AMBIENT_SIGMA_K = 1.0
#: Standard deviation of each unmodelled heat-source error, fraction of its reference power.
POWER_SIGMA_FRACTION = 0.3
#: Correlation time of the input disturbances (first-order Gauss–Markov), s.
DISTURBANCE_TIME_S = 4 * 3600.0
#: Prior standard deviation of the start state about the idle steady state in the room air, K.
START_SPREAD_K = 0.3
#: Common factor on every covariance above (process noise, measurement noise, prior), fitted on training
#: records by ``python bench/bench_live.py --calibrate`` (see :func:`covariance_scale_for_coverage`).
#: Scaling all covariances by one factor leaves the Kalman gain, hence the estimates, unchanged and
#: scales the band by its square root: the shape of the noise model is chosen, its size is fitted.
COVARIANCE_SCALE = 0.1638
#: Relative change of the Kalman gain per second of like steps below which it counts as stationary, 1/s.
GAIN_TOLERANCE = 1e-7


@dataclass
class Estimate:
    """The observer's estimate at one sample time."""

    time_s: float
    drift_um: np.ndarray        #: (3,) X, Y, Z drift, µm
    band_um: np.ndarray         #: (3,) half-width of the 95 % band, µm
    temperatures_C: np.ndarray  #: (k,) every ROM thermometer (:attr:`DriftObserver.field_names`), °C
    used: int                   #: thermometer readings fused


class _ModalKalmanFilter(KalmanFilter):
    """:class:`~models.kalman.KalmanFilter` whose covariance step uses the structure of the observer's model.

    The transition matrix is block upper triangular with a diagonal first block (the ROM's modal
    coordinates are decoupled first-order filters: e^{−λh}), F = [[diag a, F₁₂], [0, F₂₂]], so
    F P Fᵀ costs O(r² c) with c the few other states instead of O(n³).  The measurement update is the
    symmetrised standard form P − K S Kᵀ (O(n² p)); the Joseph form of the base class costs two n³
    products, which dominated the step.  Same numbers as the base class to rounding (tested).
    """

    def __init__(self, order, *args):
        super().__init__(*args)
        self.order, self.gain = order, None     # gain: K of the last update that used every measurement

    def predict(self, u):
        r, F, P = self.order, self.F, self.P
        a, F12, F22 = np.diag(F)[:r], F[:r, r:], F[r:, r:]
        P11, P12, P22 = P[:r, :r], P[:r, r:], P[r:, r:]
        T11 = a[:, None] * P11 + F12 @ P12.T
        T12 = a[:, None] * P12 + F12 @ P22
        T21, T22 = F22 @ P12.T, F22 @ P22
        top = np.hstack([T11 * a[None, :] + T12 @ F12.T, T12 @ F22.T])
        bottom = np.hstack([T21 * a[None, :] + T22 @ F12.T, T22 @ F22.T])
        P = np.vstack([top, bottom]) + self.Q
        self.P = 0.5 * (P + P.T)
        self.x = F @ self.x + self.G @ np.asarray(u, float)
        return self

    def update(self, y, u):
        y = np.asarray(y, float)
        seen = np.isfinite(y)
        self.gain = None
        if not seen.any():
            return np.nan
        H = self.H[seen]
        innovation = y[seen] - H @ self.x - self.J[seen] @ np.asarray(u, float)
        HP = H @ self.P
        S = HP @ H.T + self.R[np.ix_(seen, seen)]
        factor = cho_factor(0.5 * (S + S.T))
        K = cho_solve(factor, HP).T
        self.gain = K if seen.all() else None
        self.x = self.x + K @ innovation
        P = self.P - K @ HP
        self.P = 0.5 * (P + P.T)
        return float(innovation @ cho_solve(factor, innovation))


def _checked_thermometers(rom, thermometers):
    """The thermometer names as a list, each a surface thermometer output of ``rom`` (else a clear error)."""
    thermometers = list(thermometers)
    if not thermometers:
        raise TwinInputError("the observer needs at least one thermometer")
    kinds = dict(zip(rom.output_names, rom.output_kinds))
    for name in thermometers:
        if kinds.get(name) != "temperature":
            known = [n for n, k in kinds.items() if k == "temperature"]
            raise TwinInputError(f"thermometer {name!r} is not a surface thermometer of the ROM of "
                                 f"{rom.machine!r}; thermometers: {', '.join(known)}")
    return thermometers


def _disturbance_sigmas(rom, input_names, ambient_sigma_K, power_sigma_fraction):
    """Standard deviation of the slow error of each disturbed plant input: W for a heat source, K for an air."""
    sigmas = []
    for name in input_names:
        if name.startswith("power:"):
            src = next(s for s in rom.sources if f"power:{s['name']}" == name)
            sigmas.append(power_sigma_fraction * src["coefficient_W"])
        else:
            sigmas.append(ambient_sigma_K)
    return sigmas


class DriftObserver:
    """Kalman observer of the ROM driven by spindle speed and room air, fusing ≤ a few thermometers.

    Parameters
    ----------
    rom : :class:`~twin.rom.reduction.ReducedModel`
    thermometers : names of ROM thermometer outputs that are measured (``T03`` …)
    model_error_K, ambient_sigma_K, power_sigma_fraction, disturbance_time_s, covariance_scale : see the
        module constants
    """

    def __init__(self, rom, thermometers, model_error_K=MODEL_ERROR_K, ambient_sigma_K=AMBIENT_SIGMA_K,
                 power_sigma_fraction=POWER_SIGMA_FRACTION, disturbance_time_s=DISTURBANCE_TIME_S,
                 covariance_scale=COVARIANCE_SCALE):
        thermometers = _checked_thermometers(rom, thermometers)
        self.rom, self.thermometers = rom, thermometers
        ss = rom.plant_state_space()
        self.input_names = list(ss.input_names)
        n, m = ss.A.shape[0], ss.B.shape[1]
        # input disturbances on every zone ambient and heat source the plant takes (not the gradient)
        dist = [j for j, name in enumerate(self.input_names) if name != "ambient_gradient"]
        E = np.zeros((m, len(dist)))
        E[dist, np.arange(len(dist))] = 1.0
        p, md = len(thermometers), len(dist)
        N = n + md + p
        self._sizes = (n, md, p)
        A = np.zeros((N, N))
        A[:n, :n], A[:n, n:n + md] = ss.A, ss.B @ E
        A[np.arange(n, n + md), np.arange(n, n + md)] = -1.0 / disturbance_time_s
        self._A, self._B = A, np.vstack([ss.B, np.zeros((md + p, m))])
        scale = _disturbance_sigmas(rom, [self.input_names[j] for j in dist], ambient_sigma_K, power_sigma_fraction)
        # process-noise intensities (unit² per s)
        Qc = np.zeros((N, N))
        r = rom.order
        lags = np.array([rom.zone_lags_s[z] for z in rom.lagged_zones])
        Qc[np.arange(r, n), np.arange(r, n)] = 2 * ambient_sigma_K ** 2 / lags
        Qc[np.arange(n, n + md), np.arange(n, n + md)] = 2 * np.square(scale) / disturbance_time_s
        self._scale = float(covariance_scale)
        self._Qc, self._disturbance_var = self._scale * Qc, np.square(scale)
        kinds = dict(zip(rom.output_names, rom.output_kinds))

        def rows(names):
            idx = [rom.output_index(nm) for nm in names]
            H = np.hstack([ss.C[idx], ss.D[idx] @ E, np.zeros((len(idx), p))])
            return H, np.hstack([ss.D[idx], ss.offset[idx, None]])

        H, J = rows(thermometers)
        H[:, n + md:] = np.eye(p)
        self._H, self._J = H, J
        self.field_names = [nm for nm, k in kinds.items() if k == "temperature"]
        self._L, self._M = rows(list(AXES))
        self._Lf, self._Mf = rows(self.field_names)
        self._R = self._scale * np.full(p, RESOLUTION_C ** 2 / 12 + ROM_ERROR_K ** 2 + model_error_K ** 2)
        self._steps, self._power = {}, {}
        self._room = self.plant_inputs(0.0, 1.0)[0] - self.plant_inputs(0.0, 0.0)[0]
        self._kf = None
        self.time_s = None

    # ------------------------------------------------------------------ inputs
    def plant_inputs(self, spindle_rpm, room_C, feed_mm_min=None):
        """Plant inputs (k, m_p) and the augmented row [u, 1] for spindle speed (rpm) and room air (°C) arrays."""
        rpm = np.atleast_1d(np.asarray(spindle_rpm, float))
        room = np.broadcast_to(np.asarray(room_C, float), rpm.shape)
        ambient = {z: room for z in self.rom.measured_zones}
        return self.rom.plant_inputs_from_conditions(rpm, feed_mm_min, ambient, 0.0)

    def _model(self, dt):
        key = round(float(dt), 6)
        if key not in self._steps:
            if len(self._steps) > 64:          # irregular sampling: keep the cache bounded
                self._steps.clear()
            F, G, Q = discretize(self._A, self._B, key, self._Qc)
            self._steps[key] = (F, np.hstack([G, np.zeros((len(F), 1))]), Q)
        return self._steps[key]

    # ------------------------------------------------------------------ filtering
    def start(self, time_s, spindle_rpm, room_C):
        """Start from the idle steady state in the room air at ``time_s`` (spread :data:`START_SPREAD_K`)."""
        n, md, p = self._sizes
        u = self.plant_inputs(0.0, room_C)[0]
        x0 = np.zeros(n + md + p)
        x0[:n] = self.rom.plant_steady_state(u)
        s = np.r_[self.rom.uniform_state, np.ones(n - self.rom.order)]
        P0 = np.zeros((len(x0), len(x0)))
        P0[:n, :n] = START_SPREAD_K ** 2 * np.outer(s, s) + (0.1 * START_SPREAD_K) ** 2 * np.diag(
            np.r_[np.full(self.rom.order, s[:self.rom.order] @ s[:self.rom.order] / self.rom.order),
                  np.ones(n - self.rom.order)])
        P0[n + md:, n + md:] = np.eye(p) * OFFSET_C ** 2 / 3
        P0[n:n + md, n:n + md] = np.diag(self._disturbance_var)
        F, G, Q = self._model(1.0)
        kf = _ModalKalmanFilter(self.rom.order, F, G, self._H, self._J, Q, self._R)
        self._kf = kf.reset(x0, self._scale * P0)
        self._gain = self._frozen = None
        self.time_s, self._u = float(time_s), np.r_[u, 1.0]
        return self

    def step(self, time_s, spindle_rpm, room_C, temperatures_C):
        """Fuse one sample: thermometer readings (°C, NaN = missing) in the order of ``thermometers``.

        The inputs over the interval since the previous sample are taken as the previous sample's
        (held, as the machine reported them); a sample not later than the previous one is refused.
        A NaN speed or room air keeps the previous input.  Returns ``None`` until a room air reading
        has started the observer.

        Once the gain has settled (relative change < :data:`GAIN_TOLERANCE` between two steps of the
        same interval with every thermometer read), the filter runs on that stationary gain and
        covariance — the covariance recursion would return them unchanged — and leaves it at the
        first sample with another interval or a missing reading.
        """
        y = np.asarray(temperatures_C, float).reshape(len(self.thermometers))
        seen = np.isfinite(y)
        kf = self._kf
        if kf is None:
            if not np.isfinite(room_C):
                return None                    # no room air yet: nothing to start from
            self.start(time_s, spindle_rpm, room_C)
            kf, pattern = self._kf, None
        elif time_s <= self.time_s:
            raise TwinInputError(f"observer: sample time {time_s} s is not after the previous {self.time_s} s")
        else:
            dt = round(float(time_s) - self.time_s, 6)
            pattern = (dt, seen.all())
            F, G, Q = self._model(dt)
            self.time_s = float(time_s)
            if self._frozen is not None and self._frozen[0] == pattern:
                kf.x = F @ kf.x + G @ self._u
                self._set_input(spindle_rpm, room_C)
                kf.x = kf.x + self._frozen[1] @ (y - self._H @ kf.x - self._J @ self._u)
                u = self._u
                return Estimate(self.time_s, self._L @ kf.x + self._M @ u, self._frozen[2],
                                self._Lf @ kf.x + self._Mf @ u, int(seen.sum()))
            self._frozen = None
            kf.F, kf.G, kf.Q = F, G, Q
            kf.predict(self._u)
        self._set_input(spindle_rpm, room_C)
        kf.update(y, self._u)
        if pattern is not None and pattern[1]:
            gain = kf.gain
            last = self._gain
            if last is not None and last[0] == pattern and \
                    np.abs(gain - last[1]).max() <= GAIN_TOLERANCE * pattern[0] * np.abs(gain).max():
                self._frozen = (pattern, gain, self._estimate(seen).band_um)
            self._gain = (pattern, gain)
        return self._estimate(seen)

    def _set_input(self, spindle_rpm, room_C):
        """[u, 1] for a sample; the power part is cached per speed (machines run at a few speeds)."""
        if np.isfinite(spindle_rpm) and np.isfinite(room_C):
            power = self._power.get(spindle_rpm)
            if power is None:
                if len(self._power) > 4096:
                    self._power.clear()
                power = self._power[spindle_rpm] = self.plant_inputs(spindle_rpm, 0.0)[0]
            self._u = np.r_[power + room_C * self._room, 1.0]

    def _estimate(self, seen):
        kf, u = self._kf, self._u
        sd = np.sqrt(np.maximum(((self._L @ kf.P) * self._L).sum(axis=1), 0.0))
        return Estimate(self.time_s, self._L @ kf.x + self._M @ u, Z95 * sd, self._Lf @ kf.x + self._Mf @ u,
                        int(seen.sum()))

    def field(self):
        """The full FE temperature field (°C per thermal node) of the present state; needs a ROM built with
        ``keep_basis=True`` (:func:`twin.rom.reduction.build_rom`)."""
        if self.rom.basis is None:
            raise TwinInputError("this ROM has no basis (build it with keep_basis=True) to map the state to the "
                                 "full field; Estimate.temperatures_C has the ROM thermometers")
        return self.rom.basis @ self._kf.x[:self.rom.order]

    def run(self, times_s, spindle_rpm, room_C, temperatures_C):
        """Filter a whole record; returns (drift (N, 3) µm, 95 % half-band (N, 3) µm)."""
        T = np.asarray(temperatures_C, float)
        drift, band = np.empty((len(times_s), 3)), np.empty((len(times_s), 3))
        for k, t in enumerate(times_s):
            e = self.step(float(t), float(spindle_rpm[k]), float(room_C[k]), T[k])
            drift[k], band[k] = e.drift_um, e.band_um
        return drift, band


def covariance_scale_for_coverage(errors, bands, level=0.95):
    """Factor on every covariance that makes ``level`` of the training errors fall inside the scaled band.

    ``errors`` (µm) are estimate − truth and ``bands`` (µm) the 95 % half-widths of observers run with
    scale 1 on training records (pooled).  The band scales with the square root of the factor and the
    estimates do not change, so the factor is the squared ``level`` quantile of |error| / band.
    """
    ratio = np.abs(np.asarray(errors, float)) / np.asarray(bands, float)
    return float(np.quantile(ratio, level) ** 2)


def choose_thermometers(rom, k=6, axis="Z", candidates=None, step_s=300.0, horizon_s=4 * 3600.0):
    """Greedy choice of ``k`` ROM thermometers that minimise the observer's posterior std of ``axis``.

    Model-based (no record is used, so no scenario is favoured): for each candidate added to the set
    chosen so far, the covariance recursion of :class:`DriftObserver` is run for ``horizon_s`` at
    ``step_s`` with every thermometer read, starting from the observer's prior, at full spindle speed;
    the candidate giving the smallest final drift std is kept.  Returns the names in order of choice.
    """
    names = [n for n, kd in zip(rom.output_names, rom.output_kinds) if kd == "temperature"] \
        if candidates is None else list(candidates)
    rpm, chosen = float(rom.limits["max_spindle_rpm"]), []
    j = AXES.index(axis)
    for _ in range(k):
        best = None
        for name in names:
            if name in chosen:
                continue
            obs = DriftObserver(rom, chosen + [name])
            for step in range(int(horizon_s / step_s) + 1):
                e = obs.step(step * step_s, rpm, 20.0, np.full(len(chosen) + 1, 20.0))
            if best is None or e.band_um[j] < best[0]:
                best = (e.band_um[j], name)
        chosen.append(best[1])
    return chosen
