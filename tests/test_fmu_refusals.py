"""What the FMUs refuse, and how: bad values, steps out of time, fixed parameters, broken FMU files, failed exports.

A refused value ends a standard master's run with an error naming it (it made fmpy retry for ever, or stop early
without a word); the Python FMU's refusals cannot crash its host (two of them did).  The FMI calls that may
crash or loop on a broken FMU run in a process of their own (``_SCRIPT``), stopped by fmpy's ``step_finished``
after three times the steps a run needs, never by a clock.
"""
import json
import math
import re
import subprocess
import sys
import zipfile

import numpy as np
import pytest
from test_cli_outdir import one_error_line

from twin.cli import main
from twin.core.scenario import load_scenario
from twin.fmu import export as export_module
from twin.fmu.export import export_fmu, fmu_identity, input_table, simulate
from twin.fmu.session import FMUSession, FMUStepError
from twin.fmu.spec import FMUError

KINDS = ("native", "python")


@pytest.fixture(scope="module")
def fmus(rom, tmp_path_factory):
    folder = tmp_path_factory.mktemp("refusals")
    return {kind: export_fmu(rom, folder / f"twin_{kind}.fmu", kind=kind) for kind in KINDS}


def _ambients(rom, value=20.0):
    return {f"ambient_{z}": value for z in rom.measured_zones}


_SCRIPT = r'''
import json
import sys

import numpy as np
from fmpy import calloc, extract, free, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                       fmi2CallbackLoggerTYPE)

MESSAGES = []


def log(*args):
    MESSAGES.append(args[-1].decode())


def status(call):
    try:
        call()
        return 0
    except FMICallException as exc:
        return int(exc.status)


def run(path, rows):
    """fmpy.simulate_fmu on a spindle-speed table, stopped after three times the steps it needs."""
    table = np.array(rows, dtype=[("time", float), ("spindle_speed", float)])
    calls = [0]

    def step_finished(time, recorder):
        calls[0] += 1
        return calls[0] < 3 * rows[-1][0] / 10.0

    try:
        result = simulate_fmu(path, stop_time=rows[-1][0], step_size=10.0, input=table, output=["Z"],
                              debug_logging=True, logger=log, step_finished=step_finished)
    except FMICallException as exc:
        return {"error": str(exc)}
    return {"error": None, "last_time": float(result["time"][-1])}


def refused(path):      # a bad sensor value for 10 minutes
    return run(path, [(0, 1000), (600, 1000), (600, -100), (1200, -100), (1200, 1000), (1800, 1000)])


def at_max(path):       # fmpy's interpolation of the constant 12000 rpm gives 12000.000000000002
    return run(path, [(0, 0), (7200, 0), (7200, 12000), (10800, 12000)])


def instance(path):
    md = read_model_description(path)
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(log)
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    f = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="t")
    f.instantiate(callbacks=callbacks, loggingOn=True)
    f.keep = callbacks
    f.setupExperiment(startTime=0.0)
    f.enterInitializationMode()
    f.exitInitializationMode()
    return f, {v.name: v.valueReference for v in md.modelVariables}


def times(path):
    f, vr = instance(path)
    for k in range(3):
        f.doStep(10.0 * k, 10.0)
    state = f.getFMUstate()
    for k in range(3, 10):
        f.doStep(10.0 * k, 10.0)
    out = {f"at {t!r}": status(lambda: f.doStep(t, 10.0)) for t in (50.0, 5000.0, -1e9, 110.0)}
    out["at 100 + rounding"] = status(lambda: f.doStep(100.0 + 1e-9, 10.0))
    f.setFMUstate(state)
    out["at 30 after the restore"] = status(lambda: f.doStep(30.0, 10.0))
    out["at 120 after the restore"] = status(lambda: f.doStep(120.0, 10.0))
    f.freeFMUstate(state)
    f.terminate()
    f.freeInstance()
    return out


def fixed_after_initialisation(path):
    f, vr = instance(path)
    f.doStep(0.0, 10.0)
    sets = [status(lambda: f.setReal([vr["T_initial"]], [25.0])) for _ in range(3)]
    sets.append(status(lambda: f.setBoolean([vr["steady_start"]], [True])))
    step = status(lambda: f.doStep(10.0, 10.0))
    T_initial, z = f.getReal([vr["T_initial"], vr["Z"]])
    terminate = status(f.terminate)
    f.freeInstance()
    return {"sets": sets, "step": step, "T_initial": T_initial, "Z": z, "terminate": terminate}


def unreadable_state(path):
    f, vr = instance(path)
    f.doStep(0.0, 10.0)
    refusals = []
    for _ in range(2):
        try:
            state = f.deSerializeFMUstate(b"garbage")
        except FMICallException as exc:
            refusals.append(int(exc.status))
            continue
        refusals.append(status(lambda: f.setFMUstate(state)))
    step = status(lambda: f.doStep(10.0, 10.0))
    z = f.getReal([vr["Z"]])[0]
    terminate = status(f.terminate)
    f.freeInstance()
    return {"refusals": refusals, "step": step, "Z": z, "terminate": terminate}


out = globals()[sys.argv[1]](sys.argv[2])
out["messages"] = MESSAGES
print(json.dumps(out))
'''


