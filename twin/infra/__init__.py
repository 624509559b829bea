"""twin.infra: machinery the capabilities share, knowing no physics of their own.

- :mod:`twin.infra.sweep` — independent tasks on a Dask cluster (or serially), results in order;
- :mod:`twin.infra.outdir` — output folders and files: checked before the work, written atomically;
- :mod:`twin.infra.progress` — progress bars; :mod:`twin.infra.cli_common` — options the commands share;
- :mod:`twin.infra.plots` — dataset figures (matplotlib); :mod:`twin.infra.render` — 3-D pictures (pyvista);
- :mod:`twin.infra.tables` — Markdown tables.

``infra`` may use :mod:`twin.core`, never a capability subpackage (tests/test_architecture.py).
"""
