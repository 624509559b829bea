"""Input defects of session 36 that ran silently: an ambient log in ms, a measured CSV cut mid-row, long or
leading stretches filled by ``nan_policy="interpolate"``, a mesh size in mm, a semicolon-separated ambient CSV.
No mesh is built."""
import logging

import numpy as np
import pytest

import meshes.builder
from meshes.builder import MAX_MESH_SIZE_M, check_mesh_size
from meshes.tomlspec import DefinitionError
from twin.cli import main
from twin.core.dataset import QUIET_FILL_S, Dataset, _check_row_lengths
from twin.core.scenario import HOUR, load_scenario
from twin.errors import TwinInputError

ETVE = """[scenario]
duration_h = 6
sample_interval_s = 60.0
[ambient]
kind = "csv"
file = "air.csv"
"""


def _ambient_scenario(tmp_path, times, separator=","):
    """A 6 h scenario replaying ``air.csv``: ``times`` under a ``time_s`` header, a varying temperature."""
    rows = "".join(f"{t:g}{separator}{20.0 + np.sin(k / 10.0):.3f}\n" for k, t in enumerate(times))
    (tmp_path / "air.csv").write_text(f"time_s{separator}ambient_degC\n{rows}")
    path = tmp_path / "etve.toml"
    path.write_text(ETVE)
    return path


def test_an_ambient_log_in_ms_under_a_header_in_s_is_refused(tmp_path):
    """72 h of 10-min readings written in ms: the 6 h scenario fell between the first two readings, and the
    run replayed an ambient of 0.00 K range without a word."""
    path = _ambient_scenario(tmp_path, np.arange(0.0, 72 * HOUR + 1, 600.0) * 1e3)
    with pytest.raises(DefinitionError) as excinfo:
        load_scenario(path)
    message = str(excinfo.value)
    assert f"ambient.file {tmp_path / 'air.csv'}: column 'time_s' has 1 of its 433 readings within the " \
           "scenario's 0 … 21600 s (6 h)" in message
    assert "the times look like ms: write them in s (× 1e-3)" in message


@pytest.mark.parametrize("times, hours", [
    (np.arange(0.0, 30 * 24 * HOUR + 1, 24 * HOUR), 6),     # daily for 30 days: in ms, short of the end
    (np.arange(0.0, 366 * 24 * HOUR, 24 * HOUR), 6),        # daily for a year: in ms, 8.8 h, 86.4 s apart
    (np.arange(0.0, 30 * 24 * HOUR + 1, HOUR), 0.5)])       # hourly for a month under 0.5 h
def test_a_log_coarser_than_the_scenario_is_taken_as_written(tmp_path, times, hours):
    """1 reading inside the scenario, but readings a day apart or less read in s: nothing says they are ms (a
    room is logged at least daily): the twin interpolates between readings, as documented."""
    path = _ambient_scenario(tmp_path, times)
    path.write_text(ETVE.replace("duration_h = 6", f"duration_h = {hours}"))
    assert load_scenario(path).duration_s == hours * HOUR


@pytest.mark.parametrize("times", [np.arange(0.0, 7 * 24 * HOUR + 1, 60.0),   # a week of 1-min readings
                                   np.array([0.0, 10 * HOUR, 20 * HOUR])])    # a hand-written ramp
def test_a_longer_log_or_a_sparse_profile_in_s_is_accepted(tmp_path, times):
    scenario = load_scenario(_ambient_scenario(tmp_path, times))
    assert scenario.duration_s == 6 * HOUR


def test_a_semicolon_separated_ambient_csv_gets_the_separator_hint(tmp_path):
    path = _ambient_scenario(tmp_path, np.arange(0.0, 7 * HOUR, 600.0), separator=";")
    with pytest.raises(DefinitionError, match=r"no column 'time_s'; the header 'time_s;ambient_degC' is "
                                              r"separated by ';'; the twin reads comma-separated files"):
        load_scenario(path)


HEADER = "time_s,T01_degC,Z_um\n"


