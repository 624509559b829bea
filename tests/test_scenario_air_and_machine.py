"""Scenario checks that need the machine or the scenario's folder: the air a run applies (room, door openings,
vertical gradient) is range-checked against the machine; a relative machine path is read from the scenario's
folder; an unknown machine name in a scenario names the file and the field.  No mesh and no solver."""
import functools
import shutil
from pathlib import Path

import pytest

from meshes.tomlspec import DefinitionError
from twin.cli import main
from twin.core.machine_definition import load_machine
from twin.core.scenario import MACHINES_DIR, load_scenario

DATA = Path(__file__).parent / "data"
BASE = """[scenario]
duration_h = 2
sample_interval_s = 60.0
"""


@functools.cache
def definition(name):
    """A machine definition (read once; the checks do not change it)."""
    return load_machine(name)


def write(folder, body, name="sc.toml"):
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(body)
    return path


def door(start_min, duration_min, drop_K, zones=None, recovery_h=1.0):
    zone_line = "" if zones is None else f"zones = {zones!r}\n".replace("'", '"')
    return (f"[[events]]\nkind = \"door_opening\"\nstart_min = {start_min}\nduration_min = {duration_min}\n"
            f"drop_K = {drop_K}\nrecovery_h = {recovery_h}\n{zone_line}")


def air_error(path, machine="vmc_ram"):
    """The one-line message with which ``check_machine`` refuses the scenario at ``path`` on ``machine``."""
    sc = load_scenario(path)
    with pytest.raises(DefinitionError) as excinfo:
        sc.check_machine(definition(machine))
    message = str(excinfo.value)
    assert "\n" not in message and message.startswith(f"{path}: "), message
    return message


def assert_fragments(message, *fragments):
    for fragment in fragments:
        assert fragment in message, f"{fragment!r} not in {message!r}"


@pytest.fixture
def no_mesh(monkeypatch):
    """Fail loudly if ``twin run`` got as far as building the machine (meshing)."""
    from twin.run import workflows

    def forbidden(*args, **kwargs):
        raise AssertionError("the error should have been reported before the machine is built")

    monkeypatch.setattr(workflows, "build_machine", forbidden)


# ---------------------------------------------------------------- the air the machine sees

@pytest.mark.parametrize("drop_K, air_C, why", [(400, "-380", "is at or below absolute zero (-273.15 °C)"),
                                                (90, "-70", "is not a plausible ambient in °C (-50 to 100 °C)")],
                         ids=["below-absolute-zero", "below-range"])
def test_a_door_opening_that_takes_the_air_out_of_range_is_refused(tmp_path, drop_K, air_C, why):
    path = write(tmp_path, BASE + door(10, 30, drop_K))
    message = air_error(path)
    # deepest at the end of the fall, 10 + 30 min, in a zone without a lag
    assert_fragments(message, f"events[0].drop_K = {drop_K} (", "air at t = 0.6667 h", f": {air_C} {why}")


def test_overlapping_door_openings_add_up_and_separate_ones_do_not(tmp_path):
    overlapping = write(tmp_path, BASE + door(10, 30, 40) + door(20, 20, 40), "overlap.toml")
    assert_fragments(air_error(overlapping), "events[", "t = 0.6667 h", ": -60 is not a plausible ambient")
    apart = write(tmp_path, BASE + door(10, 30, 40, recovery_h=0.05) + door(80, 20, 40, recovery_h=0.05),
                  "apart.toml")
    load_scenario(apart).check_machine(definition("vmc_ram"))


def test_the_event_pushing_furthest_is_named(tmp_path):
    path = write(tmp_path, BASE + door(10, 30, 20) + door(20, 20, 55), "two.toml")
    assert_fragments(air_error(path), "events[1].drop_K = 55 (", ": -55 is not a plausible ambient")


def test_a_lagged_zone_sees_a_door_through_its_lag(tmp_path):
    """The enclosure of vmc_ram lags the room by 3 h: a short deep drop there is damped as the run damps it."""
    path = write(tmp_path, BASE + door(10, 5, 100, zones=["enclosure"], recovery_h=0.05))
    sc = load_scenario(path)
    lags = definition("vmc_ram").zone_lags_s
    assert lags["enclosure"] > 0
    air = sc.zone_ambient(sc.times(), ["enclosure"], lags)["enclosure"]
    assert -50 < air.min() < 19.0                       # felt, but within the range: accepted
    sc.check_machine(definition("vmc_ram"))


