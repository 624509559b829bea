"""FMUs of the default machine: export, fmpy validation (zero problems), simulation, match with the twin."""
import ast
import copy
import math
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from test_cli_outdir import one_error_line

from twin.cli import main
from twin.core.scenario import load_scenario
from twin.fmu.export import (
    export_fmu,
    fmu_identity,
    input_table,
    scenario_start,
    simulate,
    simulate_table,
    validate,
)
from twin.fmu.session import FMUSession, FMUStepError
from twin.fmu.spec import FMUError
from twin.rom.reduction import simulate_rom

KINDS = ("native", "python")


@pytest.fixture(scope="module")
def fmus(rom, tmp_path_factory):
    folder = tmp_path_factory.mktemp("fmus")
    return {kind: export_fmu(rom, folder / f"twin_{kind}.fmu", kind=kind) for kind in KINDS}


def _relative_difference(result, reference, names):
    worst = 0.0
    for j, name in enumerate(names):
        scale = max(float(np.abs(reference[:, j]).max()), 1e-12)
        worst = max(worst, float(np.abs(result[name] - reference[:, j]).max()) / scale)
    return worst


@pytest.mark.parametrize("kind", KINDS)
def test_fmu_validates_with_zero_problems(fmus, kind):
    assert validate(fmus[kind]) == []


@pytest.mark.parametrize("kind", KINDS)
def test_units_and_interface_are_declared(fmus, rom, kind):
    from fmpy import read_model_description

    md = read_model_description(str(fmus[kind]))
    assert md.fmiVersion == "2.0" and md.coSimulation is not None
    by_name = {v.name: v for v in md.modelVariables}
    assert by_name["spindle_speed"].unit == "rpm" and by_name["spindle_speed"].causality == "input"
    assert by_name["feed_x"].unit == "mm/min"
    for zone in rom.measured_zones:
        assert by_name[f"ambient_{zone}"].unit == "degC"
    # a lagged zone's air is a state of the model, not an input a plant would have to compute
    assert rom.lagged_zones == ["enclosure"] and "ambient_enclosure" not in by_name
    assert "'enclosure' (3 h)" in by_name["ambient_room"].description
    assert by_name["T_initial"].causality == "parameter" and by_name["T_initial"].unit == "degC"
    for axis in "XYZ":
        assert by_name[axis].unit == "um" and by_name[axis].causality == "output"
    assert by_name["T01"].unit == "degC"
    units = {u.name for u in md.unitDefinitions}
    assert {"degC", "um", "rpm", "mm/min"} <= units


@pytest.mark.parametrize("kind", KINDS)
def test_fmu_from_csv_matches_the_twin(fmus, rom, kind, tmp_path):
    """The input table goes through a CSV file, as a user would feed fmpy."""
    from fmpy.util import read_csv

    scenario = load_scenario("heat_cool_9000")
    table = input_table(rom, scenario)
    csv = tmp_path / "inputs.csv"
    np.savetxt(csv, np.column_stack([table[n] for n in table.dtype.names]), delimiter=",",
               header=",".join(table.dtype.names), comments="", fmt="%.17g")
    T0, steady = scenario_start(rom, scenario)
    result = simulate(fmus[kind], read_csv(str(csv)), T_initial=T0, steady_start=steady)
    reference = simulate_table(rom, table, T0, steady)
    assert len(result) == len(scenario.times()) == len(reference)
    assert _relative_difference(result, reference, rom.output_names) < 1e-6
    # ... which is the in-process twin's scenario run (ROM, ZOH), every channel and sample
    twin = simulate_rom(rom, scenario)
    assert _relative_difference(result, twin.matrix(rom.output_names), rom.output_names) < 1e-6


