"""Training and evaluating thermal-error compensation models on datasets, and the twin as a predictor.

The functions behind ``twin train`` and ``twin evaluate`` (callable from Python):

- :func:`load_dataset`: a dataset by path (a twin dataset with its sidecar, or
  a measured CSV through :meth:`~twin.core.dataset.Dataset.from_measured_csv`) or by
  scenario name (simulated on the spot);
- :func:`train` fits a :class:`~twin.compensation.store.CompensationModel` and saves it;
- :func:`evaluate` scores a model on datasets — a table (RMSE, NSE, R, max
  residual, improvement %) and a measured-vs-predicted PNG per dataset;
- :func:`physics_prediction`: the twin's own prediction of drift channels
  from a record's operating conditions (spindle speed, feeds, ambient),
  through the full FE model or the ROM — the physics half of the hybrid model.

Every metric is on the zero-referenced target (the change since the start of
the record, see :mod:`twin.compensation.store`); "uncompensated" is that change
itself, so improvement % = (1 − max|residual| / max|change|) × 100.
"""
from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

import fea
from models import metrics
from models.registry import model_traits
from models.speed import STANDSTILL_RPM, running

from ..core.clock import on_one_clock, stamp
from ..core.dataset import Dataset, finite_or_none, name_listing, sidecar_path
from ..core.machine import build_machine
from ..core.machine_definition import MachineDefinition, load_machine
from ..core.scenario import available_scenarios
from ..core.simulate import simulate
from ..errors import TwinInputError
from ..infra.cli_common import split_names
from ..infra.outdir import atomic_directory, check_output_file, check_output_folder
from ..infra.tables import markdown_table
from ..rom.reduction import cached_rom
from .protocol import (
    AUTO_CANDIDATES,
    auto_select,
    continued_prediction,
    identification_problem,
    stability_problem,
)
from .records import (
    dataset_label,
    distinct,
    distinct_labels,
    joined_when_contiguous,
    note_long_steps,
    note_unit_suspects,
    with_rest_start,
)
from .store import CompensationModel, fit_compensation_model, make_estimator

if TYPE_CHECKING:
    from ..core.machine import Machine

METRIC_COLUMNS = ("rmse", "nse", "r", "max_residual", "improvement_percent", "uncompensated_max", "rows")
#: ``twin evaluate`` warns of a record whose spindle runs faster than this factor times the top running speed of
#: the training records: a model there extrapolates. Up to it the grey-box heat (P ∝ n^b) is at most 2^b times the
#: largest trained and an error δb of the fitted b an error 2^δb − 1 in it (23 % for δb = 0.3), growing without
#: bound beyond; a speed logged in another unit (Hz under an rpm column: 60×) lands far past it
SPEED_EXTRAPOLATION = 2.0

log = logging.getLogger("thermal_twin")


# ----------------------------------------------------------------------------- datasets
def load_dataset(spec: Dataset | Path | str, column_map: dict[str, str] | None = None,
                 nan_policy: Literal["error", "interpolate", "drop", "keep"] = "error",
                 machine: Machine | MachineDefinition | str | Path | None = None, noise: bool = True,
                 label: str | None = None, channels: Sequence[str] | None = None, rest_start: bool = True,
                 reference_samples: int = 1) -> Dataset:
    """A :class:`Dataset` from a path or a scenario name.

    ``spec`` may be a :class:`Dataset` (returned as is), a CSV path (read with
    its JSON sidecar if there is one, else imported as measured data with
    ``column_map`` and ``nan_policy``; a column mapped to ``"time_s"`` is the
    time in s; a spindle or feed column that reads like another unit for ``machine`` is warned about,
    :func:`~twin.compensation.records.note_unit_suspects`), or the name of a scenario, which is
    simulated on ``machine`` (default: the scenario's) with its sensor noise.
    A twin record whose duty cycle changes ``channels`` at its start gets the
    state it started from as a first row (:func:`~twin.compensation.records.with_rest_start`),
    unless ``rest_start`` is false (a model file written before rest starts).

    Parameters
    ----------
    spec : Dataset, Path or str
        The dataset, a CSV path or a scenario name.
    column_map : dict of str to str, optional
        Measured CSV column → ``<name>_<unit>`` (or ``time_s``); given, a sidecar is ignored.
    nan_policy : {"error", "interpolate", "drop", "keep"}, default "error"
        NaNs in a measured CSV ("keep" leaves them to the caller).
    machine : Machine, MachineDefinition, str or Path, optional
        The machine of the records, built, read, or a name or TOML path (read without a mesh): its top spindle
        speed (rpm) and feed (mm/min) judge a measured CSV's columns (default: a typical machining centre's,
        :data:`~twin.core.unit_hints.TYPICAL_TOP`), and a scenario runs on it, built when it is not (default: the
        scenario's machine).
    noise : bool, default True
        Add the scenario's sensor noise (seeded).
    label : str, optional
        Stored as ``metadata["label"]``, the name the dataset goes by in tables.
    channels : sequence of str, optional
        The channels a model reads: ``nan_policy`` is about them (default every channel of a measured CSV).
    rest_start : bool, default True
        Add a twin record's rest state as a first row (:func:`~twin.compensation.records.with_rest_start`).
    reference_samples : int, default 1
        Rows the model's zero reference averages (more than one is refused when a rest row is added).

    Returns
    -------
    Dataset
        Channels in edge units (°C, µm, µε, rpm, mm/min, W).

    Raises
    ------
    TwinInputError
        Neither a file nor a known scenario, or a bad CSV (file, field, value).
    """
    if isinstance(spec, Dataset):
        return with_rest_start(spec, channels, reference_samples) if rest_start else spec
    if isinstance(machine, (str, Path)):
        machine = load_machine(machine)
    if _is_scenario(spec):
        ds = _simulated(str(spec), machine, noise)
    else:
        ds = _read_file(Path(str(spec)), column_map, nan_policy, channels, machine)
    if label:
        ds.metadata["label"] = label
    return with_rest_start(ds, channels, reference_samples) if rest_start else ds


