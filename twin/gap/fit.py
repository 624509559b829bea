"""Fitting candidate effects to a measured record and weighing the evidence on held-out data.

Residuals.  r = measured − twin on every sensor channel, with two nuisances
eliminated on the *fit* rows in every model, the nominal included: a
constant offset per channel (thermometer accuracy, probe zero) and the
free response of the initial-state shapes (:data:`~twin.gap.structure.NUISANCE_FIELDS`;
the start of a record is never known exactly).  Held-out rows use the
offsets and nuisance coefficients of the fit rows.  The initial state is a
temperature field, so its coefficients are fitted on the surface
thermometers (:data:`STATE_GROUPS`) when their fit entries determine every
coefficient, else on every channel (:meth:`Evaluator.nuisance_entries`):
fitted on every channel, one faulty displacement probe moved them and so
spread its error into every thermometer's residual.  Air sensors do not
count: they are the twin's input, and the initial state gives them no
response.

Weights.  Channels are grouped by kind (surface thermometers, air
sensors, drift, strain); w = 1 / (σ_g² n_g) with σ_g the group's scale: the
larger of its measured noise level and a model tolerance
(:data:`GROUP_FLOOR`: 0.05 K, 0.1 µm, 0.3 µε).  A group contributes about
its held-out rows when the twin is within tolerance, and much more where the
gap is: the objective follows the gap, not the channel count.

Fits.  Effects linear in their parameters are fitted by bounded linear
least squares on basis responses (one simulation per parameter); the others
(and any set with one) by bounded nonlinear least squares (trust-region
reflective, in [0, 1]-scaled and, where marked, log coordinates) after a
coarse scan of one-parameter effects.  Parameter uncertainty: a HAC
(Newey–West) sandwich around the Jacobian at the optimum, with the scores
summed per time row (channels are correlated) and Bartlett weights up to an
Andrews bandwidth (residuals are autocorrelated), inflated by the held-out
misfit (:func:`parameter_sd`, :func:`held_out_inflation`).

Evidence.  BIC-like on the held-out rows, relative to the nominal twin:
BIC = n_eff · ln(SSE_hold / SSE_hold,nominal) + k · ln(n_eff), where n_eff
counts effectively independent held-out samples (per group: the median over
channels of n(1 − ρ₁)/(1 + ρ₁), ρ₁ the lag-1 autocorrelation of the nominal
residual averaged over the twin's time step, n the number of such averages,
times the participation ratio of the channels' correlation).
ΔBIC between two models gives the evidence ratio exp(ΔBIC/2).
"""
from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares, lsq_linear

from models.robust_covariance import bartlett_long_run

from ..core.machine import Machine
from .effects import Effect
from .model import GapModel, Prediction

GROUPS = ("temperature", "air", "displacement", "strain")
#: Model tolerance per channel group (K, K, µm, µε): residuals below it are as good as a twin gets (its
#: discretisation, the time step, sensor positions on a faceted surface); the group scale is the larger of
#: this and the group's measured noise level.
GROUP_FLOOR = {"temperature": 0.05, "air": 0.05, "displacement": 0.1, "strain": 0.3}
GROUP_UNIT = {"temperature": "K", "air": "K", "displacement": "µm", "strain": "µε"}
#: Groups that observe the initial temperature field directly; its nuisance coefficients are fitted on them.
STATE_GROUPS = ("temperature",)
#: Smallest singular value, relative to the largest, of the column-normalised nuisance responses on the state
#: groups' entries for those entries to determine the coefficients (else every channel's entries are used).
STATE_CONDITION = 1e-6


@dataclass
class Residual:
    """Residuals (n, p) after offsets and nuisance, and the sums of squares on the fit and held-out rows.

    Attributes
    ----------
    R : ndarray, shape (n_times, n_channels)
        Measured − twin, in channel units (K, µm, µε); NaN where the channel has no valid sample.
    offsets : ndarray, shape (n_channels,)
        Constant offset per channel removed (mean over the valid fit rows), channel units.
    nuisance : dict of str to float
        Nuisance field → coefficient removed (K per unit shape).
    sse_fit, sse_hold : float
        Weighted sums of squares on the valid fit and held-out entries (dimensionless).
    """

    R: np.ndarray
    offsets: np.ndarray
    nuisance: dict
    sse_fit: float
    sse_hold: float


