"""Compensation studies on twin data: transfer across operating conditions, the thesis protocol, hybrid models.

- :func:`cross_condition_study` — the lesson of seed 003 (models trained on one
  condition do not transfer): train on one scenario family, test on every
  other; a transfer matrix per axis (Markdown + PNG heat map).
- :func:`thesis_protocol_study` — train on the heating/cooling Test IV, test on
  Tests I, II, III, V and VI (thesis §5).
- :func:`hybrid_study` — grey-box compensation: the nominal twin predicts the
  drift from the measured spindle speed and ambient, a data-driven model learns
  the twin's residual from the measured temperatures; compared with pure
  physics and pure data-driven on the same held-out records.  The "measured"
  records come from a *perturbed* twin (scaled source powers and convection,
  sensor noise), the physics model is the nominal twin: a known sim-to-real gap.

All simulations are independent tasks of :func:`twin.infra.sweep.run_tasks`.
Inputs and targets are zero-referenced per record (see :mod:`twin.compensation.store`).
"""
from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from models import select_sensors

from ..core.dataset import ChannelInfo, Dataset, name_listing
from ..core.scenario import available_scenarios
from ..core.simulate import record_channel_names, simulate
from ..core.variants import MachineSpec, as_scenario, zero_referenced
from ..errors import TwinInputError
from ..infra.cli_common import check_distinct
from ..infra.outdir import check_output_folder
from ..infra.sweep import run_tasks
from .records import dataset_label, with_rest_start
from .store import fit_compensation_model, make_estimator
from .study_report import (
    StudyResult,
    cross_condition_markdown,
    hybrid_markdown,
    plot_hybrid,
    plot_thesis,
    plot_transfer,
    thesis_markdown,
    write_study,
)
from .train import physics_prediction, score

#: Scenario families of the cross-condition study: the first available scenario of each is used.
FAMILIES = {
    "soft cutting": ("cutting_soft",),
    "hard cutting": ("cutting_hard",),
    "spindle heat/cool": ("heat_cool_9000", "iso230_3_spindle", "iso230_3_spindle_short"),
    "ETVE": ("iso230_3_etve", "etve_5K", "etve_summer"),
    "step speed": ("step_speed",),
}
THESIS_TRAIN = "thesis_test_4"
THESIS_TEST = ("thesis_test_1", "thesis_test_2", "thesis_test_3", "thesis_test_5", "thesis_test_6")
INSTRUMENT_NOISE = {"temperature": "DS18S20", "displacement": "NCDT", "strain": "FBG", "camera": "none"}
#: The sim-to-real gap of the hybrid study: what the "real" machine has that the nominal twin does not.
DEFAULT_GAP = {"source_scale": (("front_bearings", 1.3), ("rear_bearings", 1.2), ("spindle_motor", 0.8),
                                ("xy_drives", 1.2)),
               "convection_scale": 0.8}
HYBRID_TRAIN = ("thesis_test_4", "heat_cool_9000", "step_speed", "etve_5K")
HYBRID_TEST = ("thesis_test_3", "cutting_hard", "iso230_3_spindle_spectrum", "etve_summer")


@dataclass(frozen=True)
class SimulateTask:
    """A picklable sweep task: one scenario on a (possibly perturbed) machine → a Dataset."""

    machine: MachineSpec
    scenario: object
    noise: bool = True
    instrument_noise: bool = True     # force the thesis instruments' noise even if the scenario has none
    seed: int | None = None

    def __call__(self):
        sc = as_scenario(self.scenario)
        if self.noise and self.instrument_noise:
            sc = replace(sc, noise={**INSTRUMENT_NOISE, **{k: v for k, v in sc.noise.items() if v != "none"}})
        sc = replace(sc, record_camera=False)
        ds = simulate(sc, self.machine.build(), noise=self.noise, seed=self.seed).dataset
        if self.machine.perturbed:
            ds.metadata["effects"] = [{"kind": "perturbed twin", "source_scale": self.machine.source_scale,
                                       "convection_scale": self.machine.convection_scale}]
        return ds


@dataclass(frozen=True)
class PhysicsTask:
    """A picklable sweep task: the nominal twin's drift prediction for a record."""

    machine: MachineSpec
    dataset: object
    outputs: tuple = ("Z", "Y")
    backend: str = "fe"

    def __call__(self):
        return physics_prediction(self.machine.build(), self.dataset, self.outputs, self.backend)


