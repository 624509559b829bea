"""Step-by-step use of a twin FMU in fmpy (``doStep`` loop), with the FMU's log messages collected.

>>> with FMUSession("twin.fmu", T_initial=20.0) as s:         # doctest: +SKIP
...     s.set(spindle_speed=9000.0, ambient_room=20.0, ambient_front=20.0)
...     s.step(10.0)
...     s.get("Z")
"""
from __future__ import annotations

import shutil
from ctypes import byref
from pathlib import Path

from .spec import FMUError


class FMUStepError(FMUError):
    """The FMU rejected a call (``fmi2Error``; a Python FMU's ``fmi2Fatal``); ``messages`` holds what it logged.

    Parameters
    ----------
    message : str
        What failed.
    messages : list of str
        The FMU's log messages during the call (appended to the text).
    """

    def __init__(self, message: str, messages: list[str]):
        super().__init__(message + ("; the FMU logged: " + " | ".join(messages) if messages else ""))
        self.messages = messages


class FMUSession:
    """An instantiated, initialised FMI 2 co-simulation FMU driven step by step.

    Parameters
    ----------
    path : the FMU file
    T_initial, steady_start : the FMU's start parameters
    inputs : input values set before initialisation ends (dict name → value)
    start_time : start of the simulation, s
    logging_on : let the FMU log every message (not only errors)

    Raises
    ------
    FMUStepError
        If the FMU refuses a start value (an input or parameter out of range or not finite).
    """

    def __init__(self, path: Path | str, T_initial: float = 20.0, steady_start: bool = False,
                 inputs: dict[str, float] | None = None, start_time: float = 0.0, logging_on: bool = False):
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                               fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
        from fmpy import calloc, free

        self.description = read_model_description(str(path), validate=False)
        self.vr = {v.name: v.valueReference for v in self.description.modelVariables}
        self.types = {v.name: v.type for v in self.description.modelVariables}
        self.outputs = [v.name for v in self.description.modelVariables if v.causality == "output"]
        self.inputs = [v.name for v in self.description.modelVariables if v.causality == "input"]
        self.messages = []
        self._unzipped = extract(str(path))

        def logger(env, instance, status, category, message):
            self.messages.append(f"[{category.decode(errors='replace') if category else ''}] "
                                 f"{message.decode(errors='replace') if message else ''}")

        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(logger)
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        try:
            from fmpy.logging import addLoggerProxy

            addLoggerProxy(byref(callbacks))
        except (ImportError, OSError, AttributeError):  # pragma: no cover - fmpy without its native logging
            pass                      # helper (module, shared library or symbol missing): messages stay unformatted
        self._callbacks = callbacks   # keep the ctypes callbacks alive
        self.fmu = FMU2Slave(guid=self.description.guid, unzipDirectory=self._unzipped,
                             modelIdentifier=self.description.coSimulation.modelIdentifier,
                             instanceName="twin")
        self.fmu.instantiate(callbacks=callbacks, loggingOn=bool(logging_on))
        self.time = float(start_time)
        try:
            self._initialise({k: v for k, v in (("T_initial", T_initial), ("steady_start", steady_start))
                              if k in self.vr}, inputs or {})
        except FMUError:
            self.close()
            raise

    def _initialise(self, parameters, inputs):
        self.fmu.setupExperiment(startTime=self.time)
        self._set_values(parameters)
        self.fmu.enterInitializationMode()
        self._set_values(inputs)
        self._call(self.fmu.exitInitializationMode, "exitInitializationMode")

    # ---------------------------------------------------------------- values
    def _set_values(self, values):
        for name, value in values.items():
            if name not in self.vr:
                raise FMUError(f"the FMU has no variable {name!r}; inputs: {self.inputs}")
            if self.types[name] == "Boolean":
                self._call(self.fmu.setBoolean, f"setting {name}", [self.vr[name]], [bool(value)])
            else:
                self._call(self.fmu.setReal, f"setting {name}", [self.vr[name]], [float(value)])

    def set(self, **inputs: float) -> None:
        """Set input values by name (the FMU checks each against its range as it is set).

        Parameters
        ----------
        **inputs
            Variable name → value, in the variable's unit (Boolean parameters take a bool).

        Raises
        ------
        FMUError
            For a name the FMU does not have.
        FMUStepError
            For a value the FMU refuses (not finite, out of range, a fixed parameter after initialisation).
        """
        self._set_values(inputs)

    def get(self, *names: str) -> float | list[float]:
        """Values of Real variables: one name → a float, several → a list.

        Parameters
        ----------
        *names
            Variable names.

        Returns
        -------
        float or list of float
            In the variables' units (°C, µm, µε …).
        """
        values = self.fmu.getReal([self.vr[n] for n in names])
        return values[0] if len(names) == 1 else list(values)

    def _call(self, fn, what, *args):
        from fmpy.fmi1 import FMICallException

        before = len(self.messages)
        try:
            fn(*args)
        except FMICallException as exc:
            raise FMUStepError(f"{what} failed with status {exc.status}", self.messages[before:]) from None

    def step(self, h: float) -> None:
        """Advance by ``h`` s (``doStep``); raise :class:`FMUStepError` if the FMU refuses.

        Parameters
        ----------
        h : float
            Communication step, s.
        """
        self._call(self.fmu.doStep, f"doStep at t = {self.time:g} s", self.time, float(h))
        self.time += float(h)

    # ---------------------------------------------------------------- lifetime
    def close(self) -> None:
        """Terminate and free the instance and delete its unzipped folder; a second call does nothing."""
        if self.fmu is not None:
            from fmpy.fmi1 import FMICallException

            try:
                self.fmu.terminate()
            except FMICallException:   # an FMU that refused a step may refuse to terminate: it is freed anyway
                pass
            self.fmu.freeInstance()
            self.fmu = None
            shutil.rmtree(self._unzipped, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
