"""Compensation models with their channel contract: which inputs, which target, units, preprocessing.

A :class:`CompensationModel` wraps a fitted ``models`` estimator with what is
needed to use it on a :class:`~twin.core.dataset.Dataset`: the input channels (in
order) and the target channel, their units, the preprocessing, the training
datasets and, for grey time-series models, the sampling interval the
coefficients belong to.

Preprocessing (the default, ``zero_reference=True``): every dataset is
referenced to its own start, inputs and target alike::

    X⁰ = X − X(ref),   y⁰ = y − y(ref),   ref = mean of the first ``reference_samples`` rows

and the model maps X⁰ → y⁰.  A prediction is therefore the *change* of the
target since the start of the record (the drift since the probe was zeroed),
and a constant offset of any sensor (a thermometer reading 0.4 °C high, a
probe zeroed elsewhere) cancels exactly.  Metrics compare it with the
measured change y⁰.  The exception is the first input of a model that
declares it (:class:`models.registry.ModelTraits`: the grey-box model's
spindle speed): a speed is an operating state, not a sensor with an offset,
so it is taken as measured (``preprocessing["absolute_inputs"]``), and a
record must start with it at standstill (:func:`check_starts_at_rest`).

On disk (``.json``, no pickle)::

    {"format": "thermal-twin-compensation-model", "version": 1,
     "model_name": "anfis", "inputs": [...], "input_units": [...], "target": "Z", "target_unit": "um",
     "preprocessing": {...}, "sampling_interval_s": ..., "training": [...], "project_version": ...,
     "estimator": <models.persistence document>,
     "field_sha256": {<field>: <SHA-256 of its canonical JSON>, ...}}

``field_sha256`` (:mod:`twin.compensation.integrity`) lets :meth:`CompensationModel.load` refuse a
file edited after it was saved, naming the field.
"""
from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from models.persistence import model_from_document, model_to_document
from models.registry import model_traits, registered_models

from ..core.dataset import UNITS, Dataset, finite_or_none, name_listing, project_version
from ..core.files import write_text_atomic
from ..errors import TwinInputError
from .integrity import check_sealed, sealed
from .records import (
    check_complete,
    check_starts_at_rest,
    dataset_label,
    distinct_labels,
    note_long_steps,
    sampling_interval,
)

FORMAT = "thermal-twin-compensation-model"
FORMAT_VERSION = 1


def make_estimator(name: str, params: dict | None = None) -> object:
    """An unfitted estimator by model name (see :mod:`models.registry`) with hyperparameters overridden.

    Parameters
    ----------
    name : str
        Model name, as ``twin train --model`` takes it (case-insensitive).
    params : dict, optional
        Hyperparameters overriding the name's defaults.

    Returns
    -------
    object
        The estimator (a scikit-learn style regressor).

    Raises
    ------
    TwinInputError
        For an unknown model name or a parameter the model does not have; both list what there is.
    """
    key = str(name).lower()
    known = registered_models()
    if key not in known:
        raise TwinInputError(f"unknown model {name!r}; available: {sorted(known)}")
    entry = known[key]
    merged = {**entry.defaults, **(params or {})}
    valid = entry.cls().get_params(deep=False)
    unknown = sorted(set(merged) - set(valid))
    if unknown:
        raise TwinInputError(f"model {name!r} ({entry.cls.__name__}) has no parameter(s) {unknown}; "
                             f"parameters: {sorted(valid)}")
    return entry.cls(**merged)


def parse_params(items: Sequence[str] | None) -> dict[str, object]:
    """``["n_rules=4", "epochs=20"]`` → ``{"n_rules": 4, "epochs": 20}`` (values read as JSON when they can be).

    Parameters
    ----------
    items : sequence of str or None
        ``name=value`` strings (``--param``); None gives ``{}``.

    Returns
    -------
    dict of str to object
        Name → value (a JSON value, else the text).

    Raises
    ------
    TwinInputError
        For an item without ``=``.
    """
    out = {}
    for item in items or []:
        if "=" not in item:
            raise TwinInputError(f"model parameter {item!r} is not of the form name=value")
        key, value = item.split("=", 1)
        try:
            out[key.strip()] = json.loads(value)
        except json.JSONDecodeError:
            out[key.strip()] = value
    return out


