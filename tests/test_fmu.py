"""FMUs of the default machine: export, fmpy validation (zero problems), simulation, match with the twin."""
import ast
import math
import subprocess
import zipfile

import numpy as np
import pytest

from twin.cli import main
from twin.core.scenario import load_scenario
from twin.fmu.export import export_fmu, input_table, scenario_start, simulate, simulate_table, validate
from twin.fmu.session import FMUSession, FMUStepError
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
    for zone in rom.zones:
        assert by_name[f"ambient_{zone}"].unit == "degC"
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
    # steady start with the machine idle, as the twin does; conditions held over each step, as the FMU gets them
    twin = simulate_rom(rom, scenario, inputs="held")
    assert _relative_difference(result, twin.matrix(rom.output_names), rom.output_names) < 1e-6


def _ambients(rom, value=20.0):
    return {f"ambient_{z}": value for z in rom.zones}


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


def test_native_fmu_rejects_bad_inputs_with_fmi2error(fmus, rom):
    from fmpy.fmi2 import fmi2Error

    inputs = dict(spindle_speed=1000.0, **_ambients(rom))
    with FMUSession(fmus["native"], inputs=inputs) as s:
        s.step(10.0)
        for bad, pattern in ((dict(spindle_speed=-100.0), "spindle_speed = -100 is outside"),
                             ({f"ambient_{rom.zones[0]}": math.nan},
                              f"ambient_{rom.zones[0]} = nan is not a finite number")):
            s.set(**bad)
            with pytest.raises(FMUStepError, match=pattern) as info:
                s.step(10.0)
            assert f"status {fmi2Error}" in str(info.value)
            s.set(**inputs)
        s.step(10.0)                                     # the importer goes on
        assert math.isfinite(s.get("Z"))


def test_python_fmu_rejects_bad_inputs_without_crashing(fmus, rom):
    from fmpy.fmi2 import fmi2Discard

    inputs = dict(spindle_speed=1000.0, **_ambients(rom))
    with FMUSession(fmus["python"], inputs=inputs, logging_on=True) as s:
        s.step(10.0)
        s.set(spindle_speed=-100.0)
        with pytest.raises(FMUStepError, match="spindle_speed = -100 is outside") as info:
            s.step(10.0)
        # PythonFMU maps a refused do_step to fmi2Discard (it cannot return fmi2Error from Python).
        assert f"status {fmi2Discard}" in str(info.value)
        s.set(**inputs)
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
    assert top <= {"json", "math", "os", "numpy", "pythonfmu"}


def test_cli_exports_and_validates(tmp_path, capsys):
    out = tmp_path / "cli.fmu"
    assert main(["fmu", "export", "--kind", "native", "--out", str(out), "--outputs", "T01,X,Y,Z"]) == 0
    assert "no problems" in capsys.readouterr().out
    assert main(["fmu", "validate", str(out)]) == 0


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
    names = ["time", "spindle_speed", "feed_x", "feed_y", "feed_z"] + [f"ambient_{z}" for z in rom.zones]
    table = np.zeros(len(t), dtype=[(n, float) for n in names + ["ambient_gradient"]])
    table["time"], table["spindle_speed"] = t, 9000.0
    for z in rom.zones:
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