class Evaluator:
    """Residuals of predictions against the record's sensor channels (see the module docstring).

    Parameters
    ----------
    values : ndarray, shape (n_times, n_channels)
        Measured channels at the record's times, in channel units (°C, µm, µε); NaN where missing.
    channel_index : sequence of int
        Column of each measured channel among the model's channels (:attr:`Prediction.values`).
    kinds : sequence of str
        Kind of each channel, one of :data:`GROUPS`.
    fit_rows, hold_rows : ndarray of bool, shape (n_times,)
        Rows of the fit part and of the held-out part.
    noise : ndarray, shape (n_channels,), optional
        White-noise level of each channel, channel units (default 0; NaN taken as 0).
    block_rows : int, default 1
        Consecutive rows averaged before effectively independent samples are counted (:func:`effective_samples`):
        as many as span the twin's time step.
    """

    def __init__(self, values: np.ndarray, channel_index: Sequence[int] | np.ndarray, kinds: Sequence[str],
                 fit_rows: np.ndarray, hold_rows: np.ndarray, noise: np.ndarray | None = None, block_rows: int = 1):
        self.block_rows = max(int(block_rows), 1)
        self.Y = np.asarray(values, float)
        self.mask = np.isfinite(self.Y)
        self.Yz = np.where(self.mask, self.Y, 0.0)
        self.cols = np.asarray(channel_index)
        self.kinds = list(kinds)
        self._set_rows(fit_rows, hold_rows)
        self.noise = np.zeros(len(self.cols)) if noise is None else np.nan_to_num(np.asarray(noise, float))
        self.weights = np.ones(len(self.cols))
        self.sqrt_w = np.ones(len(self.cols))

    def _set_rows(self, fit_rows, hold_rows):
        self.fit_rows = np.asarray(fit_rows, bool)
        self.hold_rows = np.asarray(hold_rows, bool)
        self.fit_mask = self.mask & self.fit_rows[:, None]
        self.hold_mask = self.mask & self.hold_rows[:, None]
        self.n_fit = self.fit_mask.sum(axis=0)
        #: Fit entries of the surface thermometers, which the initial-state nuisance is fitted on when they can be.
        self.state_mask = self.fit_mask & np.isin(self.kinds, STATE_GROUPS)

    def leave_out(self, rows: np.ndarray) -> None:
        """Leave ``rows`` out of the fit and held-out parts (rows whose twin is not known, :mod:`twin.gap.outages`).

        Parameters
        ----------
        rows : ndarray of bool, shape (n_times,)
        """
        self._set_rows(self.fit_rows & ~rows, self.hold_rows & ~rows)

    def groups(self) -> dict[str, list[int]]:
        """The channel groups present, in the order of :data:`GROUPS`.

        Returns
        -------
        dict of str to list of int
            Group → indices of its channels (among the evaluator's channels).
        """
        return {g: [j for j, k in enumerate(self.kinds) if k == g] for g in GROUPS
                if any(k == g for k in self.kinds)}

    def set_weights(self) -> None:
        """Group scales σ_g = max(model tolerance, noise level) and weights 1 / (σ_g² n_g); see the module docstring."""
        self.sigma = {}
        for g, idx in self.groups().items():
            sigma = max(GROUP_FLOOR[g], float(np.median(self.noise[idx])))
            self.sigma[g] = sigma
            self.weights[idx] = 1.0 / (sigma ** 2 * len(idx))
        self.sqrt_w = np.sqrt(self.weights)

    def _centre(self, X):
        """Per-channel mean over the valid fit rows of X (n, p)."""
        return np.where(self.fit_mask, X, 0.0).sum(axis=0) / np.maximum(self.n_fit, 1)

    def residual(self, prediction: Prediction, nuisance: bool = True) -> Residual:
        """:class:`Residual` of a :class:`~twin.gap.model.Prediction` (offsets and nuisance eliminated).

        Parameters
        ----------
        prediction : Prediction
            The twin's channels at the record's times and the nuisance responses.
        nuisance : bool, default True
            Eliminate the nuisance fields' free responses (weighted least squares on the fit rows).

        Returns
        -------
        Residual
            Residuals, offsets, nuisance coefficients and weighted sums of squares.
        """
        P = prediction.values[:, self.cols]
        R0 = self.Yz - P
        names = list(prediction.nuisance) if nuisance else []
        beta = {}
        if names:
            N = [prediction.nuisance[n][:, self.cols] for n in names]
            weighted = [(X - self._centre(X)) * self.sqrt_w for X in N]
            rows = self.nuisance_entries(weighted)
            A = np.column_stack([X[rows] for X in weighted])
            b = ((R0 - self._centre(R0)) * self.sqrt_w)[rows]
            scale = np.maximum(np.linalg.norm(A, axis=0), 1e-300)
            coef, *_ = np.linalg.lstsq(A / scale, b, rcond=None)
            coef = coef / scale
            for n, c, X in zip(names, coef, N):
                beta[n] = float(c)
                R0 = R0 - c * X
        offsets = self._centre(R0)
        R = np.where(self.mask, R0 - offsets, np.nan)
        Rz = np.nan_to_num(R) * self.sqrt_w
        return Residual(R, offsets, beta, float(np.sum(Rz[self.fit_mask] ** 2)),
                        float(np.sum(Rz[self.hold_mask] ** 2)))

    def nuisance_entries(self, responses: Sequence[np.ndarray]) -> np.ndarray:
        """The entries the initial-state nuisance coefficients are fitted on (see the module docstring).

        Parameters
        ----------
        responses : sequence of ndarray, shape (n_times, n_channels)
            Each nuisance shape's free response at the evaluator's channels, centred and weighted.

        Returns
        -------
        ndarray of bool, shape (n_times, n_channels)
            :attr:`state_mask` (the surface thermometers' fit entries) when the responses there have full
            column rank (:data:`STATE_CONDITION`); else :attr:`fit_mask`: a record without surface
            thermometers, with none valid on the fit rows, or with too few to tell the shapes apart.
        """
        A = np.column_stack([X[self.state_mask] for X in responses])
        norms = np.linalg.norm(A, axis=0)
        if len(A) < A.shape[1] or not np.all(norms > 0):
            return self.fit_mask
        singular = np.linalg.svd(A / norms, compute_uv=False)
        return self.state_mask if singular[-1] > STATE_CONDITION * singular[0] else self.fit_mask

    def fit_vector(self, prediction: Prediction) -> np.ndarray:
        """Weighted residual entries on the valid fit rows (for least squares).

        Parameters
        ----------
        prediction : Prediction
            The twin's channels at the record's times.

        Returns
        -------
        ndarray, shape (n_entries,)
            √w · r on the valid fit entries (row-major), dimensionless.
        """
        res = self.residual(prediction)
        return (np.nan_to_num(res.R) * self.sqrt_w)[self.fit_mask]

    # ------------------------------------------------------------------ summaries
    def summary(self, residual: Residual, names: Sequence[str]) -> dict[str, dict[str, dict[str, float]]]:
        """RMS and max |r| per group and per channel on the fit and held-out rows (in channel units).

        Parameters
        ----------
        residual : Residual
            Residuals of a prediction.
        names : sequence of str
            Name of each evaluator channel (e.g. :func:`model_names`).

        Returns
        -------
        dict
            ``{"groups": {group: stats}, "channels": {name: stats}}``, stats ``fit_rms``, ``fit_max``,
            ``hold_rms``, ``hold_max`` in channel units (K, µm, µε; NaN without samples).
        """
        out = {"groups": {}, "channels": {}}
        for g, idx in self.groups().items():
            out["groups"][g] = _stats(residual.R[:, idx], self.fit_rows, self.hold_rows)
        for j, n in enumerate(names):
            out["channels"][n] = _stats(residual.R[:, [j]], self.fit_rows, self.hold_rows)
        return out


