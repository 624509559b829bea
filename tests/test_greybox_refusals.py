"""What the grey-box model and `twin train`/`twin evaluate` refuse about the spindle speed and the record's rows.

A tachometer at rest reads a few rpm: such a record never runs (`models.speed.running` has an absolute floor,
`STANDSTILL_RPM`), and a grey-box fit on it, whose spindle heat cannot be identified, is refused, in `twin` with
one line naming the record. A negative speed and a record of one row are refused by `twin` with one line
naming the file, where the model once let a 0-based row or a scikit-learn message through. A weight of the
observed thermometers that is negative or not finite is refused by name.
"""
import numpy as np
import pytest
from test_models_greybox import ambient, duty, record, simulate

from models.greybox import GreyBoxRegressor
from models.selection_cv import regime_blocks
from models.speed import STANDSTILL_RPM, running
from twin.cli import main
from twin.compensation.train import evaluate, train
from twin.errors import TwinInputError

HEADER = "time_s,spindle_rpm,air_degC,Z_um"


def _write(path, times, speed, drift):
    rows = np.column_stack([times, speed, ambient(times), drift])
    path.write_text(HEADER + "\n" + "\n".join(",".join(f"{v:.10g}" for v in row) for row in rows) + "\n")
    return path


def _at_rest(n=600, seed=0):
    """``(times s, speed rpm, drift µm)`` of a machine at rest: the tachometer reads 0-4 rpm, the room moves."""
    rng = np.random.default_rng(seed)
    times = np.arange(n) * 60.0
    speed = rng.integers(0, 5, n).astype(float)
    drift = 0.8 * (ambient(times) - ambient(times[0])) + 0.1 * rng.standard_normal(n)
    return times, speed, drift


def _running(hours=24, levels=(1500.0, 3000.0)):
    """``(times s, speed rpm, drift µm)`` of the two-node network of ``tests/test_models_greybox.py``."""
    times = np.arange(0.0, hours * 3600.0, 120.0)
    speed = duty(times, list(levels), 4 * 3600.0)
    return times, speed, simulate(times, speed)[1]


def test_a_standstill_reading_a_few_rpm_never_runs():
    assert not running([0.0, 1.0, 4.0, 3.0, 0.0]).any()          # was: 1-4 rpm ran, 5 % of a 4 rpm top
    assert not running([0.0, STANDSTILL_RPM, 0.5 * STANDSTILL_RPM]).any()
    np.testing.assert_array_equal(running([0.0, 4.0, 30.0, 60.0]), [False, False, True, True])
    # FL_THERMAL's speeds (1250-3750 rpm, ±3 rpm at rest) are judged by the 5 % alone, as before
    fl = np.r_[np.zeros(5), np.full(5, 1250.0), [3.0, 2.0], np.full(5, 3750.0), [180.0, 190.0]]
    np.testing.assert_array_equal(running(fl), np.abs(fl) > 0.05 * 3750.0)
    assert regime_blocks(np.r_[np.zeros(5), np.full(5, 1250.0), [3.0, 2.0], np.full(5, 3750.0)]) == [(0, 12), (12, 17)]
    assert not running([np.nan, 0.0, 2.0]).any() and running([np.nan, 0.0, 500.0]).tolist() == [False, False, True]


def test_the_greybox_refuses_a_fit_where_the_spindle_never_runs():
    times, speed, drift = _at_rest()
    X = np.column_stack([times, speed, ambient(times)])
    with pytest.raises(ValueError, match=r"GreyBoxRegressor: the spindle never runs on the rows fitted \(spindle "
                                         r"speed, column 1, at most 4 rpm; it runs above 20 rpm .*cannot be "
                                         r"identified"):
        GreyBoxRegressor(n_poles=1).fit(X, drift)
    # the rows fitted are those weighted: a run whose targets are all left out is not seen
    times, speed, drift = _running(hours=12, levels=(3000.0,))
    X = np.column_stack([times, speed, ambient(times)])
    with pytest.raises(ValueError, match="never runs on the rows fitted"):
        GreyBoxRegressor(n_poles=1).fit(X, drift, sample_weight=(speed == 0) & (times < 4 * 3600.0))
    GreyBoxRegressor(n_poles=1).fit(X, drift)   # it runs: fitted


