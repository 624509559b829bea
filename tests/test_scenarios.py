"""The scenario library: every shipped scenario loads, fits its machine and matches its source; bad input
gives one clear error naming file, field and value.  No mesh and no solver: runs in seconds."""
import functools
import math
import re
from pathlib import Path

import numpy as np
import pytest
from doc_examples import check_example, examples

from meshes.tomlspec import DefinitionError, read_toml
from twin.cli import main
from twin.core.machine_definition import load_machine
from twin.core.scenario import HOUR, SCENARIOS_DIR, available_scenarios, load_scenario

SHIPPED = available_scenarios()
DOC = Path(__file__).resolve().parents[1] / "docs" / "scenarios.md"
MEASURED_LIKE_EXCEPTIONS = {"etve_5K", "door_opening"}     # calibration targets: no noise on purpose


@functools.lru_cache(maxsize=None)
def machine(name):
    return load_machine(name)


def durations_min(sc):
    return [round((s.end_s - s.start_s) / 60.0, 6) for s in sc.segments]


def rpms(sc):
    return [s.spindle_rpm for s in sc.segments]


# ---------------------------------------------------------------- every shipped scenario

def test_the_library_is_complete():
    expected = {"iso230_3_spindle", "iso230_3_spindle_short", "iso230_3_etve", "etve_160h", "etve_5K",
                "heat_cool_9000", "machine_a_heat_cool", "step_speed", "machine_a_step_speed", "cutting_soft",
                "cutting_hard", "six_part_cycle", "etve_csv_ambient", "door_opening", "stratified_ambient",
                *(f"thesis_test_{i}" for i in range(1, 7))}
    assert expected <= set(SHIPPED)


@pytest.mark.parametrize("name", SHIPPED)
def test_scenario_loads_and_fits_its_machine(name):
    sc = load_scenario(name)
    sc.check_machine(machine(sc.machine))
    assert sc.name == name
    assert sc.description
    text = (SCENARIOS_DIR / f"{name}.toml").read_text()
    assert text.startswith("#") and "Assumptions" in text, "header comment with source and assumptions"
    assert "seed" in read_toml(SCENARIOS_DIR / f"{name}.toml").table("scenario"), "seed set explicitly"
    times = sc.times()
    assert times[0] == 0.0 and times[-1] == pytest.approx(sc.duration_s)


@pytest.mark.parametrize("name", SHIPPED)
def test_segment_boundaries_lie_on_the_integration_grid(name):
    """The solver integrates a segment exactly wherever it ends; the shipped ones still switch on step ends,
    so that no step averages two speeds (a ripple shorter than the step that it cannot resolve)."""
    sc = load_scenario(name)
    dt = sc.sample_interval_s / math.ceil(sc.sample_interval_s / sc.time_step_s - 1e-9)
    for s in sc.segments:
        for b in (s.start_s, s.end_s):
            assert abs(b / dt - round(b / dt)) < 1e-9, f"{s.origin} boundary {b} s is off the {dt} s grid"


@pytest.mark.parametrize("name", SHIPPED)
def test_noise_on_measured_like_scenarios(name):
    sc = load_scenario(name)
    if name in MEASURED_LIKE_EXCEPTIONS:
        assert set(sc.noise.values()) == {"none"}
    else:
        assert sc.noise["temperature"] == "DS18S20" and sc.noise["displacement"] == "NCDT"


def test_docs_list_every_scenario():
    text = DOC.read_text()
    listed = set(re.findall(r"^\| `([a-z0-9_A-Z]+)` \|", text, flags=re.M))
    assert set(SHIPPED) <= listed


@pytest.mark.parametrize("index", range(len(examples(DOC))))
def test_docs_examples_print_what_the_docs_show(index):
    check_example(DOC, index)


# ---------------------------------------------------------------- against their sources

THESIS_TESTS = {  # Table 5-3: (segment minutes, rpm), total hours
    1: ([60, 60], [4000, 0], 2), 2: ([180, 120], [4000, 0], 5), 3: ([180, 120], [4000, 0], 5),
    4: ([120, 60, 120, 180], [4000, 0, 4000, 0], 8), 5: ([60, 60], [8000, 0], 2), 6: ([60, 60], [8000, 0], 2),
}


