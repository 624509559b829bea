"""twin.gap: sim-to-real gap diagnosis of the thermal twin, and its blind benchmark.

- :func:`diagnose` — measured record + nominal twin → where the twin misses, which candidate effect
  explains it (fitted, ranked by held-out evidence), how far the residual shrinks (:mod:`.diagnose`);
- :func:`write_report` — the Markdown report with figures (:mod:`.report`);
- :func:`benchmark` — the blind check: effects switched on in a finer, noisier truth (:mod:`.benchmark`);
- :func:`default_library` — the candidate effects (:mod:`.effects`).
"""
from .benchmark import benchmark
from .diagnose import Diagnosis, diagnose
from .effects import default_library, library_by_name

__all__ = ["Diagnosis", "benchmark", "default_library", "diagnose", "library_by_name", "write_report"]


def write_report(diagnosis, out_dir, render=True, overwrite=False):
    """Write the diagnosis report (see :func:`twin.gap.report.write_report`)."""
    from .report import write_report as _write

    return _write(diagnosis, out_dir, render=render, overwrite=overwrite)
