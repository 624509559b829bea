"""``twin place`` refuses bad options in one line (exit 2) before any simulation, naming the option and value."""
import numpy as np
import pytest
from test_cli_outdir import one_error_line

from twin.cli import main
from twin.core.scenario import SCENARIOS_DIR
from twin.core.variants import as_scenario

TRAIN, VALIDATION, TEST = "iso230_3_spindle_short,cutting_soft", "thesis_test_5", "cutting_hard"
SMALL = ["--candidates", "50", "--k-max", "2", "--axes", "Z", "--methods", "greedy-loso", "--scheduler", "serial"]


@pytest.fixture
def refused(tmp_path, monkeypatch, capsys):
    """``refused(*options)``: run ``twin place`` with small defaults overridden by ``options``; assert it exits 2
    without simulating or writing, and return its one error line."""
    from twin.placement import study

    def simulate(*args, **kwargs):
        raise AssertionError("simulated although the options are bad")

    monkeypatch.setattr(study, "_simulate", simulate)
    out = tmp_path / "place"

    def run(*options):
        given = dict(zip(options[::2], options[1::2]))
        roles = {"--train": TRAIN, "--validation": VALIDATION, "--test": TEST}
        args = SMALL + [a for option, value in roles.items() if option not in given for a in (option, value)]
        assert main(["place", *args, *options, "--out", str(out)]) == 2
        assert not out.exists()
        return one_error_line(capsys)
    return run


@pytest.mark.parametrize("test", [str(SCENARIOS_DIR / "cutting_soft.toml"), "cutting_soft"])
def test_a_training_scenario_is_refused_as_a_test_one_however_given(refused, test):
    """A path is compared by the scenario's name: else an in-sample fit would be reported as held out."""
    err = refused("--test", test)
    assert "scenario 'cutting_soft' is both a training and a test scenario (--train, --test)" in err


@pytest.mark.parametrize("train", ["cutting_soft,cutting_soft", f"cutting_soft,{SCENARIOS_DIR / 'cutting_soft.toml'}"])
def test_a_scenario_repeated_in_a_role_is_refused(refused, train):
    """Two copies would let greedy-loso's leave-one-scenario-out predict a scenario from itself."""
    assert "--train names scenario 'cutting_soft' more than once" in refused("--train", train)


@pytest.mark.parametrize("axes", ["T01", "Q", "Z,cam000"])
def test_only_the_machine_drift_axes_are_axes(refused, axes):
    """A thermometer is no drift axis (its °C would be reported ×1e6 as µm); the message is short."""
    err = refused("--axes", axes)
    assert f"--axes {axes}:" in err and "is not a drift axis of 'vmc_ram'; drift axes: X,Y,Z,Y_top" in err
    assert len(err) < 200


@pytest.mark.parametrize("option", ["--train", "--validation", "--test", "--methods", "--parts", "--axes"])
@pytest.mark.parametrize("value", ["", ","])
def test_an_empty_list_is_refused_not_replaced_by_the_default(refused, option, value):
    """An unset shell variable must not silently run the default scenarios (or methods, parts)."""
    err = refused(option, value)
    assert err.startswith(f"twin place: error: {option} must name at least") and "got []" in err


def test_an_unknown_scenario_is_refused_naming_its_option(refused):
    """A misspelt name is no 'unavailable' scenario to skip: the study would run without it."""
    err = refused("--validation", "thesis_test_5,thesis_tset_6")
    assert "--validation 'thesis_tset_6': unknown scenario 'thesis_tset_6'; available: [" in err
    assert "'thesis_test_6'" in err


@pytest.mark.parametrize(("options", "message"), [
    (("--k-max", "0"), "--k-max must be positive, got 0"),
    (("--k-max", "-1"), "--k-max must be positive, got -1"),
    (("--candidates", "3", "--no-camera", "--k-max", "5"), "--k-max 5 exceeds the 3 candidates"),
    (("--candidates", "-5"), "--candidates must be ≥ 0, got -5"),
    (("--record-interval", "-60"), "--record-interval must be positive, got -60 s"),
    (("--record-interval", "nan"), "--record-interval must be positive, got nan s"),
    (("--response-horizon", "-1"), "--response-horizon must be positive, got -1 h"),
])
def test_numbers_are_checked_before_any_simulation(refused, options, message):
    assert message in refused(*options)


def test_the_header_says_how_often_each_scenario_is_recorded():
    """Three default scenarios are sampled every 300 s: a 60 s recording interval cannot make them finer."""
    from twin.placement.records import record_interval, record_times
    from twin.placement.report import _intervals
    from twin.placement.study import DEFAULT_TEST, DEFAULT_TRAIN, DEFAULT_VALIDATION

    scenarios = [as_scenario(n) for n in DEFAULT_TRAIN + DEFAULT_VALIDATION + DEFAULT_TEST]
    intervals = {s.name: record_interval(s, 60.0) for s in scenarios}
    for s in scenarios:
        assert np.allclose(np.diff(record_times(s, 60.0)), intervals[s.name])
    assert _intervals({"record_intervals_s": intervals}) == (
        "every 60 s; every 300 s for etve_5K, stratified_ambient, iso230_3_etve (their own sampling)")


@pytest.mark.parametrize("role", ["--train", "--validation", "--test"])
def test_a_scenario_beyond_the_machines_limits_is_refused_naming_file_and_limit(refused, tmp_path, role):
    """Checked against the machine before any simulation: else the study would fail (or run a spindle the
    machine does not have) after hours of the other scenarios."""
    too_fast = (SCENARIOS_DIR / "iso230_3_spindle_short.toml").read_text(encoding="utf-8").replace(
        'name = "iso230_3_spindle_short"', 'name = "too_fast"').replace("spindle_rpm = 6000", "spindle_rpm = 15000")
    path = tmp_path / "too_fast.toml"
    path.write_text(too_fast, encoding="utf-8")
    given = {"--train": f"{TRAIN},{path}", "--validation": f"{VALIDATION},{path}", "--test": f"{TEST},{path}"}
    err = refused(role, given[role])
    assert f"{path}: " in err and "spindle_rpm 15000 exceeds the maximum of machine 'vmc_ram' (12000 rpm)" in err