@pytest.mark.parametrize("number", sorted(THESIS_TESTS))
def test_thesis_tests_follow_table_5_3(number):
    minutes, speeds, hours = THESIS_TESTS[number]
    sc = load_scenario(f"thesis_test_{number}")
    assert durations_min(sc) == minutes and rpms(sc) == speeds
    assert sc.duration_s == hours * HOUR
    assert sc.sample_interval_s == 10.0 and sc.machine == "vmc_ram"


@pytest.mark.parametrize("a, b", [(2, 3), (5, 6)])
def test_thesis_test_pairs_differ_only_in_ambient_and_initial_state(a, b):
    sa, sb = load_scenario(f"thesis_test_{a}"), load_scenario(f"thesis_test_{b}")
    assert sa.segments == sb.segments
    t = np.linspace(0, sa.duration_s, 50)
    assert not np.allclose(sa.ambient(t), sb.ambient(t))
    assert sa.initial != sb.initial


def test_test_iv_at_rest_in_equilibrium():
    sc = load_scenario("thesis_test_4")
    assert sc.initial == {"kind": "steady", "spindle_rpm": 0.0, "ambient_C": None}
    rpm, _ = sc.operating([0.0, 2 * HOUR, 2 * HOUR + 10, 3 * HOUR + 10, 5 * HOUR + 10, 8 * HOUR])
    assert list(rpm) == [4000, 4000, 0, 4000, 0, 0]


@pytest.mark.parametrize("name, machine_name", [("heat_cool_9000", "vmc_ram"), ("machine_a_heat_cool", "machine_a")])
def test_machine_a_heat_cool(name, machine_name):
    sc = load_scenario(name)
    assert sc.machine == machine_name
    assert durations_min(sc) == [120, 70] and rpms(sc) == [9000, 0]
    assert sc.sample_interval_s == 10.0 and sc.record_camera


@pytest.mark.parametrize("name, machine_name", [("step_speed", "vmc_ram"), ("machine_a_step_speed", "machine_a")])
def test_step_speed_cycle_a2(name, machine_name):
    sc = load_scenario(name)
    assert sc.machine == machine_name
    assert durations_min(sc) == [60, 40, 30, 40, 40] and rpms(sc) == [8000, 0, 4000, 9000, 0]
    assert sc.duration_s == 210 * 60 and sc.sample_interval_s == 10.0


@pytest.mark.parametrize("name, speeds, feeds", [
    ("cutting_soft", [1000, 2000, 3000, 4000], [10, 20, 30, 40]),
    ("cutting_hard", [2000, 4000, 2000, 4000], [20, 40, 20, 40]),
])
def test_seed_003_table_1(name, speeds, feeds):
    sc = load_scenario(name)
    assert sc.duration_s == 120 * 60
    for k, (s, f) in enumerate(zip(speeds, feeds)):
        inside = [seg for seg in sc.segments if k * 1800 <= seg.start_s < (k + 1) * 1800]
        assert {seg.spindle_rpm for seg in inside} == {s}
        for axis in range(3):   # each axis moves at F, one at a time, a third of the section
            moving = [seg for seg in inside if seg.feed_mm_min[axis] > 0]
            assert {seg.feed_mm_min[axis] for seg in moving} == {f * 1000.0}
            assert sum(seg.end_s - seg.start_s for seg in moving) == pytest.approx(600.0)
        assert all(sum(v > 0 for v in seg.feed_mm_min) == 1 for seg in inside)
    assert machine("vmc_ram").max_feed_mm_min >= 40000


