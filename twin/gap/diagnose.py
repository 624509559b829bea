"""The gap diagnosis: measured record + nominal twin → where it misses, which effect explains it, how far it shrinks.

:func:`diagnose` runs the nominal twin with the measured inputs (spindle
speed and feeds as piecewise-constant signals integrated exactly over each
step, ambients from the air sensors), splits the record chronologically into
a fit part and a held-out part, fits every candidate effect of the library
(and pairs: the leading effect with every other one, and the pairs among the
leaders) on the fit part, ranks them by ΔBIC on the held-out part, and
decides by :func:`twin.gap.verdict.decide`: ``no_significant_gap``,
``explained``, ``partly_explained`` or ``not_explained``, per channel group
and per sensor, with the timing floor of the record's sampling (the nominal
twin's held-out change when the input change times move by ± half a sample)
in the scales.  When a gap remains, the effect discovery of
:mod:`twin.gap.discovery` searches what the library lacks.
"""
from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from decimal import Decimal
from numbers import Integral, Real
from pathlib import Path

import numpy as np

from meshes.tomlspec import DefinitionError

from ..core.dataset import Dataset
from ..core.machine import Machine, build_machine
from ..core.scenario import Scenario, load_scenario
from ..errors import TwinInputError
from ..infra.cli_common import check_distinct, split_names
from ..infra.sweep import cached
from . import attribution, verdict, where
from .discretisation import discretisation_floor
from .drive import measured_drive
from .effects import Effect, library_by_name
from .engine import FullBackend, ReducedBackend, make_backend
from .fit import (
    Evaluator,
    FitResult,
    effective_samples,
    fit_effects,
    model_names,
    nominal_result,
    relative_bic,
    score,
)
from .measured import Record, check_scale, match_record, read_measured
from .model import GapModel
from .outages import (
    MAX_HOLDOUT,
    UnknownInputs,
    check_rows_left,
    describe,
    held_across,
    outage_intervals,
    outage_spans,
    unknown_rows,
)
from .signals import noise_level, uniform_grid
from .structure import Structure, build_structure

DEFAULT_STEP_S = 60.0
#: Shortest record the diagnosis accepts, s: a fit part and a held-out part that each see the machine's
#: slow response (hours) need a few hours in all.
MIN_RECORD_S = 2 * 3600.0
#: Longest twin grid a diagnosis builds (steps): the trajectories it keeps take about steps × states × 8 bytes
#: each, some 18 kB a step in all on the default machine (a record logged in ms, 480 000 steps of 60 s,
#: grew to 8.7 GB), so this cap is about 1.8 GB, 69 days at the default 60 s step.  Refused before allocating.
MAX_GRID_STEPS = 100_000
BYTES_PER_GRID_STEP = 18e3


