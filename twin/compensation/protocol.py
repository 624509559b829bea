"""Training discipline for compensation models: automatic selection, stability refusal, continuation.

- :func:`auto_select` (``twin train --select auto``): ranks candidate models by
  blocked cross-validation across the operating regimes of the training
  record (:mod:`models.selection_cv`: leave one speed block out and rolling
  origin, scored by the geometric mean of the folds' RMSE; the grey-box
  orders 1-3 are candidates of their own) and says why it chose what it chose;
- :func:`stability_problem` (``twin train`` refuses unless ``--allow-unstable``):
  a grey model with a negative development coefficient, or a prediction that
  diverges on its own training data;
- :func:`continued_prediction` (``twin evaluate --reference train``): a record that continues the training
  record (it starts warm) is referenced to the training start instead of its
  own (``fit_compensation_model`` keeps it in the model file), and
  time-series models run over the whole history.
"""
from __future__ import annotations

import logging
from bisect import bisect_right
from collections.abc import Iterable, Mapping, Sequence
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from models.registry import model_traits
from models.selection_cv import SCHEMES, Selection, blocked_folds, record_blocks, select_by_blocked_cv

from ..core.dataset import Dataset
from ..errors import TwinInputError
from .records import (
    bridge_times,
    check_complete,
    continued_record,
    dataset_label,
    distinct_labels,
    evenly_sampled,
    note_long_steps,
    repeats,
    sampling_interval,
    starts_running,
)
from .store import CompensationModel, check_channels, make_estimator

log = logging.getLogger("thermal_twin")

#: candidates of ``--select auto``, label → (model name, hyper-parameters): fast to fit, every family (static,
#: grey, grey-box).  The grey-box orders are candidates of their own: the order is what its extrapolation
#: depends on most (FL_THERMAL ch3, block 4: 1.6 µm with 2 poles, 28 µm with 3).
AUTO_CANDIDATES = {name: (name, {}) for name in ("mlr", "pcr", "anfis", "gm0n", "gm1n", "gmc")} | {
    f"greybox n_poles={order}": ("greybox", {"n_poles": order}) for order in (1, 2, 3)}
#: a training prediction this many times larger than the largest measured change has diverged
DIVERGENCE_FACTOR = 10.0


def _speed_channel(dataset, inputs):
    """The input channel in rpm (the spindle speed) that defines the operating regimes."""
    rpm = [n for n in inputs if dataset.info(n).unit == "rpm"]
    if not rpm:
        raise TwinInputError(f"{dataset_label(dataset)}: --select auto needs a spindle-speed input in rpm to find the "
                             f"operating regimes; the inputs are {inputs} "
                             f"({', '.join(dataset.info(n).unit for n in inputs)})")
    return rpm[0]