def test_native_fmu_runs_the_etve_with_a_steady_start(fmus, rom):
    scenario = load_scenario("etve_160h")
    table = input_table(rom, scenario)
    T0, steady = scenario_start(rom, scenario)
    assert steady
    result = simulate(fmus["native"], table, T_initial=T0, steady_start=True)
    assert _relative_difference(result, simulate_table(rom, table, T0, True), rom.output_names) < 1e-6
    # steady start with the machine idle, as the twin does; conditions held over each step, as the FMU gets them.
    # The twin lags the enclosure air outside the model (from the room ambient interpolated between samples);
    # the FMU gets only the room and lags it inside: the two agree within the ROM's own error goal.
    twin = simulate_rom(rom, scenario, inputs="held")
    assert _worst_by_unit(result, twin.matrix(rom.output_names), rom) == pytest.approx(
        {"degC": 0.0, "um": 0.0}, abs=0.01)                                  # K and µm (goal 0.01 K, 0.05 µm)


def _worst_by_unit(result, reference, rom):
    """Largest |FMU − reference| per output unit (degC, um, ue) over time and channels."""
    out = {}
    for j, (name, unit) in enumerate(zip(rom.output_names, rom.output_units)):
        out[unit] = max(out.get(unit, 0.0), float(np.abs(result[name] - reference[:, j]).max()))
    return {u: out[u] for u in ("degC", "um")}


def _ambients(rom, value=20.0):
    return {f"ambient_{z}": value for z in rom.measured_zones}


def test_native_fmu_handles_any_step_size_exactly(fmus, rom):
    steps = [10.0, 10.0, 35.0, 0.5, 600.0, 10.0]
    inputs = dict(spindle_speed=9000.0, **_ambients(rom, 19.0))
    with FMUSession(fmus["native"], T_initial=20.0, inputs=inputs) as s:
        for h in steps:
            s.step(h)
        z_fmu = s.get("Z")
    t = np.concatenate([[0.0], np.cumsum(steps)])
    U = rom.inputs_from_conditions(np.full(len(t), 9000.0), {}, 19.0)
    z_rom = rom.simulate(t, U, rom.uniform(20.0))[-1, rom.output_index("Z")]
    assert z_fmu == pytest.approx(z_rom, rel=1e-9)


def test_native_fmu_refuses_bad_inputs_with_fmi2error(fmus, rom):
    """A bad input is refused as it is set, with fmi2Error (fmi2Discard from doStep made fmpy retry for ever);
    the input keeps its value, so a master that restores or goes on steps from a valid state."""
    from fmpy.fmi2 import fmi2Error

    inputs = dict(spindle_speed=1000.0, **_ambients(rom))
    with FMUSession(fmus["native"], inputs=inputs) as s:
        s.step(10.0)
        for bad, pattern in ((dict(spindle_speed=-100.0), "spindle_speed = -100 is outside"),
                             ({f"ambient_{rom.measured_zones[0]}": math.nan},
                              f"ambient_{rom.measured_zones[0]} = nan is not a finite number")):
            with pytest.raises(FMUStepError, match=pattern) as info:
                s.set(**bad)
            assert f"status {fmi2Error}" in str(info.value)
            assert s.get(*bad) == inputs.get(*bad, 20.0)
        s.step(10.0)                                     # the importer goes on
        assert math.isfinite(s.get("Z"))


def test_python_fmu_rejects_bad_inputs_without_crashing(fmus, rom):
    from fmpy.fmi2 import fmi2Fatal

    inputs = dict(spindle_speed=1000.0, **_ambients(rom))
    with FMUSession(fmus["python"], inputs=inputs, logging_on=True) as s:
        s.step(10.0)
        with pytest.raises(FMUStepError, match="spindle_speed = -100 is outside") as info:
            s.set(spindle_speed=-100.0)
        # PythonFMU 0.7 reports a refusing slave as fmi2Fatal (it cannot return fmi2Error from Python)
        assert f"status {fmi2Fatal}" in str(info.value)
        assert s.get("spindle_speed") == 1000.0
        s.step(10.0)
        assert math.isfinite(s.get("Z"))


