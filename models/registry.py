"""The one registry of estimators: a class registers itself once, with its command-line names and traits.

Usage, in the module that defines the estimator::

    from .registry import register_model

    @register_model({"mlr": {}})                                   # CLI name → default hyperparameters
    class MLRRegressor(...): ...

    @register_model({"gmc": {"random_state": 0}}, time_series=True)
    class GMCRegressor(...): ...

    @register_model({"greybox": {...}}, time_series=True, takes_time=True, first_input=("spindle speed", "rpm"),
                    observer=True)
    class GreyBoxRegressor(...): ...

    @register_model()                                              # persisted, but not a `twin train` model
    class FuzzyCMeans(...): ...

Everything that lists models derives from here: :mod:`models.persistence`
(which classes a model file may name), ``twin train --model`` and
:mod:`twin.compensation.store` (names, defaults, and the input contract of
:class:`ModelTraits`: time-series handling, a time column, a required first
input) and the tests' parametrisations.  Every module of the ``models`` package is
imported before the registry is read, so a new module's decorator is all it
takes.

Persistence contract of a registered class: a scikit-learn estimator whose
``get_params(deep=False)`` rebuilds it and whose learned state is the public
attributes ending in ``_``; their values are None, bool, int, float, str,
ndarrays, tuples, lists, dicts or registered estimators.
"""
from __future__ import annotations

import functools
import importlib
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TypeVar

T = TypeVar("T", bound=type)


@dataclass(frozen=True)
class ModelTraits:
    """What a class needs of its inputs, declared where it registers (so that callers need not know it by name).

    Attributes
    ----------
    time_series : bool
        A grey time-series model: it runs over the record's history; ``predict`` returns ``y_reference_`` +
        the predicted change (unless ``predicts_level``). Without ``takes_time`` its coefficients are per
        sample, so it trains on one contiguous, evenly sampled record; with it, on several, each from rest
        (``record_starts`` of its fit).
    takes_time : bool
        The class has a ``sampling_interval`` parameter (s); set to None, column 0 of ``X`` is the time
        (s) and any sampling (jitter, missing rows) is taken as it is.
    first_input : (str, str) or None
        What the first input must be, and its unit, e.g. ``("spindle speed", "rpm")``.
    observer : bool
        The class has an ``observed`` parameter: columns of ``X`` modelled as outputs (thermometers on the
        structure) and fused while it runs (a Kalman filter).
    predicts_level : bool
        A time-series model whose ``predict`` is the target itself, in the frame it was trained in (its
        offset is fitted), not ``y_reference_`` + a change: nothing is to be taken off it.
    """

    time_series: bool = False
    takes_time: bool = False
    first_input: tuple[str, str] | None = None
    observer: bool = False
    predicts_level: bool = False


@dataclass(frozen=True)
class ModelEntry:
    """One command-line model name.

    Attributes
    ----------
    name : str
        The name ``twin train --model`` takes (lower case).
    cls : type
        The estimator class.
    defaults : dict
        Hyperparameters that differ from the class defaults for this name.
    traits : ModelTraits
        The class's input contract.
    """

    name: str
    cls: type
    defaults: dict = field(default_factory=dict)
    traits: ModelTraits = ModelTraits()

    def make(self, **params: object) -> object:
        """An unfitted estimator with this name's defaults, overridden by ``params``.

        Parameters
        ----------
        **params
            Hyperparameters (keyword arguments of the class).

        Returns
        -------
        object
            The estimator, an instance of :attr:`cls`.
        """
        return self.cls(**{**self.defaults, **params})


_CLASSES: dict[str, type] = {}
_MODELS: dict[str, ModelEntry] = {}
_TRAITS: dict[str, ModelTraits] = {}


def register_model(names: dict[str, dict] | None = None, time_series: bool = False, takes_time: bool = False,
                   first_input: tuple[str, str] | None = None, observer: bool = False,
                   predicts_level: bool = False) -> Callable[[T], T]:
    """Class decorator: register an estimator for persistence and, with ``names``, for ``twin train``.

    Parameters
    ----------
    names : dict of str to dict, optional
        Command-line name → default hyperparameters (several names may share a class, e.g. the ANFIS
        initialisations).  None: persisted only.
    time_series, takes_time, first_input, observer, predicts_level
        The class's input contract (see :class:`ModelTraits`).

    Returns
    -------
    callable
        The decorator; it returns the class unchanged.

    Raises
    ------
    ValueError
        If a class name or command-line name is registered twice.
    """
    def decorate(cls):
        if _CLASSES.get(cls.__name__, cls) is not cls:
            raise ValueError(f"estimator class name {cls.__name__!r} is registered twice")
        traits = ModelTraits(time_series, takes_time, None if first_input is None else tuple(first_input), observer,
                             predicts_level)
        entries = [ModelEntry(name.lower(), cls, dict(defaults), traits) for name, defaults in (names or {}).items()]
        for e in entries:                    # checked before anything is registered: a refusal leaves no trace
            if e.name in _MODELS and _MODELS[e.name].cls is not cls:
                raise ValueError(f"model name {e.name!r} is registered twice ({_MODELS[e.name].cls.__name__}, "
                                 f"{cls.__name__})")
        _CLASSES[cls.__name__] = cls
        _TRAITS[cls.__name__] = traits
        _MODELS.update({e.name: e for e in entries})
        return cls
    return decorate


@functools.cache
def _load_all() -> None:
    """Import every module of the ``models`` package, so that every decorator has run."""
    package = importlib.import_module(__package__)
    for info in pkgutil.walk_packages(package.__path__, prefix=f"{__package__}."):
        if not info.name.rpartition(".")[2].startswith("_"):
            importlib.import_module(info.name)


def estimator_classes() -> dict[str, type]:
    """Class name → class of every registered estimator (what a model file may name).

    Returns
    -------
    dict of str to type
        A copy; changing it changes nothing.
    """
    _load_all()
    return dict(_CLASSES)


def registered_models() -> dict[str, ModelEntry]:
    """Command-line name → :class:`ModelEntry` of every ``twin train`` model.

    Returns
    -------
    dict of str to ModelEntry
        A copy.
    """
    _load_all()
    return dict(_MODELS)


def model_names() -> list[str]:
    """The sorted command-line model names.

    Returns
    -------
    list of str
        Lower-case names, as ``twin train --model`` takes them.
    """
    return sorted(registered_models())


def model_traits(estimator: object) -> ModelTraits:
    """The input contract of ``estimator``'s class; the default (static, any inputs) if it is not registered.

    Parameters
    ----------
    estimator : object
        Any object (its class name is looked up).

    Returns
    -------
    ModelTraits
    """
    _load_all()
    return _TRAITS.get(type(estimator).__name__, ModelTraits())

