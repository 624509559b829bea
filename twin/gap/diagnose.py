"""The gap diagnosis: measured record + nominal twin → where it misses, which effect explains it, how far it shrinks.

:func:`diagnose` runs the nominal twin with the measured inputs (spindle
speed, feeds, ambients from the air sensors), splits the record
chronologically into a fit part and a held-out part, fits every candidate
effect of the library (and the pairs of the leading ones) on the fit part,
ranks them by penalised evidence on the held-out part, and decides whether
there is a significant gap at all:

- the nominal residual must exceed the noise and the model tolerance
  (held-out RMS > :data:`NOISE_FACTOR` × max(noise, tolerance) in some
  channel group; tolerances :data:`twin.gap.fit.GROUP_FLOOR`), and
- the best model must beat the nominal twin by ΔBIC > :data:`MIN_DELTA_BIC`
  *and* be material: remove from the held-out residual of some channel group
  a component at least as large as the group's scale σ_g = max(noise,
  tolerance), i.e. (RMS_before² − RMS_after²) / σ_g² ≥ :data:`MIN_MATERIAL`.
  Long records make tiny systematic improvements "significant" by BIC alone
  (an effect bending itself to the discretisation error); materiality asks
  for a change that matters at the twin's accuracy.

A pair is named instead of a single effect only if each of its single
effects still leaves a gap (the first test, on the single's residual) and the
pair passes the second test against it: an effect is added only while a
significant gap remains.  Without the first condition a second effect that
bends itself to the twin's own discretisation error (a few % of a joint
conductance absorbing the difference between a coarse and a fine mesh) is
named beside the true one.

Otherwise the verdict is "no significant gap" and no cause is named.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..core.machine import build_machine
from ..core.scenario import Scenario, load_scenario
from ..errors import TwinInputError
from ..infra.sweep import cached
from . import attribution, where
from .drive import measured_drive
from .effects import library_by_name
from .engine import make_backend
from .fit import Evaluator, effective_samples, fit_effects, model_names, nominal_result, score
from .measured import match_record, read_measured
from .model import GapModel
from .signals import noise_level, uniform_grid
from .structure import build_structure

MIN_DELTA_BIC = 10.0
MIN_MATERIAL = 1.0
NOISE_FACTOR = 2.0
DEFAULT_STEP_S = 60.0


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
    winner: object
    runner_up: object
    significant: bool
    verdict: str
    evidence_ratio: float
    n_eff_hold: float
    noise: dict
    gap_over_noise: dict
    phases: np.ndarray
    where: dict = field(default_factory=dict)
    attribution: dict = field(default_factory=dict)
    separation: dict | None = None
    timings: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    skipped: list = field(default_factory=list)
    gap_over_tolerance: dict = field(default_factory=dict)

    @property
    def names(self):
        return self.record.names

    def result(self, name):
        for r in [self.nominal] + self.ranking:
            if r.name == name:
                return r
        raise KeyError(name)

    def shrinkage(self, result=None):
        """Held-out RMS and max before (nominal) and after ``result`` (default the winner), per group and axis."""
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

    def drift_shrinkage(self, result=None):
        """Reduction of the held-out drift RMS pooled over the displacement channels (fraction), or None."""
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


def materiality(result, reference, sigma):
    """max over channel groups of (RMS_ref² − RMS²) / σ_g² on the held-out rows (see the module docstring)."""
    out = -np.inf
    for g, sig in sigma.items():
        a = reference.summary["groups"][g]["hold_rms"]
        b = result.summary["groups"][g]["hold_rms"]
        if np.isfinite(a) and np.isfinite(b):
            out = max(out, (a * a - b * b) / sig ** 2)
    return float(out)


def gap_over_tolerance(result, sigma):
    """Held-out RMS / σ_g per channel group of a result's residual."""
    return {g: result.summary["groups"][g]["hold_rms"] / sig for g, sig in sigma.items()}


def leaves_a_gap(result, sigma):
    """True when the held-out residual still exceeds :data:`NOISE_FACTOR` × σ_g in some channel group."""
    return max(gap_over_tolerance(result, sigma).values()) > NOISE_FACTOR