def auto_select(datasets: Iterable[Dataset], inputs: list[str], target: str,
                candidates: Mapping[str, tuple[str, dict]] = AUTO_CANDIDATES,
                zero_reference: bool = True) -> tuple[str, dict, Selection]:
    """The model and hyper-parameters chosen by blocked cross-validation on the training records, and the ranking.

    Each candidate's input contract (:class:`models.registry.ModelTraits`)
    decides whether it can take the record: one whose first input must be the
    spindle speed (the grey-box model) is left out when the first input is not
    in rpm; on an unevenly sampled record (jitter, missing rows) a model that
    takes the time runs on the record's own times, and one with coefficients
    per sample (GM, GMC) is left out. The reason ends by naming what was left
    out and why.

    Parameters
    ----------
    datasets : iterable of Dataset
        One training record, or several that each start at rest (test days apart), with a spindle-speed
        input (rpm). Each record has its regime blocks (:func:`models.selection_cv.record_blocks`), and the
        grey-box candidates run each from its own start; GM(0,N), GM(1,N) and GMC, which train on one
        record, are left out of several.
    inputs : list of str
        Input channels, the same for every candidate.
    target : str
        Target channel (µm for a drift axis).
    candidates : dict label → (model name, hyper-parameters), default :data:`AUTO_CANDIDATES`
        The candidates to rank.
    zero_reference : bool, default True
        Reference inputs and target to the first row.

    Returns
    -------
    model : str
        The chosen model name.
    params : dict
        Its hyper-parameters (those of the candidate; how it takes the time is set by the training).
    selection : Selection
        Scores per candidate and fold, the ranking and the reason.

    Raises
    ------
    TwinInputError
        No record, no rpm input, channels that differ between records, a missing reading, or fewer than
        two operating-regime blocks.
    """
    datasets = list(datasets)
    if not datasets:
        raise TwinInputError("--select auto: no training record given")
    speed_name = _speed_channel(datasets[0], inputs)
    units = [datasets[0].info(n).unit for n in inputs]
    X, y = [], []
    for ds in datasets:
        check_channels(ds, inputs, units)
        check_complete(ds, [*inputs, target])
        raw, target_values = ds.matrix(inputs), ds[target]
        seen, change = (raw - raw[:1], target_values - target_values[0]) if zero_reference else (raw, target_values)
        # [time since the record's start (s), the inputs as the models see them, the first input as measured]
        X.append(np.column_stack([ds.time_s - ds.time_s[0], seen, raw[:, 0]]))
        y.append(change)
    pool, left_out = _candidate_pool(datasets, inputs, candidates, zero_reference)
    record_starts = np.cumsum([len(ds) for ds in datasets])[:-1].tolist()
    try:
        speed = np.concatenate([ds[speed_name] for ds in datasets])
        selection = select_by_blocked_cv(pool, np.vstack(X), np.concatenate(y), speed,
                                         unit=datasets[0].info(target).unit, record_starts=record_starts)
    except ValueError as exc:     # the record's (one speed regime only); a candidate's failed fit is caught inside
        which = "this record" if len(datasets) == 1 else f"these {len(datasets)} records"
        raise TwinInputError(f"{', '.join(dataset_label(ds) for ds in datasets)}: --select auto cannot "
                             f"cross-validate on {which}: {exc}") from None
    if record_starts:
        selection.reason += (f" The {len(datasets)} records each start at rest and have blocks of their own; "
                             "none spans two.")
        selection.folds = _fold_names_with_records(datasets, speed, record_starts)
    if left_out:
        selection.reason += " Left out: " + "; ".join(f"{', '.join(labels)} ({why})"
                                                      for why, labels in left_out.items()) + "."
    model, params = candidates[selection.chosen]
    return model, dict(params), selection


def _fold_names_with_records(datasets, speed, record_starts):
    """The fold names of :func:`~models.selection_cv.select_by_blocked_cv` on several records, each followed by
    the record that holds its test block ("rolling-origin block 3 (day 2)"): the blocks are numbered across the
    records in their canonical order, which a reader cannot see."""
    folds = blocked_folds(record_blocks(speed, record_starts), SCHEMES, record_starts)
    labels = distinct_labels(datasets)
    return [f"{fold.name} ({labels[bisect_right(record_starts, fold.test[0])]})" for fold in folds]


def _candidate_pool(datasets, inputs, candidates, zero_reference):
    """``(pool, left_out)``: label → (estimator, its columns of ``auto_select``'s X) of the candidates that can
    take these records, and why → labels of those that cannot, by each class's input contract."""
    interval = _common_interval(datasets)   # None: a model that takes the time runs on the records' own times
    n = len(inputs)
    pool, left_out = {}, {}
    for label, (name, params) in candidates.items():
        estimator = make_estimator(name, params)
        traits = model_traits(estimator)
        why = _left_out_because(traits, datasets, inputs[0], zero_reference, interval)
        if why is not None:
            left_out.setdefault(why, []).append(label)
            continue
        columns = list(range(1, n + 1))
        if traits.first_input is not None:
            columns = [n + 1, *columns[1:]]   # the first input as measured
        if traits.takes_time:   # at the records' interval, or on their own times where uneven
            estimator.set_params(sampling_interval=interval)
            columns = columns if interval is not None else [0, *columns]
        pool[label] = (estimator, columns)
    return pool, left_out


def _common_interval(datasets):
    """The sampling interval (s) of records all evenly sampled at the same one, else None."""
    intervals = [sampling_interval(ds) if evenly_sampled(ds) else None for ds in datasets]
    first = intervals[0]
    same = first is not None and all(i is not None and abs(i - first) <= 1e-6 * first for i in intervals)
    return first if same else None


def _left_out_because(traits, datasets, first, zero_reference, interval):
    """Why a candidate of these input ``traits`` cannot take the records, or None."""
    if traits.first_input is not None:
        why = _first_input_problem(datasets, first, traits.first_input, zero_reference)
        if why is not None:
            return why
    if traits.takes_time or not traits.time_series:
        return None
    if len(datasets) > 1:
        return f"coefficients per sample train on one record; these are {len(datasets)}"
    if interval is None:
        steps = np.diff(datasets[0].time_s)
        return (f"coefficients per sample need even sampling; steps here range from {steps.min():.4g} to "
                f"{steps.max():.4g} s")
    return None