def _stats(R, fit_rows, hold_rows):
    out = {}
    for part, rows in (("fit", fit_rows), ("hold", hold_rows)):
        r = R[rows]
        r = r[np.isfinite(r)]
        out[f"{part}_rms"] = float(np.sqrt(np.mean(r ** 2))) if r.size else float("nan")
        out[f"{part}_max"] = float(np.abs(r).max()) if r.size else float("nan")
    return out


def effective_samples(residual: Residual, evaluator: Evaluator, rows: np.ndarray) -> float:
    """Effectively independent residual samples on ``rows`` (see the module docstring).

    Parameters
    ----------
    residual : Residual
        Residuals (usually the nominal twin's).
    evaluator : Evaluator
        Defines the channel groups.
    rows : ndarray of bool, shape (n_times,)
        The rows counted (fit or held-out).

    Returns
    -------
    float
        n_eff summed over the groups, at least 2.
    """
    total = 0.0
    for idx in evaluator.groups().values():
        R = residual.R[rows][:, idx]
        per = []
        for j in range(R.shape[1]):
            r = _block_means(R[:, j][np.isfinite(R[:, j])], evaluator.block_rows)
            if len(r) < 4 or np.std(r) == 0:
                continue
            r = r - r.mean()
            rho = float(np.clip(np.sum(r[1:] * r[:-1]) / np.sum(r * r), -0.99, 0.9999))
            per.append(np.clip(len(r) * (1 - rho) / (1 + rho), 1.0, len(r)))
        if not per:
            continue
        X = np.nan_to_num(R)
        X = X[:, np.std(X, axis=0) > 0]
        if X.shape[1] > 1:
            lam = np.clip(np.linalg.eigvalsh(np.corrcoef(X.T)), 0, None)
            pr = float(lam.sum() ** 2 / max(np.sum(lam ** 2), 1e-300))
        else:
            pr = 1.0
        total += float(np.median(per)) * pr
    return max(total, 2.0)