def test_native_fmu_ships_its_sources_and_rebuilds_from_them(fmus, tmp_path):
    with zipfile.ZipFile(fmus["native"]) as z:
        names = set(z.namelist())
        z.extractall(tmp_path)
    assert {"sources/thermal_twin_rom.c", "sources/model_data.h", "sources/fmi2Functions.h",
            "binaries/linux64/thermal_twin_rom.so", "modelDescription.xml"} <= names
    from xml.etree.ElementTree import fromstring

    root = fromstring((tmp_path / "modelDescription.xml").read_bytes())
    assert [f.get("name") for f in root.findall("CoSimulation/SourceFiles/File")] == ["thermal_twin_rom.c"]
    out = tmp_path / "rebuilt.so"
    run = subprocess.run(["cc", "-shared", "-fPIC", "-O2", "-I", str(tmp_path / "sources"),
                          str(tmp_path / "sources" / "thermal_twin_rom.c"), "-o", str(out), "-lm"],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert out.stat().st_size > 0


def test_python_fmu_carries_the_rom_and_imports_only_numpy(fmus):
    with zipfile.ZipFile(fmus["python"]) as z:
        names = set(z.namelist())
        script = z.read("resources/thermal_twin_slave.py").decode()
    assert {"resources/rom.npz", "resources/interface.json"} <= names
    top = set()
    for node in ast.parse(script).body:
        if isinstance(node, ast.Import):
            top |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            top.add(node.module.split(".")[0])
    assert top <= {"ctypes", "json", "math", "os", "numpy", "pythonfmu"}


def test_cli_exports_and_validates(tmp_path, capsys):
    out = tmp_path / "cli.fmu"
    assert main(["fmu", "export", "--kind", "native", "--out", str(out), "--outputs", "T01,X,Y,Z"]) == 0
    assert "no problems" in capsys.readouterr().out
    assert main(["fmu", "validate", str(out)]) == 0


def test_an_fmu_names_the_model_it_runs(fmus, fmu3, rom):
    """Machine, digest, method and order are read back from every kind's description (fmu simulate needs them)."""
    for path in (*fmus.values(), fmu3):
        identity = fmu_identity(path)
        assert (identity.machine, identity.digest, identity.method, identity.order) == (
            rom.machine, rom.digest, rom.method, rom.order)


@pytest.mark.parametrize("name", ["O'Neil mill", "a\\b", 'bay "3"', "Fräse 5"])
def test_an_fmu_names_any_machine_a_toml_file_can_name(fmus, rom, tmp_path, name):
    """A name with a quote or a backslash was read back wrong or not at all (the FMU then refused as another
    machine's, or as no twin's)."""
    renamed = copy.copy(rom)
    renamed.machine = name
    identity = fmu_identity(export_fmu(renamed, tmp_path / "renamed.fmu", kind="native", outputs=["Z"]))
    assert (identity.machine, identity.digest, identity.order) == (name, rom.digest, rom.order)


def test_an_fmu_of_another_tool_is_not_taken_for_a_twin(fmus, tmp_path):
    other = tmp_path / "other.fmu"
    with zipfile.ZipFile(fmus["native"]) as zin, zipfile.ZipFile(other, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                data = data.replace(b'description="Thermal twin of machine', b'description="A plant of machine')
            zout.writestr(item, data)
    with pytest.raises(FMUError, match="other.fmu: not a thermal-twin FMU of this version"):
        fmu_identity(other)
    with zipfile.ZipFile(tmp_path / "empty.fmu", "w") as zout:       # a zip without a model description
        zout.writestr("readme.txt", "no model")
    with pytest.raises(FMUError, match=r"empty.fmu: not an FMU \(KeyError"):
        fmu_identity(tmp_path / "empty.fmu")


def test_fmu_simulate_compares_the_fmu_with_its_own_rom_and_refuses_another(fmus, tmp_path, capsys):
    """Another order, machine, mesh or source, or a scenario of another machine, would compare two models and
    report their difference as the FMU's (it exited 0 with 11 % and 1900 %)."""
    fmu, out = str(fmus["native"]), str(tmp_path / "out.csv")
    assert main(["fmu", "simulate", fmu, "heat_cool_9000", "--out", out]) == 0
    shown = capsys.readouterr().out.splitlines()[-1]
    assert shown.startswith("largest relative difference from the in-process krylov ROM of order 80: ")
    assert float(shown.rsplit(" ", 1)[1]) < 1e-9
    hot = tmp_path / "vmc_hot.toml"     # the same machine name, mesh and sensors; a front bearing 15 W hotter
    source = (Path(__file__).parents[1] / "meshes" / "machines" / "vmc_ram.toml").read_text(encoding="utf-8")
    hot.write_text(source.replace("coefficient_W = 105.0", "coefficient_W = 120.0", 1), encoding="utf-8")
    refused = {
        ("heat_cool_9000", "--order", "40"): "--order 40 --method krylov: ",
        ("heat_cool_9000", "--method", "modal"): "--order 80 --method modal: ",
        ("heat_cool_9000", "--machine", "machine_a"): "--machine machine_a is machine 'machine_a'; ",
        ("machine_a_heat_cool",): "scenario 'machine_a_heat_cool' is written for machine 'machine_a'; ",
        ("heat_cool_9000", "--machine", str(hot)): f"machine {hot} (mesh size its default) has digest ",
    }
    for options, message in refused.items():
        assert main(["fmu", "simulate", fmu, *options, "--out", out, "--overwrite"]) == 2, options
        err = one_error_line(capsys)
        assert message in err and "runs a krylov ROM of order 80 of machine 'vmc_ram' (digest " in err
    # run on the FMU's machine on purpose, as twin run --machine does
    assert main(["fmu", "simulate", fmu, "machine_a_heat_cool", "--machine", "vmc_ram", "--out", out,
                 "--overwrite"]) == 0


@pytest.mark.parametrize(("option", "value", "message"), [
    ("--step", "0", "(--step) 0: the default experiment's step size must be a positive number of seconds"),
    ("--step", "-5", "(--step) -5: "),
    ("--step", "nan", "(--step) nan: "),
    ("--initial-temperature", "500", "(--initial-temperature) 500: must be in [-50, 100] °C"),
    ("--initial-temperature", "nan", "(--initial-temperature) nan: "),
])
def test_fmu_export_refuses_a_start_or_step_the_fmu_cannot_run_with(option, value, message, tmp_path, capsys):
    """They exported with 'no problems', then the FMU failed in its first step or initialisation (or gcc's
    output was the error)."""
    out = tmp_path / "bad.fmu"
    assert main(["fmu", "export", "--kind", "native", option, value, "--out", str(out)]) == 2
    assert message in one_error_line(capsys) and not out.exists()


def test_scenario_start_takes_a_scenario_name_as_input_table_does(rom):
    assert scenario_start(rom, "heat_cool_9000") == scenario_start(rom, load_scenario("heat_cool_9000"))


def test_cli_reports_an_order_too_high(machine, capsys):
    n = machine.thermal.n_nodes
    assert main(["rom", "build", "--order", str(n + 5)]) == 2
    err = capsys.readouterr().err
    assert "exceeds" in err and "thermal unknowns" in err


@pytest.mark.slow
def test_python_fmu_with_the_fe_engine_matches_the_full_model(machine, rom, tmp_path):
    """The full FE inside the FMU (backward Euler, inputs held) against the ROM on a short cycle."""
    path = export_fmu(rom, tmp_path / "fe.fmu", kind="python", engine="fe",
                      fe_options=dict(machine="vmc_ram", max_step_s=60.0), outputs=["T18", "Z"])
    assert validate(path) == []
    t = np.arange(0.0, 3600.0 + 1, 60.0)
    names = ["time", "spindle_speed", "feed_x", "feed_y", "feed_z"] + [f"ambient_{z}" for z in rom.measured_zones]
    table = np.zeros(len(t), dtype=[(n, float) for n in names + ["ambient_gradient"]])
    table["time"], table["spindle_speed"] = t, 9000.0
    for z in rom.measured_zones:
        table[f"ambient_{z}"] = 20.0
    result = simulate(path, table)
    ref = simulate_table(rom, table, outputs=["T18", "Z"])
    assert np.abs(result["Z"] - ref[:, 1]).max() < 0.05 * np.abs(ref[:, 1]).max()


@pytest.fixture(scope="module")
def fmu3(rom, tmp_path_factory):
    return export_fmu(rom, tmp_path_factory.mktemp("fmu3") / "twin_fmi3.fmu", kind="native", fmi_version=3)


def test_fmi3_native_fmu_validates_and_matches_the_twin(fmu3, rom):
    from fmpy import read_model_description

    assert validate(fmu3) == []
    md = read_model_description(str(fmu3))
    assert md.fmiVersion == "3.0"
    assert {v.name: v.unit for v in md.modelVariables}["Z"] == "um"
    scenario = load_scenario("heat_cool_9000")
    table = input_table(rom, scenario)
    T0, steady = scenario_start(rom, scenario)
    result = simulate(fmu3, table, T_initial=T0, steady_start=steady)
    twin = simulate_rom(rom, scenario)
    assert _relative_difference(result, twin.matrix(rom.output_names), rom.output_names) < 1e-6
    with zipfile.ZipFile(fmu3) as z:
        names = set(z.namelist())
    assert {"sources/buildDescription.xml", "sources/thermal_twin_rom.c",
            "binaries/x86_64-linux/thermal_twin_rom.so"} <= names


def test_fmi3_native_fmu_rejects_bad_inputs(fmu3, rom):
    scenario = load_scenario("heat_cool_9000")
    table = input_table(rom, scenario)[:40].copy()
    table["spindle_speed"][20:] = -5.0
    with pytest.raises(Exception, match="fmi3DoStep|status"):
        simulate(fmu3, table)


# ----------------------------------------------------------------------------- FMI semantics
def _instance(path):
    """An fmpy slave (FMI 2 or 3) of the FMU, instantiated; returns (slave, value references, FMI major version)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    from fmpy.fmi3 import FMU3Slave

    md = read_model_description(str(path))
    v3 = md.fmiVersion.startswith("3")
    cls = FMU3Slave if v3 else FMU2Slave
    slave = cls(guid=md.instantiationToken if v3 else md.guid, unzipDirectory=extract(str(path)),
                modelIdentifier=md.coSimulation.modelIdentifier, instanceName="t")
    if v3:
        slave.instantiate()
    else:                            # callbacks of our own, kept alive with the slave, as FMUSession does
        from fmpy import calloc, free
        from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                               fmi2CallbackLoggerTYPE)

        slave.messages = []
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(lambda env, name, status, cat, msg: slave.messages.append(msg))
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        slave.own_callbacks = callbacks
        slave.instantiate(callbacks=callbacks)
    return slave, {v.name: v.valueReference for v in md.modelVariables}, 3 if v3 else 2


def _start_outputs(rom, steady, names, T_initial=25.0, room=23.0, front=21.0, rpm=6000.0):
    """The twin's outputs for the start state T_initial / steady_start imply (the lagged air at the room's)."""
    u = rom.plant_inputs_from_conditions([rpm], {}, {"room": room, "front": front})[0]
    x0 = rom.plant_steady_state(u) if steady else rom.plant_uniform(T_initial, room)
    return rom.plant_outputs(x0, u)[[rom.output_index(n) for n in names]]


@pytest.mark.parametrize("kind", ("native", "fmi3"))
@pytest.mark.parametrize("steady", [False, True])
def test_initialization_mode_outputs_are_the_start_state(fmus, fmu3, rom, kind, steady):
    """Outputs read in Initialization Mode equal those of the state T_initial / steady_start imply (twin ROM)."""
    slave, vr, version = _instance(fmu3 if kind == "fmi3" else fmus[kind])
    get, set_real = (slave.getFloat64, slave.setFloat64) if version == 3 else (slave.getReal, slave.setReal)
    if version == 3:
        slave.enterInitializationMode(startTime=0.0)
        slave.setBoolean([vr["steady_start"]], [steady])
    else:
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.setBoolean([vr["steady_start"]], [steady])
    inputs = {"T_initial": 25.0, "ambient_room": 23.0, "ambient_front": 21.0, "spindle_speed": 6000.0}
    set_real([vr[n] for n in inputs], list(inputs.values()))
    names = ["T01", "A_front", "X", "Z"]
    during = get([vr[n] for n in names])
    np.testing.assert_allclose(during, _start_outputs(rom, steady, names), rtol=1e-12, atol=1e-9)
    slave.exitInitializationMode()
    np.testing.assert_allclose(get([vr[n] for n in names]), during, rtol=0, atol=1e-12)
    slave.terminate()
    slave.freeInstance()


def test_fmu_state_restores_the_model_and_fixed_parameters_stay_fixed(fmus):
    """Native FMU: Get/SetFMUstate restore the run exactly; T_initial is fixed after initialisation;
    doStep after fmi2Terminate is refused (fmi2Error)."""
    kind = "native"
    from fmpy import read_model_description
    from fmpy.fmi1 import FMICallException

    assert read_model_description(str(fmus[kind])).coSimulation.canGetAndSetFMUstate
    slave, vr, _ = _instance(fmus[kind])
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    slave.setReal([vr["spindle_speed"]], [9000.0])
    for k in range(3):
        slave.doStep(60.0 * k, 60.0)
    state = slave.getFMUstate()
    runs = []
    for _ in range(2):
        slave.setFMUstate(state)
        slave.setReal([vr["ambient_room"]], [24.0])
        for k in range(3, 10):
            slave.doStep(60.0 * k, 60.0)
        runs.append(slave.getReal([vr["Z"], vr["T01"]]))
    assert runs[0] == runs[1] and runs[0][0] != 0.0
    slave.freeFMUstate(state)
    slave.terminate()
    with pytest.raises(FMICallException):          # no step after terminate: fmi2Error
        slave.doStep(600.0, 60.0)
    with pytest.raises(FMICallException):          # a fixed parameter after initialisation: fmi2Error
        slave.setReal([vr["T_initial"]], [30.0])
    slave.freeInstance()


SEMANTICS = Path(__file__).with_name("data") / "python_fmu_semantics.py"


def test_python_fmu_initialization_state_and_refusals(fmus, rom):
    """Python FMU, in a process of its own (tests/data/python_fmu_semantics.py): Initialization Mode outputs
    are the start state; Get/SetFMUstate (now declared) restore the run; doStep after fmi2Terminate and
    T_initial after initialisation are refused (fmi2Fatal: PythonFMU's mapping of a refusing slave; its
    fmi2Discard would end fmpy's run early without an error)."""
    import json
    import sys

    run = subprocess.run([sys.executable, str(SEMANTICS), str(fmus["python"]), "25", "23", "21", "6000"],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    out = json.loads(run.stdout.strip().splitlines()[-1])
    names = ["T01", "A_front", "X", "Z"]
    np.testing.assert_allclose(out["initialization_mode"], _start_outputs(rom, False, names), rtol=1e-12, atol=1e-9)
    assert out["after_initialization"] == out["initialization_mode"]
    assert out["can_get_and_set_state"] and out["runs_from_one_state"][0] == out["runs_from_one_state"][1]
    assert out["runs_from_one_state"][0][0] != 0.0
    assert out["doStep_after_terminate"] == 4 and out["set_T_initial_after_initialization"] == 4


@pytest.mark.parametrize("kind", KINDS)
def test_declared_dependencies_are_the_direct_feedthrough(fmus, rom, kind):
    """An output lists exactly the inputs that change it with no step in between (measured in the FMU)."""
    from fmpy import read_model_description

    md = read_model_description(str(fmus[kind]))
    declared = {o.variable.name: {d.name for d in (o.dependencies or [])} for o in md.outputs}
    assert sum(bool(d) for d in declared.values()) == 4           # the air thermometers; no false loops
    inputs = dict(spindle_speed=3000.0, feed_x=100.0, feed_y=100.0, feed_z=100.0, ambient_gradient=0.1,
                  **_ambients(rom, 20.0))
    measured = {name: set() for name in declared}
    with FMUSession(fmus[kind], inputs=inputs) as s:
        s.step(60.0)
        before = dict(zip(s.outputs, s.get(*s.outputs)))
        for name, value in inputs.items():
            s.set(**{name: value + 1.0})
            after = dict(zip(s.outputs, s.get(*s.outputs)))
            for out in s.outputs:
                if after[out] != before[out]:
                    measured[out].add(name)
            s.set(**{name: value})
    assert measured == declared


# ----------------------------------------------------------------------------- importers the project does not use
@pytest.mark.parametrize("kind", KINDS + ("fmi3",))
def test_fmutool_check_finds_no_error(fmus, fmu3, kind):
    """fmu-manipulation-toolbox's conformity and semantic checks (a second validator besides fmpy)."""
    run = subprocess.run(["fmutool", "-input", str(fmu3 if kind == "fmi3" else fmus[kind]), "-check"],
                         capture_output=True, text=True, timeout=120)
    log = run.stdout + run.stderr
    assert run.returncode == 0, log
    assert "seems to be compliant with FMI-" in log and "No semantic error" in log, log
    assert "ERROR" not in log, log


def _step_table(rom):
    t = np.arange(0.0, 7200.0 + 1.0, 60.0)
    names = ["time", "spindle_speed"] + [f"ambient_{z}" for z in rom.measured_zones]
    table = np.zeros(len(t), dtype=[(n, float) for n in names])
    table["time"], table["spindle_speed"] = t, np.where(t < 3600.0, 9000.0, 0.0)
    for z in rom.measured_zones:
        table[f"ambient_{z}"] = 20.0 + 1e-3 * t
    return table


_SIMULATE = """
import sys
import numpy as np
from fmpy import simulate_fmu
table = np.load(sys.argv[1])
for fmu in sys.argv[2:]:
    result = simulate_fmu(fmu, stop_time=7200.0, output_interval=60.0, step_size=60.0, input=table)
    np.save(fmu + ".out.npy", result)
"""


def _simulate_in_own_process(fmu_paths, table, tmp_path):
    """fmpy results of some FMUs, simulated in a fresh process: a Python FMU loaded earlier in the same test
    process (pythonfmu) can leave it in a state in which instantiating another FMU crashes (seen as a
    segfault in fmi2Instantiate of the container under pytest-xdist; the test alone passed)."""
    np.save(tmp_path / "input.npy", table)
    run = subprocess.run([sys.executable, "-c", _SIMULATE, str(tmp_path / "input.npy"), *map(str, fmu_paths)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    return [np.load(f"{path}.out.npy") for path in fmu_paths]


def test_fmucontainer_round_trip_equals_the_bare_fmu(fmus, rom, tmp_path):
    """The native FMU wrapped by fmucontainer (fmu-manipulation-toolbox) gives the bare FMU's outputs."""
    (tmp_path / "twin.fmu").write_bytes(fmus["native"].read_bytes())
    (tmp_path / "box.csv").write_text("rule;from_fmu;from_port;to_fmu;to_port\nFMU;twin.fmu;;;\n")
    run = subprocess.run(["fmucontainer", "-container", "box.csv:60", "-fmu-directory", str(tmp_path)],
                         cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0 and (tmp_path / "box.fmu").exists(), run.stdout + run.stderr
    bare, boxed = _simulate_in_own_process([tmp_path / "twin.fmu", tmp_path / "box.fmu"], _step_table(rom), tmp_path)
    for name in ("T01", "A_front", "Z"):
        np.testing.assert_allclose(boxed[name], bare[name], rtol=0, atol=1e-11)
    assert np.abs(bare["Z"]).max() > 5.0


HOST = Path(__file__).with_name("data") / "fmi2_c_host.c"


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler (cc) to build the plain C host")
def test_plain_c_host_steps_the_native_fmu_like_fmpy(fmus, tmp_path):
    """A C master (dlopen and the fmi2 calls, no Python in the process) gets fmpy's numbers bit for bit."""
    from fmpy import read_model_description

    with zipfile.ZipFile(fmus["native"]) as z:
        z.extractall(tmp_path / "fmu")
    host = tmp_path / "host"
    build = subprocess.run(["cc", "-std=c99", "-O2", "-Wall", "-I", str(tmp_path / "fmu" / "sources"), str(HOST),
                            "-o", str(host), "-ldl"], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    md = read_model_description(str(fmus["native"]))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    steps, h = 40, 90.0
    run = subprocess.run([str(host), str(tmp_path / "fmu" / "binaries" / "linux64" / "thermal_twin_rom.so"),
                          md.guid, (tmp_path / "fmu" / "resources").as_uri(), str(vr["spindle_speed"]), "9000",
                          str(vr["Z"]), str(steps), str(h)], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    from_c = [float(line) for line in run.stdout.split()]
    from_fmpy = []
    with FMUSession(fmus["native"]) as s:
        s.set(spindle_speed=9000.0)
        for _ in range(steps):
            s.step(h)
            from_fmpy.append(s.get("Z"))
    assert len(from_c) == steps and from_c == from_fmpy and abs(from_c[-1]) > 1.0


@pytest.mark.parametrize("kind", KINDS)
def test_tunable_spindle_power_factor_scales_the_spindle_sources(fmus, rom, kind):
    """Set between steps, the factor gives the twin whose spindle-driven sources' coefficients are scaled."""
    import dataclasses

    factor = {"spindle": 2.5}
    scaled = dataclasses.replace(rom, sources=[dict(s, coefficient_W=s["coefficient_W"] * factor.get(s["driver"], 1.0))
                                               for s in rom.sources])
    assert any(s["driver"] == "spindle" for s in rom.sources)
    t = np.arange(0.0, 3600.0 + 1.0, 120.0)
    with FMUSession(fmus[kind], inputs=_ambients(rom, 20.0)) as s:
        s.set(spindle_speed=9000.0, spindle_power_factor=2.5)
        for _ in t[1:]:
            s.step(120.0)
        z_fmu = s.get("Z")
    def final_z(model):
        U = model.plant_inputs_from_conditions(np.full(len(t), 9000.0), {}, {z: 20.0 for z in rom.measured_zones})
        X = model.plant_states(t, U, model.plant_uniform(20.0))
        return model.plant_outputs(X[-1], U[-1])[rom.output_index("Z")]

    assert z_fmu == pytest.approx(final_z(scaled), rel=1e-9)
    assert abs(z_fmu - final_z(rom)) > 1.0                                 # the factor matters


def test_input_table_refuses_an_event_that_only_a_lagged_zone_sees(rom):
    from twin.core.scenario import DoorOpening
    from twin.fmu.spec import FMUError

    scenario = load_scenario("door_opening")
    scenario.events = [DoorOpening(1800.0, 900.0, 5.0, 2400.0, ("enclosure",))]
    with pytest.raises(FMUError, match=r"events\[0\] reaches zone\(s\) \['enclosure'\] but not the room"):
        input_table(rom, scenario)