def _available(names):
    known = set(available_scenarios())
    return [n for n in names if n in known or Path(str(n)).exists()]


def simulate_many(scenarios: list, machine: MachineSpec | None = None, scheduler: str | object = "local",
                  noise: bool = True, progress: Callable[[int, int], None] | None = None) -> list[Dataset]:
    """Datasets of ``scenarios`` on ``machine`` (default: the nominal ``vmc_ram``), one sweep task each.

    Each record gets the thesis instruments' noise (:data:`INSTRUMENT_NOISE`) where its scenario has
    none, and no camera spots.

    Parameters
    ----------
    scenarios : list
        Scenario names, TOML paths or :class:`~twin.core.scenario.Scenario` objects.
    machine : MachineSpec, optional
        The (possibly perturbed) machine.
    scheduler : str or distributed.Client, default "local"
        See :func:`twin.infra.sweep.run_tasks`.
    noise : bool, default True
        Add sensor noise (seeded by each scenario).
    progress : callable, optional
        ``progress(done, total)``.

    Returns
    -------
    list of Dataset
        In the order of ``scenarios``.
    """
    machine = machine or MachineSpec()
    machine.build()       # mesh and operator caches ready before the workers start (none meshes twice)

    return run_tasks([SimulateTask(machine, s, noise) for s in scenarios], scheduler=scheduler, progress=progress)


def installed_thermometers(dataset: Dataset) -> list[str]:
    """The thermometer channels of a record (kind ``temperature``): the candidate inputs of a study.

    Parameters
    ----------
    dataset : Dataset

    Returns
    -------
    list of str
    """
    return dataset.names_of_kind("temperature")


def select_inputs(datasets: Sequence[Dataset], target: str, k: int = 4, method: str = "gm-influence+fcm",
                  candidates: list[str] | None = None, random_state: int = 0) -> list[str]:
    """Choose ``k`` input channels for ``target`` on training datasets by a seed method (zero-referenced).

    Parameters
    ----------
    datasets : sequence of Dataset
        Training records, stacked after zero-referencing each.
    target : str
        Target channel (µm for a drift axis).
    k : int, default 4
        Inputs to choose (at most the number of candidates).
    method : str, default "gm-influence+fcm"
        A method of :func:`models.selection.select_sensors`.
    candidates : list of str, optional
        Candidate channels (default: the first record's thermometers); those that never move in the records
        are left out.
    random_state : int, default 0
        Seeds FCM.

    Returns
    -------
    list of str
        The chosen channels, best score first.
    """
    candidates = candidates or installed_thermometers(datasets[0])
    X = np.vstack([zero_referenced(d.matrix(candidates)) for d in datasets])
    moving = np.ptp(X, axis=0) > 0   # a thermometer that never moves here carries nothing, and cannot be trained on
    candidates, X = [c for c, m in zip(candidates, moving) if m], X[:, moving]
    y = np.concatenate([d[target] - d[target][0] for d in datasets])
    sel = select_sensors(X, y, method=method, n_select=min(k, len(candidates)), random_state=random_state)
    return [candidates[i] for i in sel.indices]


def check_study_options(axes: Sequence[str], models: Sequence[str], k: int, physics_backend: str = "fe") -> None:
    """Refuse study options that are wrong whatever the machine, before it is built or anything simulated.

    The studies fit their models only after minutes of simulation; a typo found there costs all of it.

    Parameters
    ----------
    axes : sequence of str
        Drift axes: at least one, none twice.
    models : sequence of str
        Model names: at least one, none twice, each known to :mod:`models.registry`.
    k : int
        Inputs to choose: a whole number ≥ 1.
    physics_backend : str, default "fe"
        ``fe`` or ``rom``.

    Raises
    ------
    TwinInputError
        One line naming the option and the value.
    """
    check_distinct("--axes", [str(a) for a in axes], "drift axis")
    check_distinct("--model", [str(m) for m in models], "model")
    for model in models:
        make_estimator(model)           # an unknown name: the registry's one-line error listing the models
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise TwinInputError(f"--k must be a whole number of inputs, at least 1, got {k!r}")
    if physics_backend not in ("fe", "rom"):
        raise TwinInputError(f"--physics must be fe or rom, got {physics_backend!r}")


