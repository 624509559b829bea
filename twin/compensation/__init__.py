"""twin.compensation: ``twin train``, ``twin evaluate`` and ``twin study`` — thermal-error compensation models.

- :mod:`twin.compensation.store` — :class:`~twin.compensation.store.CompensationModel`: a fitted model with its
  channels and preprocessing, saved as JSON; :mod:`twin.compensation.model_names` — the model names;
- :mod:`twin.compensation.train` — load datasets, train, evaluate, and the twin as a physics predictor;
- :mod:`twin.compensation.studies` — cross-condition, thesis-protocol and hybrid studies;
- :mod:`twin.compensation.cli` — the commands.
"""
