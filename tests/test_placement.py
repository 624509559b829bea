"""The placement study end to end on the default machine, with short scenarios and few candidates."""
import json

import numpy as np
import pytest

from twin.cli import main
from twin.core.scenario import load_scenario
from twin.core.variants import MachineSpec, perturbed_definition
from twin.placement.candidates import CandidateSpec, candidate_locations
from twin.placement.records import RecordTask, ResponseTask, elementary_inputs

HEAT = """
[scenario]
name = "{name}"
sample_interval_s = 300.0
time_step_s = 300.0
[ambient]
kind = "{ambient_kind}"
{ambient}
[[segments]]
duration_h = {h1}
spindle_rpm = {rpm1}
[[segments]]
duration_h = {h2}
spindle_rpm = {rpm2}
[[segments]]
duration_h = 1
spindle_rpm = 0
"""


def short_scenarios(folder):
    """Three short training records, one validation and one test record (other duty cycles and ambients)."""
    specs = {
        "p_heat": dict(ambient_kind="constant", ambient="temperature_C = 20.0", h1=2, rpm1=9000, h2=1, rpm2=0),
        "p_steps": dict(ambient_kind="constant", ambient="temperature_C = 20.0", h1=1, rpm1=4000, h2=1.5,
                        rpm2=8000),
        "p_room": dict(ambient_kind="piecewise", ambient="times_h = [0, 4]\nvalues_C = [20.0, 22.0]", h1=1,
                       rpm1=3000, h2=1, rpm2=0),
        "p_val": dict(ambient_kind="piecewise", ambient="times_h = [0, 4]\nvalues_C = [20.0, 21.0]", h1=1,
                      rpm1=7000, h2=1, rpm2=2000),
        "p_test": dict(ambient_kind="piecewise", ambient="times_h = [0, 4]\nvalues_C = [20.0, 19.0]", h1=1.5,
                       rpm1=6000, h2=0.5, rpm2=10000),
    }
    paths = {}
    for name, kw in specs.items():
        path = folder / f"{name}.toml"
        path.write_text(HEAT.format(name=name, **kw))
        paths[name] = str(path)
    return paths


def test_candidates_are_outer_surface_nodes_and_camera_spots(machine):
    c = candidate_locations(machine, parts=("ram", "carrier", "column"), n_surface=300)
    kinds = np.array(c.kinds)
    assert np.sum(kinds == "surface") == 300 and np.sum(kinds == "camera") == len(machine.definition.camera.spots())
    assert set(np.array(c.parts)[kinds == "surface"]) <= {"ram", "carrier", "column"}
    surf = np.flatnonzero(kinds == "surface")
    rows = c.rows[surf]
    assert np.allclose(rows.sum(axis=1), 1.0) and rows.nnz == len(surf)          # identity rows of nodes
    nodes = rows.indices
    assert np.allclose(machine.thermal.points[nodes], c.points[surf])
    cam = np.flatnonzero(kinds == "camera")
    ref = machine.outputs.subset([c.names[i] for i in cam]).matrix
    assert abs(c.rows[cam] - ref).max() == 0
    # no node of the sealed cavities: every candidate node lies on a facet outside the 'cavities' group
    gt, gl = machine.mesh.facet_group("cavities")
    cavity_nodes = set(machine.mesh.facet_nodes(gt, gl, tets=machine.thermal.tets).ravel().tolist())
    outer = set(np.unique(machine.mesh.facet_nodes(*machine.mesh.boundary_facets(), tets=machine.thermal.tets)))
    assert set(nodes.tolist()) <= outer
    assert len(set(nodes.tolist()) & cavity_nodes) < 0.05 * len(nodes)          # only shared edge nodes
    with pytest.raises(Exception, match="unknown part"):
        candidate_locations(machine, parts=("spindle_housing",))