def study_machine(spec: MachineSpec, axes: Sequence[str], k: int, inputs: Sequence[str] | None) -> None:
    """Build the study's machine and refuse ``axes`` and ``k`` it cannot serve, before any simulation.

    Building is cheap from the mesh and operator caches, and the simulations build it anyway (once per process).

    Parameters
    ----------
    spec : MachineSpec
        The nominal machine.
    axes : sequence of str
        Drift axes: each must be a displacement channel of the machine (X, Y, Z, Y_top).
    k : int
        Inputs to choose when ``inputs`` is None: at most the machine's installed thermometers.
    inputs : sequence of str or None
        Fixed inputs (``k`` is then unused): each must be a channel of the machine's records.

    Raises
    ------
    TwinInputError
        An axis that is not a drift axis, ``k`` above the number of installed thermometers (both numbers named),
        or an input that is not a channel of the records (the channels listed).
    """
    machine = spec.build()
    # camera spots too: some of the studies' scenarios record them
    channels = record_channel_names(machine, camera=True)
    unknown = [name for name in inputs or () if name not in channels]
    if unknown:
        raise TwinInputError(f"--inputs {','.join(inputs)}: {unknown[0]!r} is not a channel of {machine.name!r}'s "
                             f"records; channels: {name_listing(channels)}")
    drift = [c.name for c in machine.channels if c.kind == "displacement"]
    bad = [a for a in axes if a not in drift]
    if bad:
        raise TwinInputError(f"--axes {','.join(axes)}: {bad[0]!r} is not a drift axis of {machine.name!r}; "
                             f"drift axes: {','.join(drift)}")
    # the candidates of select_inputs: the records' thermometers, which are the machine's (air sensors are not)
    installed = sum(c.kind == "temperature" for c in machine.channels)
    if not inputs and k > installed:
        raise TwinInputError(f"--k {k} exceeds the {installed} installed thermometers of {machine.name!r} "
                             "(the candidate inputs)")


def _chosen_inputs(datasets, axis, k, select_method, where, log):
    """``select_inputs``, with a note when fewer than ``k`` candidates move in ``datasets`` (fewer are chosen)."""
    ins = select_inputs(datasets, axis, k, select_method)
    if log and len(ins) < k:
        log(f"{axis}: only {len(ins)} thermometers move {where}: {len(ins)} inputs chosen, not {k}")
    return ins


# ----------------------------------------------------------------------------- cross-condition
def _family_scenarios(families, log):
    """Family → its first available scenario; families without one are left out (noted)."""
    chosen = {}
    for fam, names in families.items():
        avail = _available(names)
        if avail:
            chosen[fam] = avail[0]
        elif log:
            log(f"family {fam!r}: none of {list(names)} is available, left out")
    if len(chosen) < 2:
        raise TwinInputError(f"the cross-condition study needs ≥ 2 families with an available scenario; "
                             f"have {chosen}")
    return chosen


def _transfer(data, axis, model, inputs, k, select_method, params, log):
    """Rows of one axis's transfer matrix, the matrix (improvement %) and the inputs per training family."""
    M = np.full((len(data), len(data)), np.nan)
    rows, used = [], {}
    for i, (train_fam, train_ds) in enumerate(data.items()):
        ins = list(inputs) if inputs else _chosen_inputs([train_ds], axis, k, select_method, f"on {train_fam}", log)
        used[(train_fam, axis)] = ins
        cm = fit_compensation_model([with_rest_start(train_ds, [*ins, axis])], ins, axis, model, params)
        for j, (test_fam, test_ds) in enumerate(data.items()):
            test_ds = with_rest_start(test_ds, [*ins, axis])
            s = score(cm.target_values(test_ds), cm.predict(test_ds))
            M[i, j] = s["improvement_percent"]
            rows.append({"axis": axis, "train": train_fam, "test": test_fam, "rmse": s["rmse"],
                         "max_residual": s["max_residual"], "improvement_percent": s["improvement_percent"],
                         "uncompensated_max": s["uncompensated_max"], "inputs": " ".join(ins)})
    return rows, M, used