def _block_means(r, size):
    """Means of consecutive blocks of ``size`` samples (a shorter last block dropped): the residual on the twin's
    time step, which resolves nothing finer; else white noise at a dense sampling counts as independent evidence
    about effects that are smooth on that scale (n_eff grew with the sampling rate and with the noise)."""
    n = len(r) // size * size
    return r[:n].reshape(-1, size).mean(axis=1)


# ============================================================================= parameter coordinates
class Coordinates:
    """[0, 1]-scaled (and log where marked) coordinates of the parameters of a set of effects.

    Parameters
    ----------
    effects : iterable of Effect
        The effects, their parameters concatenated in this order.
    machine : Machine
        Resolves the parameters' nominals and bounds.
    """

    def __init__(self, effects: Iterable[Effect], machine: Machine):
        self.effects = list(effects)
        self.params = [(e, p) for e in self.effects for p in e.parameters(machine)]
        self.sizes = [len(e.parameters(machine)) for e in self.effects]
        self.lo = np.array([np.log10(p.lower) if p.log else p.lower for _, p in self.params])
        self.hi = np.array([np.log10(p.upper) if p.log else p.upper for _, p in self.params])
        self.log = np.array([p.log for _, p in self.params])
        self.nominal_values = np.array([p.nominal for _, p in self.params])

    def values(self, u: Sequence[float] | np.ndarray) -> np.ndarray:
        """Parameter values from unit coordinates.

        Parameters
        ----------
        u : array_like, shape (k,)
            Unit coordinates, 0 at the lower bound, 1 at the upper (log10-scaled where marked).

        Returns
        -------
        ndarray, shape (k,)
            Parameter values, in each parameter's unit.
        """
        x = self.lo + np.asarray(u, float) * (self.hi - self.lo)
        out = x.copy()
        out[self.log] = 10.0 ** x[self.log]
        return out

    def unit(self, values: Sequence[float] | np.ndarray) -> np.ndarray:
        """Unit coordinates of parameter values (the inverse of :meth:`values`), clipped to [0, 1].

        Parameters
        ----------
        values : array_like, shape (k,)
            Parameter values, in each parameter's unit.

        Returns
        -------
        ndarray, shape (k,)
            Unit coordinates in [0, 1].
        """
        v = np.asarray(values, float)
        x = np.where(self.log, np.log10(np.maximum(v, 1e-300)), v)
        return np.clip((x - self.lo) / (self.hi - self.lo), 0.0, 1.0)

    def split(self, values: Sequence[float] | np.ndarray) -> list[tuple[Effect, np.ndarray]]:
        """Parameter values split per effect, as :meth:`~twin.gap.model.GapModel.predict` takes them.

        Parameters
        ----------
        values : array_like, shape (k,)
            Parameter values of all the effects, concatenated.

        Returns
        -------
        list of (Effect, ndarray)
            ``[(effect, θ), …]``.
        """
        out, k = [], 0
        for e, n in zip(self.effects, self.sizes):
            out.append((e, np.asarray(values[k:k + n], float)))
            k += n
        return out

    @property
    def labels(self) -> list[str]:
        """``effect.parameter`` label of every parameter."""
        return [f"{e.name}.{p.name}" for e, p in self.params]