def _is_scenario(spec: Dataset | Path | str) -> bool:
    """Whether :func:`load_dataset` runs ``spec`` as a shipped scenario: a name of one that is not a file (a file
    of that name is read)."""
    return not isinstance(spec, Dataset) and not Path(str(spec)).exists() and str(spec) in available_scenarios()


def _read_file(path, column_map, nan_policy, channels, machine):
    """The dataset of a CSV ``path`` (:func:`load_dataset`'s arguments), or a refusal of a name that is neither a
    file nor a scenario."""
    if not path.exists():
        raise TwinInputError(f"{str(path)!r} is neither a dataset file nor a scenario; scenarios: "
                             f"{available_scenarios()}")
    if sidecar_path(path).exists() and column_map is None:
        return Dataset.read(path)
    column_map = dict(column_map or {})
    time_cols = [k for k, v in column_map.items() if v == "time_s"]
    for k in time_cols:
        del column_map[k]
    ds = Dataset.from_measured_csv(path, column_map=column_map, nan_policy=nan_policy,
                                   time_column=time_cols[0] if time_cols else "time_s", nan_channels=channels)
    note_unit_suspects(ds, machine)     # a spindle in krpm trains a model that misreads rpm
    return ds


def _load_all(specs, column_map, nan_policy, machine, **options):
    """:func:`load_dataset` of each of ``specs``, in their order, with ``machine`` read once (a name or TOML path):
    the files first, so that a malformed CSV is refused before a machine is built (minutes on a cold cache), then
    the scenarios, on the machine built once for them all (:func:`_simulated` builds a definition per scenario: a
    mesh, thermal system and output operator per dataset)."""
    if isinstance(machine, (str, Path)):
        machine = load_machine(machine)
    scenario = [_is_scenario(s) for s in specs]
    loaded = {k: load_dataset(s, column_map, nan_policy, machine, **options)
              for k, s in enumerate(specs) if not scenario[k]}
    if any(scenario) and isinstance(machine, MachineDefinition):
        machine = build_machine(definition=machine)
    loaded.update({k: load_dataset(s, column_map, nan_policy, machine, **options)
                   for k, s in enumerate(specs) if scenario[k]})
    return [loaded[k] for k in range(len(specs))]


def _simulated(scenario, machine, noise):
    """The dataset of a shipped ``scenario`` run on ``machine`` (a definition is built; None: the scenario's own),
    with its sensor noise if ``noise``."""
    built = build_machine(definition=machine) if isinstance(machine, MachineDefinition) else machine
    return simulate(scenario, built, noise=noise).dataset


def _input_files(specs):
    """The files among dataset/model specs (paths, not objects or scenario names), with their sidecars."""
    paths = [Path(s) for s in specs if isinstance(s, (str, Path)) and Path(s).is_file()]
    return paths + [sidecar_path(p) for p in paths]


# ----------------------------------------------------------------------------- metrics
def score(y_true: ArrayLike, y_pred: ArrayLike) -> dict[str, float | int]:
    """Metrics of a prediction of the (zero-referenced) target: dict of :data:`METRIC_COLUMNS`.

    NSE and R are NaN for a constant target (R also for a constant prediction), the improvement for a
    target that never moves.

    Parameters
    ----------
    y_true : array_like, shape (n,)
        Measured change of the target (e.g. µm).
    y_pred : array_like, shape (n,)
        Predicted change, same unit.

    Returns
    -------
    dict
        ``rmse``, ``max_residual``, ``uncompensated_max``, ``uncompensated_rmse`` (unit of y), ``nse``,
        ``r`` (dimensionless), ``improvement_percent`` (%) and ``rows``.
    """
    y_true, y_pred = np.asarray(y_true, float), np.asarray(y_pred, float)
    peak = float(np.max(np.abs(y_true)))
    out = {"rmse": metrics.rmse(y_true, y_pred), "max_residual": metrics.max_abs_residual(y_true, y_pred),
           "uncompensated_max": peak, "uncompensated_rmse": float(np.sqrt(np.mean(y_true ** 2))),
           "rows": int(len(y_true))}
    spread_ok = np.ptp(y_true) > 0
    out["nse"] = metrics.nse(y_true, y_pred) if spread_ok else float("nan")
    out["r"] = metrics.pearson_r(y_true, y_pred) if spread_ok and np.ptp(y_pred) > 0 else float("nan")
    out["improvement_percent"] = metrics.improvement_percent(y_true, y_pred) if peak > 0 else float("nan")
    return out