def test_a_vertical_gradient_is_checked_at_the_machine_floor(tmp_path):
    path = write(tmp_path, BASE + "[ambient]\nkind = \"constant\"\nvertical_gradient_K_per_m = 500\n")
    # vmc_ram: reference height 1 m, lowest convecting part at z = 0: 20 − 500 K
    assert_fragments(air_error(path), "ambient.vertical_gradient_K_per_m = 500 (", "air at z = 0 m, t = 0 h",
                     ": -480 is at or below absolute zero")


def test_a_vertical_gradient_is_checked_at_the_machine_top(tmp_path):
    """Warmer up: vmc_ram's top surface is at 1.87 m, 0.87 m above its reference height; the mini machine is
    0.5 m tall, all below its reference, so the same air is accepted there."""
    body = BASE + "[ambient]\nkind = \"constant\"\ntemperature_C = 60\nvertical_gradient_K_per_m = 50\n"
    path = write(tmp_path, body)
    assert_fragments(air_error(path), "ambient.vertical_gradient_K_per_m = 50 (", "air at z = 1.87 m, t = 0 h",
                     ": 103.5 is not a plausible ambient")
    load_scenario(path).check_machine(definition(str(DATA / "mini_machine.toml")))


def test_a_steady_start_adds_the_gradient_to_its_ambient(tmp_path):
    body = (BASE + "[initial]\nkind = \"steady\"\nambient_C = -45\n"
            "[ambient]\nkind = \"constant\"\ntemperature_C = 20\nvertical_gradient_K_per_m = 10\n")
    path = write(tmp_path, body)
    assert_fragments(air_error(path), "ambient.vertical_gradient_K_per_m = 10 (", "z = 0 m, the steady start",
                     ": -55 is not a plausible ambient")


@pytest.mark.parametrize("kind, lines, where", [
    ("piecewise", "times_h = [0, 2]\nvalues_C = [20, 99.5]\n", "ambient.values_C[1] (with the HVAC ripple)"),
    ("csv", "file = \"air.csv\"\n", "air.csv: column 'ambient_degC', row 3 (with the HVAC ripple)"),
], ids=["piecewise", "csv"])
def test_the_hvac_ripple_widens_a_piecewise_or_csv_ambient_as_it_does_a_constant_one(tmp_path, kind, lines, where):
    (tmp_path / "air.csv").write_text("time_s,ambient_degC\n0,20\n7200,99.5\n")
    body = BASE + f"[ambient]\nkind = \"{kind}\"\n{lines}hvac_amplitude_K = 1\n"
    path = write(tmp_path, body)
    with pytest.raises(DefinitionError) as excinfo:
        load_scenario(path)
    message = str(excinfo.value)
    assert "\n" not in message and message.startswith(f"{path}: ambient.")
    assert_fragments(message, f"{where}: 100.5 is not a plausible ambient")


def test_twin_run_refuses_a_deep_door_before_meshing(tmp_path, capsys, no_mesh):
    path = write(tmp_path, BASE + door(10, 30, 400))
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--no-views"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("twin run: error:")
    assert_fragments(err, str(path), "events[0].drop_K = 400", "-380")
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------- a machine path is scenario-relative

@pytest.fixture
def elsewhere(tmp_path, monkeypatch):
    """A current folder that is neither the scenario's nor the machine's."""
    folder = tmp_path / "elsewhere"
    folder.mkdir()
    monkeypatch.chdir(folder)
    return folder


def test_a_relative_machine_path_is_read_from_the_scenario_folder(tmp_path, elsewhere):
    machine_file = tmp_path / "mach" / "pillar.toml"
    machine_file.parent.mkdir()
    shutil.copy(MACHINES_DIR / "machine_a.toml", machine_file)
    path = write(tmp_path / "sc", BASE.replace("[scenario]\n", "[scenario]\nmachine = \"../mach/pillar.toml\"\n"))
    sc = load_scenario(path)
    assert Path(sc.machine) == machine_file.resolve()
    assert load_machine(sc.machine).source == str(machine_file.resolve())