def test_record_task_records_candidates_and_drift_only(machine, tmp_path):
    sc = short_scenarios(tmp_path)["p_heat"]
    task = RecordTask(MachineSpec(), CandidateSpec(("ram",), 40, camera=False), sc, ("Y", "Z"), None)
    rec = task()
    assert rec.temperatures.shape == (len(load_scenario(sc).times()), 40)
    assert set(rec.drift) == {"Y", "Z"}
    assert np.ptp(rec.drift["Z"]) > 1.0 and rec.temperatures.max() > 21.0
    from twin.core.simulate import simulate

    ds = simulate(sc, machine, noise=False).dataset
    assert np.allclose(rec.drift["Z"], ds["Z"], atol=1e-9)      # the same run as the full twin


def test_step_responses_cover_every_thermal_input(machine):
    steps = {name: step for name, _j, step in elementary_inputs(machine)}
    assert list(steps) == list(machine.thermal.input_names)
    assert steps["ambient:room"] == 2.0 and steps["ambient_gradient"] == 1.0
    assert all(steps[f"power:{s.name}"] == s.coefficient_W for s in machine.definition.sources)
    cands = CandidateSpec(("ram", "carrier"), 30, camera=False)
    room = ResponseTask(MachineSpec(), cands, "ambient:room", ("Y", "Z"), 4 * 3600.0)()
    assert room.scenario == "step:ambient:room" and len(room.time_s) == 17
    assert np.all(room.temperatures[0] == 20.0) and room.drift["Z"][0] == pytest.approx(0.0, abs=1e-9)
    assert room.temperatures.min() >= 20.0 - 1e-9 and room.temperatures.max() <= 22.0 + 1e-9
    assert np.all(np.diff(room.temperatures.mean(axis=1)) > 0)           # the machine follows the warmer room
    heat = ResponseTask(MachineSpec(), cands, "power:front_bearings", ("Z",), 4 * 3600.0)()
    assert heat.temperatures[-1].max() > 20.5 and abs(heat.drift["Z"][-1]) > 5.0
    with pytest.raises(Exception, match="no thermal input"):
        ResponseTask(MachineSpec(), cands, "power:coolant", ("Z",), 3600.0)()


def test_perturbed_definition_scales_sources_and_convection(machine):
    d = perturbed_definition(machine.definition, (("front_bearings", 2.0),), 0.5)
    before = {s.name: s.coefficient_W for s in machine.definition.sources}
    after = {s.name: s.coefficient_W for s in d.sources}
    assert after["front_bearings"] == 2 * before["front_bearings"]
    assert all(after[n] == before[n] for n in before if n != "front_bearings")
    assert [c.coefficient for c in d.convection] == [0.5 * c.coefficient for c in machine.definition.convection]
    with pytest.raises(Exception, match="unknown source"):
        perturbed_definition(machine.definition, (("coolant", 1.1),))


