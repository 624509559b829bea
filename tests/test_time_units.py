"""A measured CSV's time is in s: a header that names hours or minutes is refused, a record timed in hours is named.

On the code before this check, an 8 h test logged in hours trained as an 8 s one without a word, and a
``time_h`` or ``t [min]`` column mapped to ``time_s`` was read as seconds.
"""
import logging
import re

import numpy as np
import pandas as pd
import pytest

from twin.cli import main
from twin.compensation.train import evaluate, load_dataset, train
from twin.core.dataset import Dataset
from twin.errors import TwinInputError


def _test_frame(hours=8.0, step_s=60.0):
    """A heat-up and cool-down logged every ``step_s``: 6000 rpm for half the record, two thermometers (°C) and
    a drift Z (µm) that follow it."""
    t = np.arange(0.0, hours * 3600.0 + step_s / 2, step_s)
    T1 = 20.0 + 6.0 * (1.0 - np.exp(-t / 3000.0))
    T2 = 20.0 + 2.0 * (1.0 - np.exp(-t / 5000.0))
    return pd.DataFrame({"time_s": t, "spindle_rpm": np.where(t < hours * 1800.0, 6000.0, 0.0), "T01_degC": T1,
                         "T02_degC": T2, "Z_um": -4.0 * (T1 - 20.0) + 2.5 * (T2 - 20.0)})


@pytest.mark.parametrize("header, unit, factor", [("time_h", "hours", "3600"), ("t [min]", "minutes", "60"),
                                                   ("Time (hours)", "hours", "3600"), ("elapsed_min", "minutes", "60"),
                                                   ("time_ms", "milliseconds", "0.001")])
def test_a_time_column_named_in_another_unit_is_refused(tmp_path, header, unit, factor):
    frame = _test_frame()
    frame["time_s"] *= float(factor) ** -1
    path = tmp_path / "test.csv"
    frame.rename(columns={"time_s": header}).to_csv(path, index=False)
    message = (re.escape(f"test.csv: column '{header}' looks like the time column, and its header says {unit} (")
               + ".*" + re.escape(f"; the twin reads time in s and does not convert it: write the column in s "
                                  f"(× {factor}) as time_s"))
    with pytest.raises(TwinInputError, match=message):
        Dataset.from_measured_csv(path)


def test_a_column_map_does_not_turn_hours_into_seconds(tmp_path, capsys):
    frame = _test_frame()
    frame["time_s"] /= 3600.0
    path = tmp_path / "logger.csv"
    frame.rename(columns={"time_s": "time_h"}).to_csv(path, index=False)
    with pytest.raises(TwinInputError, match=r"logger.csv: column 'time_h' is the time column \(mapped to time_s\), "
                                             r"and its header says hours \(h\)"):
        load_dataset(path, column_map={"time_h": "time_s"})
    code = main(["train", str(path), "--column-map", '{"time_h": "time_s"}', "--inputs", "T01,T02", "--target", "Z",
                 "--model", "mlr", "--out", str(tmp_path / "m.json")])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert "logger.csv" in err and "'time_h'" in err and "hours" in err


def test_a_record_timed_in_hours_gets_a_hint_naming_file_column_and_values(tmp_path, caplog):
    frame = _test_frame()
    frame["time_s"] /= 3600.0        # the logger wrote hours under a time_s header
    path = tmp_path / "heat_up.csv"
    frame.to_csv(path, index=False)
    with caplog.at_level(logging.WARNING, logger="thermal_twin"):
        ds = Dataset.from_measured_csv(path)
    hint = ds.metadata["import"]["time_unit_hint"]
    assert str(path) in hint and "column 'time_s' spans 8 s in steps of 0.0166667 s" in hint
    assert "T01 changes by 6 K" in hint and "hours (× 3600" in hint
    assert [r.getMessage() for r in caplog.records] == [hint]
    # twin train and twin evaluate read it through the same import, and say it once each
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="thermal_twin"):
        cm = train([path], "T01,T02", "Z", model="mlr")
        evaluate(cm, [path])
    assert [r.getMessage() for r in caplog.records].count(hint) == 2


@pytest.mark.parametrize("hours, step_s, scale", [
    (8.0, 60.0, 1.0),           # an 8 h test in s
    (1.0 / 30, 0.1, 0.02),      # a 2 min capture at 10 Hz: its temperatures move by a tenth of a kelvin
    (0.05, 0.25, 1.0),          # 3 min at 4 Hz of a full heat-up's start
])
def test_records_in_seconds_get_no_hint(tmp_path, caplog, hours, step_s, scale):
    frame = _test_frame(hours, step_s)
    for column in ("T01_degC", "T02_degC"):
        frame[column] = 20.0 + scale * (frame[column] - 20.0)
    frame["Z_um"] *= scale
    path = tmp_path / "fast.csv"
    frame.to_csv(path, index=False)
    with caplog.at_level(logging.WARNING, logger="thermal_twin"):
        ds = Dataset.from_measured_csv(path)
    assert "time_unit_hint" not in ds.metadata["import"] and not caplog.records


def test_a_temperature_column_named_for_its_minimum_is_no_time(tmp_path):
    frame = _test_frame().rename(columns={"T02_degC": "T_min_degC"})
    path = tmp_path / "ok.csv"
    frame.to_csv(path, index=False)
    assert "T_min" in Dataset.from_measured_csv(path)
    frame.drop(columns="time_s").to_csv(path, index=False)
    with pytest.raises(TwinInputError, match=r"ok.csv: no time column 'time_s'"):
        Dataset.from_measured_csv(path)