@dataclass
class FitResult:
    """One fitted model (an effect, a pair, or the nominal twin) and its evidence.

    Attributes
    ----------
    name : str
        Effect names joined by ``+``, or ``nominal``.
    effects, labels, units : list of str
        Effect names; ``effect.parameter`` label and unit of every parameter.
    values, sd : ndarray, shape (k,)
        Fitted parameters and their standard deviations, in the parameters' units.
    residual : Residual
        Residuals at the fit.
    summary : dict
        :meth:`Evaluator.summary` of the residuals.
    seconds : float
        Wall time of the fit, s.
    nfev : int
        Model runs of the fit.
    linear : bool
        Fitted by linear least squares.
    bic, delta_bic : float
        BIC relative to the nominal twin and ΔBIC = −BIC (set by :func:`score`).
    n_eff_fit : float
        Effectively independent samples of the fit rows.
    prediction : Prediction
        The twin at the fit.
    notes : list of str
        Remarks (parameters at a bound).
    """

    name: str
    effects: list
    labels: list
    units: list
    values: np.ndarray
    sd: np.ndarray
    residual: Residual
    summary: dict
    seconds: float
    nfev: int
    linear: bool
    bic: float = 0.0
    delta_bic: float = 0.0
    n_eff_fit: float = 0.0
    prediction: object = None
    notes: list = field(default_factory=list)
    bounds: list = field(default_factory=list)   #: (lower, upper) of each parameter, in its unit; [] unbounded

    @property
    def k(self) -> int:
        """Number of fitted parameters."""
        return len(self.values)

    def params(self) -> list[dict[str, float | str]]:
        """The fitted parameters as records.

        Returns
        -------
        list of dict
            ``name``, ``value``, ``sd`` (in ``unit``), ``interval`` (90 %, :func:`interval90`) and ``unit`` of
            every parameter.
        """
        bounds = self.bounds or [(-np.inf, np.inf)] * len(self.labels)
        return [{"name": lab, "value": float(v), "sd": float(s), "interval": interval90(v, s, *b), "unit": u}
                for lab, v, s, u, b in zip(self.labels, self.values, self.sd, self.units, bounds, strict=True)]


#: Standard normal 95 % quantile: a 90 % two-sided interval is ± Z90 sd.
Z90 = 1.6448536269514722


def interval90(value: float, sd: float, lower: float, upper: float) -> list[float]:
    """The 90 % interval of a fitted parameter, ± :data:`Z90` sd cut to its bounds, outside which the model
    does not exist (a negative lag). The cut removes no value the fit could have returned, so the coverage
    checked on truth records (``docs/gap_benchmark.md``) is that of the uncut interval.

    Parameters
    ----------
    value, sd : float
        The estimate and its standard deviation, in the parameter's unit.
    lower, upper : float
        The parameter's bounds, same unit.

    Returns
    -------
    list of float
        ``[low, high]``, same unit.
    """
    return [float(max(value - Z90 * sd, lower)), float(min(value + Z90 * sd, upper))]


