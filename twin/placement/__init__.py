"""twin.placement: ``twin place`` — where to put K thermometers so that a compensation model generalises.

- :mod:`twin.placement.candidates` — candidate locations (surface nodes, camera spots) as output rows;
- :mod:`twin.placement.records` — scenarios and step responses through the twin, cached on disk, noise;
- :mod:`twin.placement.selection` — the seed pipelines and our methods choose sets per axis and K;
- :mod:`twin.placement.scoring` — a compensation model per set, scored on unseen scenarios; the best set;
- :mod:`twin.placement.report` — tables, verdicts, files, render;
- :mod:`twin.placement.study` — :func:`~twin.placement.study.placement_study`, the steps in order;
- :mod:`twin.placement.cli` — the command.

Nothing is imported here: ``twin --help`` must not load numpy.
"""