@dataclass
class Diagnosis:
    """Everything :func:`diagnose` found (see :mod:`twin.gap.report` for the written form)."""

    machine: object
    record: object
    model: object
    evaluator: object
    split_s: float
    nominal: object
    singles: list
    pairs: list
    ranking: list
    decision: object                 # twin.gap.verdict.Verdict
    scales: object                   # twin.gap.verdict.Scales
    n_eff_hold: float
    noise: dict
    gap_over_noise: dict
    phases: np.ndarray
    verdict: str = ""
    where: dict = field(default_factory=dict)
    attribution: dict = field(default_factory=dict)
    separation: dict | None = None
    discovery: object = None
    timings: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    skipped: list = field(default_factory=list)
    unknown_inputs: UnknownInputs | None = None

    @property
    def names(self) -> list[str]:
        """The record's sensor channels used in the residuals (machine channel names), in column order."""
        return self.record.names

    @property
    def outcome(self) -> str:
        """``no_significant_gap``, ``explained``, ``partly_explained`` or ``not_explained``."""
        return self.decision.outcome

    @property
    def winner(self) -> FitResult | None:
        """The model the verdict names, or None."""
        return self.decision.winner

    @property
    def runner_up(self) -> FitResult | None:
        """The best single-effect fit sharing no effect with the named model (without one, the best after the
        best), or None."""
        return self.decision.runner_up

    @property
    def significant(self) -> bool:
        """Whether a model is named."""
        return self.decision.significant

    @property
    def gap_over_tolerance(self) -> dict[str, float]:
        """Held-out RMS / σ_g of the nominal twin per channel group (σ_g with the timing floor)."""
        return self.decision.nominal_gap

    @property
    def evidence_ratio(self) -> float:
        """The Bayes-factor equivalent of ΔBIC over the runner-up (inf when it overflows a float; no clamp)."""
        ev = self.decision.evidence()
        if "log10_ratio_vs_runner_up" not in ev:
            return float("inf")
        with np.errstate(over="ignore"):
            return float(np.power(10.0, ev["log10_ratio_vs_runner_up"]))

    def result(self, name: str) -> FitResult:
        """The fitted model of that name: the nominal twin, an effect or a pair.

        Parameters
        ----------
        name : str
            Model name (``nominal``, an effect, or ``a+b``).

        Returns
        -------
        FitResult
            The model.

        Raises
        ------
        KeyError
            When no model has that name.
        """
        for r in [self.nominal] + self.ranking:
            if r.name == name:
                return r
        raise KeyError(name)

    def shrinkage(self, result: FitResult | None = None) -> dict[str, dict[str, float]]:
        """Held-out RMS and max before (nominal) and after ``result`` (default the winner), per group and axis.

        Parameters
        ----------
        result : FitResult, optional
            The model (default the winner).

        Returns
        -------
        dict of str to dict
            Channel group, then each displacement channel (drift axis) → ``before_rms``, ``after_rms``,
            ``before_max``, ``after_max`` (the group's unit: K, µm, µε) and ``reduction`` of the RMS (fraction;
            NaN when the nominal RMS is 0).  Empty when there is no model.
        """
        result = result or self.winner
        out = {}
        if result is None:
            return out
        for key in list(self.nominal.summary["groups"]) + [n for n, k in zip(self.names, self.evaluator.kinds)
                                                             if k == "displacement"]:
            src = "groups" if key in self.nominal.summary["groups"] else "channels"
            b, a = self.nominal.summary[src][key], result.summary[src][key]
            out[key] = {"before_rms": b["hold_rms"], "after_rms": a["hold_rms"], "before_max": b["hold_max"],
                        "after_max": a["hold_max"],
                        "reduction": 1.0 - a["hold_rms"] / b["hold_rms"] if b["hold_rms"] > 0 else float("nan")}
        return out

    def drift_shrinkage(self, result: FitResult | None = None) -> float | None:
        """Reduction of the held-out drift RMS pooled over the displacement channels (fraction), or None.

        Parameters
        ----------
        result : FitResult, optional
            The model (default the winner).

        Returns
        -------
        float or None
            1 − RMS after / RMS before; None without a model, a drift channel or a nominal drift residual.
        """
        result = result or self.winner
        if result is None or "displacement" not in self.nominal.summary["groups"]:
            return None
        b = self.nominal.summary["groups"]["displacement"]["hold_rms"]
        a = result.summary["groups"]["displacement"]["hold_rms"]
        return 1.0 - a / b if b > 0 else None


def _pair_candidates(ranked, n_pairs):
    """Pairs to fit: the leading single with every other effect (forward selection: a second effect masked by a
    dominant first one still gets its chance), and the pairs among the top ``n_pairs`` singles."""
    if n_pairs <= 0 or not ranked or ranked[0].delta_bic <= 0:
        return []
    out = [(ranked[0], r) for r in ranked[1:]]
    lead = [r for r in ranked[1:n_pairs] if r.delta_bic > 0]
    out += [(lead[i], lead[j]) for i in range(len(lead)) for j in range(i + 1, len(lead))]
    return out