def cross_condition_study(families: dict | None = None, axes: tuple = ("Z", "Y"), model: str = "mlr",
                          inputs: list[str] | None = None, k: int = 4, select_method: str = "gm-influence+fcm",
                          machine: str = "vmc_ram", mesh_size_m: float | None = None,
                          scheduler: str | object = "local", out_dir: Path | str | None = None,
                          params: dict | None = None, progress: Callable[[int, int], None] | None = None,
                          log: Callable[[str], object] | None = print, overwrite: bool = False) -> StudyResult:
    """Train on one scenario family, test on the others; the transfer matrix per axis.

    Parameters
    ----------
    families : dict, optional
        Family → scenario names (the first available one is used); default :data:`FAMILIES`.
    axes, model, params
        Drift axes, the model name and its hyperparameters.
    inputs : list of str, optional
        Fixed input channels, or None to choose ``k`` of the installed thermometers on each training
        family with ``select_method`` (as a user would on their one training condition).
    machine, mesh_size_m
        The machine (name or TOML path) and its element size, m (default: the machine's).
    scheduler : str or distributed.Client, default "local"
        Where the simulations run (see :func:`twin.infra.sweep.run_tasks`).
    progress : callable, optional
        ``progress(done, total)`` of the simulations.
    log : callable or None, default print
        Receives notes (scenarios left out); None is silent.
    out_dir, overwrite
        The report folder, checked before the work (see :func:`twin.infra.outdir.check_output_folder`).

    Returns
    -------
    StudyResult
        Cells are the held-out max |residual| (µm), RMSE (µm) and improvement %; the diagonal is the
        training fit.

    Raises
    ------
    TwinInputError
        Fewer than 2 families with an available scenario, an unusable ``out_dir``, or before any simulation an
        option :func:`check_study_options` or :func:`study_machine` refuses.
    """
    check_output_folder(out_dir, overwrite, inputs=(machine,))
    check_study_options(axes, (model,), k)
    chosen = _family_scenarios(dict(families or FAMILIES), log)
    spec = MachineSpec(machine, mesh_size_m)
    study_machine(spec, axes, k, inputs)
    data = dict(zip(chosen, simulate_many(list(chosen.values()), spec, scheduler, progress=progress)))
    rows, matrices, used_inputs = [], {}, {}
    for axis in axes:
        axis_rows, matrices[axis], used = _transfer(data, axis, model, inputs, k, select_method, params, log)
        rows += axis_rows
        used_inputs.update(used)
    md = cross_condition_markdown(rows, matrices, chosen, used_inputs, axes, model, inputs, k, select_method)
    result = StudyResult("cross-condition", None, {"transfer": rows}, md,
                         {"families": chosen, "matrices": {a: m.tolist() for a, m in matrices.items()}})
    if out_dir is not None:
        write_study(result, out_dir, overwrite,
                    lambda tmp: plot_transfer(matrices, list(data), axes, tmp / "transfer_matrix.png", model))
    return result