def format_table(rows: Sequence[dict], columns: Sequence[str] | None = None, floatfmt: str = ".3g") -> str:
    """Markdown table of a list of dicts: ``columns`` (default: the first row's keys), floats as ``floatfmt``.

    Parameters
    ----------
    rows : sequence of dict
        One dict per table row; a missing key prints empty.
    columns : sequence of str, optional
        Keys shown, in order; also the headers.
    floatfmt : str, default ".3g"
        Format spec of non-integer numbers.

    Returns
    -------
    str
        The table, ending with a newline.
    """
    columns = columns or list(rows[0])
    return markdown_table([[r.get(c, "") for c in columns] for r in rows], columns, formats=floatfmt) + "\n"


# ----------------------------------------------------------------------------- train / evaluate
@dataclass
class Evaluation:
    """The result of :func:`evaluate`.

    Attributes
    ----------
    rows : list of dict
        One per dataset: ``dataset`` (its label) and the metrics of :func:`score`.
    out_dir : Path or None
        Where the table and plots were written.
    predictions : dict
        Label → (time_s, measured change, predicted change), arrays in s and the target's unit.
    """

    rows: list            # one dict per dataset
    out_dir: Path | None
    predictions: dict     # label → (time_s, measured change, predicted change)

    def table(self) -> str:
        """The metrics as a Markdown table, one row per dataset.

        Returns
        -------
        str
        """
        cols = ["dataset", "rows", "rmse", "nse", "r", "max_residual", "improvement_percent", "uncompensated_max"]
        return format_table(self.rows, cols)


def train(datasets: Sequence[Dataset | Path | str], inputs: str | list[str], target: str, model: str = "anfis",
          params: dict | None = None, out: Path | str | None = None, zero_reference: bool = True,
          reference_samples: int = 1, column_map: dict[str, str] | None = None,
          nan_policy: Literal["error", "interpolate", "drop", "keep"] = "error",
          machine: Machine | MachineDefinition | str | Path | None = None, overwrite: bool = False,
          select: str | None = None, allow_unstable: bool = False,
          observe: str | list[str] | None = None) -> CompensationModel:
    """Fit a compensation model on datasets (paths, scenario names or :class:`Dataset`) and save it to ``out``.

    ``out`` is checked before the work (:func:`twin.infra.outdir.check_output_file`): an existing
    file is replaced only with ``overwrite``, and never a dataset of the training.

    ``select="auto"`` chooses the model by blocked cross-validation across the
    record's operating regimes (:func:`~twin.compensation.protocol.auto_select`;
    the reason is in ``model.metadata["selection"]``). An unstable fit
    (:func:`~twin.compensation.protocol.stability_problem`), or a grey-box fit
    whose records do not determine its slowest pole
    (:func:`~twin.compensation.protocol.identification_problem`), is refused
    with a :class:`TwinInputError` unless ``allow_unstable`` (then it is saved
    and the problem kept in ``model.metadata["unstable"]``).

    Returns the :class:`CompensationModel`; its training metrics are in
    ``model.metadata["training_metrics"]``, and the top running speed of the
    training records per input in rpm (for :func:`evaluate`'s warning) in
    ``model.metadata["training_top_speed_rpm"]``. For a model that takes the
    spindle speed as measured (the grey-box model), a negative speed, and
    records in none of which the spindle runs (:func:`models.speed.running`),
    are refused.

    Parameters
    ----------
    datasets : sequence of Dataset, Path or str
        Training records (see :func:`load_dataset`), in any order: they are fitted in the canonical
        order of :mod:`twin.compensation.record_order` (by first time stamp, then by content; never by
        file name or path), so a permutation, a renamed or a moved file gives the same model. Records
        that continue one another (one starts one sampling interval after another ends) are one record
        (:func:`~twin.compensation.records.joined_when_contiguous`).
    inputs : str or list of str
        Input channels (comma-separated names allowed, as ``--inputs`` gives them).
    target : str
        Target channel (µm for a drift axis).
    model : str, default "anfis"
        Model name (see :mod:`models.registry`); ignored with ``select``.
    params : dict, optional
        Hyperparameters overriding the model's defaults.
    out : Path or str, optional
        Model file to write (JSON).
    zero_reference, reference_samples
        Reference inputs and target to the mean of their first ``reference_samples`` rows.
    column_map, nan_policy, machine
        See :func:`load_dataset`.
    overwrite : bool, default False
        Replace an existing ``out``.
    select : {"auto"}, optional
        Choose the model (and the grey-box order) by blocked cross-validation; ``params`` then override the
        chosen candidate's.
    allow_unstable : bool, default False
        Save an unstable or unidentified fit instead of refusing it.
    observe : str or list of str, optional
        Thermometers the model fuses while it runs (``--observe``; a model with an observer, the
        grey-box model): outputs of the model, corrected by their readings, not inputs. With
        ``nan_policy="keep"`` their missing readings are left out of the fit.

    Returns
    -------
    CompensationModel

    Raises
    ------
    TwinInputError
        Bad data, channels, model or parameters, an unusable ``out``, an unstable fit, or a grey-box model on
        records where the spindle never runs.
    """
    if out is not None:
        check_output_file(out, overwrite, inputs=_input_files(datasets))
    observe = split_names(observe)
    channels = [*split_names(inputs), *observe, target]
    records = on_one_clock(_load_all(datasets, column_map, nan_policy, machine, channels=channels,
                                     reference_samples=reference_samples))
    # in the canonical order (first time stamp, then content), never the order given: the fit depends on the order
    # of the rows it stacks, the model must not depend on that of the files (twin.compensation.record_order)
    loaded = joined_when_contiguous(records, channels)

    def fit(model_name, model_params):
        _check_speed_input(records, split_names(inputs), model_name)
        return fit_compensation_model(loaded, split_names(inputs), target, model_name, model_params,
                                      zero_reference, reference_samples, observe)

    if select is None:
        cm = fit(model, params)
        predictions, (kind, problem) = _predicted_and_checked(cm, loaded)
    else:
        if select != "auto":
            raise TwinInputError(f"--select {select!r}: the only selection rule is 'auto'")
        if observe:
            raise TwinInputError("--observe names thermometers for a model with an observer (--model greybox); "
                                 "--select auto ranks candidates on the same inputs, without one")
        _, _, selection = auto_select(loaded, split_names(inputs), target, zero_reference=zero_reference)
        cm, predictions, (kind, problem) = _first_sound_fit(selection, fit, loaded, params or {})
    cm.metadata["training_metrics"] = {label: score(cm.target_values(ds), predicted)
                                       for ds, label, predicted in zip(loaded, distinct_labels(loaded), predictions)}
    _keep_time_spans(cm, loaded)
    # `twin evaluate` warns of a record far faster than these (SPEED_EXTRAPOLATION)
    cm.metadata["training_top_speed_rpm"] = {name: max(_top_running_speed(ds[name]) for ds in loaded)
                                             for name in _speed_inputs(cm)}
    if problem is not None:
        if not allow_unstable:
            raise TwinInputError(f"{kind} MODEL REFUSED (not saved): {problem}; pass --allow-unstable to save it "
                                 "anyway")
        cm.metadata["unstable"] = f"{kind}: {problem}"
    if out is not None:
        cm.save(out)
    return cm