def _first_input_problem(datasets, first, required, zero_reference):
    """Why ``first`` cannot be a model's declared first input ``required = (what, unit)``, or None."""
    what, unit = required
    if datasets[0].info(first).unit != unit:
        return f"the first input must be the {what} in {unit}"
    warm = [dataset_label(ds) for ds in datasets if zero_reference and starts_running(ds, first)]
    if warm:
        which = "the record starts" if len(datasets) == 1 else f"{', '.join(warm)} start(s)"
        return f"{which} with the spindle running, and they take its first row as rest"
    return None


def stability_problem(cm: CompensationModel, datasets: Sequence[Dataset],
                      predictions: Sequence[np.ndarray] | None = None) -> str | None:
    """Why the fitted model is unstable, or None: a < 0, or a diverging prediction on the training data.

    Parameters
    ----------
    cm : CompensationModel
        The fitted model.
    datasets : sequence of Dataset
        Its training records.
    predictions : sequence of ndarray, optional
        ``cm.predict`` of each record, where the caller has made them already (a grey-box observer runs a
        Kalman filter over every row).

    Returns
    -------
    str or None
        The reason, or None for a stable model.
    """
    a = getattr(cm.estimator, "development_coefficient_", None)
    if a is not None and a < 0:
        return (f"{cm.model_name}: development coefficient a = {a:.3g} < 0, an unstable grey model whose prediction "
                "grows without bound")
    # against the largest change of any training record: a quiet record (a day at rest) changes little, and
    # a model that is right there by the others' scale is no divergence
    if predictions is None:
        predictions = [cm.predict(ds) for ds in datasets]
    runs = [(ds, cm.target_values(ds), predicted) for ds, predicted in zip(datasets, predictions)]
    scale = max(max((float(np.max(np.abs(measured))) for _, measured, _ in runs), default=0.0), 1e-12)
    for ds, _, predicted in runs:
        if not np.all(np.isfinite(predicted)) or np.max(np.abs(predicted)) > DIVERGENCE_FACTOR * scale:
            return (f"{cm.model_name}: the prediction diverges on its own training data {dataset_label(ds)} "
                    f"(max |prediction| {np.nanmax(np.abs(predicted)):.3g} against max |measured change| "
                    f"{scale:.3g} {cm.target_unit} over the training records)")
    return None


def identification_problem(cm: CompensationModel, datasets: Sequence[Dataset]) -> str | None:
    """Why the training records do not determine the fitted grey-box model, or None.

    A pole whose time constant is longer than the longest training record,
    or on the upper bound of ``time_constant_bounds``, is seen only at its
    start: there its response is nearly a ramp, which a slower pole with a
    larger gain, or two such poles with gains of opposite sign, fit as well.
    Such a model can fit its record to the noise and be off by tens of times
    the drift on the next (a 4 h warm-up: time constants 23 h and 46 h with
    gains that cancel, against 0.6 h and 4.3 h in truth).

    Parameters
    ----------
    cm : CompensationModel
        The fitted model.
    datasets : sequence of Dataset
        Its training records.

    Returns
    -------
    str or None
        The reason, or None for a model without time constants or one whose records cover them.
    """
    taus = getattr(cm.estimator, "time_constants_", None)
    span = max(float(ds.time_s[-1] - ds.time_s[0]) for ds in datasets)
    if taus is None or cm.estimator.determined_by(span):
        return None
    slowest, n_poles = float(np.max(taus)), len(taus)
    where = (f"sits on its upper bound, {slowest / 3600:.3g} h (time_constant_bounds)"
             if not cm.estimator.determined_by(np.inf) else    # however long the records, it is on the bound
             f"is {slowest / 3600:.3g} h, longer than the longest training record ({span / 3600:.3g} h)")
    fewer = f", or with fewer poles (--param n_poles={n_poles - 1})" if n_poles > 1 else ""
    return (f"{cm.model_name}: its slowest time constant {where}: the records show only the start of that "
            "response, so they do not determine its gain, and the model can be far off on another record; train "
            f"on a record that lasts longer than its slow response{fewer}")