@pytest.mark.parametrize("rows, message", [
    # the last row cut mid-number: T01 = "2" had been a reading of 2 °C and Z a NaN
    ("0,20.1,1.0\n60,20.2,1.1\n120,2", (r"data row 3 \(line 4, '120,2'\) has 2 fields, the header 3 \(cut short\? "
                                        r"it is the file's last row\)")),
    ("0,20.1,1.0\n60,20.2\n120,20.3,1.2\n", r"data row 2 \(line 3, '60,20.2'\) has 2 fields, the header 3$"),
    ("0,20.1,1.0,9\n60,20.2,1.1,9\n", r"data row 1 \(line 2, '0,20.1,1.0,9'\) has 4 fields, the header 3$"),
    # pandas would take the time column as the index and shift every channel by one column
    ("0,20.1,1.0,\n60,20.2,1.1,\n", (r"data row 1 \(line 2, '0,20.1,1.0,'\) has 4 fields, the header 3 \(a "
                                     r"trailing comma on each row\? remove it\)$")),
    ("# logger v2 firmware 1.3\n0,20.1,1.0\n", r"data row 1 \(line 2, '# logger v2 firmware 1\.3'\) has 1 fields"),
    ("0,20.1,1.0\n60,20.2,1.1\n" + "9" * 100 + "\n", rf"data row 3 \(line 4, '{'9' * 60}'\) has 1"),
])
def test_a_row_with_another_number_of_fields_than_the_header_is_refused(tmp_path, rows, message):
    path = tmp_path / "m.csv"
    path.write_text(HEADER + rows)
    with pytest.raises(TwinInputError, match=rf"^{path}: {message}"):
        Dataset.from_measured_csv(path, nan_policy="interpolate")



def test_a_line_of_spaces_is_skipped_as_pandas_skips_it(tmp_path):
    path = tmp_path / "m.csv"
    path.write_text(HEADER + "0,20.1,1.0\n  \n60,20.2,1.1\n")
    ds = Dataset.from_measured_csv(path)
    assert ds["T01"].tolist() == [20.1, 20.2] and ds["Z"].tolist() == [1.0, 1.1]


def test_a_quoted_field_after_a_space_is_split_as_pandas_splits_it():
    """``0,20, "a,b"`` has 3 fields for pandas (spaces after a comma skipped, then the quotes hold the comma)."""
    _check_row_lengths("m.csv", 'time_s,T01_degC,note\n0,20, "a,b"\n')

def _record_with_nans(tmp_path, nan_rows, n=600, step_s=15.0):
    """``n`` rows every ``step_s`` s, T01 missing at ``nan_rows``."""
    t = np.arange(n) * step_s
    temps = [("" if k in nan_rows else f"{20.0 + 1e-3 * k:.4f}") for k in range(n)]
    path = tmp_path / "gappy.csv"
    path.write_text(HEADER + "".join(f"{t[k]:g},{temps[k]},{k * 0.01:.2f}\n" for k in range(n)))
    return path


def test_a_long_interpolated_gap_is_warned_of_and_counted(tmp_path, caplog):
    """250 rows of 15 s (an hour) filled by a straight line, as 4.2 h of a real record were, without a word."""
    path = _record_with_nans(tmp_path, range(100, 350))
    with caplog.at_level(logging.WARNING, logger="thermal_twin"):
        ds = Dataset.from_measured_csv(path, nan_policy="interpolate")
    assert ds["T01"][200] == pytest.approx(20.2)
    assert ds.metadata["import"]["filled"] == {"T01": {"values": 250, "longest_run_rows": 250,
                                                       "longest_run_s": 251 * 15.0}}
    assert "column 'T01_degC': nan_policy='interpolate' filled 250 rows in a row with a straight line over " \
           "1 h (t = 1500 … 5235 s; 250 values filled in all)" in caplog.text


def test_a_short_interpolated_gap_is_counted_quietly(tmp_path, caplog):
    path = _record_with_nans(tmp_path, {10, 11, 300})
    with caplog.at_level(logging.WARNING, logger="thermal_twin"):
        ds = Dataset.from_measured_csv(path, nan_policy="interpolate")
    assert ds.metadata["import"]["filled"]["T01"] == {"values": 3, "longest_run_rows": 2, "longest_run_s": 45.0}
    assert caplog.text == ""