def test_seed_001_six_part_cycle():
    sc = load_scenario("six_part_cycle")
    assert sc.duration_s == 200 * 60 and sc.sample_interval_s == 10.0
    probing = [s for s in sc.segments if s.spindle_rpm == 0]
    machining = [s for s in sc.segments if s.spindle_rpm > 0]
    assert [(p.start_s / 60, p.end_s / 60) for p in probing] == [(90, 100), (190, 200)]   # after parts 3 and 6
    assert {s.spindle_rpm for s in machining} == {9000}
    assert {max(s.feed_mm_min) for s in machining} == {5000}
    assert sum(s.end_s - s.start_s for s in machining) == 180 * 60                        # six 30 min parts
    for axis in range(3):
        assert any(s.feed_mm_min[axis] > 0 for s in machining), "each part excites X, Y and Z"


def test_iso230_3_spindle_tests():
    full = load_scenario("iso230_3_spindle")
    assert full.iso_test == "spindle"
    assert rpms(full) == [6000, 0] and durations_min(full) == [240, 120]
    assert full.segments[0].spindle_rpm == 0.5 * machine("vmc_ram").max_spindle_rpm
    short = load_scenario("iso230_3_spindle_short")
    assert short.iso_test == "spindle" and short.duration_s <= 2 * HOUR
    assert rpms(short) == [6000, 0] and len(short.times()) <= 100
    spectrum = load_scenario("iso230_3_spindle_spectrum")
    heating = [s for s in spectrum.segments if s.end_s <= 4 * HOUR]
    assert {s.spindle_rpm for s in heating} == {0, 3000, 6000, 9000, 12000}
    assert spectrum.iso_test == "spindle"


def test_regime_blocks_56h_is_shaped_like_fl_thermal_part1_and_continues_with_what_it_lacks():
    from models.selection_cv import regime_blocks

    sc = load_scenario("regime_blocks_56h")
    times = sc.times()
    speed, _ = sc.operating(times)
    part1 = times < 32.5 * HOUR
    blocks = regime_blocks(speed[part1])
    assert [float(speed[part1][a:b].max()) for a, b in blocks] == [2000, 4000, 6000, 8000]  # FL's 1 : 2 : 3 : 4
    runs = [s for s in sc.segments if s.end_s <= 32.5 * HOUR and s.spindle_rpm > 0]
    assert [round((s.end_s - s.start_s) / HOUR, 6) for s in runs] == [4.0] * 4
    continuation = set(speed[~part1]) - {0.0}
    assert continuation and not continuation & set(speed[part1])   # speeds part 1 never ran
    assert max(continuation) > 8000 and any(2000 < v < 8000 for v in continuation)  # above and between
    assert sc.duration_s == 56.5 * HOUR


def test_iso230_3_etve():
    sc = load_scenario("iso230_3_etve")
    assert sc.iso_test == "etve" and not sc.segments and sc.duration_s >= 24 * HOUR
    assert sc.initial["kind"] == "steady"
    day = sc.ambient(np.arange(0, 48 * HOUR, 60.0))
    assert np.ptp(day) == pytest.approx(2.0 + 2 * 0.3, abs=0.05)


def test_etve_160h_follows_the_thesis():
    sc = load_scenario("etve_160h")
    assert sc.duration_s == 160 * HOUR and sc.sample_interval_s == 60.0 and not sc.segments
    t = np.arange(0, 160 * HOUR + 1, 60.0)
    assert np.ptp(sc.ambient(t)) == pytest.approx(5.0, abs=0.05)                 # day/night swing
    clock = (sc.ambient.params["start_clock_h"] + t / HOUR) % 24
    warm = sc.ambient(t)
    assert 14 <= clock[np.argmax(warm[: 1440])] <= 20 and 2 <= clock[np.argmin(warm[: 1440])] <= 9
    assert len(sc.events) == 3
    first, *later = sorted(sc.events, key=lambda e: e.start_s)
    assert first.start_s < HOUR and first.duration_s == 1800 and first.drop_K == pytest.approx(9.0)
    assert all(120 * HOUR <= e.start_s and e.start_s + e.duration_s <= 140 * HOUR for e in later)
    room = sc.zone_ambient(t, ["front", "room"])
    low = room["room"][t < 2 * HOUR].min()
    assert low < 11.0 and sc.ambient(first.start_s) - low == pytest.approx(9.0, abs=0.5)