def _keep_time_spans(cm, loaded):
    """Keep each training record's first and last time (s) and its clock's date-time origin (None for a
    ``time_s`` clock) in the model file: ``twin evaluate --reference train`` refuses a record that starts
    inside the training record, as it continues it (:func:`_check_starts_after_training`)."""
    for entry, ds in zip(cm.training, loaded):      # the fit lists the records in the order it was given them
        entry["time_span_s"] = [_first_row_s(ds), float(ds.time_s[-1])]
        entry["time_origin"] = ds.metadata.get("import", {}).get("time_origin")


def _check_speed_input(datasets, inputs, model):
    """Refuse, for a model that takes the spindle speed as its first input (the grey-box model), a negative speed
    (:func:`_check_speed_sign`), or records in none of which the spindle runs (:func:`models.speed.running`): the
    heat of a spindle seen nowhere cannot be identified, and a gain fitted to the few rpm a tachometer reads at
    rest would scale any real speed by that noise."""
    first = model_traits(make_estimator(model)).first_input
    if first is None or not inputs or any(inputs[0] not in ds or ds.info(inputs[0]).unit != first[1]
                                          for ds in datasets):
        return   # fit_compensation_model names a missing speed channel or its wrong unit
    speed = inputs[0]
    for ds in datasets:
        _check_speed_sign(ds, speed)
    readings = np.concatenate([ds[speed] for ds in datasets])
    # one reading throughout (a speed of 0) is an input that never changes, which fit_compensation_model names
    if np.nanmax(readings) > np.nanmin(readings) and not any(running(ds[speed]).any() for ds in datasets):
        top = float(np.max(np.abs(readings), initial=0.0, where=np.isfinite(readings)))
        raise TwinInputError(f"{', '.join(dataset_label(ds) for ds in datasets)}: the spindle never runs ({speed} at "
                             f"most {top:g} rpm; it runs above {STANDSTILL_RPM:g} rpm), so {model} cannot identify "
                             "the heat of the spindle, and its gain would be fitted to the speed reading's noise at "
                             "rest: train on a record where the spindle runs")


def _check_speed_sign(dataset, speed):
    """Refuse a negative spindle speed, naming the file (or record), the column, the time and the value."""
    values = dataset[speed]
    negative = np.flatnonzero(values < 0)
    if negative.size:
        k = int(negative[0])
        row = k + ("rest_row_s" not in dataset.metadata)     # an added rest row is no row of the file
        raise TwinInputError(f"{dataset.metadata.get('source') or dataset_label(dataset)}: column "
                             f"{dataset.info(speed).column!r} is {values[k]:g} rpm at t = {dataset.time_s[k]:g} s "
                             f"(data row {row}); a spindle speed is >= 0 rpm, its magnitude whichever way the "
                             "spindle turns")


def _speed_inputs(cm):
    """The model's input channels in rpm: spindle speeds, whatever the model."""
    return [name for name, unit in zip(cm.inputs, cm.input_units) if unit == "rpm"]


def _top_running_speed(values):
    """The highest |speed| of the rows where the spindle runs (:func:`models.speed.running`), rpm; 0 if none."""
    speed = np.abs(np.asarray(values, float))
    return float(speed[running(speed)].max(initial=0.0))


def _predicted_and_checked(cm, datasets):
    """``(predictions of each training record, (kind, problem))``: the problem is None for a fit that is stable
    (:func:`~twin.compensation.protocol.stability_problem`) and determined by its records
    (:func:`~twin.compensation.protocol.identification_problem`)."""
    predictions = [cm.predict(ds) for ds in datasets]
    problem = stability_problem(cm, datasets, predictions)
    if problem is not None:
        return predictions, ("UNSTABLE", problem)
    return predictions, ("UNIDENTIFIED", identification_problem(cm, datasets))