def _fit_linear(model, evaluator, co):
    """``(values, Jacobian, model runs)`` of effects linear in their parameters: one run per parameter gives the
    sensitivities, then a bounded linear least squares on the nuisance-projected, centred, weighted design."""
    base = model.predict()
    deltas = co.hi - co.lo
    G = []
    for j in range(len(co.params)):
        v = co.nominal_values.copy()
        v[j] += deltas[j]
        G.append((model.predict(co.split(v)).values - base.values) / deltas[j])

    def predict(values):
        d = values - co.nominal_values
        Y = base.values + sum(dj * Gj for dj, Gj in zip(d, G))
        return Prediction(Y, base.nuisance, None, None, None)

    r0 = evaluator.fit_vector(predict(co.nominal_values))
    A = np.column_stack([r0 - evaluator.fit_vector(predict(co.nominal_values + e)) for e in np.eye(len(co.params))])
    lower = np.array([p.lower for _, p in co.params]) - co.nominal_values
    upper = np.array([p.upper for _, p in co.params]) - co.nominal_values
    sol = lsq_linear(A, r0, bounds=(lower, upper), method="bvls")
    return co.nominal_values + sol.x, A, len(co.params)


def _fit_nonlinear(model, evaluator, co, start, max_nfev):
    """``(values, Jacobian in parameter units, model runs)``: bounded trust-region fits from the best starts."""
    cache = {}

    def fun(u):
        key = tuple(np.round(u, 12))
        if key not in cache:
            cache[key] = evaluator.fit_vector(model.predict(co.split(co.values(u))))
        return cache[key]

    best = None
    for u0 in _starting_points(co, start, fun):
        sol = least_squares(fun, u0, bounds=(0.0, 1.0), method="trf", x_scale=1.0, diff_step=1e-3,
                            max_nfev=max_nfev, xtol=1e-6, ftol=1e-8)
        if best is None or sol.cost < best.cost:
            best = sol
    values = co.values(best.x)
    J = _jacobian(lambda v: evaluator.fit_vector(model.predict(co.split(v))), values, co)
    return values, J, len(cache) + len(values)


def fit_effects(model: GapModel, evaluator: Evaluator, effects: Sequence[Effect], start: np.ndarray | None = None,
                max_nfev: int = 60) -> FitResult:
    """Fit the parameters of ``effects`` (one or several, jointly) → :class:`FitResult`.

    Parameters
    ----------
    model : GapModel
        The twin of the record.
    evaluator : Evaluator
        Residuals and weights (set before, e.g. by :func:`nominal_result`).
    effects : sequence of Effect
        The effects fitted jointly; linear fit when all are linear.
    start : ndarray, shape (k,), optional
        Extra starting values of a nonlinear fit, in the parameters' units.
    max_nfev : int, default 60
        Function evaluations per local nonlinear fit.

    Returns
    -------
    FitResult
        Values, standard deviations, residuals and summary (no BIC yet: :func:`score`).
    """
    t0 = time.perf_counter()
    co = Coordinates(effects, model.structure.machine)
    linear = all(e.linear for e in effects)
    values, J, nfev = (_fit_linear(model, evaluator, co) if linear else
                       _fit_nonlinear(model, evaluator, co, start, max_nfev))
    pred = model.predict(co.split(values))
    res = evaluator.residual(pred)
    n_eff = effective_samples(res, evaluator, evaluator.fit_rows)
    sd = parameter_sd(J, (np.nan_to_num(res.R) * evaluator.sqrt_w)[evaluator.fit_mask],
                      np.nonzero(evaluator.fit_mask)[0], held_out_inflation(res, evaluator))
    result = FitResult("+".join(e.name for e in effects), [e.name for e in effects], co.labels,
                       [p.unit for _, p in co.params], values, sd, res,
                       evaluator.summary(res, model_names(model, evaluator)), time.perf_counter() - t0, nfev,
                       linear, n_eff_fit=n_eff, prediction=pred,
                       bounds=[(p.lower, p.upper) for _, p in co.params])
    at_bound = [lab for lab, u in zip(co.labels, co.unit(values)) if u <= 1e-6 or u >= 1 - 1e-6]
    if at_bound:
        result.notes.append(f"at a bound: {', '.join(at_bound)}")
    return result


#: Space-filling starting candidates of a multi-parameter nonlinear fit (Sobol points, fixed seed).
N_START_CANDIDATES = 16
#: Local fits run from the best candidates.
N_STARTS = 2