def check_channels(dataset: Dataset, names: Sequence[str], units: Sequence[str] | None = None,
                   role: str = "input") -> None:
    """Raise a :class:`TwinInputError` naming missing channels or unit mismatches, listing what is there.

    Parameters
    ----------
    dataset : Dataset
        A record (twin or measured).
    names : sequence of str
        Channels that must be there.
    units : sequence of str, optional
        Their required units (``degC``, ``um``, ``rpm`` …); None checks presence only.
    role : str, default "input"
        Named in the message (``input``, ``target``).
    """
    missing = [n for n in names if n not in dataset]
    if missing:
        raise TwinInputError(f"{dataset_label(dataset)}: lacks {role} channel(s) {missing}; it has "
                             f"{name_listing(dataset.names)}")
    if units is not None:
        bad = [(n, u, dataset.info(n).unit) for n, u in zip(names, units) if dataset.info(n).unit != u]
        if bad:
            text = ", ".join(f"{n} is {have!r}, the model needs {want!r}" for n, want, have in bad)
            raise TwinInputError(f"{dataset_label(dataset)}: channel units do not match: {text}")


def check_reference_samples(count: object, n_rows: int, label: str) -> None:
    """Raise unless ``count`` (rows averaged for the zero reference) is a whole number in 1 .. ``n_rows``.

    Parameters
    ----------
    count : object
        The ``reference_samples`` value given.
    n_rows : int
        Rows of the dataset.
    label : str
        Names the dataset in the message.
    """
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise TwinInputError(f"reference_samples (--reference-samples) must be a whole number of rows, at least 1; "
                             f"got {count}")
    if count > n_rows:
        raise TwinInputError(f"{label}: reference_samples (--reference-samples) = {int(count)} is more than the "
                             f"{n_rows} rows it has")


def reference_rows(values: ArrayLike, preprocessing: dict, label: str = "dataset",
                   absolute: Sequence[int] = ()) -> NDArray[np.float64]:
    """Subtract each column's reference (mean of the first ``reference_samples`` rows) when zero-referencing.

    Parameters
    ----------
    values : array_like, shape (n_rows, n_columns)
        Channel values, in their units.
    preprocessing : dict
        A model's ``preprocessing`` (``zero_reference``, ``reference_samples``).
    label : str, default "dataset"
        Names the dataset in errors.
    absolute : sequence of int, default ()
        Columns taken as they are (a speed).

    Returns
    -------
    ndarray, shape (n_rows, n_columns)
        The changes since the reference (or the values, unchanged, without zero-referencing), same units.
    """
    values = np.asarray(values, float)
    if not preprocessing.get("zero_reference", True):
        return values
    k = preprocessing.get("reference_samples", 1)
    check_reference_samples(k, len(values), label)
    reference = values[:k].mean(axis=0)
    reference[list(absolute)] = 0.0
    return values - reference


