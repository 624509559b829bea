"""`twin study` and `twin rom report` refuse bad options in one line before any simulation.

Every test replaces the simulation entry points with one that fails the test: a refusal must come first.
"""
from pathlib import Path

import pytest

from twin.cli import main


def error_line(capsys):
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


def _no_work(*args, **kwargs):
    raise AssertionError("a simulation ran before the options were checked")


@pytest.fixture
def no_study_simulation(monkeypatch):
    """The studies run every simulation through ``run_tasks``; here it fails the test."""
    from twin.compensation import studies

    monkeypatch.setattr(studies, "run_tasks", _no_work)
    monkeypatch.setattr(studies, "simulate", _no_work)


@pytest.fixture
def no_fe_run(monkeypatch):
    """The ROM report's FE runs and bases fail the test."""
    from twin.rom import report

    monkeypatch.setattr(report, "simulate", _no_work)
    monkeypatch.setattr(report, "compute_basis", _no_work)


def study(tmp_path, *args):
    return main(["study", *args, "--scheduler", "serial", "--out", str(tmp_path / "st")])


# ----------------------------------------------------------------------------- twin study
@pytest.mark.parametrize("args, says", [
    (["thesis", "--k", "0"], "--k must be a whole number of inputs, at least 1, got 0"),             # D5
    (["thesis", "--model", "foo"], "unknown model 'foo'; available:"),                               # D6
    (["thesis", "--model", "mlr,mlr"], "--model names model 'mlr' more than once"),
    (["hybrid", "--model", "foo"], "unknown model 'foo'; available:"),
    (["cross-condition", "--axes", "Z,Z"], "--axes names drift axis 'Z' more than once"),
    (["thesis", "--physics", "rom"], "--physics applies to the hybrid study only, not to thesis"),    # minor
    (["cross-condition", "--physics", "fe"], "--physics applies to the hybrid study only"),
])
def test_study_options_wrong_on_any_machine_are_refused_first(args, says, tmp_path, no_study_simulation,
                                                              monkeypatch, capsys):
    from twin.core.variants import MachineSpec

    monkeypatch.setattr(MachineSpec, "build", _no_work)       # these need not even build the machine
    assert study(tmp_path, *args) == 2
    err = error_line(capsys)
    assert err.startswith("twin study: error: ") and says in err
    assert not (tmp_path / "st").exists()


@pytest.mark.parametrize("args, says", [
    (["thesis", "--axes", "Q"], "--axes Q: 'Q' is not a drift axis of 'vmc_ram'; drift axes: X,Y,Z,Y_top"),   # D6
    (["hybrid", "--axes", "Z,FBG1"], "'FBG1' is not a drift axis of 'vmc_ram'"),
    (["thesis", "--k", "30", "--model", "mlr", "--axes", "Z"],                                                # D7
     "--k 30 exceeds the 25 installed thermometers of 'vmc_ram'"),
    (["cross-condition", "--k", "26"], "--k 26 exceeds the 25 installed thermometers"),
    (["hybrid", "--inputs", "T01,T99"], ("--inputs T01,T99: 'T99' is not a channel of 'vmc_ram''s records; "
                                          "channels: spindle,feed_x")),
    (["cross-condition", "--inputs", "spindel"], "'spindel' is not a channel of 'vmc_ram''s records"),
])
def test_study_options_wrong_for_the_machine_are_refused_before_simulating(args, says, tmp_path,
                                                                           no_study_simulation, capsys):
    assert study(tmp_path, *args) == 2
    err = error_line(capsys)
    assert err.startswith("twin study: error: ") and says in err


def test_k_up_to_the_installed_thermometers_and_fixed_inputs_pass_the_checks(tmp_path, no_study_simulation):
    """The checks refuse nothing valid: the study gets as far as its simulations (which fail the test here)."""
    with pytest.raises(AssertionError, match="a simulation ran"):
        study(tmp_path, "thesis", "--k", "25", "--model", "mlr", "--axes", "Z,Y_top")
    with pytest.raises(AssertionError, match="a simulation ran"):
        study(tmp_path, "hybrid", "--physics", "rom", "--inputs", "T01,T02", "--k", "99", "--model", "mlr")
    with pytest.raises(AssertionError, match="a simulation ran"):
        study(tmp_path, "cross-condition", "--inputs", "spindle,ambient_room,T05", "--model", "mlr")