def _starting_points(co, start, fun):
    """Starting points of a nonlinear fit, in unit coordinates, best first.

    Candidates: the nominal values, ``start`` (e.g. the single effects' fits of a pair), and a 7-point grid
    (one parameter) or :data:`N_START_CANDIDATES` Sobol points (several); all kept 2 % inside the bounds,
    because a trust-region start on a bound cannot leave it when the parameter sits there at the nominal
    (ε = 0 of radiation, k = 0 of a drift coefficient) and another parameter's gradient vanishes with it.
    The :data:`N_STARTS` cheapest by the objective are returned.
    """
    from scipy.stats import qmc

    n = len(co.params)
    cands = [co.unit(co.nominal_values)] + ([co.unit(start)] if start is not None else [])
    if n == 1:
        cands += [np.array([g]) for g in np.linspace(0.0, 1.0, 7)]
    else:
        cands += list(qmc.Sobol(n, seed=0).random(N_START_CANDIDATES))
    cands = np.unique(np.clip(np.array(cands), 0.02, 0.98), axis=0)
    costs = [float(np.sum(fun(u) ** 2)) for u in cands]
    return [cands[i] for i in np.argsort(costs)[:N_STARTS]]


def model_names(model: GapModel, evaluator: Evaluator) -> list[str]:
    """Names of the evaluator's channels among the model's channels.

    Parameters
    ----------
    model : GapModel
        The twin (its structure names the channels).
    evaluator : Evaluator
        Its ``cols`` index the model's channels.

    Returns
    -------
    list of str
        Channel name of every evaluator column.
    """
    return [model.structure.names[c] for c in evaluator.cols]


def _jacobian(fun, values, co, rel=1e-3):
    f0 = fun(values)
    cols = []
    for j in range(len(values)):
        v = values.copy()
        span = (co.hi[j] - co.lo[j]) * rel
        if co.log[j]:
            h = values[j] * (10 ** span - 1)
        else:
            h = span
        if values[j] + h > (10 ** co.hi[j] if co.log[j] else co.hi[j]):
            h = -h
        v[j] += h
        cols.append((fun(v) - f0) / h)
    return -np.column_stack(cols)


def held_out_inflation(residual: Residual, evaluator: Evaluator) -> float:
    """Mean square of the weighted residual on the held-out entries over that on the fit entries, at least 1: a
    model that misses held-out data more than the fit data carries discrepancy its Jacobian does not see.

    Parameters
    ----------
    residual : Residual
        Residuals of the fitted model.
    evaluator : Evaluator
        Its fit and held-out masks count the entries.

    Returns
    -------
    float
        Variance inflation factor, ≥ 1.
    """
    ms_fit = residual.sse_fit / max(int(evaluator.fit_mask.sum()), 1)
    ms_hold = residual.sse_hold / max(int(evaluator.hold_mask.sum()), 1)
    return max(1.0, ms_hold / max(ms_fit, 1e-300))