# ----------------------------------------------------------------------------- thesis protocol
def thesis_protocol_study(axes: tuple = ("Z", "Y"), models: tuple = ("anfis", "mlr"), inputs: list[str] | None = None,
                          k: int = 4, select_method: str = "gm-influence+fcm", machine: str = "vmc_ram",
                          mesh_size_m: float | None = None, scheduler: str | object = "local",
                          out_dir: Path | str | None = None, progress: Callable[[int, int], None] | None = None,
                          log: Callable[[str], object] | None = print, overwrite: bool = False) -> StudyResult:
    """Train on Test IV, test on Tests I, II, III, V, VI (thesis §5): a table per axis and model (µm).

    ``inputs``: fixed input channels, or None to choose ``k`` installed thermometers on Test IV with
    ``select_method``.  ``out_dir`` is checked before the work (``overwrite``: see
    :func:`twin.infra.outdir.check_output_folder`).

    Parameters
    ----------
    axes : tuple of str, default ("Z", "Y")
        Drift axes (µm).
    models : tuple of str, default ("anfis", "mlr")
        Model names.
    inputs : list of str, optional
        Fixed input channels.
    k, select_method
        How many inputs are chosen, and by which method, when ``inputs`` is None.
    machine, mesh_size_m
        The machine (name or TOML path) and its element size, m (default: the machine's).
    scheduler : str or distributed.Client, default "local"
        Where the simulations run (see :func:`twin.infra.sweep.run_tasks`).
    progress : callable, optional
        ``progress(done, total)`` of the simulations.
    log : callable or None, default print
        Receives notes (scenarios left out); None is silent.
    out_dir : Path or str, optional
        Report folder (Markdown, JSON, plots), written atomically.
    overwrite : bool, default False
        See :func:`twin.infra.outdir.check_output_folder`.

    Returns
    -------
    StudyResult
        Rows per axis, model and record: RMSE and max |residual| (µm), NSE, improvement %.

    Raises
    ------
    TwinInputError
        Test IV or all the other tests unavailable, an unusable ``out_dir``, or before any simulation an option
        :func:`check_study_options` or :func:`study_machine` refuses.
    """
    check_output_folder(out_dir, overwrite, inputs=(machine,))
    check_study_options(axes, models, k)
    tests = _available(THESIS_TEST)
    if not _available([THESIS_TRAIN]) or not tests:
        raise TwinInputError(f"the thesis protocol needs {THESIS_TRAIN} and some of {list(THESIS_TEST)}")
    if log and len(tests) < len(THESIS_TEST):
        log(f"missing thesis tests left out: {sorted(set(THESIS_TEST) - set(tests))}")
    spec = MachineSpec(machine, mesh_size_m)
    study_machine(spec, axes, k, inputs)
    sims = simulate_many([THESIS_TRAIN] + tests, spec, scheduler, progress=progress)
    train_ds, test_ds = sims[0], sims[1:]
    rows, plots = [], {}
    for axis in axes:
        ins = list(inputs) if inputs else _chosen_inputs([train_ds], axis, k, select_method, "on Test IV", log)
        started = [with_rest_start(ds, [*ins, axis]) for ds in [train_ds, *test_ds]]
        for model in models:
            cm = fit_compensation_model(started[:1], ins, axis, model)
            for ds in started:
                y, p = cm.target_values(ds), cm.predict(ds)
                s = score(y, p)
                rows.append({"axis": axis, "model": model, "dataset": dataset_label(ds),
                             "role": "training" if ds is started[0] else "test", "rmse": s["rmse"], "nse": s["nse"],
                             "max_residual": s["max_residual"], "improvement_percent": s["improvement_percent"],
                             "uncompensated_max": s["uncompensated_max"], "inputs": " ".join(ins)})
                plots[(axis, model, dataset_label(ds))] = (ds.time_s, y, p)
    result = StudyResult("thesis-protocol", None, {"thesis_protocol": rows},
                         thesis_markdown(rows, axes, models, inputs, k, select_method))
    if out_dir is not None:
        write_study(result, out_dir, overwrite, lambda tmp: plot_thesis(plots, tmp))
    return result


# ----------------------------------------------------------------------------- hybrid
def _hybrid_rows(measured, physics, tr, axis, model, ins):
    """Per-record scores of physics, data-driven and hybrid on one axis, and the curves (µm) for the plots."""
    changing = [name for name in ins if any(with_rest_start(ds, [name]) is not ds for ds in measured)]
    if changing:
        raise TwinInputError(f"--inputs: the hybrid study's records start their duty cycle at t = 0, so "
                             f"{changing[0]!r} changes at their start, where the twin's drift is referenced; "
                             "give thermometers")
    data_model = fit_compensation_model([measured[i] for i in tr], ins, axis, model)
    # residual datasets: the target replaced by measured − physics (both zero-referenced)
    resid = [_with_residual(ds, axis, phys[axis]) for ds, phys in zip(measured, physics)]
    hybrid_model = fit_compensation_model([resid[i] for i in tr], ins, f"{axis}_residual", model)
    rows, curves = [], {}
    for i, ds in enumerate(measured):
        y = ds[axis] - ds[axis][0]
        p_phys = physics[i][axis] - physics[i][axis][0]
        p_data = data_model.predict(ds)
        p_hyb = p_phys + hybrid_model.predict(resid[i])
        for name, p in (("physics (nominal twin)", p_phys), (f"data-driven ({model})", p_data),
                        (f"hybrid (twin + {model} residual)", p_hyb)):
            s = score(y, p)
            rows.append({"axis": axis, "approach": name, "dataset": dataset_label(ds),
                         "role": "training" if i in tr else "held-out", "rmse": s["rmse"],
                         "max_residual": s["max_residual"], "improvement_percent": s["improvement_percent"],
                         "uncompensated_max": s["uncompensated_max"]})
        curves[(axis, dataset_label(ds))] = (ds.time_s, y, p_phys, p_data, p_hyb)
    return rows, curves