def _parsimonious(ranking, sigma):
    """The best model, but a pair only when each of its effects earns its place (module docstring)."""
    by_name = {r.name: r for r in ranking}
    for r in ranking:
        if len(r.effects) == 1:
            return r
        singles = [by_name[e] for e in r.effects if e in by_name]
        if all(leaves_a_gap(s, sigma) and r.delta_bic - s.delta_bic > MIN_DELTA_BIC
               and materiality(r, s, sigma) >= MIN_MATERIAL for s in singles):
            return r
    return ranking[0]


def engine(machine, effects, backend="rom", **options):
    """(structure, backend) for a machine and a library, built once per process (:func:`twin.infra.sweep.cached`)."""
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
    """A built machine as given, or one built by name (and mesh size) once per process."""
    if isinstance(machine, str):
        return cached(("machine", machine, mesh_size_m), lambda: build_machine(machine, mesh_size_m))
    return machine


def diagnose(measured, machine="vmc_ram", scenario=None, column_map=None, holdout_fraction=0.3, effects=None,
             n_pairs=3, backend="rom", step_s=DEFAULT_STEP_S, initial=None, progress=None, engine_options=None):
    """Diagnose the sim-to-real gap of a measured record; return a :class:`Diagnosis`.

    Parameters
    ----------
    measured : a :class:`~twin.core.dataset.Dataset`, a twin dataset path (CSV with sidecar) or a measured CSV
    machine : machine name or a built :class:`~twin.core.machine.Machine`
    scenario : optional scenario (name, path or object): fallback for missing spindle/feeds/ambient and the
        initial state
    column_map : dict csv column → ``<name>_<unit>`` for measured CSVs
    holdout_fraction : the last fraction of the record (by time) held out from the fits
    effects : names of library effects to consider (default: all that apply to the machine)
    n_pairs : pairs fitted: the leading single effect with every other one, and the pairs among the top
        ``n_pairs`` singles (0: no pairs)
    backend : ``rom`` (parametric reduced model) or ``fe`` (full finite elements, slow)
    step_s : the twin's time step, s
    initial : ``steady`` (idle steady state at the first sample, the default) or ``uniform``
    progress : optional callable ``progress(done, total)`` over the fits
    """
    timings = {}
    t0 = time.perf_counter()
    if not 0.05 <= float(holdout_fraction) <= 0.8:
        raise TwinInputError(f"holdout_fraction must lie in [0.05, 0.8], got {holdout_fraction}")
    machine = _machine(machine)
    sc = None
    if scenario is not None:
        sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    record = match_record(read_measured(measured, column_map), machine)
    if initial is None:
        initial = "uniform" if sc is not None and sc.initial["kind"] == "uniform" else "steady"
    library = library_by_name(effects)
    applicable = [e for e in library if e.applicable(machine)]
    skipped = [e.name for e in library if not e.applicable(machine)]
    structure, be = engine(machine, library_by_name(None), backend, **(engine_options or {}))
    timings["engine_s"] = time.perf_counter() - t0
    t = record.time_s
    grid = uniform_grid(t[0], t[-1], float(step_s))
    drive = measured_drive(machine, grid, record, sc)
    model = GapModel(structure, be, drive, t, initial)
    model.effects = applicable
    split = t[0] + (1.0 - float(holdout_fraction)) * (t[-1] - t[0])
    fit_rows, hold_rows = t <= split, t > split
    if fit_rows.sum() < 5 or hold_rows.sum() < 5:
        raise TwinInputError(f"the split at {split / 3600:.2f} h leaves too few rows "
                             f"({fit_rows.sum()} fit, {hold_rows.sum()} held out)")
    cols = [structure.index[n] for n in record.names]
    noise = noise_level(record.values)
    ev = Evaluator(record.values, cols, record.kinds, fit_rows, hold_rows, noise)
    nominal = nominal_result(model, ev)
    n_eff_hold = effective_samples(nominal.residual, ev, hold_rows)
    timings["nominal_s"] = time.perf_counter() - t0 - timings["engine_s"]

    t1 = time.perf_counter()
    total = len(applicable)
    singles = []
    for i, e in enumerate(applicable):
        singles.append(fit_effects(model, ev, [e]))
        if progress is not None:
            progress(i + 1, total)
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
    ranking = score(singles + pairs, nominal, n_eff_hold)
    timings["fits_s"] = time.perf_counter() - t1

    # ------------------------------------------------------------------ decision
    groups = ev.groups()
    noise_g = {g: float(np.nanmedian(noise[idx])) for g, idx in groups.items()}
    gap_over_noise = {g: nominal.summary["groups"][g]["hold_rms"] / max(noise_g[g], 1e-9) for g in groups}
    gap_tolerance = gap_over_tolerance(nominal, ev.sigma)
    best = _parsimonious(ranking, ev.sigma)
    reduction = 1.0 - best.residual.sse_hold / max(nominal.residual.sse_hold, 1e-300)
    material = materiality(best, nominal, ev.sigma)
    above_noise = leaves_a_gap(nominal, ev.sigma)
    significant = bool(above_noise and best.delta_bic > MIN_DELTA_BIC and material >= MIN_MATERIAL)
    winner = best if significant else None
    if winner is not None:
        others = [r for r in ranking if not set(r.effects) & set(winner.effects) and len(r.effects) == 1]
    else:
        others = ranking[1:]
    runner = others[0] if others else None
    evidence_ratio = float(np.exp(min((runner.bic - best.bic) / 2, 700))) if runner is not None else float("inf")
    if not above_noise:
        verdict = ("no significant gap: the nominal twin's held-out residual is within the noise and the model "
                   f"tolerance (at most {max(gap_tolerance.values()):.1f} × max(noise, tolerance))")
    elif not significant:
        verdict = (f"no significant gap: no candidate effect beats the nominal twin on held-out data by "
                   f"ΔBIC > {MIN_DELTA_BIC:g} with a material change (best: {best.name}, ΔBIC {best.delta_bic:.1f}, "
                   f"materiality {material:.2f} < {MIN_MATERIAL:g})")
    else:
        values = ", ".join(f"{p['name']} = {p['value']:.3g} ± {p['sd']:.2g} {p['unit']}" for p in winner.params())
        verdict = (f"gap explained by {winner.name} ({values}); "
                   f"ΔBIC {winner.delta_bic:.1f} vs nominal, held-out residual −{reduction:.0%}")
        if runner is not None:
            ratio = "> 1e100" if evidence_ratio > 1e100 else f"{evidence_ratio:.3g}"
            verdict += f"; evidence ratio {ratio} over the runner-up {runner.name}"

    # ------------------------------------------------------------------ where
    t2 = time.perf_counter()
    names = model_names(model, ev)
    labels = where.phases(drive, t)
    where_out = {"phases": where.phase_table(nominal.residual, ev, labels, names),
                 "bands": where.band_table(nominal.residual, ev, t, names)}
    if winner is not None:
        where_out["phases_after"] = where.phase_table(winner.residual, ev, labels, names)
        where_out["bands_after"] = where.band_table(winner.residual, ev, t, names)
    attr = {"regions": attribution.region_estimate(structure, ev, nominal.residual, names)}
    if winner is not None:
        attr["winner"] = attribution.effect_attribution(model, winner, nominal, names)
    separation = None
    if runner is not None:
        try:
            separation = attribution.separating_sensor(model, winner or best, runner, nominal,
                                                       noise_K=max(noise_g.get("temperature", 0.02), 0.02))
        except Exception as exc:  # pragma: no cover - diagnostic extra, never fatal
            separation = {"error": str(exc)}
    timings["where_s"] = time.perf_counter() - t2
    timings["total_s"] = time.perf_counter() - t0
    notes = list(drive.notes)
    return Diagnosis(machine, record, model, ev, float(split), nominal, singles, pairs, ranking, winner, runner,
                     significant, verdict, evidence_ratio, n_eff_hold, noise_g, gap_over_noise, labels, where_out,
                     attr, separation, timings, notes, skipped, gap_tolerance)