def parameter_sd(J: np.ndarray, r: np.ndarray, rows: np.ndarray, inflation: float = 1.0,
                 tolerance: bool = True) -> np.ndarray:
    """Standard deviations of least-squares parameters from a HAC (Newey–West, Bartlett) sandwich covariance.

    ``J`` (e, k) is the Jacobian of the weighted residual entries ``r`` (e,) that were sampled at time rows
    ``rows`` (e,).  Residuals of a thermal twin are strongly autocorrelated in time and correlated across
    channels, so the scores are summed per time row and Ω is their Bartlett long-run covariance with Andrews'
    bandwidth over the fit rows as one stretch (:func:`models.robust_covariance.bartlett_long_run`, the grey-box
    model's estimator): cov = H⁻¹ Ω H⁻¹ · ``inflation`` with H = JᵀJ.

    With ``tolerance``, the covariance also carries the twin's own discretisation error: a systematic residual
    as large as a group's model tolerance (:data:`GROUP_FLOOR`) throughout the record, lined up with a
    parameter's signature, moves the estimate by √(n_rows · H⁻¹ⱼⱼ) (the weights make such a residual's squared
    norm n_rows); n_rows · H⁻¹ is added.  Noise averages out over a long record, the mesh and time-step error
    of the twin does not: without this term, a truth made with another integrator and step lay 4 sd from
    its fit (spindle_power_scale, 1.297 for 1.3, in the coverage cases of ``tests/test_gap_verdict.py``).

    Parameters
    ----------
    J : ndarray, shape (e, k)
        Jacobian of the weighted residual entries, per parameter unit (its sign does not matter).
    r : ndarray, shape (e,)
        Weighted residual entries (dimensionless).
    rows : ndarray of int, shape (e,)
        Time row of each entry.
    inflation : float, default 1.0
        Factor on the sandwich covariance (:func:`held_out_inflation`).
    tolerance : bool, default True
        Add the model-tolerance term n_rows · H⁻¹.

    Returns
    -------
    ndarray, shape (k,)
        Standard deviations, in the parameters' units (NaN if H cannot be inverted).
    """
    k = J.shape[1]
    if k == 0:
        return np.zeros(0)
    _, t = np.unique(rows, return_inverse=True)
    scores = np.zeros((t.max() + 1, k))
    np.add.at(scores, t, J * r[:, None])
    omega = bartlett_long_run(scores, [(0, len(scores))])
    try:
        H = np.linalg.pinv(J.T @ J)
    except np.linalg.LinAlgError:
        return np.full(k, np.nan)
    cov = H @ omega @ H * float(inflation)
    if tolerance:
        cov = cov + H * float(t.max() + 1)
    return np.sqrt(np.clip(np.diag(cov), 0, None))


def nominal_result(model: GapModel, evaluator: Evaluator) -> FitResult:
    """The nominal twin as a :class:`FitResult` (nuisance and offsets only); sets the evaluator's weights.

    Parameters
    ----------
    model : GapModel
        The twin of the record.
    evaluator : Evaluator
        Residuals; its weights are set here (:meth:`Evaluator.set_weights`).

    Returns
    -------
    FitResult
        Named ``nominal``, no parameters.
    """
    t0 = time.perf_counter()
    pred = model.predict()
    evaluator.set_weights()
    res = evaluator.residual(pred)
    n_eff = effective_samples(res, evaluator, evaluator.fit_rows)
    return FitResult("nominal", [], [], [], np.zeros(0), np.zeros(0), res,
                     evaluator.summary(res, model_names(model, evaluator)), time.perf_counter() - t0, 1, True,
                     n_eff_fit=n_eff, prediction=pred)


def relative_bic(sse_ratio: float, k: float, n_eff: float) -> float:
    """Held-out BIC of a model against a reference: n_eff·ln(SSE/SSE_ref) + k·ln n_eff (lower is better).

    Parameters
    ----------
    sse_ratio : float
        Held-out sum of squares of the model over the reference's, 1 (floored at 1e-300).
    k : float
        Parameters the model has beyond the reference.
    n_eff : float
        Effectively independent held-out samples (:func:`effective_samples`).

    Returns
    -------
    float
        The BIC difference; −10 or less is strong evidence for the model.
    """
    return float(n_eff * np.log(max(sse_ratio, 1e-300)) + k * np.log(n_eff))


def score(results: list[FitResult], nominal: FitResult, n_eff_hold: float) -> list[FitResult]:
    """Set BIC (relative to the nominal) and ΔBIC vs the nominal on every result; return them ranked.

    Parameters
    ----------
    results : list of FitResult
        Fitted models; their ``bic`` and ``delta_bic`` are set.
    nominal : FitResult
        The nominal twin (its BIC and ΔBIC set to 0).
    n_eff_hold : float
        Effectively independent held-out samples (:func:`effective_samples`).

    Returns
    -------
    list of FitResult
        ``results`` by increasing BIC (best first).
    """
    ref = max(nominal.residual.sse_hold, 1e-300)
    nominal.bic, nominal.delta_bic = 0.0, 0.0
    for r in results:
        r.bic = relative_bic(max(r.residual.sse_hold, 1e-300) / ref, r.k, n_eff_hold)
        r.delta_bic = -r.bic
    return sorted(results, key=lambda r: r.bic)