def _pooled(rows, curves, axes):
    """Scores of every approach pooled over the held-out records, per axis (µm)."""
    pooled = []
    for axis in axes:
        for approach in dict.fromkeys(r["approach"] for r in rows if r["axis"] == axis):
            sub = [r for r in rows if r["axis"] == axis and r["approach"] == approach and r["role"] == "held-out"]
            ys = np.concatenate([curves[(axis, r["dataset"])][1] for r in sub])
            k_ = {"physics": 2, "data-driven": 3, "hybrid": 4}[approach.split(" ")[0]]
            ps = np.concatenate([curves[(axis, r["dataset"])][k_] for r in sub])
            s = score(ys, ps)
            pooled.append({"axis": axis, "approach": approach, "rmse": s["rmse"], "max_residual": s["max_residual"],
                           "improvement_percent": s["improvement_percent"], "uncompensated_max": s["uncompensated_max"]})
    return pooled


def hybrid_study(train: tuple = HYBRID_TRAIN, test: tuple = HYBRID_TEST, axes: tuple = ("Z", "Y"),
                 model: str = "anfis", inputs: list[str] | None = None, k: int = 4,
                 select_method: str = "gm-influence+fcm", gap: dict | None = None, machine: str = "vmc_ram",
                 mesh_size_m: float | None = None, physics_backend: str = "fe", scheduler: str | object = "local",
                 out_dir: Path | str | None = None, progress: Callable[[int, int], None] | None = None,
                 log: Callable[[str], object] | None = print, overwrite: bool = False) -> StudyResult:
    """Pure physics vs pure data-driven vs hybrid (physics + learned residual) on held-out records.

    "Measured" records: the twin with ``gap`` (default :data:`DEFAULT_GAP`:
    bearing and drive powers ±20–30 %, convection −20 %) and instrument noise.
    Physics: the nominal twin driven by the records' spindle speed, feeds and
    ambient (:func:`twin.compensation.train.physics_prediction`), started at rest.
    Data-driven: ``model`` on ``k`` thermometers (chosen on the training records).
    Hybrid: the same ``model`` and inputs fitted to the physics residual
    (measured − physics change); prediction = physics + learned residual.
    Scores are in µm.

    Parameters
    ----------
    train, test : tuple of str
        Training and held-out scenarios (names or TOML paths; unavailable ones are left out).
    axes : tuple of str, default ("Z", "Y")
        Drift axes (µm).
    model : str, default "anfis"
        Model name of the data-driven and the residual model.
    inputs : list of str, optional
        Fixed input channels.
    k, select_method
        How many inputs are chosen, and by which method, when ``inputs`` is None.
    gap : dict, optional
        ``source_scale`` ((source, factor) pairs or one factor) and ``convection_scale`` of the "real" machine.
    machine, mesh_size_m
        The machine (name or TOML path) and its element size, m (default: the machine's).
    scheduler : str or distributed.Client, default "local"
        Where the simulations run (see :func:`twin.infra.sweep.run_tasks`).
    progress : callable, optional
        ``progress(done, total)`` of the simulations.
    log : callable or None, default print
        Receives a note when fewer than ``k`` thermometers move on the training records (unavailable
        scenarios are left out silently).
    physics_backend : {"fe", "rom"}, default "fe"
        See :func:`twin.compensation.train.physics_prediction`.
    out_dir : Path or str, optional
        Report folder (Markdown, JSON, plot), written atomically.
    overwrite : bool, default False
        See :func:`twin.infra.outdir.check_output_folder`.

    Returns
    -------
    StudyResult
        Per-record and pooled held-out rows per approach: RMSE and max |residual| (µm), improvement %.

    Raises
    ------
    TwinInputError
        No training or no held-out scenario available, an unusable ``out_dir``, or before any simulation an
        option :func:`check_study_options` or :func:`study_machine` refuses.
    """
    check_output_folder(out_dir, overwrite, inputs=(machine,))
    check_study_options(axes, (model,), k, physics_backend)
    study_machine(MachineSpec(machine, mesh_size_m), axes, k, inputs)
    gap = dict(DEFAULT_GAP if gap is None else gap)
    t0 = time.perf_counter()
    measured, physics, train, test = hybrid_records(train, test, axes, gap, machine, mesh_size_m, physics_backend,
                                                    scheduler, progress)
    sim_s = time.perf_counter() - t0
    tr, te = list(range(len(train))), list(range(len(train), len(measured)))
    used = {axis: list(inputs) if inputs else _chosen_inputs([measured[i] for i in tr], axis, k, select_method,
                                                             "on the training records", log)
            for axis in axes}
    rows, curves, pooled = hybrid_scores(measured, physics, len(train), axes, model, used)
    md = hybrid_markdown(rows, pooled, gap, train, test, used, model, k, select_method, physics_backend)
    result = StudyResult("hybrid", None, {"hybrid": rows, "hybrid_pooled": pooled}, md,
                         {"gap": gap, "train": train, "test": test, "inputs": used, "simulation_s": sim_s})
    if out_dir is not None:
        write_study(result, out_dir, overwrite,
                    lambda tmp: plot_hybrid(curves, te_labels=[dataset_label(measured[i]) for i in te], axes=axes,
                                            path=tmp / "hybrid_heldout.png"))
    return result