def test_cli_place_writes_the_report(machine, tmp_path, capsys):
    sc = short_scenarios(tmp_path)
    out = tmp_path / "place"
    code = main(["place", "--parts", "ram,carrier,column,spindle_motor", "--candidates", "120",
                 "--train", f"{sc['p_heat']},{sc['p_steps']},{sc['p_room']}", "--validation", sc["p_val"],
                 "--test", sc["p_test"],
                 "--k-max", "3", "--record-interval", "60", "--response-horizon", "4", "--scheduler", "serial",
                 "--no-cache", "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    text = capsys.readouterr().out
    assert "## Z: validation max |residual|" in text and "| K | gra+fcm |" in text
    assert "## Chosen locations (method and K = 1–3 chosen on validation)" in text and "4–5" not in text
    assert "; records every 300 s\n" in text                    # the scenarios' own sampling, not 60 s
    for name in ("placement.md", "placement.json", "k_method_table.csv", "candidate_scores.csv",
                 "chosen_sensors.csv", "chosen_sensors.png", "k_curves.png"):
        assert (out / name).exists(), name
    assert (out / "chosen_sensors.png").stat().st_size > 20000
    report = json.loads((out / "placement.json").read_text())
    assert report["config"]["n_candidates"] == 120 + 525
    rows = report["table"]
    assert len(rows) == 7 * 3 * 2                                   # methods × K × axes
    assert report["timings"]["responses"] == 11                     # every thermal input stepped once
    physics = {axis: [r["sensors"] for r in rows if r["axis"] == axis and r["method"] == "greedy-physics"]
               for axis in ("Z", "Y")}
    assert physics["Z"] == physics["Y"]                             # one sensor set for both axes
    assert all(list(r["per_scenario"]) == ["p_val"] for r in rows)  # the K × method table: validation only
    for axis in ("Z", "Y"):                                         # the choice: the validation minimum
        val = [r for r in rows if r["axis"] == axis]
        best = min(val, key=lambda r: r["max_residual"])
        assert (report["test"]["best"][axis]["method"], report["test"]["best"][axis]["K"]) == (best["method"],
                                                                                               best["K"])
        assert list(report["test"]["best"][axis]["per_scenario"]) == ["p_test"]
    for axis in ("Z", "Y"):
        peak = report["uncompensated"][axis][0]
        greedy = [r for r in rows if r["axis"] == axis and r["method"] == "greedy-loso"]
        assert min(r["max_residual"] for r in greedy) < 0.5 * peak  # compensation helps on held-out data
    import pandas as pd

    scores = pd.read_csv(out / "candidate_scores.csv")
    assert len(scores) == 645 and {"x_m", "grade_Z", "greedy_alone_Y", "chosen_K_greedy-loso_Z", "physics_alone",
                                   "chosen_K_greedy-physics_Y"} <= set(scores)
    # the records as datasets with the chosen sensors, ready for `twin train` / `twin evaluate`
    chosen = pd.read_csv(out / "chosen_sensors.csv")
    z_sensors = ",".join(chosen[chosen.axis == "Z"].name)
    data = out / "datasets"
    assert sorted(p.name for p in data.glob("*.csv")) == ["p_heat.csv", "p_room.csv", "p_steps.csv", "p_test.csv",
                                                                  "p_val.csv"]
    assert main(["train", str(data / "p_heat.csv"), str(data / "p_steps.csv"), str(data / "p_room.csv"),
                 "--inputs", z_sensors, "--target", "Z", "--model", "mlr", "--out", str(tmp_path / "z.json")]) == 0
    assert main(["evaluate", str(tmp_path / "z.json"), str(data / "p_test.csv")]) == 0
    table = capsys.readouterr().out
    z_row = report["test"]["best"]["Z"]                               # the chosen set, scored on the test
    assert (z_row["method"], z_row["K"]) == (report["chosen"][0]["method"], report["chosen"][0]["K"])
    assert f"| p_test | {len(load_scenario(sc['p_test']).times())} | {z_row['rmse']:.3g} |" in table
    # a bad method name is one clear line
    assert main(["place", "--methods", "random", "--scheduler", "serial", "--out", str(tmp_path / "x")]) == 2
    assert "unknown placement method(s) ['random']" in capsys.readouterr().err


def test_a_scenario_in_two_roles_is_refused(tmp_path):
    from twin.errors import TwinInputError
    from twin.placement.study import placement_study

    sc = short_scenarios(tmp_path)
    with pytest.raises(TwinInputError, match="both a training and a test scenario"):
        placement_study(train=(sc["p_heat"], sc["p_steps"]), validation=(sc["p_val"],), test=(sc["p_heat"],),
                        scheduler="serial", log=None)


def test_noise_seed_follows_the_scenario_name_in_every_process():
    """Not Python's salted hash(): the same name gives the same seed under any PYTHONHASHSEED."""
    import os
    import subprocess
    import sys

    from twin.placement.records import scenario_seed

    code = "from twin.placement.records import scenario_seed; print(scenario_seed('etve_summer'))"
    seeds = {subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                            env={**os.environ, "PYTHONHASHSEED": h}).stdout.strip() for h in ("1", "2")}
    assert seeds == {str(scenario_seed("etve_summer"))}
    assert scenario_seed("etve_summer") != scenario_seed("etve_5K") and 0 <= scenario_seed("x") < 2 ** 31