def test_a_missing_machine_file_names_the_scenario_field_value_and_path(tmp_path, elsewhere):
    path = write(tmp_path / "sc", BASE.replace("[scenario]\n", "[scenario]\nmachine = \"../mach/none.toml\"\n"))
    with pytest.raises(DefinitionError) as excinfo:
        load_scenario(path).machine_definition()
    message = str(excinfo.value)
    assert "\n" not in message
    assert_fragments(message, f"{path}: scenario.machine", "'../mach/none.toml'",
                     str((tmp_path / "mach" / "none.toml").resolve()), "scenario file's folder")


def test_a_machine_path_found_only_from_the_current_folder_says_how_to_write_it(tmp_path, monkeypatch):
    """The old reading (from the current folder) is refused, with the path that works now."""
    (tmp_path / "mach").mkdir()
    shutil.copy(MACHINES_DIR / "machine_a.toml", tmp_path / "mach" / "pillar.toml")
    path = write(tmp_path / "sc", BASE.replace("[scenario]\n", "[scenario]\nmachine = \"mach/pillar.toml\"\n"))
    monkeypatch.chdir(tmp_path)
    with pytest.raises(DefinitionError, match=r"sc\.toml: scenario\.machine .*write '\.\./mach/pillar\.toml'"):
        load_scenario(path).machine_definition()


def test_a_bare_machine_name_stays_a_name(tmp_path, elsewhere):
    (elsewhere / "machine_a.toml").write_text("not a machine")       # a file of that name here is not read
    path = write(tmp_path, BASE.replace("[scenario]\n", "[scenario]\nmachine = \"machine_a\"\n"))
    assert load_scenario(path).machine == "machine_a"


def test_the_test_scenario_finds_the_test_machine_beside_it(elsewhere):
    """tests/data/mini_scenario.toml names ``mini_machine.toml``, the file in its own folder."""
    sc = load_scenario(DATA / "mini_scenario.toml")
    assert Path(sc.machine) == (DATA / "mini_machine.toml").resolve()


def test_the_machines_folder_is_the_meshes_one():
    from meshes.definition import MACHINES_DIR as MESHES_MACHINES_DIR

    assert MACHINES_DIR == MESHES_MACHINES_DIR


# ---------------------------------------------------------------- an unknown machine name

def test_an_unknown_machine_name_names_the_scenario_and_the_field(tmp_path):
    path = write(tmp_path, BASE.replace("[scenario]\n", "[scenario]\nmachine = \"vmc_rma\"\n"))
    with pytest.raises(DefinitionError) as excinfo:
        load_scenario(path).machine_definition()
    message = str(excinfo.value)
    assert "\n" not in message
    assert_fragments(message, f"{path}: scenario.machine names an unknown machine 'vmc_rma'", "'vmc_ram'")


def test_twin_run_unknown_machine_in_a_scenario_is_one_line(tmp_path, capsys, no_mesh):
    path = write(tmp_path, BASE.replace("[scenario]\n", "[scenario]\nmachine = \"vmc_rma\"\n"))
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{path}: scenario.machine" in err and "'vmc_rma'" in err


class _Built(Exception):
    """Raised in place of building the machine: the run got past every check."""


@pytest.mark.parametrize("written", ["acme_lathe", "../elsewhere/acme.toml"])
def test_the_machine_option_replaces_a_scenario_machine_this_install_lacks(tmp_path, monkeypatch, written):
    """A scenario shared from another site names its machine; --machine replaces it, so it is not checked."""
    from twin.run import workflows

    def built(*args, **kwargs):
        raise _Built

    monkeypatch.setattr(workflows, "build_machine", built)
    path = write(tmp_path, BASE.replace("[scenario]\n", f"[scenario]\nmachine = \"{written}\"\n"))
    with pytest.raises(_Built):
        main(["run", str(path), "--machine", "vmc_ram", "--out", str(tmp_path / "out")])


def test_an_unknown_machine_option_is_not_blamed_on_the_scenario(tmp_path, capsys, no_mesh):
    path = write(tmp_path, BASE)
    assert main(["run", str(path), "--machine", "vmc_rmb", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert "unknown machine 'vmc_rmb'" in err and "scenario.machine" not in err
