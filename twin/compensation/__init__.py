"""twin.compensation: ``twin train``, ``twin evaluate`` and ``twin study`` — thermal-error compensation models.

- :mod:`twin.compensation.store` — :class:`~twin.compensation.store.CompensationModel`: a fitted model with its
  channels and preprocessing, saved as JSON; the model names come from :mod:`models.registry`;
- :mod:`twin.compensation.records` — the clocks and start of measured records: sampling, long steps, records
  that continue one another, a start at rest;
- :mod:`twin.compensation.record_order` — the canonical order of training records (first time stamp, then
  content), so that ``twin train`` gives one model whatever order its files are given in;
- :mod:`twin.compensation.protocol` — ``--select auto``, the refusal of unstable fits, ``--reference train``;
- :mod:`twin.compensation.train` — load datasets, train, evaluate, and the twin as a physics predictor;
- :mod:`twin.compensation.studies` — cross-condition, thesis-protocol and hybrid studies;
  :mod:`twin.compensation.study_report` — their Markdown reports, figures and folders;
- :mod:`twin.compensation.cli` — the commands.
"""