def _in_own_process(case, fmu, tmp_path):
    """``case`` of ``_SCRIPT`` on ``fmu`` in a fresh process (a crash is its exit code, not pytest's)."""
    script = tmp_path / "refusals.py"
    script.write_text(_SCRIPT, encoding="utf-8")
    run = subprocess.run([sys.executable, str(script), case, str(fmu)], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, f"exit {run.returncode}: {run.stderr[-2000:]}"
    return json.loads(run.stdout.strip().splitlines()[-1])


# ----------------------------------------------------------------------------- values
@pytest.mark.parametrize("kind", KINDS)
def test_fmpy_run_with_a_refused_input_ends_with_an_error_naming_it(fmus, kind, tmp_path):
    """It looped for ever (native: fmi2Discard from doStep, not terminated) or ended early without an error
    (Python: fmi2Discard with fmi2Terminated)."""
    out = _in_own_process("refused", fmus[kind], tmp_path)
    assert out["error"] and out["error"].startswith("fmi2SetReal failed with status"), out
    assert "fmi2SetReal: spindle_speed = -100 is outside [0, 12000]" in out["messages"]


@pytest.mark.parametrize("kind", KINDS)
def test_fmpy_run_at_the_top_speed_is_not_refused_for_rounding(fmus, kind, tmp_path):
    out = _in_own_process("at_max", fmus[kind], tmp_path)
    assert out["error"] is None and out["last_time"] == 10800.0, out


@pytest.mark.parametrize("kind", KINDS)
def test_a_value_within_rounding_of_a_bound_is_the_bound_and_one_beyond_is_printed_exactly(fmus, rom, kind):
    with FMUSession(fmus[kind], inputs=_ambients(rom), logging_on=True) as s:
        s.set(spindle_speed=12000.000000000002, ambient_room=-50.0 - 1e-12)
        assert s.get("spindle_speed", "ambient_room") == [12000.0, -50.0]
        with pytest.raises(FMUStepError, match=re.escape("spindle_speed = 12000.001 is outside [0, 12000]")):
            s.set(spindle_speed=12000.001)
        assert s.get("spindle_speed") == 12000.0
        s.step(10.0)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize(("value", "message"), [
    (math.nan, "fmi2SetReal: T_initial = nan is not a finite number"),
    (500.0, "fmi2SetReal: T_initial = 500 is outside [-50, 100]"),
    (-300.0, "fmi2SetReal: T_initial = -300 is outside [-50, 100]"),
])
def test_an_initial_temperature_out_of_range_or_nan_is_refused(fmus, kind, value, message):
    """Both FMUs started from 500 °C, and the Python one from NaN (all outputs NaN, status OK)."""
    with pytest.raises(FMUStepError, match=re.escape(message)):
        FMUSession(fmus[kind], T_initial=value, logging_on=True)


# ----------------------------------------------------------------------------- steps
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("h", [math.inf, math.nan, 0.0, -10.0])
def test_a_step_that_is_not_positive_and_finite_is_refused(fmus, rom, kind, h):
    """The Python FMU took a step of +inf."""
    with FMUSession(fmus[kind], inputs=_ambients(rom), logging_on=True) as s:
        with pytest.raises(FMUStepError, match="must be positive and finite"):
            s.step(h)
        s.step(10.0)
        assert math.isfinite(s.get("Z"))


@pytest.mark.parametrize("kind", KINDS)
def test_a_step_starts_at_the_fmus_time_or_at_that_of_a_restored_state(fmus, kind, tmp_path):
    """After stepping to t = 100 s, steps from 50, 5000 and -1e9 s were taken (status OK)."""
    out = _in_own_process("times", fmus[kind], tmp_path)
    refused = 3 if kind == "native" else 4              # PythonFMU reports a refusing slave as fmi2Fatal
    assert [out[f"at {t!r}"] for t in (50.0, 5000.0, -1e9, 110.0)] == [refused] * 4, out
    assert "fmi2DoStep at t = 50 s: the FMU is at t = 100 s; a step starts where the last one ended (or at the " \
           "time of a state restored with SetFMUstate)" in out["messages"]
    assert out["at 100 + rounding"] == 0 and out["at 30 after the restore"] == 0, out
    assert out["at 120 after the restore"] == refused, out


# ----------------------------------------------------------------------------- fixed parameters
@pytest.mark.parametrize("kind", KINDS)
def test_setting_a_fixed_parameter_after_initialisation_is_refused_and_harmless(fmus, kind, tmp_path):
    """Python FMU: two such sets (fmi2Fatal), then fmi2Terminate, crashed the host (exit 139)."""
    out = _in_own_process("fixed_after_initialisation", fmus[kind], tmp_path)
    refused = 3 if kind == "native" else 4
    assert out["sets"] == [refused] * 4 and out["step"] == 0 and out["terminate"] == 0, out
    assert out["T_initial"] == 20.0 and math.isfinite(out["Z"])
    assert "fmi2SetReal: T_initial is a fixed parameter: it can only be set before initialisation ends" \
        in out["messages"]


@pytest.mark.parametrize("kind", KINDS)
def test_bytes_that_are_no_state_are_refused_and_harmless(fmus, kind, tmp_path):
    """Python FMU: PythonFMU reads state bytes on the class, outside _keeping_alive: two garbage deserialisations
    then fmi2FreeInstance crashed the host (exit 139)."""
    out = _in_own_process("unreadable_state", fmus[kind], tmp_path)
    assert all(code >= 3 for code in out["refusals"]) and len(out["refusals"]) == 2, out
    assert out["step"] == 0 and out["terminate"] == 0 and math.isfinite(out["Z"]), out


# ----------------------------------------------------------------------------- through twin's own runner
def test_simulate_turns_a_refused_input_into_an_error_naming_it(fmus, rom):
    """twin.fmu.export.simulate (used by twin fmu simulate) raised fmpy's bare exception, or (native) looped."""
    table = input_table(rom, load_scenario("heat_cool_9000"))[:40].copy()
    table["spindle_speed"][20:] = -5.0
    calls = []
    with pytest.raises(FMUError, match=re.escape("spindle_speed = -5 is outside [0, 12000]")):
        simulate(fmus["native"], table, step_finished=lambda *a: calls.append(1) or len(calls) < 200)


# ----------------------------------------------------------------------------- broken FMU files
def _changed(fmu, prefix, out, content=None):
    """A copy of ``fmu`` whose members whose names start with ``prefix`` are left out, or hold ``content``."""
    with zipfile.ZipFile(fmu) as zin, zipfile.ZipFile(out, "w") as zout:
        for item in zin.infolist():
            if not item.filename.startswith(prefix):
                zout.writestr(item, zin.read(item.filename))
            elif content is not None:
                zout.writestr(item, content)
    return out


@pytest.mark.parametrize(("kind", "prefix", "content", "missing"), [
    ("native", "binaries/", None, ("binaries/linux64/thermal_twin_rom.so is missing: the shared library for this "
                                   "platform (linux64); its sources/ can rebuild it")),
    ("python", "binaries/", None, "binaries/linux64/ThermalTwin.so is missing: the shared library for this platform"),
    ("python", "resources/rom.npz", None, "resources/rom.npz is missing: the reduced model the slave runs"),
    ("python", "resources/interface.json", b"{}",          # validate raised KeyError: 'engine'
     "resources/interface.json is unreadable: not a JSON object naming the slave's engine"),
])
def test_an_fmu_without_its_binary_or_rom_data_is_reported_not_run(fmus, kind, prefix, content, missing, tmp_path,
                                                                   capsys):
    """simulate ended in a traceback ("Failed to instantiate model") and validate said "no problems"."""
    broken = str(_changed(fmus[kind], prefix, tmp_path / "broken.fmu", content))
    assert main(["fmu", "simulate", broken, "heat_cool_9000", "--out", str(tmp_path / "x.csv")]) == 2
    err = one_error_line(capsys)
    assert f"{broken}: cannot run here: {missing}" in err, err
    assert not (tmp_path / "x.csv").exists()
    assert main(["fmu", "validate", broken]) == 2
    captured = capsys.readouterr()
    assert f"problem: {missing}" in captured.out and "broken.fmu: 1 problem(s)" in captured.err


# ----------------------------------------------------------------------------- exports
@pytest.mark.parametrize(("kind", "outputs", "message"), [
    ("native", "T01,T01", "--outputs names output 'T01' more than once"),
    ("python", "Z,Z", "--outputs names output 'Z' more than once"),
    ("native", "", "--outputs must name at least one output, got none"),
])
def test_export_refuses_outputs_that_name_nothing_or_one_twice(kind, outputs, message, tmp_path, capsys):
    """T01,T01 left an invalid FMU, Z,Z an internal message and a .partial file; "" meant every output."""
    out = tmp_path / "o.fmu"
    assert main(["fmu", "export", "--kind", kind, "--outputs", outputs, "--out", str(out)]) == 2
    assert message in one_error_line(capsys)
    assert list(tmp_path.iterdir()) == []


def test_a_failed_export_leaves_neither_the_fmu_nor_a_partial_file(rom, tmp_path, monkeypatch):
    """The FMU is validated before it takes its name: one with a problem never replaces the file there."""
    out = tmp_path / "kept.fmu"
    out.write_bytes(b"the previous export")
    monkeypatch.setattr(export_module, "validate", lambda path: ["a problem"])
    with pytest.raises(FMUError, match=r"kept.fmu: not written: the exported FMU has 1 problem\(s\): a problem"):
        export_fmu(rom, out, kind="native", outputs=["Z"])
    assert [p.name for p in tmp_path.iterdir()] == ["kept.fmu"] and out.read_bytes() == b"the previous export"


def test_an_fe_engine_fmu_says_it_runs_the_full_model(tmp_path, capsys):
    """Its description, the export message and twin fmu simulate said "krylov ROM of order 80"."""
    out = tmp_path / "fe.fmu"
    assert main(["fmu", "export", "--kind", "python", "--engine", "fe", "--outputs", "T18,Z", "--out", str(out)]) == 0
    assert "engine fe (full finite-element model, 2 outputs)" in capsys.readouterr().out
    identity = fmu_identity(out)
    assert (identity.method, identity.order) == (None, None)
    assert str(identity).startswith("the full FE model of machine 'vmc_ram'")


def test_simulate_writes_units_in_its_csv_header(fmus, tmp_path, capsys):
    """Columns are named <name>_<unit>, as in the datasets (it wrote Z, T01)."""
    out = tmp_path / "run.csv"
    assert main(["fmu", "simulate", str(fmus["native"]), "heat_cool_9000", "--out", str(out)]) == 0
    header = out.read_text(encoding="utf-8").splitlines()[0].split(",")
    assert header[0] == "time_s" and {"T01_degC", "A_front_degC", "Z_um", "FBG1_ue"} <= set(header)
    assert "it runs a krylov ROM of order 80 of machine 'vmc_ram'" in capsys.readouterr().out
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    assert data.shape[1] == len(header)
