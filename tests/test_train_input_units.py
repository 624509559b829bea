"""``twin train``/``twin evaluate`` on a measured CSV warn of a spindle column that reads like krpm or Hz (and feeds
like m/min), as the gap diagnosis does: the same rule (:func:`twin.core.unit_hints.other_unit_hint`)."""
import logging

import numpy as np
import pytest

T = np.arange(241) * 120.0                      # 8 h every 2 min


def _csv(path, spindle, feed=None):
    """A measured CSV: the spindle column given, a thermometer and a Z drift that follow it; a feed if given."""
    heat = np.cumsum(np.abs(spindle)) / max(np.abs(spindle).sum(), 1.0)
    columns = {"time_s": T, "spindle_rpm": spindle, "T01_degC": 20.0 + 3.0 * heat, "Z_um": -8.0 * heat}
    if feed is not None:
        columns["feed_x_mm_min"] = feed
    np.savetxt(path, np.column_stack(list(columns.values())), delimiter=",", header=",".join(columns),
               comments="", fmt="%.6g")
    return path


def _held(levels):
    return np.repeat(np.asarray(levels, float), -(-len(T) // len(levels)))[:len(T)]


def _warnings(caplog):
    return [r.getMessage() for r in caplog.records if r.name == "thermal_twin" and r.levelno == logging.WARNING]


def test_a_spindle_in_krpm_is_warned_about_on_import(tmp_path, caplog):
    """12000 rpm logged in krpm (12) trained a model silently; the gap diagnosis warned of the same column."""
    from twin.compensation.train import load_dataset

    path = _csv(tmp_path / "krpm.csv", _held([0, 4.5, 9, 12, 0]), feed=_held([0, 5, 0, 5, 0]))
    with caplog.at_level(logging.WARNING, logger="thermal_twin"):
        data = load_dataset(path)
    said = _warnings(caplog)
    assert len(said) == 2, said
    assert said[0].startswith(f"{path}: column 'spindle_rpm' peaks at about 12 rpm (99th percentile), 0.1 % of the "
                              "12000 rpm top speed of a typical machining centre (no machine given)")
    assert "in krpm, 12000 rpm (× 1000)" in said[0] and "convert it to rpm" in said[0]
    assert "column 'feed_x_mm_min' peaks at about 5 mm/min" in said[1]
    assert data.metadata["import"]["unit_suspects"] == ["spindle_rpm", "feed_x_mm_min"]


def test_the_machine_given_sets_the_top_speed(tmp_path, caplog):
    from twin.compensation.train import load_dataset
    from twin.gap.diagnose import _machine

    path = _csv(tmp_path / "hz.csv", _held([0, 50, 100, 150, 0]))          # 9000 rpm in Hz: 150
    with caplog.at_level(logging.WARNING, logger="thermal_twin"):
        load_dataset(path, machine=_machine("vmc_ram"))
    said = _warnings(caplog)
    assert len(said) == 1 and "1.2 % of the 12000 rpm top speed of machine 'vmc_ram'" in said[0], said
    assert "in Hz (rev/s), the speed is 9000 rpm (× 60)" in said[0]


@pytest.mark.parametrize("spindle", [_held([0, 4500, 9000, 12000, 0]), np.zeros(len(T)),
                                     np.random.default_rng(1).uniform(0.0, 3.0, len(T))])
def test_a_spindle_in_rpm_or_at_rest_is_not_warned_about(spindle, tmp_path, caplog):
    from twin.compensation.train import load_dataset

    with caplog.at_level(logging.WARNING, logger="thermal_twin"):
        data = load_dataset(_csv(tmp_path / "rpm.csv", spindle))
    assert _warnings(caplog) == [] and "unit_suspects" not in data.metadata["import"]


def test_train_warns_through_the_command_line(tmp_path, capsys):
    from twin.cli import main

    path = _csv(tmp_path / "krpm.csv", _held([0, 4.5, 9, 12, 0]))
    code = main(["train", str(path), "--inputs", "T01", "--target", "Z", "--model", "mlr",
                 "--out", str(tmp_path / "m.json")])
    err = capsys.readouterr().err
    assert code == 0 and "column 'spindle_rpm' peaks at about 12 rpm" in err, err


# ---------------------------------------------------------------- --machine: the limits of the machine given

@pytest.fixture
def unbuilt(monkeypatch):
    """Fail loudly if a machine given by name were built (meshed) to judge a measured CSV: its file suffices."""
    from twin.core import machine

    def refuse(*args, **kwargs):
        raise AssertionError("the machine was built (meshed)")
    monkeypatch.setattr(machine, "build_mesh", refuse)


def test_a_machine_given_by_name_judges_the_columns_without_a_mesh(tmp_path, caplog, unbuilt):
    """A 250 mm/min finishing feed is 0.8 % of a typical 30 m/min top, 1.25 % of Machine A's 20 m/min: only the
    first reads like m/min; a spindle in Hz (150 for 9000 rpm) is judged against Machine A's 9000 rpm."""
    from twin.compensation.train import load_dataset

    path = _csv(tmp_path / "a.csv", _held([0, 50, 100, 150, 0]), feed=_held([0, 250, 0, 250, 0]))
    with caplog.at_level(logging.WARNING, logger="thermal_twin"):
        load_dataset(path)
    assert [m.split("peaks")[0] for m in _warnings(caplog)] == [f"{path}: column 'spindle_rpm' ",
                                                               f"{path}: column 'feed_x_mm_min' "]
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="thermal_twin"):
        data = load_dataset(path, machine="machine_a")
    said = _warnings(caplog)
    assert len(said) == 1 and "1.7 % of the 9000 rpm top speed of machine 'machine_a'" in said[0], said
    assert data.metadata["import"]["unit_suspects"] == ["spindle_rpm"]


@pytest.mark.parametrize("command", ["train", "evaluate"])
def test_train_and_evaluate_take_the_machine(command, tmp_path, capsys, unbuilt):
    from twin.cli import main

    path = _csv(tmp_path / "a.csv", _held([0, 4500, 9000, 0]), feed=_held([0, 250, 0, 250, 0]))
    model = tmp_path / "m.json"
    train = ["train", str(path), "--inputs", "T01", "--target", "Z", "--model", "mlr", "--out", str(model)]
    evaluate = ["evaluate", str(model), str(path)]
    if command == "evaluate":
        assert main(train) == 0
        capsys.readouterr()
    argv = train + ["--overwrite"] if command == "train" else evaluate
    assert main(argv) == 0
    assert "column 'feed_x_mm_min' peaks at about 250 mm/min" in capsys.readouterr().err
    assert main([*argv, "--machine", "machine_a"]) == 0
    assert "feed_x_mm_min" not in capsys.readouterr().err
    assert main([*argv, "--machine", "machine_q"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "machine_q" in err and "machine_a" in err, err


def test_help_says_what_is_assumed_without_a_machine(capsys):
    """The numbers in --help are those of twin.core.unit_hints.TYPICAL_TOP (--help must not import numpy)."""
    from twin.cli import main
    from twin.compensation import cli
    from twin.core.unit_hints import TYPICAL_TOP

    assert (cli.TYPICAL_TOP_RPM, 1000 * cli.TYPICAL_TOP_FEED_M_MIN) == (TYPICAL_TOP["rpm"], TYPICAL_TOP["mm_min"])
    for command in ("train", "evaluate"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        text = " ".join(capsys.readouterr().out.split())
        assert "--machine MACHINE" in text and "a typical machining centre's 12000 rpm and 30 m/min" in text


def test_a_scenario_among_the_datasets_runs_on_the_machine_given(monkeypatch):
    """As with ``twin run --machine``: a machine given by name is built for a scenario (not for a CSV)."""
    from twin.compensation import train
    from twin.core.machine_definition import load_machine

    class Ran(Exception):
        """The simulation was called, with the machine in its args."""

    def simulate(spec, machine, noise):
        raise Ran(machine)
    monkeypatch.setattr(train, "build_machine", lambda definition: ("built", definition.name))
    monkeypatch.setattr(train, "simulate", simulate)
    for given, built in (("machine_a", ("built", "machine_a")), (load_machine("machine_a"), ("built", "machine_a")),
                         (None, None)):
        with pytest.raises(Ran) as ran:
            train.load_dataset("iso230_3_etve", machine=given)
        assert ran.value.args == (built,)


def test_the_top_of_a_machine_is_one_function():
    from twin.core.machine_definition import load_machine
    from twin.core.unit_hints import machine_top, top_of

    machine_a = load_machine("machine_a")
    assert (machine_top(machine_a, "rpm"), machine_top(machine_a, "mm_min")) == (9000.0, 20000.0)
    assert top_of(machine_a, "mm_min") == (20000.0, "machine 'machine_a'")
    assert top_of(None, "rpm") == (12000.0, "a typical machining centre (no machine given)")