def _first_sound_fit(selection, fit, datasets, params):
    """The selection's choice fitted on all the records; if that fit is refused, the next candidate in the
    ranking whose fit is not (the reason says so), else the choice with its problem.

    The folds score each candidate trained on part of the records; only the final fit shows whether all of
    them determine it (a third pole that settles on its bound there is no model to ship, however it scored).
    """
    order = [selection.chosen, *(c for c in selection.ranking if c != selection.chosen
                                 and np.isfinite(selection.score[c]))]
    tried = []
    for label in order:
        name, candidate_params = AUTO_CANDIDATES[label]
        cm = fit(name, {**candidate_params, **params})
        predictions, (kind, problem) = _predicted_and_checked(cm, datasets)
        tried.append((label, cm, predictions, (kind, problem)))
        if problem is None:
            break
    label, cm, predictions, (kind, problem) = tried[-1] if problem is None else tried[0]
    if len(tried) > 1 or problem is not None:
        first_kind, first_problem = tried[0][3]
        selection.reason += (f" Trained on all the records, {selection.chosen} is refused ({first_kind.lower()}: "
                             f"{first_problem.split(': ', 1)[-1]}); "
                             + (f"the next in rank that is not, {label}, is trained instead." if problem is None
                                else "so is every other candidate."))
    cm.metadata["selection"] = {"reason": selection.reason, "chosen": selection.chosen, "trained": label,
                                "ranking": selection.ranking, "geometric_mean_rmse": selection.score,
                                "mean_rmse": selection.mean_rmse, "folds": selection.folds,
                                "fold_rmse": selection.fold_rmse}
    return cm, predictions, (kind, problem)


def evaluate(model: CompensationModel | Path | str, datasets: Sequence[Dataset | Path | str],
             out_dir: Path | str | None = None, column_map: dict[str, str] | None = None,
             nan_policy: Literal["error", "interpolate", "drop", "keep"] = "error",
             machine: Machine | MachineDefinition | str | Path | None = None, plots: bool = True,
             overwrite: bool = False, reference: Literal["own", "train"] = "own",
             history: Dataset | Path | str | None = None, gap: Literal["refuse", "interpolate"] = "refuse"
             ) -> Evaluation:
    """Score a model (a :class:`CompensationModel` or a saved model path) on datasets.

    Writes (when ``out_dir`` is given) ``evaluation.md``, ``evaluation.csv``,
    ``evaluation.json`` and ``<dataset>_<target>.png`` (measured vs predicted
    change and the residual).  A dataset whose channels do not match the
    model's raises a :class:`TwinInputError` naming them, as does a record of
    fewer than 2 rows, or with a negative speed for a model that takes it as
    measured. A warning on the ``thermal_twin`` logger names a model saved
    with ``allow_unstable`` (and why its check refused it), and a record
    whose spindle runs over :data:`SPEED_EXTRAPOLATION` times the training
    records' top running speed (the model extrapolates).

    Each record is scored on its own (with ``reference="own"``), so its row does not depend on the other
    records or their order; the rows are in the order given, which is the time order of a
    ``reference="train"`` chain.

    ``reference="train"``: each dataset continues the training record (it may
    start warm), so it is referenced to the training start, and time-series
    models run over ``history`` (the training record) and then the dataset
    (:func:`~twin.compensation.protocol.continued_prediction`). A dataset that
    starts after the end of the one before it continues that one: the model
    runs over the history and every dataset before it.

    Parameters
    ----------
    model : CompensationModel, Path or str
        The model, or its file.
    datasets : sequence of Dataset, Path or str
        Records to score (see :func:`load_dataset`); a repeated label gets ``_2``, ``_3`` …
    out_dir : Path or str, optional
        Folder for the table and plots, written atomically; None writes nothing.
    column_map, nan_policy, machine
        See :func:`load_dataset`; ``nan_policy="keep"`` leaves missing readings in the thermometers the
        model observes, which its filter skips (anywhere else they are refused).
    plots : bool, default True
        Write the PNGs.
    overwrite : bool, default False
        See :func:`twin.infra.outdir.check_output_folder`.
    reference : {"own", "train"}, default "own"
        Zero reference of each record (above).
    history : Dataset, Path or str, optional
        The training record, for ``reference="train"``.
    gap : {"refuse", "interpolate"}, default "refuse"
        With ``reference="train"``, a record that starts more than one interval after ``history``
        ends is refused, or bridged (:func:`~twin.compensation.protocol.continuation_times`).

    Returns
    -------
    Evaluation
        The metric rows, the predictions and the folder.

    Raises
    ------
    TwinInputError
        Bad data or channels, a model that cannot predict a record, or an unusable ``out_dir``.
    """
    _check_reference(reference, history, gap)
    check_output_folder(out_dir, overwrite, inputs=_input_files([model, *datasets]))
    cm = model if isinstance(model, CompensationModel) else CompensationModel.load(model)
    _warn_unstable(cm, model)
    channels = [*cm.inputs, cm.target]   # the observed thermometers are among the inputs
    # a model file written before rest starts keeps the first row as its reference, as it was trained
    rest = {"rest_start": cm.preprocessing.get("rest_start", False),
            "reference_samples": cm.preprocessing.get("reference_samples", 1)}
    loaded = on_one_clock(_load_all([*datasets, *([] if history is None else [history])], column_map, nan_policy,
                                    machine, channels=channels, **rest))
    past = None if history is None else loaded.pop()
    for ds in loaded + ([past] if past is not None else []):
        _check_evaluated(cm, ds)
    rows, predictions = [], {}
    for ds, label in zip(loaded, distinct_labels(loaded)):
        _warn_faster_than_trained(cm, ds, label)
        if reference == "train" and not cm.is_time_series:   # a time-series model's clocks: continuation_times
            _check_starts_after_training(cm, ds, label, past)
        y, p, ran_over = _measured_and_predicted(cm, ds, label, reference, past, gap)
        rows.append({"dataset": label, **score(y, p)})
        predictions[label] = (ds.time_s, y, p)
        if ran_over is not None:   # a later record continues this one, as the model ran over it
            past = ran_over
    out_dir = Path(out_dir) if out_dir is not None else None
    result = Evaluation(rows, out_dir, predictions)
    if out_dir is not None:
        with atomic_directory(out_dir, overwrite) as tmp:
            _write_evaluation(cm, result, tmp, plots)
        result.out_dir = out_dir
    return result


