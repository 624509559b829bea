"""twin.fmu: FMI 2.0 (and 3.0) Co-Simulation FMUs of the thermal twin.

- :mod:`twin.fmu.export` — :func:`~twin.fmu.export.export_fmu` (Python or native C), ``validate`` (fmpy),
  ``simulate`` an FMU through a scenario and the input tables it needs;
- :mod:`twin.fmu.spec` — the interface both kinds share: variables, units, GUID, model structure, ``FMUError``;
- :mod:`twin.fmu.session` — :class:`~twin.fmu.session.FMUSession`, an FMU stepped by hand;
- :mod:`twin.fmu.native_source` — the C sources of the native kind (fixed files in ``c/``, package data) and
  the generated ``model_data.h``;
- ``thermal_twin_slave.py`` — the PythonFMU slave, copied into every Python FMU (it runs outside this package);
- :mod:`twin.fmu.cli` — ``twin fmu export|validate|simulate``.

Nothing is imported here: the command line imports :mod:`twin.fmu.cli`, which must not load numpy.
"""