def test_etve_5K_swing_is_exactly_5_K():
    sc = load_scenario("etve_5K")
    assert sc.initial["kind"] == "steady" and not sc.events and not sc.segments
    t = np.arange(0, sc.duration_s + 1, 60.0)
    assert np.ptp(sc.ambient(t)) == pytest.approx(5.0, abs=0.01)
    assert sc.ambient(t).mean() == pytest.approx(20.0, abs=0.05)


def test_door_opening_drops_9_K_in_30_min_and_recovers():
    sc = load_scenario("door_opening")
    (ev,) = sc.events
    assert set(ev.zones) <= set(machine("vmc_ram").zones) and "front" in ev.zones
    t = np.array([0.0, ev.start_s, ev.start_s + 900, ev.start_s + 1800, sc.duration_s])
    air = sc.zone_ambient(t, ["front", "room"])
    for zone in ("front", "room"):
        assert air[zone][:2] == pytest.approx([20.0, 20.0])
        assert air[zone][2] == pytest.approx(20.0 - 4.5)                          # linear fall
        assert air[zone][3] == pytest.approx(20.0 - 9.0)                          # −9 K after 30 min
        assert 19.5 < air[zone][4] < 20.0                                         # nearly recovered
    assert sc.sample_interval_s == 60.0 and sc.duration_s >= 3 * HOUR


def test_csv_ambient_replays_the_file():
    sc = load_scenario("etve_csv_ambient")
    import pandas as pd

    frame = pd.read_csv(SCENARIOS_DIR / "data" / "workshop_ambient_72h.csv")
    assert list(frame.columns) == ["time_s", "ambient_degC"]
    assert np.allclose(sc.ambient(frame["time_s"].to_numpy(float)), frame["ambient_degC"])
    assert frame["time_s"].iloc[-1] >= sc.duration_s


def test_stratified_ambient_has_gradient_and_hvac():
    sc = load_scenario("stratified_ambient")
    assert sc.ambient.gradient_K_per_m == pytest.approx(1.5)
    t = np.arange(0, 2 * HOUR, 60.0)
    ripple = sc.ambient(t) - np.interp(t, sc.ambient.params["times_s"], sc.ambient.params["values_C"])
    assert np.ptp(ripple) == pytest.approx(0.6, abs=0.01)
    assert sc.initial == {"kind": "uniform", "temperature_C": 16.0}


# ---------------------------------------------------------------- bad input: one clear error

BASE = """[scenario]
duration_h = 2
sample_interval_s = 60.0
"""


def write(tmp_path, body, name="bad.toml"):
    path = tmp_path / name
    path.write_text(body)
    return path


def one_error(excinfo, *fragments):
    message = str(excinfo.value)
    assert "\n" not in message, "one line"
    for fragment in fragments:
        assert fragment in message, f"{fragment!r} not in {message!r}"


def load_error(path, *fragments):
    """Loading the scenario at ``path`` fails with one error naming the file and ``fragments``."""
    with pytest.raises(DefinitionError) as excinfo:
        load_scenario(path)
    one_error(excinfo, str(path), *fragments)