def hybrid_records(train: tuple, test: tuple, axes: tuple, gap: dict, machine: str = "vmc_ram",
                   mesh_size_m: float | None = None, physics_backend: str = "fe",
                   scheduler: str | object = "local", progress: Callable[[int, int], None] | None = None
                   ) -> tuple[list[Dataset], list[dict], list[str], list[str]]:
    """The hybrid study's simulations: "measured" records of the machine with ``gap``, and the nominal twin's
    prediction of each.

    Parameters
    ----------
    train, test, axes, machine, mesh_size_m, physics_backend, scheduler, progress
        See :func:`hybrid_study`.
    gap : dict
        ``source_scale`` and ``convection_scale`` of the "real" machine (see :data:`DEFAULT_GAP`).

    Returns
    -------
    measured : list of Dataset
        The training records, then the held-out ones (instrument noise included).
    physics : list of dict
        Per record, axis → the nominal twin's drift, µm.
    train, test : list of str
        The scenarios available here, in that order.

    Raises
    ------
    TwinInputError
        No training or no held-out scenario available.
    """
    train, test = _available(train), _available(test)
    if not train or not test:
        raise TwinInputError(f"the hybrid study needs training and held-out scenarios; have {train}, {test}")
    truth = MachineSpec(machine, mesh_size_m, gap.get("source_scale", 1.0), gap.get("convection_scale", 1.0))
    nominal = MachineSpec(machine, mesh_size_m)
    nominal.build()
    truth.build()
    measured = run_tasks([SimulateTask(truth, s) for s in list(train) + list(test)], scheduler=scheduler,
                         progress=progress)
    physics = run_tasks([PhysicsTask(nominal, ds, tuple(axes), physics_backend) for ds in measured],
                        scheduler=scheduler, progress=progress)
    return measured, physics, train, test


def hybrid_scores(measured: list[Dataset], physics: list[dict], n_train: int, axes: tuple, model: str,
                  inputs: dict[str, list[str]]) -> tuple[list[dict], dict, list[dict]]:
    """Fit the data-driven and the residual model on the first ``n_train`` records and score the three approaches.

    Parameters
    ----------
    measured, physics
        From :func:`hybrid_records`.
    n_train : int
        How many of the records (the first ones) are training records.
    axes : tuple of str
        Drift axes (µm).
    model : str
        Model name of the data-driven and the residual model.
    inputs : dict
        Axis → its input channels.

    Returns
    -------
    rows : list of dict
        Per record, axis and approach: RMSE and max |residual| (µm), improvement %.
    curves : dict
        (axis, record) → (time_s, measured, physics, data-driven, hybrid), µm.
    pooled : list of dict
        The same scores over the held-out records together.
    """
    tr = list(range(n_train))
    rows, curves = [], {}
    for axis in axes:
        axis_rows, axis_curves = _hybrid_rows(measured, physics, tr, axis, model, inputs[axis])
        rows += axis_rows
        curves.update(axis_curves)
    return rows, curves, _pooled(rows, curves, axes)


def _with_residual(ds, axis, physics_abs):
    r = (ds[axis] - ds[axis][0]) - (physics_abs - physics_abs[0])
    return Dataset(ds.time_s, np.column_stack([ds.values, r]),
                   ds.channels + [ChannelInfo(f"{axis}_residual", ds.info(axis).unit, "displacement")], ds.metadata)