def test_twin_train_refuses_a_record_where_the_spindle_never_runs_in_one_line(tmp_path, capsys):
    times, speed, drift = _at_rest()
    speed[0] = 1.0   # a first reading of 1 rpm is rest, not "the record starts with the spindle running"
    csv = _write(tmp_path / "rest.csv", times, speed, drift)
    out = tmp_path / "m.json"
    code = main(["train", str(csv), "--inputs", "spindle,air", "--target", "Z", "--model", "greybox",
                 "--param", "n_poles=1", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err and not out.exists()
    assert ("rest: the spindle never runs (spindle at most 4 rpm; it runs above 20 rpm), so greybox cannot "
            "identify the heat of the spindle") in err
    # among records where it runs, a day at rest is one more record
    running_csv = _write(tmp_path / "day.csv", *_running())
    cm = train([running_csv, csv], "spindle,air", "Z", model="greybox", params={"n_poles": 1})
    assert cm.metadata["training_top_speed_rpm"] == {"spindle": 3000.0}


def test_a_negative_speed_is_refused_naming_the_file_column_time_and_value(tmp_path, capsys):
    times, speed, drift = _running(hours=12)
    speed[300] = -50.0
    csv = _write(tmp_path / "neg.csv", times, speed, drift)
    message = f"{csv}: column 'spindle_rpm' is -50 rpm at t = 36000 s (data row 301); a spindle speed is >= 0 rpm"
    code = main(["train", str(csv), "--inputs", "spindle,air", "--target", "Z", "--model", "greybox",
                 "--param", "n_poles=1", "--out", str(tmp_path / "m.json")])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and message in err
    good = _write(tmp_path / "good.csv", *_running(hours=12))
    train([good], "spindle,air", "Z", model="greybox", params={"n_poles": 1}, out=tmp_path / "m.json")
    with pytest.raises(TwinInputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        evaluate(tmp_path / "m.json", [csv])


def test_evaluate_refuses_a_record_of_one_row_in_one_line(tmp_path, capsys):
    times, speed, drift = _running(hours=12)
    good = _write(tmp_path / "good.csv", times, speed, drift)
    one = _write(tmp_path / "one.csv", times[:1], speed[:1], drift[:1])
    train([good], "spindle,air", "Z", model="greybox", params={"n_poles": 1}, out=tmp_path / "m.json")
    assert main(["evaluate", str(tmp_path / "m.json"), str(one)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "sample(s)" not in err
    assert f"{one}: 1 row; a model is scored on the change of a record since its first row" in err


@pytest.mark.parametrize("weight, shown", [(-1.0, "-1.0"), (np.nan, "nan"), (np.inf, "inf"), ("heavy", "'heavy'")])
def test_an_observed_weight_that_is_negative_or_not_finite_is_refused_by_name(weight, shown):
    """It multiplies the thermometers' residuals: a negative one would be squared away, and NaN or inf would make
    every residual NaN (was: accepted)."""
    X, y = record(np.arange(0.0, 12 * 3600.0, 120.0), [1500.0, 3000.0])
    model = GreyBoxRegressor(n_poles=1, temperature_inputs=(2,), observed=(3,), observed_weight=weight)
    with pytest.raises(ValueError, match=rf"^GreyBoxRegressor: observed_weight must be finite and >= 0, got {shown}\.$"):
        model.fit(X, y)
    GreyBoxRegressor(n_poles=1, temperature_inputs=(2,), observed=(3,), observed_weight=0.0).fit(X, y)
