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