def engine(machine: Machine, effects: Sequence[Effect], backend: str = "rom",
           **options: int | float | bool) -> tuple[Structure, ReducedBackend | FullBackend]:
    """(structure, backend) for a machine and a library, built once per process (:func:`twin.infra.sweep.cached`).

    Parameters
    ----------
    machine : Machine
        The built machine (cached by its identity).
    effects : sequence of Effect
        The library the structure is built for.
    backend : str, default "rom"
        ``rom`` (parametric reduced model) or ``fe`` (full finite elements).
    **options
        Options of the backend (:func:`twin.gap.engine.make_backend`): ``nominal_order``, ``term_order``,
        ``keep_basis`` (rom) or ``theta`` (fe).

    Returns
    -------
    structure : Structure
        The effects' structure on the machine.
    backend : ReducedBackend or FullBackend
        The backend; its ``structure_seconds`` is the structure's build time, s.
    """
    key = ("gap-engine", id(machine), tuple(e.name for e in effects), backend, tuple(sorted(options.items())))

    def build():
        t0 = time.perf_counter()
        structure = build_structure(machine, effects)
        t1 = time.perf_counter()
        be = make_backend(structure, backend, **options)
        be.structure_seconds = t1 - t0
        return structure, be

    return cached(key, build)


def _machine(machine, mesh_size_m=None):
    """A built machine as given, or one built by name or TOML path (and mesh size) once per process."""
    if isinstance(machine, (str, Path)):
        return cached(("machine", str(machine), mesh_size_m), lambda: build_machine(str(machine), mesh_size_m))
    return machine


def _check_length(record, holdout_fraction):
    """Stop with a clear message on a record too short to split into a fit and a held-out part."""
    t = record.time_s
    span = float(t[-1] - t[0])
    source = record.report.get("source", "the record")
    if span < MIN_RECORD_S:
        raise TwinInputError(f"{source}: the record spans {span / 3600:.2f} h; a diagnosis needs at least "
                             f"{MIN_RECORD_S / 3600:g} h (a fit part and a held-out part that each see the machine's "
                             "slow thermal response)")
    split = t[0] + (1.0 - float(holdout_fraction)) * span
    fit_rows, hold_rows = t <= split, t > split
    if fit_rows.sum() < 5 or hold_rows.sum() < 5:
        raise TwinInputError(f"{source}: the split at {split / 3600:.2f} h leaves too few rows "
                             f"({fit_rows.sum()} fit, {hold_rows.sum()} held out)")
    return split, fit_rows, hold_rows


#: Where between two differing samples the input change is put (fraction of the sample interval): the earliest
#: possible time, the midpoint, the latest.  :func:`reconstruct_inputs` picks one on the fit part.
POSITIONS = (0.0, 0.5, 1.0)


