"""Save and load fitted ``models`` estimators as versioned JSON (no pickle).

File layout (schema version 1)::

    {"format": "thermal-twin-model", "version": 1,
     "class": "ANFISRegressor",
     "params": {...hyperparameters, get_params(deep=False)...},
     "learned": {...every public attribute ending in "_"...}}

Arrays are stored as ``{"__ndarray__": {"dtype", "shape", "data"}}`` with
floats written by ``repr`` (shortest round-trip form), so a loaded model
reproduces predictions bit for bit. Tuples, dicts and nested estimators
(e.g. the ANFIS inside AGO-ANFIS) have their own tagged forms. The classes a file may name are those
of :mod:`models.registry`. Loading checks
the format, version and class first, then every value (an array's
``shape`` against its ``data``, the hyperparameters against the class) and,
for an estimator that has one (the grey-box model), its ``check_fitted``
(the learned attributes a fit can give), and raises ``ValueError`` naming
the file, the field and the offending value.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from sklearn.base import BaseEstimator

from .registry import estimator_classes

FORMAT = "thermal-twin-model"
VERSION = 1

def _encode(value):
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    if isinstance(value, np.ndarray):
        return {
            "__ndarray__": {
                "dtype": value.dtype.str,
                "shape": list(value.shape),
                "data": [_encode(v) for v in value.ravel().tolist()],
            }
        }
    if isinstance(value, tuple):
        return {"__tuple__": [_encode(v) for v in value]}
    if isinstance(value, list):
        return [_encode(v) for v in value]
    if isinstance(value, dict):
        return {"__dict__": {str(k): _encode(v) for k, v in value.items()}}
    if isinstance(value, BaseEstimator):
        return {"__estimator__": _model_document(value)}
    raise TypeError(f"cannot store a value of type {type(value).__name__} in a model file.")


def _decode(value, path):
    if isinstance(value, list):
        return [_decode(v, path) for v in value]
    if not isinstance(value, dict):
        return value
    if "__ndarray__" in value:
        spec = value["__ndarray__"]
        return np.array(spec["data"], dtype=np.dtype(spec["dtype"])).reshape(spec["shape"])
    if "__tuple__" in value:
        return tuple(_decode(v, path) for v in value["__tuple__"])
    if "__dict__" in value:
        return {k: _decode(v, path) for k, v in value["__dict__"].items()}
    if "__estimator__" in value:
        return _build(value["__estimator__"], path)
    raise ValueError(f"unknown tagged value {sorted(value)!r}")


def _decoded_field(value, path, field):
    """``_decode(value)``, or a ValueError naming the file, the field and its value (an array whose ``data`` do
    not fill its ``shape``, an unknown ``dtype``, a tag without its parts)."""
    try:
        return _decode(value, path)
    except (KeyError, TypeError, ValueError) as exc:
        if str(exc).startswith(f"{path}: "):   # a nested estimator's own message names its field already
            raise
        raise ValueError(f"{path}: field {field!r} has value {_shown(value)}, which is not a stored value: "
                         f"{exc}.") from None


def _shown(value, limit=160):
    """The JSON of a value, cut to ``limit`` characters for a message."""
    text = json.dumps(value)
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _section(document, name, path):
    """The ``params`` or ``learned`` object of a document ({} when absent), or a ValueError if it is no object."""
    section = document.get(name, {})
    if not isinstance(section, dict):
        raise ValueError(f"{path}: field {name!r} has value {_shown(section)}, expected an object.")
    return section


def _model_document(estimator) -> dict:
    cls = type(estimator).__name__
    known = estimator_classes()
    if known.get(cls) is not type(estimator):
        raise ValueError(f"cannot save {cls}: known classes are {sorted(known)} (see models.registry).")
    learned = {
        k: _encode(v) for k, v in vars(estimator).items() if k.endswith("_") and not k.startswith("_")
    }
    return {
        "format": FORMAT,
        "version": VERSION,
        "class": cls,
        "params": {k: _encode(v) for k, v in estimator.get_params(deep=False).items()},
        "learned": learned,
    }


def _build(document, path):
    for field, expected in (("format", FORMAT), ("version", VERSION)):
        if document.get(field) != expected:
            raise ValueError(
                f"{path}: field '{field}' has value {document.get(field)!r}; "
                f"this version of models reads {field} {expected!r}."
            )
    cls_name = document.get("class")
    known = estimator_classes()
    if cls_name not in known:
        raise ValueError(
            f"{path}: field 'class' has value {cls_name!r}, which is not a known estimator "
            f"({', '.join(sorted(known))})."
        )
    params = {name: _decoded_field(value, path, f"params.{name}")
              for name, value in _section(document, "params", path).items()}
    unknown = sorted(set(params) - set(known[cls_name]().get_params(deep=False)))
    if unknown:
        raise ValueError(f"{path}: field 'params.{unknown[0]}' has value {_shown(document['params'][unknown[0]])}, "
                         f"but {cls_name} has no parameter {unknown[0]!r}.")
    estimator = known[cls_name](**params)
    learned = _section(document, "learned", path)
    # only the names _model_document writes: any other would set a private or a method of the estimator
    for name in learned:
        if not name.endswith("_") or name.startswith("_"):
            raise ValueError(f"{path}: field 'learned' has an entry {name!r}; learned attributes end in '_' and "
                             "do not start with it.")
    for name, value in learned.items():
        setattr(estimator, name, _decoded_field(value, path, f"learned.{name}"))
    return _checked_fit(estimator, path)


def _checked_fit(estimator, path):
    """``estimator``, after its own ``check_fitted`` where it has one (a ValueError then names the file)."""
    check = getattr(estimator, "check_fitted", None)
    if check is not None:
        try:
            check()
        except (TypeError, ValueError) as exc:   # a hyperparameter of the wrong type (null) fails as TypeError
            raise ValueError(f"{path}: {exc}") from None
    return estimator


def model_to_document(estimator: BaseEstimator) -> dict:
    """The JSON-ready document :func:`save_model` writes (for embedding in a larger file).

    Parameters
    ----------
    estimator : BaseEstimator
        An instance of a registered class (fitted or not).

    Returns
    -------
    dict
        ``format``, ``version``, ``class``, ``params`` and ``learned`` (see the module docstring).

    Raises
    ------
    ValueError
        If the class is not registered in :mod:`models.registry`.
    """
    return _model_document(estimator)


def model_from_document(document: object, source: str = "<document>") -> BaseEstimator:
    """Rebuild an estimator from a :func:`model_to_document` document; ``source`` names it in errors.

    Parameters
    ----------
    document : object
        The parsed JSON document (must be a dict).
    source : str, default "<document>"
        Names the document in error messages.

    Returns
    -------
    BaseEstimator
        The estimator, with its hyperparameters and learned attributes.

    Raises
    ------
    ValueError
        A wrong format, version, class or tagged value, naming ``source`` and the field.
    """
    if not isinstance(document, dict):
        raise ValueError(f"{source}: field '<root>' has value of type {type(document).__name__}, expected an object.")
    return _build(document, source)


def save_model(estimator: BaseEstimator, path: Path | str) -> Path:
    """Write ``estimator`` (fitted or not) to ``path`` as JSON; returns the path.

    Parameters
    ----------
    estimator : BaseEstimator
        An instance of a registered class.
    path : Path or str
        The file to write (replaced if it exists).

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    path.write_text(json.dumps(_model_document(estimator)))
    return path


def load_model(path: Path | str) -> BaseEstimator:
    """Read an estimator written by :func:`save_model`.

    Parameters
    ----------
    path : Path or str
        The JSON model file.

    Returns
    -------
    BaseEstimator
        The estimator, predicting as the saved one did.

    Raises
    ------
    ValueError
        Not JSON, or a wrong format, version, class or value (naming the file and field).
    """
    path = Path(path)
    try:
        document = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not a JSON model file ({exc}).") from exc
    if not isinstance(document, dict):
        raise ValueError(f"{path}: field '<root>' has value of type {type(document).__name__}, expected an object.")
    return _build(document, path)