def continued_prediction(cm: CompensationModel, dataset: Dataset, history: Dataset | None = None,
                         gap: Literal["refuse", "interpolate"] = "refuse"
                         ) -> tuple[NDArray[np.float64], NDArray[np.float64], Dataset | None]:
    """``(measured, predicted, ran_over)``: the change of the target since the *training* start, for a record that
    continues it (for a time-series model trained on several records, the start of the one ``history`` is).

    Static models map the inputs referenced to the training start. A
    time-series model runs over ``history`` (the training record, from its
    start) followed by ``dataset`` at the training sampling interval, and the
    tail is returned. Its state carries from one to the other, so the two
    clocks are checked (:func:`continuation_times`): a record that starts one
    interval after the history's end follows it; one that starts later leaves
    a gap, refused unless ``gap="interpolate"``; one that overlaps the history
    is refused; one whose clock restarts (it starts no later than the
    history's first row) is taken to follow directly, with a notice on the
    ``thermal_twin`` logger.

    Parameters
    ----------
    cm : CompensationModel
        A model trained by this version (its file holds the training reference).
    dataset : Dataset
        The record that continues the training one.
    history : Dataset, optional
        The training record (for a model trained on several, the one the record continues), required for a
        time-series model; the change is then since its start.
    gap : {"refuse", "interpolate"}, default "refuse"
        What to do when the record starts more than one interval after the history ends.

    Returns
    -------
    measured : ndarray, shape (n_rows,)
        Target change since the training start, in the target's unit (µm for a drift axis).
    predicted : ndarray, shape (n_rows,)
        The model's prediction of it, same unit.
    ran_over : Dataset or None
        For a time-series model, the record it ran over, in its inputs and target: ``history``, the bridge and
        ``dataset`` on the history's clock (the history of a record that continues this one); None for a
        static model.

    Raises
    ------
    TwinInputError
        No training reference, missing channels, no ``history`` for a time-series model, another
        sampling interval, a ``history`` that does not start like the training record, or clocks
        that overlap or leave a refused gap.
    """
    ref = cm.preprocessing.get("training_reference")
    if ref is None:
        raise TwinInputError("--reference train needs a model trained by this version (its file holds no training "
                             "reference); retrain it")
    cm.check(dataset)
    if not cm.is_time_series:   # the reference is the start of the training record it continues, if named
        if history is not None:
            cm.check(history)
        start = None if history is None else _history_start(cm, history)
        return (dataset[cm.target] - cm.target_reference(start),
                np.asarray(cm.estimator.predict(dataset.matrix(cm.inputs) - cm.input_reference(start)), float), None)
    if history is None:
        which = "the training record" if len(cm.training) < 2 else \
            f"the training record it continues (one of {', '.join(t['label'] for t in cm.training)})"
        raise TwinInputError(f"{cm.model_name} is a time-series model: --reference train needs {which} as --history "
                             "to run over the whole history")
    cm.check(history)
    timed = bool(cm.preprocessing.get("time_column"))
    for ds in (history, dataset):
        if timed:   # a model that takes the time steps exactly, at any sampling
            note_long_steps(ds)
            continue
        dt = sampling_interval(ds, strict=True)
        if abs(dt - cm.sampling_interval_s) > 1e-6 * dt:
            raise TwinInputError(f"{dataset_label(ds)}: sampled every {dt:g} s, the model was trained at "
                                 f"{cm.sampling_interval_s:g} s; --reference train needs the same interval")
    start = _history_start(cm, history)
    measured = dataset[cm.target] - cm.target_reference(start)
    interval_s = continuation_interval(cm, history)
    record_s = continuation_times(history, dataset, cm.inputs, interval_s, gap, on_grid=not timed)
    ran_over = continued_record(history, Dataset(record_s, dataset.values, dataset.channels, dataset.metadata),
                                [*cm.inputs, cm.target], interval_s)
    X = ran_over.matrix(cm.inputs) - cm.input_reference(start)
    if timed:
        X = np.column_stack([ran_over.time_s - history.time_s[0], X])
    predicted = np.asarray(cm.estimator.predict(X), float)[len(ran_over) - len(dataset):]
    return measured, cm.series_change(predicted), ran_over


def continuation_interval(cm: CompensationModel, history: Dataset) -> float:
    """The sampling interval at which a record continues ``history``, s: the model's, or, for a model that takes
    the time (trained on records of any interval; its file keeps its first training record's), the history's own.

    Parameters
    ----------
    cm : CompensationModel
        A time-series model.
    history : Dataset
        The record continued.

    Returns
    -------
    float
    """
    return sampling_interval(history, strict=False) if cm.preprocessing.get("time_column") else cm.sampling_interval_s