def reconstruct_inputs(machine: Machine, structure: Structure, be: ReducedBackend | FullBackend, grid: np.ndarray,
                       record: Record, sc: Scenario | None, initial: str,
                       evaluator: Evaluator) -> tuple[GapModel, float, np.ndarray, UnknownInputs]:
    """The record's twin with its input change times placed by the data, the timing floor and the outages.

    The nominal twin runs with every spindle/feed change at the earliest, middle and latest time the sampling
    allows (:data:`POSITIONS`); the placement with the smallest weighted residual on the *fit* rows is kept (a
    logger's convention — a sample that describes the interval before it, or the speed at its instant — is a
    property of the record, chosen on training data).  The timing floor per sensor is the held-out RMS of half
    the residual change between the earliest and latest placements: what ± half a sample of timing does.
    A logging outage across which an input changed (:mod:`twin.gap.outages`) keeps its change at its middle
    in all three; the rows after it on which the twin depends on when that change happened are left out of
    ``evaluator``'s fit and held-out parts.

    Parameters
    ----------
    machine : Machine
        The nominal machine.
    structure : Structure
        The effects' structure on it.
    be : ReducedBackend or FullBackend
        The backend.
    grid : ndarray, shape (n_grid,)
        The twin's time grid, s.
    record : Record
        The matched measured record.
    sc : Scenario or None
        Fallback for missing spindle or feeds.
    initial : str
        ``steady`` or ``uniform``.
    evaluator : Evaluator
        The record's evaluator (its weights are set here).

    Returns
    -------
    model : GapModel
        The nominal twin with the chosen placement.
    position : float
        The chosen placement, a fraction of the sample interval (one of :data:`POSITIONS`).
    floor : ndarray, shape (n_sensors,)
        Timing floor per sensor, in the sensor's unit (K, µm, µε).
    unknown : UnknownInputs
        The outages and the rows left out.

    Raises
    ------
    TwinInputError
        When the rows left out leave too few fit or held-out rows.
    """
    evaluator.set_weights()
    spans = outage_spans(record.time_s, record.read_inputs)
    outage = outage_intervals(record.time_s, spans)

    def twin(position, inputs_of=record):
        return GapModel(structure, be, measured_drive(machine, grid, inputs_of, sc, position), record.time_s,
                        initial)

    models = {p: twin(np.where(outage, 0.5, p)) for p in POSITIONS}
    residuals = {p: evaluator.residual(m.predict()) for p, m in models.items()}
    best = min(POSITIONS, key=lambda p: residuals[p].sse_fit)
    half = 0.5 * (residuals[POSITIONS[-1]].R - residuals[POSITIONS[0]].R)[evaluator.hold_rows]
    floor = np.sqrt(np.nanmean(half ** 2, axis=0))
    unknown = UnknownInputs(describe(record.time_s, record.read_inputs, spans), np.zeros(len(record.time_s), bool))
    if unknown.outages:
        early, late = (evaluator.residual(twin(np.where(outage, end, best), _held(record, spans, side)).predict()).R
                       for side, end in (("start", 0.0), ("end", 1.0)))
        scale = np.fmax(floor, [evaluator.sigma[k] for k in evaluator.kinds])
        unknown.rows = unknown_rows(record.time_s, unknown.outages[0][0], late - early, scale)
        check_rows_left(evaluator.fit_rows, evaluator.hold_rows, unknown, record.time_s, record.report["source"])
        evaluator.leave_out(unknown.rows)
    return models[best], best, floor, unknown


def _held(record, spans, side):
    """The record with every outage's input change at the outage's ``side`` (:func:`twin.gap.outages.held_across`;
    ``spans``: :func:`twin.gap.outages.outage_spans`), each input over its own outages only."""
    spindle = None if record.spindle is None else held_across(record.spindle, spans.get("spindle_rpm", []), side)
    return dataclasses.replace(record, spindle=spindle, feeds={
        a: held_across(v, spans.get(f"feed_{a}_mm_min", []), side) for a, v in record.feeds.items()})


def _judge(model, ev, names, timing, nominal, ranking, timings, notes, backend="rom", engine_options=None):
    """``(scales, decision)``: the verdict on the timing floor, and, when the nominal twin has a gap, again with
    every sensor's discretisation floor (which only widens σ_j, so it cannot make a gap where there is none),
    measured with the nominal twin's ``backend`` and ``engine_options``.  A coarser mesh that cannot be made
    leaves the floor out, and ``notes`` says why."""
    scales = verdict.scales(ev, names, timing)
    decision = verdict.decide(nominal, ranking, scales)
    if decision.outcome == "no_significant_gap":
        return scales, decision
    t0 = time.perf_counter()
    try:
        floor = discretisation_floor(model, nominal, ev,
                                     lambda m, effects: engine(m, effects, backend, **(engine_options or {})))
    except DefinitionError as exc:
        notes.append(f"discretisation floor not measured (the verdict is judged without it): {exc}")
        return scales, decision
    timings["discretisation_s"] = time.perf_counter() - t0
    scales = verdict.scales(ev, names, timing, floor)
    return scales, verdict.decide(nominal, ranking, scales)


