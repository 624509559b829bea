"""twin.rom: ``twin rom`` — reduced-order models of the twin's thermal system and their error against the FE.

- :mod:`twin.rom.reduction` — Krylov or modal reduction to a state-space model, cached; simulating it;
- :mod:`twin.rom.report` — the error against the full FE over orders, methods and scenarios;
- :mod:`twin.rom.cli` — ``twin rom build|report``.
"""