@dataclass
class CompensationModel:
    """A fitted estimator plus its channel contract; ``predict(dataset)`` gives the target change.

    Attributes
    ----------
    estimator : object
        The fitted ``models`` estimator.
    model_name : str
        Its registry name (``anfis``, ``mlr`` …).
    inputs : list of str
        The channels the estimator's X is made of, in its column order: the inputs, then any observed
        thermometers (``preprocessing["observed"]``).
    target : str
        Target channel.
    input_units, target_unit : list of str, str
        Their units (``degC``, ``um`` …), checked on every dataset.
    preprocessing : dict
        ``zero_reference``, ``reference_samples``, ``time_column`` (true when the estimator takes the
        time since the record's start as its first column: the grey-box model), ``absolute_inputs``
        (inputs taken as measured: the grey-box model's speed), ``observed`` (thermometers the model fuses
        while it runs), ``rest_start`` (twin records are read from the rest state before their start,
        :func:`~twin.compensation.records.with_rest_start`; absent in files written before) and, once
        fitted, the raw ``training_reference``.
    training : list of dict
        Label, rows, source, scenario, kind, duration (h) and ``reference`` (raw inputs and target at its
        start) of each training record.
    sampling_interval_s : float or None
        The training interval, s (time-series models only; the median step when the model takes the time).
    metadata : dict
        Training metrics, selection and stability notes.
    """

    estimator: object
    model_name: str
    inputs: list
    target: str
    input_units: list
    target_unit: str
    preprocessing: dict = field(default_factory=lambda: {"zero_reference": True, "reference_samples": 1})
    training: list = field(default_factory=list)
    sampling_interval_s: float | None = None
    metadata: dict = field(default_factory=dict)

    @property
    def is_time_series(self) -> bool:
        """Whether the estimator is a grey time-series model (coefficients per sample)."""
        return model_traits(self.estimator).time_series

    @property
    def absolute_columns(self) -> list[int]:
        """Input columns taken as measured, not zero-referenced (``preprocessing["absolute_inputs"]``)."""
        absolute = self.preprocessing.get("absolute_inputs", [])
        return [i for i, name in enumerate(self.inputs) if name in absolute]

    def input_reference(self, start: dict | None = None) -> NDArray[np.float64]:
        """What is subtracted from the inputs of a record that continues a training one: that record's
        start's raw inputs (0 for those taken as measured), or zeros without zero-referencing.

        Parameters
        ----------
        start : dict, optional
            The raw ``inputs`` and ``target`` at a training record's start (an entry's ``reference`` in
            :attr:`training`); default the first record's (``preprocessing["training_reference"]``).

        Returns
        -------
        ndarray, shape (n_inputs,)
            In the inputs' units.
        """
        start = self.preprocessing["training_reference"] if start is None else start
        reference = np.array(start["inputs"], float)
        reference[self.absolute_columns] = 0.0
        return reference if self.preprocessing.get("zero_reference", True) else np.zeros_like(reference)

    def target_reference(self, start: dict | None = None) -> float:
        """What is subtracted from the target of a record that continues a training one: that record's
        start's raw target, or 0 without zero-referencing.

        Parameters
        ----------
        start : dict, optional
            As for :meth:`input_reference`.

        Returns
        -------
        float
            In the target's unit.
        """
        start = self.preprocessing["training_reference"] if start is None else start
        return float(start["target"]) if self.preprocessing.get("zero_reference", True) else 0.0

    def describe(self) -> str:
        """One line: name, class, kind, inputs → target [unit].

        Returns
        -------
        str
        """
        kind = "grey time-series" if self.is_time_series else "static"
        observed = self.preprocessing.get("observed", [])
        drivers = [name for name in self.inputs if name not in observed]
        return (f"{self.model_name} ({type(self.estimator).__name__}, {kind}): {', '.join(drivers)} → "
                f"{self.target} [{self.target_unit}]" + (f", observing {', '.join(observed)}" if observed else ""))

    # ------------------------------------------------------------------ data
    def check(self, dataset: Dataset) -> None:
        """Raise a :class:`TwinInputError` unless ``dataset`` has the inputs and the target in the model's units.

        Parameters
        ----------
        dataset : Dataset
            A record (twin or measured).
        """
        check_channels(dataset, self.inputs, self.input_units, "input")
        check_channels(dataset, [self.target], [self.target_unit], "target")

    def check_readings(self, dataset: Dataset) -> None:
        """Raise a :class:`TwinInputError` for a missing (NaN) reading the model cannot run over: any but in
        the thermometers it observes (their fit leaves them out, their filter skips them), and theirs in the
        reference rows (:func:`~twin.compensation.records.check_complete`).

        Parameters
        ----------
        dataset : Dataset
            A record with the model's channels (:meth:`check`).
        """
        check_complete(dataset, [*self.inputs, self.target], self.preprocessing.get("observed", ()),
                       self.preprocessing.get("reference_samples", 1))

    def features(self, dataset: Dataset) -> NDArray[np.float64]:
        """The input matrix as the estimator sees it (zero-referenced unless that is switched off).

        Parameters
        ----------
        dataset : Dataset
            A record (twin or measured).

        Returns
        -------
        ndarray, shape (n_rows, n_inputs) or (n_rows, 1 + n_inputs)
            In the inputs' units; a model that takes the time (``preprocessing["time_column"]``) gets
            the time since the record's start first, s.
        """
        check_channels(dataset, self.inputs, self.input_units, "input")
        absolute = self.absolute_columns
        if absolute and self.preprocessing.get("zero_reference", True):
            check_starts_at_rest(dataset, self.inputs[absolute[0]], self.model_name)
        X = reference_rows(dataset.matrix(self.inputs), self.preprocessing, dataset_label(dataset), absolute)
        if self.preprocessing.get("time_column"):
            return np.column_stack([dataset.time_s - dataset.time_s[0], X])
        return X

    def target_values(self, dataset: Dataset) -> NDArray[np.float64]:
        """The measured target as the model sees it (zero-referenced unless that is switched off).

        Parameters
        ----------
        dataset : Dataset
            A record (twin or measured).

        Returns
        -------
        ndarray, shape (n_rows,)
            In the target's unit (µm for a drift axis).
        """
        check_channels(dataset, [self.target], [self.target_unit], "target")
        return reference_rows(dataset[self.target][:, None], self.preprocessing, dataset_label(dataset))[:, 0]

    def predict(self, dataset: Dataset) -> NDArray[np.float64]:
        """Predicted target (its change since the record's start when zero-referenced), one per row.

        A time-series model sampled at another interval than in training is run on the record resampled
        (linearly) onto the training interval and its prediction interpolated back.

        Parameters
        ----------
        dataset : Dataset
            A record (twin or measured).

        Returns
        -------
        ndarray, shape (n_rows,)
            In the target's unit (µm for a drift axis).
        """
        X = self.features(dataset)
        if not self.is_time_series:
            return np.asarray(self.estimator.predict(X), float)
        if self.preprocessing.get("time_column"):  # it steps exactly from row to row, at any sampling
            return self._predict_series(X)
        dt = sampling_interval(dataset, strict=False)
        t = dataset.time_s
        if self.sampling_interval_s is None or abs(dt - self.sampling_interval_s) <= 1e-6 * dt:
            sampling_interval(dataset, strict=True)
            return self._predict_series(X)
        # Grey coefficients are per sample: resample onto the training interval, predict, interpolate back.
        grid = np.arange(t[0], t[-1] + 1e-9 * self.sampling_interval_s, self.sampling_interval_s)
        Xg = np.column_stack([np.interp(grid, t, X[:, j]) for j in range(X.shape[1])])
        return np.interp(t, grid, self._predict_series(Xg))

    def _predict_series(self, X):
        return self.series_change(np.asarray(self.estimator.predict(X), float))

    def series_change(self, predicted: np.ndarray) -> np.ndarray:
        """A time-series estimator's prediction in the referenced frame of the data.

        A grey series model predicts ``y_reference_`` (its first training target) + the change since
        the first row it runs over; with the zero reference that target is taken off. A model that
        predicts the level itself (``ModelTraits.predicts_level``, the grey-box model: its offset is
        fitted) is left as it is; taking ``y_reference_`` off it would shift it by the first training
        row's noise whenever the reference is a mean of several rows.

        Parameters
        ----------
        predicted : ndarray, shape (n_rows,)
            ``estimator.predict`` of a record, in the target's unit.

        Returns
        -------
        ndarray, shape (n_rows,)
            The same, in the target's referenced frame.
        """
        if model_traits(self.estimator).predicts_level or not self.preprocessing.get("zero_reference", True):
            return predicted
        return predicted - float(self.estimator.y_reference_)

    # ------------------------------------------------------------------ files
    def to_document(self) -> dict:
        """The JSON-ready file document (layout in the module docstring).

        Returns
        -------
        dict
        """
        return {
            "format": FORMAT, "version": FORMAT_VERSION, "model_name": self.model_name,
            "inputs": list(self.inputs), "input_units": list(self.input_units),
            "target": self.target, "target_unit": self.target_unit,
            "preprocessing": dict(self.preprocessing), "sampling_interval_s": self.sampling_interval_s,
            "training": list(self.training), "project_version": project_version(),
            "metadata": finite_or_none(dict(self.metadata)), "estimator": model_to_document(self.estimator),
        }

    def save(self, path: Path | str) -> Path:
        """Write the model as JSON (atomically), with the digest of each field
        (:func:`twin.compensation.integrity.sealed`); returns the path.

        Parameters
        ----------
        path : Path or str
            The ``.json`` file; its folder is created.

        Returns
        -------
        Path
            ``path``.
        """
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        return write_text_atomic(path, json.dumps(sealed(self.to_document()), indent=1))

    @classmethod
    def load(cls, path: Path | str) -> CompensationModel:
        """Read a model written by :meth:`save`; a wrong format or version, or a field changed since it was saved
        (:func:`twin.compensation.integrity.check_sealed`), is a clear error.

        Parameters
        ----------
        path : Path or str
            The model file.

        Returns
        -------
        CompensationModel

        Raises
        ------
        TwinInputError
            Missing file, not JSON, wrong format or version, missing fields, a bad estimator document, or a
            field whose digest does not match.
        """
        path = Path(path)
        doc = _read_document(path)
        # digests first: an edited field is named as such before the estimator reads (and may choke on) it
        check_sealed(doc, path)
        try:
            estimator = model_from_document(doc["estimator"], f"{path} [estimator]")
        except ValueError as exc:
            raise TwinInputError(str(exc)) from None
        return cls(estimator, doc["model_name"], list(doc["inputs"]), doc["target"], list(doc["input_units"]),
                   doc["target_unit"], dict(doc.get("preprocessing") or {}), list(doc.get("training") or []),
                   doc.get("sampling_interval_s"), dict(doc.get("metadata") or {}))