def _fit_library(model, ev, applicable, nominal, n_pairs, progress):
    """Fit every single effect and the pairs; return (singles, pairs, ranking, n_eff_hold)."""
    hold_rows = ev.hold_rows
    n_eff_hold = effective_samples(nominal.residual, ev, hold_rows)
    singles = []
    for i, e in enumerate(applicable):
        singles.append(fit_effects(model, ev, [e]))
        if progress is not None:
            progress(i + 1, len(applicable))
    # Effective held-out samples from what is left after the best single effect (the nominal's when none
    # helps): an F-test-like reference that keeps systematic leftovers from counting as independent evidence.
    best_single = min(singles, key=lambda r: r.residual.sse_hold) if singles else nominal
    if best_single.residual.sse_hold < nominal.residual.sse_hold:
        n_eff_hold = effective_samples(best_single.residual, ev, hold_rows)
    ranked = score(singles, nominal, n_eff_hold)
    pairs = []
    for a, b in _pair_candidates(ranked, n_pairs):
        ea, eb = [e for e in applicable if e.name in (a.name, b.name)]
        start = np.r_[a.values, b.values] if ea.name == a.name else np.r_[b.values, a.values]
        pairs.append(fit_effects(model, ev, [ea, eb], start=start))
        if progress is not None:
            progress(len(applicable) + len(pairs), len(applicable) + len(pairs))
    return singles, pairs, score(singles + pairs, nominal, n_eff_hold), n_eff_hold


