"""twin.run: ``twin run``, ``twin mesh`` and ``twin report`` — a scenario or a dataset to a result folder.

- :mod:`twin.run.workflows` — run a scenario, mesh a machine, report a dataset (plots, views, summary);
- :mod:`twin.run.summary` — the run summary and the ISO 230-3 quantities;
- :mod:`twin.run.calibration` — the default machine's calibration targets and how the twin meets them;
- :mod:`twin.run.cli` — the commands.
"""