def test_the_report_says_when_fewer_inputs_than_k_were_chosen():
    """D7: fewer thermometers may move on the training record than --k asks; the header must not claim k."""
    from twin.compensation.study_report import thesis_markdown

    row = {"axis": "Z", "model": "mlr", "dataset": "thesis_test_4", "role": "training", "rmse": 0.1, "nse": 0.9,
           "max_residual": 0.4, "improvement_percent": 97.0, "uncompensated_max": 16.0, "inputs": "T01 T02"}
    text = thesis_markdown([row], ("Z",), ("mlr",), None, 23, "gm-influence+fcm")
    assert "23 installed thermometers chosen by gm-influence+fcm on Test IV (only 2 move there: that many chosen)" \
        in text
    assert "(only" not in thesis_markdown([row], ("Z",), ("mlr",), None, 2, "gm-influence+fcm")


# ----------------------------------------------------------------------------- twin rom report
@pytest.mark.parametrize("args, says", [
    (["--orders", "80,80", "--methods", "krylov", "--scenarios", "iso230_3_spindle_short"],            # D8
     "--orders names order 80 more than once"),
    (["--orders", "80", "--methods", "krylov,krylov"], "--methods names method 'krylov' more than once"),
    (["--orders", "80", "--methods", "foo"], "--methods: unknown ROM method 'foo'; methods: krylov,modal"),  # D6
    (["--orders", "80", "--scenarios", "nope"], "--scenarios nope: unknown scenario 'nope'; available: ['cutting"),
    (["--orders", "80", "--scenarios", "machine_a_heat_cool"],
     "--scenarios machine_a_heat_cool: runs on machine 'machine_a', not on 'vmc_ram'"),
    (["--orders", "80", "--scenarios", "step_speed,step_speed"], "--scenarios names scenario 'step_speed' more than once"),
])
def test_rom_report_refuses_bad_options_before_any_fe_run(args, says, no_fe_run, capsys):
    assert main(["rom", "report", *args]) == 2
    err = error_line(capsys)
    assert err.startswith("twin rom report: error: ") and says in err


def test_rom_report_where_no_scenario_ran_is_an_error(monkeypatch, capsys, tmp_path):
    """D8: a report of nothing ("smallest Krylov order …: None", exit 0) is an error naming why."""
    from twin.rom import report

    def fails(*args, **kwargs):
        raise RuntimeError("solver diverged")

    monkeypatch.setattr(report, "simulate", fails)
    monkeypatch.setattr(report, "compute_basis", _no_work)      # no basis for a report of nothing
    out = tmp_path / "table.md"
    assert main(["rom", "report", "--orders", "80", "--methods", "krylov", "--scenarios",
                 "iso230_3_spindle_short", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err == ("twin rom report: error: no scenario could be run on 'vmc_ram': "
                   "iso230_3_spindle_short: RuntimeError: solver diverged")
    assert not out.exists()


def test_a_scenario_naming_its_machine_by_path_runs_on_that_machine(tmp_path):
    """A scenario's machine path is resolved (absolute); it is the same machine as the one built from that file."""
    from twin.core.machine import build_machine
    from twin.core.scenario import MACHINES_DIR, load_scenario
    from twin.rom.report import runs_on

    machine = build_machine("vmc_ram")
    text = (Path(__file__).parents[1] / "scenarios" / "iso230_3_spindle_short.toml").read_text()
    by_path = tmp_path / "by_path.toml"
    by_path.write_text(text.replace('machine = "vmc_ram"', f'machine = "{MACHINES_DIR / "vmc_ram.toml"}"'))
    assert runs_on(load_scenario(by_path), machine)
    assert runs_on(load_scenario("iso230_3_spindle_short"), machine)
    assert not runs_on(load_scenario("machine_a_heat_cool"), machine)