def test_a_filled_first_row_is_warned_of_and_a_long_one_refused(tmp_path, caplog):
    """The first row is the reference of a record's changes: holding a later reading back to it extrapolates."""
    with caplog.at_level(logging.WARNING, logger="thermal_twin"):
        Dataset.from_measured_csv(_record_with_nans(tmp_path, range(3)), nan_policy="interpolate")
    assert "column 'T01_degC' has no reading before t = 45 s (3 rows, 45 s): nan_policy='interpolate' holds " \
           "that reading back to the first row" in caplog.text
    rows = int(QUIET_FILL_S / 15.0) + 1
    with pytest.raises(TwinInputError, match=rf"no reading before t = {rows * 15} s \({rows} rows, {rows * 15} s\): "
                                             r".*cut the record to start at its first reading or drop the "
                                             r"incomplete rows \(--nan-policy drop; nan_policy='drop' in Python\)"):
        Dataset.from_measured_csv(_record_with_nans(tmp_path, range(rows)), nan_policy="interpolate")



def test_a_slow_logger_missing_its_first_reading_is_filled_with_a_warning(tmp_path, caplog):
    """A 15-min logger whose first T01 reading is missing: one sampling interval (900 s > QUIET_FILL_S) held back."""
    with caplog.at_level(logging.WARNING, logger="thermal_twin"):
        ds = Dataset.from_measured_csv(_record_with_nans(tmp_path, {0}, n=40, step_s=900.0), nan_policy="interpolate")
    assert ds["T01"][0] == ds["T01"][1] and "no reading before t = 900 s (1 rows, 900 s)" in caplog.text
    with pytest.raises(TwinInputError, match=r"no reading before t = 1800 s \(2 rows, 1800 s\)"):
        Dataset.from_measured_csv(_record_with_nans(tmp_path, {0, 1}, n=40, step_s=900.0), nan_policy="interpolate")

@pytest.mark.parametrize("value, hint", [("35", "; is it in mm? 35 mm is a mesh size of 0.035 m"),
                                         ("2000", ""), ("0.6", ""),    # 0.6 mm: no machine is meshed so fine
                                         ("2", "; is it in mm? 2 mm is a mesh size of 0.002 m")])
def test_a_mesh_size_in_mm_is_refused_before_any_meshing(monkeypatch, capsys, value, hint):
    def mesher_must_not_run(*args):
        raise AssertionError("fTetWild was started")

    monkeypatch.setattr(meshes.builder, "tetrahedralize", mesher_must_not_run)
    with pytest.raises(SystemExit) as exc:
        main(["run", "iso230_3_spindle_short", "--mesh-size", value, "--no-views"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert f"argument --mesh-size: {value!r} is not a mesh size: give a finite length in m, from 0.0001 m " \
           f"(0.1 mm) to {MAX_MESH_SIZE_M:g} m{hint}\n" in err


def test_a_mesh_size_argument_over_the_bound_is_refused():
    assert check_mesh_size(MAX_MESH_SIZE_M) == MAX_MESH_SIZE_M
    with pytest.raises(DefinitionError, match=r"to 0\.5 m, got 35 m; is it in mm\? 35 mm is a mesh size of 0\.035 m"):
        check_mesh_size(35)


def test_a_slow_loggers_missing_first_reading_is_not_called_a_straight_line(tmp_path, caplog):
    """A 15-min logger without its first reading: held back one step (warned of as such); it had also been reported
    as "filled 1 rows in a row with a straight line over 0.25 h"."""
    path = tmp_path / "slow.csv"
    path.write_text(HEADER + "".join(f"{900 * k},{'' if k == 0 else 20 + 0.1 * k},{0.01 * k:.2f}\n"
                                     for k in range(20)))
    with caplog.at_level(logging.WARNING, logger="thermal_twin"):
        ds = Dataset.from_measured_csv(path, nan_policy="interpolate")
    assert ds["T01"][0] == pytest.approx(20.1)
    assert "holds that reading back" in caplog.text and "straight line" not in caplog.text