@pytest.mark.parametrize("body, fragments", [
    (BASE + "[[segments]]\nduration_min = 30\nspindel_rpm = 4000\n", ["segments[0]", "spindel_rpm"]),
    (BASE + "[[segments]]\nduration_min = -5\nspindle_rpm = 4000\n", ["segments[0].duration_min", "-5"]),
    (BASE + "[[segments]]\nrepeat = 2\nsteps = [{ duration_s = -10 }]\n", ["segments[0].steps[0].duration_s", "-10"]),
    (BASE + "[[segments]]\nrepeat = 2\nspindle_rpm = 100\nsteps = [{ duration_s = 10 }]\n",
     ["segments[0].spindle_rpm", "steps"]),
    (BASE + "[[segments]]\nduration_min = 30\nspindle_rpm = -1\n", ["segments[0].spindle_rpm", "-1"]),
    (BASE + "[ambient]\nkind = \"sinusiod\"\n", ["ambient.kind", "sinusiod"]),
    (BASE + "[ambient]\nkind = \"piecewise\"\ntimes_h = [0, 2, 1]\nvalues_C = [20, 21, 22]\n",
     ["ambient.times_h", "increase"]),
    (BASE + "[[events]]\nkind = \"door_opening\"\nstart_h = 3\nduration_min = 30\ndrop_K = 9\n",
     ["events[0].start_h", "3"]),
    (BASE + "[initial]\nkind = \"uniform\"\nspindle_rpm = 100\n", ["initial", "spindle_rpm"]),
    ("[scenario]\nduration_min = 10\nsample_interval_s = 7.0\n", ["scenario.sample_interval_s", "7.0"]),
    ("[scenario]\nduraton_h = 2\n", ["scenario", "duraton_h"]),
    (BASE + "[noise]\ntemperature = \"PT100\"\n", ["noise.temperature", "PT100"]),
    # ambients in kelvin, or below absolute zero
    (BASE + "[ambient]\ntemperature_C = 293.15\n", ["ambient.temperature_C", "293.15", "kelvin"]),
    (BASE + "[ambient]\ntemperature_C = -273.15\n", ["ambient.temperature_C", "-273.15", "absolute zero"]),
    (BASE + "[ambient]\nkind = \"sinusoid\"\nmean_C = 295.0\namplitude_K = 2.5\n", ["ambient.mean_C", "kelvin"]),
    (BASE + "[ambient]\nkind = \"piecewise\"\ntimes_h = [0, 1]\nvalues_C = [20, -300]\n",
     ["ambient.values_C[1]", "-300", "absolute zero"]),
    (BASE + "[initial]\nkind = \"steady\"\nambient_C = 293.0\n", ["initial.ambient_C", "293", "kelvin"]),
    # a run that cannot fit in memory is refused before any array is made
    ("[scenario]\nduration_h = 87600\nsample_interval_s = 1.0\n",
     ["scenario.sample_interval_s", "315,360,001 samples", "GB of memory", "1.0"]),
])
def test_bad_scenarios_give_one_clear_error(tmp_path, body, fragments):
    path = write(tmp_path, body)
    load_error(path, *fragments)


def test_malformed_toml(tmp_path):
    path = write(tmp_path, BASE + "[[segments]]\nduration_min = 30\nspindle_rpm = \n")
    load_error(path, "malformed TOML")


def test_rpm_above_the_machine_maximum(tmp_path):
    path = write(tmp_path, BASE + """[[segments]]
duration_min = 30
spindle_rpm = 9000
[[segments]]
repeat = 2
steps = [{ duration_min = 10, spindle_rpm = 4000 }, { duration_min = 5, spindle_rpm = 13000 }]
""")
    sc = load_scenario(path)                          # speeds are checked against a machine, not on reading
    with pytest.raises(DefinitionError) as excinfo:
        sc.check_machine(machine("vmc_ram"))
    one_error(excinfo, str(path), "segments[1].steps[1].spindle_rpm", "13000", "vmc_ram", "12000")
    sc.segments = sc.segments[:1]
    sc.check_machine(machine("machine_a"))            # 9000 rpm is Machine A's maximum: allowed


def test_feed_above_the_machine_maximum(tmp_path):
    path = write(tmp_path, BASE + "[[segments]]\nduration_min = 30\nfeed_y_mm_min = 45000\n")
    with pytest.raises(DefinitionError) as excinfo:
        load_scenario(path).check_machine(machine("vmc_ram"))
    one_error(excinfo, str(path), "segments[0].feed_y_mm_min", "45000")


def test_unknown_zone_in_an_event(tmp_path):
    path = write(tmp_path, BASE + """[[events]]
kind = "door_opening"
start_min = 10
duration_min = 30
drop_K = 9
zones = ["door"]
""")
    with pytest.raises(DefinitionError) as excinfo:
        load_scenario(path).check_machine(machine("vmc_ram"))
    one_error(excinfo, str(path), "events[0].zones", "'door'", "front", "room")