def split_half_sd(model: GapModel, ev: Evaluator, result: FitResult, effects: Sequence[Effect]) -> np.ndarray:
    """Delete-a-half jackknife sd of a model's parameters: |θ(first half) − θ(second half)| / 2, each half of
    the fit rows fitted alone.  A parameter that drifts through the record (model discrepancy the Jacobian and
    the HAC sandwich do not see) shows here; :func:`diagnose` reports the larger of the two sds.

    Parameters
    ----------
    model : GapModel
        The twin the model was fitted with.
    ev : Evaluator
        The record's evaluator (its fit rows are halved).
    result : FitResult
        The fitted model (its values start both fits).
    effects : sequence of Effect
        The model's effects, in its parameter order.

    Returns
    -------
    ndarray, shape (n_params,)
        Jackknife sd per parameter, in the parameter's unit.
    """
    n = len(ev.fit_rows)
    rows = np.flatnonzero(ev.fit_rows)
    first = np.arange(n) < rows[len(rows) // 2]
    estimates = []
    for half in (ev.fit_rows & first, ev.fit_rows & ~first):
        sub = Evaluator(ev.Y, ev.cols, ev.kinds, half, ev.hold_rows, ev.noise, ev.block_rows)
        sub.set_weights()
        estimates.append(fit_effects(model, sub, effects, start=result.values).values)
    return np.abs(estimates[1] - estimates[0]) / 2.0


def _read_inputs(measured, machine, scenario, column_map, holdout_fraction, initial, step_s):
    """``(machine, scenario or None, matched record, (split, fit rows, held-out rows), initial)`` of a diagnosis,
    each checked (clear errors for a bad hold-out fraction, time step, record or scenario)."""
    holdout_fraction = _checked_number("holdout_fraction (--holdout)", holdout_fraction,
                                       f"lie in [0.05, {MAX_HOLDOUT}]", lambda f: 0.05 <= f <= MAX_HOLDOUT)
    step_s = _checked_number("step_s (--step)", step_s, "be a positive number of seconds", lambda s: 0.0 < s < np.inf)
    machine = _machine(machine)
    sc = None
    if scenario is not None:
        sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    record = match_record(read_measured(measured, column_map), machine, sc)
    rows = _check_length(record, holdout_fraction)
    held_out_s = record.time_s[-1] - rows[0]
    if step_s > held_out_s / 10.0:
        raise TwinInputError(f"step_s (--step) {step_s:g} s is longer than a tenth of the held-out "
                             f"{held_out_s:g} s of the record: the twin would take too few steps there")
    _check_grid_size(record, step_s)
    if initial is None:
        initial = "uniform" if sc is not None and sc.initial["kind"] == "uniform" else "steady"
    return machine, sc, record, rows, initial


def _check_grid_size(record, step_s):
    """Stop before allocating a twin grid of more than :data:`MAX_GRID_STEPS` steps of ``step_s`` s over the
    record's span, naming the span, the step, the memory it would take and the record's time-unit hint."""
    span_s = float(record.time_s[-1] - record.time_s[0])
    steps = span_s / step_s
    if steps <= MAX_GRID_STEPS:
        return
    hint = (record.metadata.get("import", {}).get("time_unit_hint", "").split(": ", 1)[-1]
            or "is the time in ms (÷ 1000)?")
    raise TwinInputError(
        f"{record.report.get('source', 'the record')}: the record spans {span_s:g} s ({span_s / 86400:.4g} days); "
        f"at a step of {step_s:g} s the twin's grid would take {steps:.4g} steps (about "
        f"{steps * BYTES_PER_GRID_STEP / 1e9:.3g} GB), over the {MAX_GRID_STEPS} allowed; {hint.rstrip('.')}. "
        "Otherwise split the record or give a longer --step")


def _explain(d, drive, discovery, timings):
    """Fill the discovery beyond the library (when a gap remains; it may displace the named model), where the gap
    lies, and the verdict sentence."""
    if discovery and d.outcome in ("partly_explained", "not_explained"):
        t3 = time.perf_counter()
        d.discovery = _discover(d)
        timings["discovery_s"] = time.perf_counter() - t3
    t2 = time.perf_counter()
    _where(d, drive)
    timings["where_s"] = time.perf_counter() - t2
    d.verdict = verdict.sentence(d)


def _widen(model, ev, result, applicable):
    """Widen a named model's sds to its split-half jackknife sd where that is larger (in place)."""
    effects = [next(e for e in applicable if e.name == name) for name in result.effects]
    jack = split_half_sd(model, ev, result, effects)
    result.sd = np.maximum(result.sd, jack)
    result.notes.append("sd: max(HAC sandwich, split-half jackknife " + ", ".join(f"{j:.3g}" for j in jack) + ")")


def _where(d, drive):
    """Fill ``d.where``, ``d.attribution`` and ``d.separation`` (residuals by phase and band, parts)."""
    model, ev, nominal, winner = d.model, d.evaluator, d.nominal, d.winner
    t = d.record.time_s
    names = model_names(model, ev)
    d.where = {"phases": where.phase_table(nominal.residual, ev, d.phases, names),
               "bands": where.band_table(nominal.residual, ev, t, names)}
    if winner is not None:
        d.where["phases_after"] = where.phase_table(winner.residual, ev, d.phases, names)
        d.where["bands_after"] = where.band_table(winner.residual, ev, t, names)
    d.attribution = {"regions": attribution.region_estimate(model.structure, ev, nominal.residual, names)}
    if winner is not None:
        d.attribution["winner"] = attribution.effect_attribution(model, winner, nominal, names)
    runner, best = d.runner_up, winner or d.decision.best
    if runner is not None and best is not None:
        try:
            d.separation = attribution.separating_sensor(model, best, runner, nominal,
                                                         noise_K=max(d.noise.get("temperature", 0.02), 0.02))
        except Exception as exc:  # pragma: no cover - diagnostic extra, never fatal, but reported
            d.separation = {"error": str(exc)}


def _discover(d):
    """Run :func:`twin.gap.discovery.discover` on the nominal twin's residual and, with a named model, on what that
    model leaves (:func:`_better_start`); the result, or None with a note when the discovery fails (reported,
    never silent)."""
    from .discovery import discover

    try:
        found = discover(d.model, d.evaluator, base=d.nominal)
        if d.winner is None:
            return found
        return _better_start(d, discover(d.model, d.evaluator, base=d.winner), found)
    except Exception as exc:  # the verdict stands without it; the report says why it is missing
        d.notes.append(f"effect discovery failed: {type(exc).__name__}: {exc}")
        return None


def _better_start(d, after_winner, after_nominal):
    """The discovery to report: on what the named model leaves, unless the one on the nominal residual fits the
    held-out record better by ΔBIC > :data:`twin.gap.verdict.MIN_DELTA_BIC` with every parameter counted (the
    named model's and each accepted atom); then the named model is displaced (:func:`twin.gap.verdict.displace`).

    A library model that stands in for an unlisted effect takes part of its signature, and the search on what
    it leaves then finds the rest in the wrong place or of the wrong kind; so both starts are searched and held-out
    evidence decides between them, as it decides everything else in the diagnosis.
    """
    n = d.n_eff_hold
    bic_winner = d.winner.bic + relative_bic(after_winner.held_out_sse_ratio, after_winner.n_atoms, n)
    bic_nominal = relative_bic(after_nominal.held_out_sse_ratio, after_nominal.n_atoms, n)
    if after_nominal.items and bic_nominal < bic_winner - verdict.MIN_DELTA_BIC:
        verdict.displace(d.decision, "the effects discovered on the nominal twin's residual", bic_winner - bic_nominal)
        return after_nominal
    return after_winner


#: What a value of each kind :func:`_checked_number` takes is, for its message.
_KIND_WORDS = {Real: "a number", Integral: "a whole number"}


def _checked_number(name: str, value, rule: str, within: Callable[[float], bool], kind: type = Real) -> float:
    """``value`` as a Python number (float; int for ``kind`` Integral) once it is a number of ``kind``
    (:func:`_as_number`) for which ``within`` holds (NaN never does), else a TwinInputError "``name`` must ``rule``,
    got ``value``" ("(not a number)" after a value of another type): ``float()`` had raised a TypeError on None and
    read a string ("60") or a bool as a number."""
    number = _as_number(value, kind)
    if number is None:
        raise TwinInputError(f"{name} must {rule}, got {value!r} (not {_KIND_WORDS[kind]})")
    if not within(number):
        raise TwinInputError(f"{name} must {rule}, got {number:g}")
    return number


def _as_number(value, kind):
    """``value`` as a float (``kind`` Real: a :class:`numbers.Real` such as a Fraction, a Decimal, a 0-d numpy
    array of one) or an int (``kind`` Integral), or None when it is not one (a bool, a string, None, a complex)."""
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]               # its numpy scalar
    if isinstance(value, (bool, np.bool_)):
        return None
    if kind is Integral:
        return int(value) if isinstance(value, Integral) else None
    return float(value) if isinstance(value, (Real, Decimal)) else None