def _warn_unstable(cm, model):
    """Warn (``thermal_twin`` logger) of a model saved despite its stability or identification check."""
    if "unstable" in cm.metadata:
        where = "the model" if isinstance(model, CompensationModel) else str(model)
        log.warning("%s: saved with --allow-unstable although its check refused it (%s): its scores show how far "
                    "off it is, it is no model to compensate with", where, cm.metadata["unstable"])


def _check_evaluated(cm, dataset):
    """Refuse a record the model cannot be scored on: its channels, missing readings, fewer than 2 rows (a
    change needs a start and a later row), or a negative speed of a model that takes it as measured."""
    cm.check(dataset)
    cm.check_readings(dataset)
    if len(dataset) < 2:
        raise TwinInputError(f"{dataset.metadata.get('source') or dataset_label(dataset)}: {len(dataset)} row; "
                             "a model is scored on the change of a record since its first row, so it needs at "
                             "least 2 rows")
    for speed in cm.preprocessing.get("absolute_inputs", []):
        _check_speed_sign(dataset, speed)


def _warn_faster_than_trained(cm, dataset, label):
    """Warn (``thermal_twin`` logger) where the record's spindle runs over :data:`SPEED_EXTRAPOLATION` times
    the top running speed of the training records, as the model file keeps it (a file written before it kept it
    is not checked)."""
    for name, trained in cm.metadata.get("training_top_speed_rpm", {}).items():
        top = _top_running_speed(dataset[name])
        if top > SPEED_EXTRAPOLATION * trained:
            log.warning("%s: %s runs up to %g rpm, over %g× the top speed of the training records (%g rpm): the "
                        "model extrapolates (a speed logged in another unit, Hz in an rpm column, is 60× off)",
                        label, name, top, SPEED_EXTRAPOLATION, trained)


def _check_reference(reference, history, gap):
    """Refuse an unknown ``reference`` or ``gap``, and a history or gap without ``reference="train"``."""
    if reference not in ("own", "train"):
        raise TwinInputError(f"--reference {reference!r}: choose 'own' (each record's start) or 'train'")
    if gap not in ("refuse", "interpolate"):
        raise TwinInputError(f"--gap {gap!r}: choose 'refuse' or 'interpolate'")
    if reference == "own" and (history is not None or gap != "refuse"):
        raise TwinInputError("--history and --gap describe a record that continues the training one; they need "
                             "--reference train (each record is referenced to its own start without it)")


def _check_starts_after_training(cm, ds, label, history):
    """Refuse, for ``--reference train``, a record that starts inside the time span of the training record it
    continues (``history``, else the model's first training record): its first rows were trained on, and the
    change since the training start across them is no continuation. A record whose clock restarts (it starts no
    later than the training record) is taken to follow it, as
    :func:`~twin.compensation.protocol.continuation_times` does."""
    source = ds.metadata.get("source") or label
    if history is not None:
        span, name = (_first_row_s(history), float(history.time_s[-1])), dataset_label(history)
    else:
        span, name = _training_span(cm, ds, source), (cm.training or [{}])[0].get("label", "?")
    start = _first_row_s(ds)
    if span is None or not span[0] < start <= span[1]:
        return
    origin = ds.metadata.get("import", {}).get("time_origin")
    # with several training records, the first is the one continued unless --history names another
    which = (" (the model's first training record; give the one it continues with --history)"
             if history is None and len(cm.training) > 1 else "")
    raise TwinInputError(f"{source}: {'its stamps' if origin else 'time_s'} run from "
                         f"{_span_text(origin, start, float(ds.time_s[-1]), ' to ')} and it starts inside the "
                         f"training record {name} ({_span_text(origin, *span, '–')}){which}, which --reference "
                         "train continues after it ends; give the rows after the training record's end, or "
                         "evaluate without --reference train")


def _first_row_s(dataset):
    """Time of a record's first row of its own, s: after the rest row a twin run's record gets one sampling
    interval before its start (:func:`~twin.compensation.records.with_rest_start`), which no clock read."""
    return float(dataset.time_s[1] if "rest_row_s" in dataset.metadata else dataset.time_s[0])