def _history_start(cm, history):
    """The start (raw inputs and target) of the training record that ``history`` is, found by its inputs and
    target (records that start at rest often share their inputs there; the target tells them apart, and where
    it does not, their references are the same)."""
    rows = slice(0, cm.preprocessing.get("reference_samples", 1))
    start = np.r_[history.matrix(cm.inputs)[rows].mean(axis=0), history[cm.target][rows].mean()]
    starts = [t["reference"] for t in cm.training if "reference" in t] or [cm.preprocessing["training_reference"]]
    for ref in starts:
        if np.allclose(start, np.r_[ref["inputs"], ref["target"]], rtol=1e-9, atol=1e-9):
            return ref
    which = "the training record" if len(starts) == 1 else f"any of the {len(starts)} training records"
    theirs = " or ".join(str(np.round(np.r_[ref["inputs"], ref["target"]], 4).tolist()) for ref in starts)
    raise TwinInputError(f"{dataset_label(history)}: --history does not start like {which} "
                         f"(inputs and {cm.target} {np.round(start, 4).tolist()} against {theirs})")


def continuation_times(history: Dataset, dataset: Dataset, inputs: list[str], interval_s: float,
                       gap: Literal["refuse", "interpolate"] = "refuse", on_grid: bool = True
                       ) -> NDArray[np.float64]:
    """The times of ``dataset`` on the clock of the ``history`` it continues, once the two clocks are checked;
    the input rows missing between them are bridged by :func:`~twin.compensation.records.continued_record`.

    A time-series model carries its thermal state from the history into the
    record, so the rows it does not see are not harmless: after a stop of a
    few hours the state has decayed, and running on as if none had passed
    leaves the model warm (``docs/models.md``: FL_THERMAL ch3 on block 4 from
    1.7 h in, 12.5 µm RMSE run on, 1.58 µm with the rows, 5.9 µm bridged).

    Parameters
    ----------
    history : Dataset
        The training record.
    dataset : Dataset
        The record that continues it.
    inputs : list of str
        The model's input channels.
    interval_s : float
        The interval of the rows, s: the model's, or the history's own for a model that takes the time.
    gap : {"refuse", "interpolate"}, default "refuse"
        A gap is an error, or bridged by linear interpolation of every input
        between the history's last row and the record's first (the spindle
        speed too: a guess, which the state forgets after a few of its slowest
        time constants).
    on_grid : bool, default True
        The record must start a whole number of intervals after the history (a model with a
        sampling interval); False for a model that takes the time (any sampling, jitter allowed).

    Returns
    -------
    ndarray, shape (n_rows,)
        The record's times on the history's clock, s (shifted to follow it directly when its clock restarts).

    Raises
    ------
    TwinInputError
        The record is the history again, overlaps it, starts off the model's time grid, or leaves a gap and
        ``gap="refuse"``.
    """
    end, start = float(history.time_s[-1]), float(dataset.time_s[0])
    label, source = dataset_label(dataset), dataset_label(history)
    if repeats(history, dataset, inputs):
        raise TwinInputError(f"{label} starts with the rows of --history {source} (t = {start:g} s, the same "
                             "readings): a record cannot continue itself; evaluate it without --reference train, "
                             "or pass as --history the record it continues")
    if start <= float(history.time_s[0]):
        log.warning("%s: its time starts at %g s, not after --history %s ends (%g s): taken to follow it directly",
                    label, start, source, end)
        return dataset.time_s - start + end + interval_s
    if start <= end:
        raise TwinInputError(f"{label}: time_s starts at {start:g} s, inside --history {source} ({history.time_s[0]:g}"
                             f"..{end:g} s); pass as --history the record that ends where this one starts")
    missing = (start - end) / interval_s - 1.0
    if on_grid and abs(missing - round(missing)) > 1e-6 * (1.0 + missing):
        raise TwinInputError(f"{label}: time_s starts at {start:g} s, {start - end:g} s after --history {source} "
                             f"ends: not a whole number of the model's {interval_s:g} s steps")
    times = bridge_times(end, start, interval_s)
    if len(times) == 0:
        return dataset.time_s
    if gap != "interpolate":
        raise TwinInputError(f"{label}: time_s starts at {start:g} s, {start - end:g} s after --history {source} "
                             f"ends ({end:g} s): {len(times)} rows of {', '.join(inputs)} are missing, and a "
                             "time-series model carries its state through them. Pass the missing rows, or "
                             "--gap interpolate to bridge them by linear interpolation (the spindle speed too)")
    log.warning("%s: %d missing rows after --history %s bridged by linear interpolation of the inputs",
                label, len(times), source)
    return dataset.time_s