def _read_document(path):
    """The JSON document of a compensation-model file, its format, version and fields checked."""
    if not path.exists():
        raise TwinInputError(f"{path}: model file not found")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise TwinInputError(f"{path}: not a JSON model file ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        got = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        hint = " (a bare models.save_model file? train it with `twin train`)" \
            if isinstance(doc, dict) and doc.get("format") == "thermal-twin-model" else ""
        raise TwinInputError(f"{path}: format {got!r} is not {FORMAT!r}{hint}")
    if doc.get("version") != FORMAT_VERSION:
        raise TwinInputError(f"{path}: compensation-model version {doc.get('version')!r} was written by "
                             f"project version {doc.get('project_version', '?')}; this version "
                             f"({project_version()}) reads version {FORMAT_VERSION} only — retrain it")
    missing = [k for k in ("model_name", "inputs", "input_units", "target", "target_unit", "estimator")
               if k not in doc]
    if missing:
        raise TwinInputError(f"{path}: model file lacks field(s) {missing}")
    return doc


def _check_channel_choice(inputs, target):
    """Refuse no inputs, an input given twice, or the target among the inputs."""
    if not inputs:
        raise TwinInputError("no input channel given")
    repeated = sorted({n for n in inputs if inputs.count(n) > 1})
    if repeated:
        raise TwinInputError(f"input channel(s) {repeated} given more than once; each input must be a different "
                             "channel")
    if target in inputs:
        raise TwinInputError(f"the target {target!r} is also an input")


def _channel_units(datasets, inputs, target):
    """Units of the inputs and the target in the first dataset; every other dataset must have the same."""
    first = datasets[0]
    check_channels(first, inputs, role="input")
    check_channels(first, [target], role="target")
    units = [first.info(n).unit for n in inputs]
    target_unit = first.info(target).unit
    for ds in datasets[1:]:
        check_channels(ds, inputs, units, "input")
        check_channels(ds, [target], [target_unit], "target")
    return units, target_unit


def _preprocessing(estimator, model, inputs, units, zero_reference, reference_samples, observe):
    """The model's ``preprocessing``, after checking its declared first input (a speed, taken as measured)."""
    # rest_start: twin records were read from the rest state before their start (with_rest_start), and a
    # record evaluated with this model is read so too
    prep = {"zero_reference": bool(zero_reference), "reference_samples": int(reference_samples),
            "convention": "inputs and target minus their value at the start of each dataset"
            if zero_reference else "raw values", "rest_start": True}
    first = model_traits(estimator).first_input
    if first is not None:
        if units[0] != first[1]:
            raise TwinInputError(f"{model} takes the {first[0]} (unit {first[1]}) as its first input, and "
                                 f"{inputs[0]!r} is in {units[0]}; put the {first[0]} first (--inputs "
                                 f"<{first[0]}>,<the others…>)")
        prep["absolute_inputs"] = [inputs[0]]   # a speed is an operating state, not a sensor with an offset
        prep["convention"] += f" ({inputs[0]} as measured)" if zero_reference else ""
    if observe:
        prep["observed"] = list(observe)
    return prep


def _check_inputs_move(datasets, inputs, units, zero_reference):
    """Refuse an input that the model sees constant in every training record: any model fits it a zero (or an
    arbitrary) effect, which is then silently wrong wherever it does move (a log of a night at rest, a
    climate chamber at one temperature)."""
    for name, unit in zip(inputs, units):
        values = [ds[name][np.isfinite(ds[name])] for ds in datasets]
        seen = values if zero_reference else [np.concatenate(values)]   # referenced, each record starts at 0
        if all(np.ptp(v) == 0 for v in seen):
            level = ", ".join(sorted({f"{v[0]:g}" for v in values}))
            raise TwinInputError(
                f"input {name!r} never changes in the training records ({level} {UNITS.get(unit, unit)} throughout"
                f"{', each record referenced to its start' if zero_reference and len(values) > 1 else ''}): "
                "no model can learn what it does, and it would be ignored wherever it moves; train on records "
                "where it changes, or leave it out of --inputs")


def _with_observed(estimator, model, inputs, observe, params):
    """The model's channels: ``inputs``, then the thermometers it observes (checked against its contract)."""
    observe = list(observe)
    if "observed" in (params or {}):
        raise TwinInputError("name the observed thermometers with --observe, not --param observed=")
    if not observe:
        return inputs
    if not model_traits(estimator).observer:
        raise TwinInputError(f"--observe {','.join(observe)}: {model} has no observer that fuses thermometers (the "
                             "grey-box model has one: --model greybox)")
    both = [n for n in observe if n in inputs]
    if both:
        raise TwinInputError(f"--observe {both[0]!r} is also in --inputs: an observed thermometer is an output of "
                             "the model, corrected by its readings, not an input")
    return inputs + observe


def _time_series_interval(cm, datasets, params):
    """The training interval of a time-series model (s, the median step of the records), after setting up how
    it takes the time."""
    takes_time = model_traits(cm.estimator).takes_time
    if len(datasets) > 1 and not takes_time:
        raise TwinInputError(f"model {cm.model_name!r} is a grey time-series model and trains on one contiguous "
                             f"record; got {len(datasets)} datasets that do not continue one another (each "
                             "must start one sampling interval after another ends, by its clock; or "
                             "use a model that trains on several records, each from rest: greybox, or a static "
                             "model: mlr, pcr, ann, anfis)")
    timed = takes_time and "sampling_interval" not in (params or {})
    if timed:
        # a model that takes the time (the grey-box model) steps exactly over every interval, so a record
        # with jitter or missing rows needs no resampling; its time constants are in s
        cm.estimator.set_params(sampling_interval=None)
        cm.preprocessing["time_column"] = True
    if len(datasets) > 1 and not cm.preprocessing.get("zero_reference", True):
        raise TwinInputError(f"model {cm.model_name!r} shares its offset between records, so several records need "
                             "the zero reference (each record's change since its start): drop --no-zero-reference")
    intervals = [sampling_interval(ds, strict=not timed) for ds in datasets]
    for ds, interval in zip(datasets, intervals):
        if timed:
            note_long_steps(ds)
        elif abs(interval - intervals[0]) > 1e-6 * intervals[0]:
            raise TwinInputError(f"{dataset_label(ds)}: sampled every {interval:g} s, {dataset_label(datasets[0])} "
                                 f"every {intervals[0]:g} s; with a fixed sampling_interval every record needs it")
    return float(np.median(np.concatenate([np.diff(ds.time_s) for ds in datasets])))


def fit_compensation_model(datasets: list, inputs: list[str], target: str, model: str = "anfis",
                           params: dict | None = None, zero_reference: bool = True,
                           reference_samples: int = 1, observe: Sequence[str] = ()) -> CompensationModel:
    """Fit a :class:`CompensationModel` on one or more datasets.

    Static models (MLR, PCR, ANN, ANFIS) are fitted on the rows of all
    datasets, each referenced to its own start; the grey-box model on all
    of them too, each run from rest at its own start (``record_starts`` of
    its fit); the other grey time-series models take one evenly sampled
    dataset.

    Parameters
    ----------
    datasets : list of Dataset
        Training records.
    inputs : list of str
        Input channels (their units are kept in the model and checked on use).
    target : str
        Target channel (µm for a drift axis).
    model, params
        Model name (see :mod:`models.registry`) and hyperparameters overriding its defaults.
    zero_reference, reference_samples
        Reference inputs and target to the mean of their first ``reference_samples`` rows.
    observe : sequence of str, default ()
        Thermometers the model fuses while it runs (a model with an observer, :class:`models.registry.ModelTraits`):
        outputs of the model, not inputs; a record must hold them, and only their readings may be missing
        (NaN: left out of the fit, skipped by the filter).

    Returns
    -------
    CompensationModel
        Fitted, with its training records and training reference (metrics are added by
        :func:`twin.compensation.train.train`).

    Raises
    ------
    TwinInputError
        For missing or repeated channels, unit mismatches, an unknown model, or a fit that fails.
    """
    datasets = list(datasets)
    if not datasets:
        raise TwinInputError("no training dataset given")
    inputs = list(inputs)
    estimator = make_estimator(model, params)
    channels = _with_observed(estimator, model, inputs, observe, params)
    _check_channel_choice(channels, target)
    for ds in datasets:
        check_reference_samples(reference_samples, len(ds), dataset_label(ds))
    units, target_unit = _channel_units(datasets, channels, target)
    prep = _preprocessing(estimator, model, inputs, units, zero_reference, reference_samples, observe)
    cm = CompensationModel(estimator, str(model).lower(), channels, target, units, target_unit, prep)
    for ds in datasets:
        cm.check_readings(ds)
    _check_inputs_move(datasets, inputs, units, zero_reference)
    dt = _time_series_interval(cm, datasets, params) if cm.is_time_series else None
    if observe:   # the observed columns, after the inputs and the time column the model may take
        first_observed = len(inputs) + int(bool(cm.preprocessing.get("time_column")))
        estimator.set_params(observed=tuple(range(first_observed, first_observed + len(observe))))
    X = np.vstack([cm.features(ds) for ds in datasets])
    y = np.concatenate([cm.target_values(ds) for ds in datasets])
    several = {"record_starts": np.cumsum([len(ds) for ds in datasets])[:-1].tolist()} \
        if cm.is_time_series and len(datasets) > 1 else {}
    try:
        estimator.fit(X, y, **several)
    except ValueError as exc:
        hint = " (in `twin train`, --model anfis-fcm is the FCM-initialised ANFIS)" \
            if getattr(estimator, "init", None) == "grid" else ""
        raise TwinInputError(f"cannot fit {model!r} on {X.shape[0]} rows × {len(inputs)} inputs: {exc}{hint}") \
            from None
    cm.sampling_interval_s = dt
    # raw values at each training start: `twin evaluate --reference train` continues from them
    k = int(reference_samples)
    starts = [{"inputs": ds.matrix(channels)[:k].mean(axis=0).tolist(), "target": float(np.mean(ds[target][:k]))}
              for ds in datasets]
    cm.preprocessing["training_reference"] = starts[0]
    cm.training = [{"label": label, "rows": len(ds), "source": ds.metadata.get("source"),
                    "scenario": ds.metadata.get("scenario"), "kind": ds.metadata.get("kind"),
                    "duration_h": float((ds.time_s[-1] - ds.time_s[0]) / 3600.0), "reference": start}
                   for ds, label, start in zip(datasets, distinct_labels(datasets), starts)]
    return cm