def _span_text(origin, first_s, last_s, between):
    """``first_s``…``last_s`` (s on a record's clock) as a message shows them: date-times from the clock's
    ``origin`` (:func:`~twin.core.clock.stamp`) for a stamped record, s for a ``time_s`` one."""
    if not origin:
        return f"{first_s:g}{between}{last_s:g} s"
    return f"{stamp(origin, first_s)}{between}{stamp(origin, last_s)}"


def _training_span(cm, ds, source):
    """The first training record's time span (s) on ``ds``'s clock; None when the model file keeps none or
    one clock has date-time stamps and the other ``time_s`` (no common clock to compare them on).

    Stamps with a UTC offset against stamps without one are refused, as :func:`~twin.core.clock.on_one_clock`
    refuses them among records read together: the check would need a guess of the offset, and skipping it
    would let a record that starts inside the training record through."""
    first = cm.training[0] if cm.training else {}
    if "time_span_s" not in first:
        return None                                   # a model file written before spans were kept
    origins = first.get("time_origin"), ds.metadata.get("import", {}).get("time_origin")
    if not origins[0] and not origins[1]:
        return tuple(first["time_span_s"])           # both on time_s
    if not origins[0] or not origins[1]:
        return None
    import pandas as pd

    trained, given = pd.Timestamp(origins[0]), pd.Timestamp(origins[1])
    if (trained.tzinfo is None) != (given.tzinfo is None):
        with_offset = "with" if given.tzinfo is not None else "without"
        raise TwinInputError(f"{source} has date-time stamps {with_offset} a UTC offset and the model's training "
                             f"record {first.get('label', '?')} was read from stamps "
                             f"{'without' if with_offset == 'with' else 'with'} one: they cannot be put on one "
                             "clock to check that it starts after the training record; give its stamps as the "
                             "training record's were")
    shift = (trained - given).total_seconds()
    return first["time_span_s"][0] + shift, first["time_span_s"][1] + shift


def _measured_and_predicted(cm, ds, label, reference, past, gap):
    """The record's measured and predicted change (see :func:`evaluate`); a model that cannot predict it is named."""
    try:
        if reference == "train":
            return continued_prediction(cm, ds, past, gap)
        if cm.preprocessing.get("time_column"):
            note_long_steps(ds)
        return cm.target_values(ds), cm.predict(ds), None
    except TwinInputError:
        raise
    except ValueError as exc:
        raise TwinInputError(f"{label}: {cm.model_name} cannot predict it: {exc}") from None


def _write_evaluation(cm, result, folder, plots):
    import pandas as pd

    from ..infra.plots import plot_measured_vs_predicted  # on use: it switches matplotlib to Agg

    head = (f"# Evaluation of {cm.describe()}\n\nTrained on: "
            f"{', '.join(t['label'] for t in cm.training) or '?'}. Metrics on the target's change since the "
            f"start of each dataset ({cm.target_unit}); improvement % = (1 − max|residual| / max|change|) × 100.\n\n")
    (folder / "evaluation.md").write_text(head + result.table(), encoding="utf-8")
    pd.DataFrame(result.rows).to_csv(folder / "evaluation.csv", index=False)
    (folder / "evaluation.json").write_text(json.dumps({"model": cm.to_document()["model_name"],
                                                        "inputs": cm.inputs, "target": cm.target,
                                                        "rows": finite_or_none(result.rows)}, indent=1))
    if plots:
        # file names of distinct labels may still meet ("run 1" and "run_1" are both "run_1")
        stems = distinct(["".join(c if c.isalnum() or c in "-_." else "_" for c in label)
                          for label in result.predictions])
        for (label, (t, y, p)), stem in zip(result.predictions.items(), stems):
            row = next(r for r in result.rows if r["dataset"] == label)
            title = (f"{cm.target} on {label}: {cm.model_name}, RMSE {row['rmse']:.2f}, "
                     f"max residual {row['max_residual']:.2f} {cm.target_unit}")
            plot_measured_vs_predicted(t, y, p, cm.target_unit, title, folder / f"{stem}_{cm.target}.png")


