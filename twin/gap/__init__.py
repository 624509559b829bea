"""twin.gap: sim-to-real gap diagnosis of the thermal twin, and its blind benchmark.

- :func:`twin.gap.diagnose.diagnose` — measured record + nominal twin → where the twin misses, which
  candidate effect explains it (fitted, ranked by held-out evidence), how far the residual shrinks;
- :func:`twin.gap.report.write_report` — the Markdown report with figures;
- :func:`twin.gap.benchmark.benchmark` — the blind check: effects switched on in a finer, noisier truth;
- :func:`twin.gap.effects.default_library` — the candidate effects;
- :mod:`twin.gap.cli` — ``twin gap diagnose|truth|benchmark``.

Nothing is imported here: the command line imports :mod:`twin.gap.cli`, which must not load numpy.
"""
