"""The sensor-placement study: where to put K thermometers so a compensation model generalises.

Procedure (:func:`placement_study`), one module per step:

1. **Candidates** (:mod:`twin.placement.candidates`): outer surface nodes of
   chosen parts thinned by farthest-point sampling, plus the camera's spots.
2. **Records** (:mod:`twin.placement.records`): every scenario run through the
   twin with an output operator of the candidates and the drift only, as sweep
   tasks cached on disk; noise drawn afterwards per scenario.  ``greedy-physics``
   adds the twin's step response to every thermal input.
3. **Selection** (:mod:`twin.placement.selection`) on the training scenarios
   only, per drift axis, for K = 1 … K_max: the seed pipelines of
   :mod:`models.selection` and our ``greedy-loso``, ``qr-drift``, ``greedy-physics``.
4. **Choice** (:mod:`twin.placement.scoring`): an MLR per method, axis and K,
   fitted on the training rows and scored on the *validation* scenarios; the
   method and K of each axis (and the best own and best seed method, for the
   comparison) are chosen on those scores.
5. **Test**: only the chosen sets are scored on the *test* scenarios, which no
   choice has seen; ANFIS-FCM on the chosen sets as a check, on the test too.
   The chosen method and K of each axis run again with the noise drawn anew.
6. **Report** (:mod:`twin.placement.report`).

The three scenario sets must be disjoint; each is sorted by scenario name first,
so the order they are given in changes nothing.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from meshes.tomlspec import DefinitionError, duplicates

from ..core.variants import MachineSpec, as_scenario
from ..errors import TwinInputError
from ..infra.outdir import atomic_directory, check_output_folder
from ..rom.report import runs_on
from .candidates import DEFAULT_PARTS, Candidates, CandidateSpec
from .records import (
    RESPONSE_HORIZON_S,
    RecordTask,
    ResponseTask,
    add_noise,
    elementary_inputs,
    record_interval,
    record_times,
    run_records,
    scenario_seed,
)
from .report import placement_summary, write_placement_report
from .scoring import (
    anfis_scores,
    choose_best,
    score_choices,
    score_set,
    score_table,
    uncompensated,
)
from .selection import METHODS, OWN_METHODS, SEED_METHODS, select_one, select_sets

#: Training scenarios cover the speed range (0–12000 rpm through the ISO 230-3 speed spectrum), feeds
#: (soft cutting, six-part cycle) and a day/night ambient; the test ones differ in duty cycle (periodic
#: hard cutting, step speeds) and in ambient (a summer ETVE of 24 ± 4 K, a warm machine in a cooling room).
DEFAULT_TRAIN = ("heat_cool_9000", "iso230_3_spindle_spectrum", "thesis_test_4", "six_part_cycle", "cutting_soft",
                 "etve_5K")
#: Validation scenarios choose the method and K: other thesis tests, a door opening, a stratified room, the
#: ISO 230-3 ambient and spindle tests.
DEFAULT_VALIDATION = ("thesis_test_2", "thesis_test_5", "thesis_test_6", "door_opening", "stratified_ambient",
                      "iso230_3_etve", "iso230_3_spindle")
DEFAULT_TEST = ("cutting_hard", "step_speed", "etve_summer", "thesis_test_3")
DEFAULT_AXES = ("Z", "Y")


@dataclass
class PlacementResult:
    """What :func:`placement_study` found.

    Attributes
    ----------
    out_dir : Path or None
        The report folder.
    table : list of dict
        One row per method, K and axis: ``max_residual``, ``rmse`` (µm), ``reduction_percent``, ``sensors``,
        ``per_scenario``.
    selections : dict
        ``(method, axis)`` → candidate index lists per K.
    candidates : Candidates
    uncompensated : dict
        Axis → (max, RMS) drift change on the validation scenarios, µm.
    best : dict
        Axis → (method, K, candidate indices), chosen on the validation scores.
    timings : dict
        Phase → wall time, s, and counts of runs.
    anfis : list of dict
        The ANFIS-FCM check on the best sets.
    summary : str
        The Markdown report.
    test : dict
        ``"best"``, ``"own"``, ``"seed"`` → axis → the chosen set's row scored on the test scenarios
        (``own``/``seed``: the best own and best seed method chosen on validation, if both kinds ran).
    uncompensated_test : dict
        Axis → (max, RMS) drift change on the test scenarios, µm.
    redraw : dict
        Axis → the chosen method and K run again with the sensor noise drawn anew: ``sensors``, ``shared`` (how many
        of the chosen ones it picks again), ``others_distance_m`` (each chosen sensor not picked again: m to the
        nearest one picked again), ``others_same_part`` (how many of those are on that one's part),
        ``test_max_residual_chosen`` and ``test_max_residual_again`` (µm, with the new noise); empty without noise
        or the check.

    :func:`placement_study` also sets ``config`` (the study's settings, dict), ``cand_scores`` (score name →
    one value per candidate) and ``records`` (the noisy scenario records, or None).
    """

    out_dir: Path | None
    table: list
    selections: dict
    candidates: Candidates
    uncompensated: dict
    best: dict
    timings: dict
    anfis: list = field(default_factory=list)
    summary: str = ""
    test: dict = field(default_factory=dict)
    uncompensated_test: dict = field(default_factory=dict)
    redraw: dict = field(default_factory=dict)


#: The option of each scenario role, named in the messages.
ROLE_OPTIONS = {"training": "--train", "validation": "--validation", "test": "--test"}


def _check_list(option, items, what, least=1):
    """Refuse a list option with fewer than ``least`` items or with an item given twice."""
    items = [str(i) for i in items]
    if len(items) < least:
        raise TwinInputError(f"{option} must name at least {least} {what}{'s' if least > 1 else ''}, got {items}"
                             + ("; leave the option out for the default" if not items else ""))
    if duplicates(items):
        raise TwinInputError(f"{option} names {what} {duplicates(items)[0]!r} more than once")


def _check_positive(option, value, unit="", zero=False):
    """Refuse a numeric option that is not a finite number > 0 (≥ 0 with ``zero``); ``unit`` follows the value."""
    if not (math.isfinite(value) and (value >= 0 if zero else value > 0)):
        raise TwinInputError(f"{option} must be {'≥ 0' if zero else 'positive'}, got {value:g}{unit}")


def _check_options(methods, parts, n_candidates, k_max, axes, record_interval_s, response_horizon_s):
    """Refuse an unknown method, an empty or repeating list, or a bad number, before anything is built."""
    _check_list("--methods", methods, "method")
    bad = sorted(set(methods) - set(METHODS))
    if bad:
        raise TwinInputError(f"unknown placement method(s) {bad}; methods: {list(METHODS)}")
    _check_list("--parts", parts, "part")
    _check_list("--axes", axes, "axis")
    _check_positive("--candidates", n_candidates, zero=True)         # 0: the camera spots only
    _check_positive("--k-max", k_max)
    if record_interval_s is not None:
        _check_positive("--record-interval", record_interval_s, " s")
    _check_positive("--response-horizon", response_horizon_s / 3600.0, " h")


def _load_role(option, value):
    """The scenario ``value`` of ``option`` (a shipped name or a TOML path), loaded; an unknown one refused."""
    try:
        return as_scenario(value)
    except DefinitionError as exc:          # its message lists the shipped scenarios for an unknown name
        raise TwinInputError(f"{option} {str(value)!r}: {exc}") from None


def _resolve_roles(train, validation, test):
    """``(role → list of Scenario, the values as given in the same order)``, loaded before any simulation, each role
    sorted by scenario name.

    The order the names come in must not matter: the training records are stacked in a row, and a grey model's
    accumulated series (GM(0,N) influence of ``gm-influence+fcm``) runs over that row, so another order chose
    other sensors.  A scenario is compared by its name, however it was given (name, path or Scenario): refused
    when it is unknown, repeated within a role (``greedy-loso`` would predict it from its own copy), in two roles
    (an in-sample fit reported as held out), or when there are fewer than 2 training or no validation or test
    scenarios.
    """
    roles = {"training": train, "validation": validation, "test": test}
    loaded, given, seen = {}, [], {}
    for role, option in ROLE_OPTIONS.items():
        pairs = sorted(((v, _load_role(option, v)) for v in roles[role]), key=lambda pair: pair[1].name)
        loaded[role] = [sc for _v, sc in pairs]
        given += [v for v, _sc in pairs]
        _check_list(option, [s.name for s in loaded[role]], "scenario", 2 if role == "training" else 1)
        for s in loaded[role]:
            if seen.setdefault(s.name, role) != role:
                raise TwinInputError(f"scenario {s.name!r} is both a {seen[s.name]} and a {role} scenario "
                                     f"({ROLE_OPTIONS[seen[s.name]]}, {option}); training, validation and test "
                                     "scenarios must differ")
    return loaded, given


def _check_record_rows(roles, record_interval_s, k_max):
    """Refuse a scenario whose record would have too few rows, before any simulation.

    An MLR with K sensors has K + 1 coefficients and needs more rows than that (else it reproduces its data
    whatever they mean, or is singular); ``greedy-loso`` and ``greedy-physics`` fit it, up to K = ``k_max``, on
    the training scenarios but one — with two of them on one alone — so each training record needs
    ``k_max`` + 2 rows.  A validation or test record is only predicted: it needs a second row, a drift change
    from its zero reference.
    """
    for role, option in ROLE_OPTIONS.items():
        need = k_max + 2 if role == "training" else 2
        for sc in roles[role]:
            rows, step = len(record_times(sc, record_interval_s)), record_interval(sc, record_interval_s)
            if rows >= need:
                continue
            why = (f"a training record needs at least --k-max + 2 = {need}: the MLR with K sensors has K + 1 "
                   "coefficients and greedy-loso fits it on the training scenarios but one (with two, on one "
                   "alone)" if role == "training" else "a validation or test record needs at least 2 (a drift "
                   "change to compensate)")
            given = record_interval_s is not None and step == record_interval_s
            raise TwinInputError(f"{option} {sc.name}: {sc.duration_s:g} s recorded every {step:g} s "
                                 f"({'--record-interval' if given else 'its own sampling'}) gives {rows} row"
                                 f"{'s' if rows != 1 else ''}; {why}"
                                 + ("; lower --record-interval" + (" or --k-max" if role == "training" else "")
                                    if given else ""))


def _check_against_machine(machine, cands, axes, k_max, roles):
    """Refuse ``axes`` that are not drift axes of ``machine``, a ``k_max`` above the number of candidates, and a
    scenario (``roles``: role → scenarios) written for another machine or that the machine cannot run (speeds,
    feeds, zones) — before any simulation."""
    drift = [c.name for c in machine.channels if c.kind == "displacement"]     # TCP drift X, Y, Z and Y_top, µm
    bad = [a for a in axes if a not in drift]
    if bad:
        raise TwinInputError(f"--axes {','.join(axes)}: {bad[0]!r} is not a drift axis of "
                             f"{machine.definition.name!r}; drift axes: {','.join(drift)}")
    if k_max > len(cands):
        raise TwinInputError(f"--k-max {k_max} exceeds the {len(cands)} candidates (--candidates, --parts, "
                             "--no-camera)")
    for role, option in ROLE_OPTIONS.items():
        for sc in roles[role]:
            if not runs_on(sc, machine):        # its loads, limits and zones are those of the other machine
                raise TwinInputError(f"{option} {sc.name}: the scenario is written for machine {sc.machine!r}, "
                                     f"not for {machine.name!r} (--machine)")
            sc.check_machine(machine.definition)


def _record_axes(axes):
    """The axes a record keeps: every one of X, Y, Z (a cached record serves other ``--axes``), else ``axes``."""
    return tuple(sorted(set(axes) | {"X", "Y", "Z"}, key="XYZ".index)) if set(axes) <= set("XYZ") else tuple(axes)


def _simulate(machine, spec, cspec, scenarios, axes, record_interval_s, response_horizon_s, physics, scheduler,
              use_cache, progress):
    """(scenario records, step responses, timings) — noise-free, from the cache where possible. ``machine`` is
    ``spec`` built here first, so that its mesh and operator caches are ready for the workers."""
    t0 = time.perf_counter()
    tasks = [RecordTask(spec, cspec, s, axes, record_interval_s) for s in scenarios]
    if physics:
        tasks += [ResponseTask(spec, cspec, name, axes, float(response_horizon_s))
                  for name, _j, _s in elementary_inputs(machine)]
    everything = run_records(tasks, scheduler=scheduler, use_cache=use_cache, progress=progress)
    timings = {"simulation_s": time.perf_counter() - t0, "simulated": sum(not r.from_cache for r in everything),
               "from_cache": sum(r.from_cache for r in everything), "responses": len(everything) - len(scenarios),
               "simulation_cpu_s": sum(r.seconds for r in everything if not r.from_cache)}
    return everything[:len(scenarios)], everything[len(scenarios):], timings


def _measured(records, cands, base=0):
    """Measured-like copies of noise-free records: sensor noise seeded by each record's name and ``base``."""
    return [add_noise(r, cands.kinds, scenario_seed(r.scenario, base)) for r in records]


def _by_role(records, roles):
    """Role → its records, from ``records`` in the order of ``roles`` (training, validation, test)."""
    out, start = {}, 0
    for role, scenarios in roles.items():
        out[role], start = records[start:start + len(scenarios)], start + len(scenarios)
    return out


@contextmanager
def _fits_of(training):
    """A fit that fails on the records (singular, too few rows) becomes one line naming the training scenarios."""
    try:
        yield
    except TwinInputError:
        raise
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise TwinInputError(f"a fit on the training records ({', '.join(s.name for s in training)}) failed: {exc} "
                             "— too few rows, or temperatures and drift that barely change (--train, "
                             "--record-interval)") from None


def _choose_and_test(by_role, responses, cands, methods, axes, k_max, max_rows, anfis_check, log):
    """``(PlacementResult without config, Selection)``: selection on the training records, choice of method and
    K on the validation ones, the chosen sets scored on the test ones, and the ANFIS check."""
    rec_train, rec_val, rec_test = by_role["training"], by_role["validation"], by_role["test"]
    t0 = time.perf_counter()
    chosen = select_sets(rec_train, responses, methods, axes, k_max, max_rows, log)
    timings = {"selection_s": time.perf_counter() - t0}
    t0 = time.perf_counter()
    table, uncomp = score_table(chosen.sets, rec_train, rec_val, cands, methods, axes)
    best = choose_best(table, cands, axes, k_max)
    tested = _test_choices(table, best, cands, axes, k_max, methods, rec_train, rec_test)
    uncomp_test = {axis: uncompensated(rec_test, axis) for axis in axes}
    timings["scoring_s"] = time.perf_counter() - t0
    anfis = []
    if anfis_check:
        t0 = time.perf_counter()
        anfis = anfis_scores(best, chosen.sets, rec_train, rec_test, uncomp_test, k_max)
        timings["anfis_s"] = time.perf_counter() - t0
    return PlacementResult(None, table, chosen.sets, cands, uncomp, best, timings, anfis, "", tested,
                           uncomp_test), chosen


#: The second noise draw of :func:`_redrawn` (the ``base`` of :func:`~twin.placement.records.scenario_seed`).
REDRAW_NOISE_BASE = 1


def _redrawn(raw, raw_responses, best, cands, axes, max_rows):
    """Axis → the chosen method and K run again on the training records with the sensor noise drawn anew
    (:data:`REDRAW_NOISE_BASE`): the sensors it picks, how many of the chosen ones among them, for each chosen one
    not picked again the distance (m) to the nearest one that is and whether it is on the same part, and the test
    max |residual| (µm) of both sets with the new noise (``raw``: role → noise-free records)."""
    train, test = _measured(raw["training"], cands, REDRAW_NOISE_BASE), _measured(raw["test"], cands,
                                                                                   REDRAW_NOISE_BASE)
    responses = _measured(raw_responses, cands, REDRAW_NOISE_BASE)
    out, picked = {}, {}
    for axis, (method, k, idx) in best.items():
        key = (method, k) if method == "greedy-physics" else (method, k, axis)     # one physics set for all axes
        if key not in picked:
            picked[key] = select_one(train, responses, method, axis, tuple(axes), k, max_rows)
        again = picked[key]
        nearest = {i: again[int(np.argmin(np.linalg.norm(cands.points[again] - cands.points[i], axis=1)))]
                   for i in idx if i not in again}
        out[axis] = {"method": method, "K": k, "sensors": [cands.names[i] for i in again],
                     "shared": k - len(nearest),
                     "others_distance_m": [float(np.linalg.norm(cands.points[j] - cands.points[i]))
                                           for i, j in nearest.items()],
                     "others_same_part": sum(cands.parts[i] == cands.parts[j] for i, j in nearest.items()),
                     "test_max_residual_chosen": score_set(train, test, np.asarray(idx), axis)[0],
                     "test_max_residual_again": score_set(train, test, np.asarray(again), axis)[0]}
    return out


def _test_choices(table, best, cands, axes, k_max, methods, rec_train, rec_test):
    """The sets chosen on validation — overall, best own method, best seed method — scored on the test."""
    tested = {"best": score_choices(best, rec_train, rec_test, cands)}
    own, seed = [m for m in methods if m in OWN_METHODS], [m for m in methods if m in SEED_METHODS]
    if own and seed:
        for label, among in (("own", own), ("seed", seed)):
            tested[label] = score_choices(choose_best(table, cands, axes, k_max, tuple(among)), rec_train, rec_test,
                                          cands)
    return tested


def placement_study(machine: str = "vmc_ram", mesh_size_m: float | None = None, parts: tuple = DEFAULT_PARTS,
                    n_candidates: int = 2000, camera: bool = True, train: tuple = DEFAULT_TRAIN,
                    validation: tuple = DEFAULT_VALIDATION, test: tuple = DEFAULT_TEST, methods: tuple = METHODS,
                    k_max: int = 8, axes: tuple = DEFAULT_AXES, record_interval_s: float | None = 60.0,
                    max_selection_rows: int = 2000, scheduler: str | object = "local", use_cache: bool = True,
                    noise: bool = True, report_k: int = 5, anfis_check: bool = True, write_datasets: bool = True,
                    out_dir: Path | str | None = None, progress: Callable[[int, int], None] | None = None,
                    log: Callable[[str], object] | None = print, response_horizon_s: float = RESPONSE_HORIZON_S,
                    overwrite: bool = False, redraw: bool = True) -> PlacementResult:
    """Run the placement study; write its report to ``out_dir`` (see the module docstring).

    Parameters
    ----------
    machine, mesh_size_m
        The machine and its element size (m; None: its default).
    parts, n_candidates, camera
        Candidates: surface nodes of ``parts`` thinned to ``n_candidates``, plus the camera spots.
    train, validation, test
        Scenario names, paths or :class:`~twin.core.scenario.Scenario` s, disjoint: the selection sees the
        training scenarios, the choice of method and K the validation scenarios, and the chosen sets are
        scored once on the test scenarios.  Compared by the scenario's name however given; an unknown or repeated
        one is refused; at least two training scenarios and one of each other kind are needed.  The order within
        each list does not matter: each is sorted by scenario name before anything is computed.
    methods, k_max, axes
        Selection methods (:data:`~twin.placement.selection.METHODS`), the largest K (1 … the number of
        candidates), the drift axes (the machine's displacement channels: X, Y, Z, Y_top).
    record_interval_s
        Recording interval, s (None: the scenario's samples; a scenario sampled more coarsely keeps its samples).
    max_selection_rows
        Training rows the selection uses (thinned evenly per scenario).
    scheduler, use_cache, progress
        The sweep (see :func:`twin.infra.sweep.run_tasks`) and the record cache.
    log : callable or None, default print
        Receives notes (selection progress); None is silent.
    noise
        Draw DS18S20/S65/NCDT noise on the records, seeded by each scenario's name.
    report_k
        Kept in the configuration of the report.
    anfis_check
        Fit ANFIS-FCM on the best sets as a check.
    write_datasets
        The report folder gets ``datasets/<scenario>.csv``: every record as a dataset with the best sets'
        sensors as thermometers, for ``twin train``.
    out_dir, overwrite
        The report folder, checked before the work (see :func:`twin.infra.outdir.check_output_folder`).
    response_horizon_s
        Length of the step responses of ``greedy-physics``, s.
    redraw
        With ``noise``: run the chosen method and K of each axis again with the noise drawn anew (a second seed
        per scenario), to report how much the chosen locations owe to one noise draw.

    Returns
    -------
    PlacementResult

    Raises
    ------
    TwinInputError
        Before any simulation: an unknown method, scenario or drift axis; an empty list or one naming an item
        twice; a scenario in two roles, or written for another machine; too few scenarios; a non-positive number
        (``n_candidates`` may be 0: camera spots only); ``k_max`` above the number of candidates; a recording
        interval that leaves a training record fewer than ``k_max`` + 2 rows, or another record fewer than 2; or
        an unusable ``out_dir``.  After the simulations: a fit that fails on the records (singular).
    """
    check_output_folder(out_dir, overwrite, inputs=(machine,))
    t_start = time.perf_counter()
    methods = list(methods)
    _check_options(methods, parts, n_candidates, k_max, axes, record_interval_s, response_horizon_s)
    roles, given = _resolve_roles(train, validation, test)
    spec = MachineSpec(machine, mesh_size_m)
    cspec = CandidateSpec(tuple(parts), int(n_candidates), bool(camera))
    m = spec.build()
    cands = cspec.build(m)
    _check_against_machine(m, cands, axes, k_max, roles)
    _check_record_rows(roles, record_interval_s, k_max)
    raw, raw_responses, timings = _simulate(
        m, spec, cspec, given, _record_axes(axes), record_interval_s, response_horizon_s,
        "greedy-physics" in methods, scheduler, use_cache, progress)
    # the step responses too: greedy-physics sees them as measured
    records, responses = (_measured(raw, cands), _measured(raw_responses, cands)) if noise else (raw, raw_responses)
    with _fits_of(roles["training"]):
        result, chosen = _choose_and_test(_by_role(records, roles), responses, cands, methods, axes, k_max,
                                          max_selection_rows, anfis_check, log)
        if noise and redraw:
            t0 = time.perf_counter()
            result.redraw = _redrawn(_by_role(raw, roles), raw_responses, result.best, cands, axes,
                                     max_selection_rows)
            timings["redraw_s"] = time.perf_counter() - t0
    result.timings = {**timings, **result.timings, "total_s": time.perf_counter() - t_start}
    result.config = {"machine": machine, "mesh_size_m": mesh_size_m, "parts": list(parts),
                     "n_candidates": len(cands), "n_surface": int(sum(k == "surface" for k in cands.kinds)),
                     "n_camera": int(sum(k == "camera" for k in cands.kinds)),
                     "train": [s.name for s in roles["training"]],
                     "validation": [s.name for s in roles["validation"]], "test": [s.name for s in roles["test"]],
                     "methods": methods, "k_max": k_max, "axes": list(axes), "record_interval_s": record_interval_s,
                     "record_intervals_s": {s.name: record_interval(s, record_interval_s)
                                            for scenarios in roles.values() for s in scenarios},
                     "noise": noise, "model": "mlr", "selection_rows": chosen.rows, "report_k": report_k,
                     "response_horizon_s": float(response_horizon_s) if "greedy-physics" in methods else None}
    result.cand_scores = chosen.scores
    result.records = records if write_datasets else None
    result.config["scenario_objects"] = given
    result.summary = placement_summary(result)
    if out_dir is not None:
        with atomic_directory(out_dir, overwrite) as tmp:
            write_placement_report(result, m, tmp)
        result.out_dir = Path(out_dir)
    return result