def _checked_choices(effects, n_pairs):
    """The effect names of ``effects`` (a sequence or a comma list; None: the whole library), after refusing an
    empty or repeated list and an ``n_pairs`` that is not a whole number ≥ 0 — the rules of ``--effects`` and
    ``--pairs`` too, which hand their values on unchecked (an empty list had meant the whole library, a negative
    count no pairs)."""
    _checked_number("n_pairs (--pairs)", n_pairs, "be a whole number of top effects to pair, 0 (no pairs) or more",
                    lambda n: n >= 0, Integral)
    if effects is None:
        return None
    names = split_names(effects)
    if not names:
        raise TwinInputError(f"effects (--effects) {effects!r} names no effect: give effects of the library (a list "
                             "or a comma list), or leave it out for the whole library")
    check_distinct("effects (--effects)", names, "effect")
    return names


def diagnose(measured: Dataset | str | Path, machine: str | Path | Machine = "vmc_ram",
             scenario: str | Path | Scenario | None = None, column_map: dict[str, str] | None = None,
             holdout_fraction: float = 0.3, effects: str | Sequence[str] | None = None, n_pairs: int = 3,
             backend: str = "rom", step_s: float = DEFAULT_STEP_S, initial: str | None = None,
             progress: Callable[[int, int], None] | None = None,
             engine_options: Mapping[str, int | float | bool] | None = None, discovery: bool = True) -> Diagnosis:
    """Diagnose the sim-to-real gap of a measured record; return a :class:`Diagnosis`.

    Parameters
    ----------
    measured : Dataset, str or Path
        A :class:`~twin.core.dataset.Dataset`, a twin dataset path (CSV with sidecar) or a measured CSV.
    machine : str, Path or Machine, default "vmc_ram"
        Machine name or TOML path, or a built :class:`~twin.core.machine.Machine`.
    scenario : str, Path or Scenario, optional
        Scenario (name, path or object): fallback for missing spindle/feeds/ambient and the initial state.
    column_map : dict of str to str, optional
        CSV column → ``<name>_<unit>`` for measured CSVs.
    holdout_fraction : float, default 0.3
        The last fraction of the record (by time) held out from the fits, in [0.05, 0.8].
    effects : str or sequence of str, optional
        Names of library effects to consider, a sequence or a comma list (as ``--effects``), none twice
        (default: all that apply to the machine).
    n_pairs : int, default 3
        Pairs fitted: the leading single effect with every other one, and the pairs among the top ``n_pairs``
        singles (0: no pairs; a whole number ≥ 0).
    backend : str, default "rom"
        ``rom`` (parametric reduced model) or ``fe`` (full finite elements, slow).
    step_s : float, default :data:`DEFAULT_STEP_S`
        The twin's time step, s.
    initial : str, optional
        ``steady`` (idle steady state at the first sample) or ``uniform``; default ``uniform`` when the scenario
        starts uniform, else ``steady``.
    progress : callable, optional
        ``progress(done, total)``, called after each fit.
    engine_options : mapping of str to int, float or bool, optional
        Backend options (see :func:`engine`).
    discovery : bool, default True
        Search beyond the library (:mod:`twin.gap.discovery`) when a gap remains unexplained.

    Returns
    -------
    Diagnosis
        The verdict, ranking, fits, where the gap lies and the timings (s).

    Raises
    ------
    TwinInputError
        On a bad hold-out fraction, time step, pair count or effect list (empty, or naming one twice; these before
        any work), an unreadable or too short record, or unknown effects, channels or units.
    """
    effects = _checked_choices(effects, n_pairs)
    timings = {}
    t0 = time.perf_counter()
    machine, sc, record, (split, fit_rows, hold_rows), initial = _read_inputs(
        measured, machine, scenario, column_map, holdout_fraction, initial, step_s)
    library = library_by_name(effects)
    applicable = [e for e in library if e.applicable(machine)]
    structure, be = engine(machine, library_by_name(None), backend, **(engine_options or {}))
    timings["engine_s"] = time.perf_counter() - t0
    t = record.time_s
    grid = uniform_grid(t[0], t[-1], float(step_s))
    noise = noise_level(record.values)
    ev = Evaluator(record.values, [structure.index[n] for n in record.names], record.kinds, fit_rows, hold_rows,
                   noise, block_rows=int(step_s // record.report["sampling_interval_s"]))
    model, position, timing, unknown = reconstruct_inputs(machine, structure, be, grid, record, sc, initial, ev)
    drive = model.drive
    model.effects = applicable
    nominal = nominal_result(model, ev)
    check_scale(record, nominal.prediction.values[:, ev.cols], record.report["columns"])
    timings["nominal_s"] = time.perf_counter() - t0 - timings["engine_s"]

    t1 = time.perf_counter()
    singles, pairs, ranking, n_eff_hold = _fit_library(model, ev, applicable, nominal, n_pairs, progress)
    timings["fits_s"] = time.perf_counter() - t1

    judge_notes = []
    scales, decision = _judge(model, ev, record.names, timing, nominal, ranking, timings, judge_notes, backend,
                              engine_options)
    if decision.winner is not None:
        _widen(model, ev, decision.winner, applicable)
    noise_g = {g: float(np.nanmedian(noise[idx])) for g, idx in ev.groups().items()}
    position_note = (f"spindle and feed changes placed {position:g} of the way between samples (chosen on the "
                     "fit part among 0, 0.5, 1)")
    d = Diagnosis(machine, record, model, ev, float(split), nominal, singles, pairs, ranking, decision, scales,
                  n_eff_hold, noise_g,
                  {g: nominal.summary["groups"][g]["hold_rms"] / max(noise_g[g], 1e-9) for g in noise_g},
                  where.phases(drive, t), notes=[*record.report["warnings"], *drive.notes, position_note, *judge_notes],
                  skipped=[e.name for e in library if not e.applicable(machine)], unknown_inputs=unknown)
    _explain(d, drive, discovery, timings)
    timings["total_s"] = time.perf_counter() - t0
    d.timings = timings
    return d