# ----------------------------------------------------------------------------- the twin as a predictor
class RecordSchedule:
    """Thermal inputs of a machine from a record's operating channels, interpolated in time.

    Channels used: ``spindle`` (rpm, required), ``feed_x/y/z`` (mm/min, 0
    when absent), ``ambient_<zone>`` per zone, else one ambient for all zones
    from the mean of the ``ambient``/``air`` channels, and ``ambient_gradient``
    (K/m, 0 when absent).

    Parameters
    ----------
    machine : Machine
        The machine whose thermal inputs are built.
    dataset : Dataset
        The record.

    Raises
    ------
    TwinInputError
        No ``spindle`` channel, or no ambient channel at all.
    """

    def __init__(self, machine: Machine, dataset: Dataset):
        self.machine = machine
        self.t = dataset.time_s
        if "spindle" not in dataset:
            raise TwinInputError(f"{dataset_label(dataset)}: the twin needs a 'spindle' channel (rpm); "
                                 f"channels: {name_listing(dataset.names)}")
        self.spindle = dataset["spindle"]
        self.feeds = {a: dataset[f"feed_{a}"] if f"feed_{a}" in dataset else np.zeros(len(dataset)) for a in "xyz"}
        zones = machine.zones
        if all(f"ambient_{z}" in dataset for z in zones):
            self.ambient = {z: dataset[f"ambient_{z}"] for z in zones}
        else:
            air = dataset.names_of_kind("ambient", "air")
            air = [n for n in air if dataset.info(n).unit == "degC"]
            if not air:
                raise TwinInputError(f"{dataset_label(dataset)}: the twin needs the ambient: channels "
                                     f"{[f'ambient_{z}' for z in zones]} or an air/ambient thermometer; "
                                     f"channels: {name_listing(dataset.names)}")
            mean = dataset.matrix(air).mean(axis=1)
            self.ambient = {z: mean for z in zones}
        self.gradient = dataset["ambient_gradient"] if "ambient_gradient" in dataset else np.zeros(len(dataset))

    def conditions(self, times_s: ArrayLike) -> tuple[NDArray[np.float64], dict[str, NDArray[np.float64]],
                                                      dict[str, NDArray[np.float64]], NDArray[np.float64]]:
        """The operating conditions at ``times_s``, linearly interpolated in the record.

        Parameters
        ----------
        times_s : array_like
            Times, s (clamped to the record's span).

        Returns
        -------
        rpm : ndarray
            Spindle speed, rpm.
        feeds : dict of str to ndarray
            Axis → feed, mm/min.
        ambient : dict of str to ndarray
            Zone → air temperature, °C.
        gradient : ndarray
            Vertical ambient gradient, K/m.
        """
        t = np.atleast_1d(np.asarray(times_s, float))
        rpm = np.interp(t, self.t, self.spindle)
        feeds = {a: np.interp(t, self.t, v) for a, v in self.feeds.items()}
        ambient = {z: np.interp(t, self.t, v) for z, v in self.ambient.items()}
        return rpm, feeds, ambient, np.interp(t, self.t, self.gradient)

    def sample(self, times_s: ArrayLike) -> NDArray[np.float64]:
        """Thermal inputs ``u`` of the machine at ``times_s`` (what :meth:`fea.ThermalSolver.run` samples).

        Parameters
        ----------
        times_s : array_like
            Times, s.

        Returns
        -------
        ndarray, shape (n_times, n_inputs)
            Columns as ``machine.thermal.input_names`` (°C, K/m, W).
        """
        rpm, feeds, ambient, gradient = self.conditions(times_s)
        return self.machine.input_matrix(rpm, feeds, ambient, gradient)

    def at_rest(self) -> NDArray[np.float64]:
        """Inputs at t₀ with spindle and feeds stopped: the machine in equilibrium with the room.

        Returns
        -------
        ndarray, shape (n_inputs,)
            Thermal inputs (°C, K/m, W).
        """
        rpm, feeds, ambient, gradient = self.conditions([self.t[0]])
        return self.machine.input_matrix(rpm * 0, {a: f * 0 for a, f in feeds.items()}, ambient, gradient)[0]


PHYSICS_BACKENDS = ("fe", "rom")


def physics_prediction(machine: Machine, dataset: Dataset, outputs: Sequence[str] = ("Z", "Y"),
                       backend: Literal["fe", "rom"] = "fe", max_step_s: float | None = None,
                       initial: Literal["rest"] | float = "rest") -> dict[str, NDArray[np.float64]]:
    """The twin's prediction of ``outputs`` (edge units, e.g. µm) from a record's operating conditions.

    Parameters
    ----------
    machine : the (nominal) :class:`~twin.core.machine.Machine`
    dataset : record with spindle speed, feeds and ambient channels (see :class:`RecordSchedule`)
    outputs : channel names of the machine to predict (drift X/Y/Z/Y_top, sensors …)
    backend : ``"fe"`` (full finite-element run, one factorisation reused for every step)
        or ``"rom"`` (the cached reduced model of :mod:`twin.rom.reduction`, when available)
    max_step_s : sub-step length (default: the record's sampling interval)
    initial : ``"rest"`` — steady state with spindle and feeds stopped at the first ambient
        (a record rarely knows more); or a uniform temperature in °C

    Returns
    -------
    dict of str to ndarray
        Name → (n,) array in edge units, absolute (not zero-referenced).
    """
    if backend not in PHYSICS_BACKENDS:
        raise TwinInputError(f"unknown physics backend {backend!r}; available: {PHYSICS_BACKENDS}")
    outputs = list(outputs)
    channels = [machine.channel(n) for n in outputs]
    fe_names = machine.outputs.names
    schedule = RecordSchedule(machine, dataset)
    times = dataset.time_s
    if backend == "rom":
        rom = cached_rom(machine)
        z0 = rom.steady_state(schedule.at_rest()) if initial == "rest" else rom.uniform(float(initial))
        U = schedule.sample(times)
        Y = rom.simulate(times, U, z0, scheme="theta")
        return {n: Y[:, rom.output_index(n)] for n in outputs}
    missing = [n for n in outputs if n not in fe_names]
    if missing:
        raise TwinInputError(f"physics outputs {missing} are not FE outputs of {machine.name!r}")
    operator = machine.outputs.subset(outputs)
    solver = fea.ThermalSolver(machine.thermal)
    T0 = solver.steady_state(schedule.at_rest()) if initial == "rest" else float(initial)
    run = solver.run(T0, times, schedule, operator, max_step_s=max_step_s)
    return {n: run.outputs[:, j] * c.scale for j, (n, c) in enumerate(zip(outputs, channels))}