def csv_scenario(tmp_path, rows):
    (tmp_path / "air.csv").write_text("time_s,ambient_degC\n" + "".join(f"{a},{b}\n" for a, b in rows))
    return write(tmp_path, BASE + "[ambient]\nkind = \"csv\"\nfile = \"air.csv\"\n")


def test_csv_ambient_with_a_non_monotonic_time_column(tmp_path):
    path = csv_scenario(tmp_path, [(0, 20.0), (600, 20.5), (1200, 21.0), (900, 21.5)])
    load_error(path, "ambient.file", "air.csv", "time_s", "900", "1200")


@pytest.mark.parametrize("rows, fragments", [
    ([(0, 20.0), (600, "warm")], ["air.csv", "row 3", "warm"]),
    ([(0, 20.0), (600, 20.0), (600, 21.0)], ["air.csv", "time_s", "600"]),
    ([(0, 293.15), (600, 293.65)], ["air.csv", "'ambient_degC'", "row 2", "293.15", "kelvin", "20.00 °C"]),
    ([(0, 20.0), (600, -274.0)], ["air.csv", "row 3", "-274", "absolute zero"]),
    ([(0, 20.0), (600, 150.0)], ["air.csv", "row 3", "150", "not a plausible ambient"]),
])
def test_csv_ambient_other_errors(tmp_path, rows, fragments):
    path = csv_scenario(tmp_path, rows)
    load_error(path, *fragments)


def test_csv_ambient_file_missing(tmp_path):
    path = write(tmp_path, BASE + "[ambient]\nkind = \"csv\"\nfile = \"nowhere.csv\"\n")
    load_error(path, "ambient.file", "nowhere.csv")


def test_unknown_scenario_name_lists_the_library():
    with pytest.raises(DefinitionError) as excinfo:
        load_scenario("no_such_scenario")
    one_error(excinfo, "no_such_scenario", "heat_cool_9000")


# ---------------------------------------------------------------- the CLI, before any mesh is built

@pytest.fixture
def no_mesh(monkeypatch):
    """Fail loudly if the command got as far as building the machine (meshing)."""
    import twin.run.workflows as workflows

    def forbidden(*args, **kwargs):
        raise AssertionError("the error should have been reported before the machine is built")

    monkeypatch.setattr(workflows, "build_machine", forbidden)


@pytest.mark.parametrize("body, fragment", [
    (BASE + "[[segments]]\nduration_min = 30\nspindle_rpm = \n", "malformed TOML"),
    (BASE + "[[segments]]\nduration_min = 30\nspindel_rpm = 4000\n", "spindel_rpm"),
    (BASE + "[[segments]]\nduration_min = -5\n", "segments[0].duration_min must be > 0.0, got -5"),
])
def test_cli_run_bad_scenario_is_one_line(tmp_path, capsys, no_mesh, body, fragment):
    path = write(tmp_path, body)
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("twin run: error:")
    assert str(path) in err and fragment in err
    assert not (tmp_path / "out").exists()


def test_cli_run_missing_scenario_file(tmp_path, capsys, no_mesh):
    assert main(["run", str(tmp_path / "missing.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "missing.toml" in err and "not found" in err


@pytest.mark.parametrize("initial, rpm, ambient", [({"kind": "steady", "spindle_rpm": None, "ambient_C": None}, 0.0,
                                                     {"room": 21.0, "enclosure": 22.0}),
                                                    ({"kind": "steady", "spindle_rpm": 4500.0, "ambient_C": 18.5},
                                                     4500.0, {"room": 18.5, "enclosure": 18.5})])
def test_a_steady_start_is_idle_in_the_starting_air_unless_the_scenario_names_them(initial, rpm, ambient):
    from dataclasses import replace
    scenario = replace(load_scenario("heat_cool_9000"), initial=initial)
    speed, feeds, air = scenario.idle_start({"room": np.array([21.0]), "enclosure": np.array([22.0])})
    assert speed.tolist() == [rpm]
    assert {a: f.tolist() for a, f in feeds.items()} == {"x": [0.0], "y": [0.0], "z": [0.0]}
    assert {z: a.tolist() for z, a in air.items()} == {z: [v] for z, v in ambient.items()}
