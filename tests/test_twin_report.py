"""`twin report`: plots and summary of an existing dataset, measured or synthetic."""
import json

import numpy as np
import pytest

from twin.cli import main


def test_report_on_measured_recording(fl_thermal_csv, tmp_path, capsys):
    out = tmp_path / "report"
    assert main(["report", str(fl_thermal_csv), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["drift"]) == {"ch1", "ch2", "ch3", "ch4", "ch5"}
    assert summary["drift"]["ch3"]["peak_um"] == pytest.approx(-71.12, abs=0.01)   # −71.02 from its first 0.10 µm
    assert json.loads((out / "import_report.json").read_text())["rows"] == 7711
    assert summary["run_seconds"] is None                  # nothing was simulated: no run time, not 0.0 s
    assert "run time" not in (out / "summary.md").read_text()
    assert (out / "drift.png").exists() and (out / "temperatures.png").exists()
    assert "| ch3 |" in capsys.readouterr().out


def test_report_needs_a_nan_policy_for_gappy_data(tmp_path, capsys):
    path = tmp_path / "gappy.csv"
    path.write_text("time_s,T01_degC,Z_um\n0,20,0\n60,,1\n120,21,2\n")
    assert main(["report", str(path), "--out", str(tmp_path / "r")]) == 2
    assert "choose nan_policy" in capsys.readouterr().err
    assert main(["report", str(path), "--out", str(tmp_path / "r"), "--nan-policy", "interpolate"]) == 0


def _record(tmp_path, name, rows, header="time_s,spindle_rpm,T01_degC,X_um,Y_um,Z_um,Y_top_um"):
    path = tmp_path / f"{name}.csv"
    path.write_text(header + "\n" + "\n".join(",".join(f"{v:g}" for v in row) for row in rows) + "\n")
    return path


def _logger_rows(clock_s=36000.0, z_zero=50.0):
    """A 4 h record on a logger clock that starts at ``clock_s``, with a Z probe that reads ``z_zero`` at the
    start: Z sinks by 15 µm, the upper Y probe moves 0.4 µm more than Y (4 µrad over the 0.1 m spacing)."""
    t = np.arange(0.0, 4 * 3600.0 + 1.0, 600.0)
    share = t / t[-1]
    return np.column_stack([clock_s + t, np.full_like(t, 6000.0), 20.0 + 5.0 * share, 0.2 * np.sin(share * 6),
                            3.0 * share, z_zero - 15.0 * share, 3.4 * share + 1.0])


def test_drift_and_times_count_from_the_first_sample(tmp_path):
    out = tmp_path / "r"
    assert main(["report", str(_record(tmp_path, "logger", _logger_rows())), "--iso", "spindle",
                 "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["duration_h"] == pytest.approx(4.0)
    assert summary["drift"]["Z"] == pytest.approx({"peak_um": -15.0, "at_h": 4.0, "range_um": 15.0})
    iso = summary["iso230_3_spindle"]
    assert iso["max_abs_drift_um"]["Z"] == pytest.approx(15.0)
    assert iso["max_abs_tilt_yz_urad"] == pytest.approx(4.0)          # (0.4 µm more) / 0.1 m, not the 10 µm offset


def test_a_record_without_drift_says_so(tmp_path):
    path = _record(tmp_path, "temperatures", _logger_rows()[:, :3], header="time_s,spindle_rpm,T01_degC")
    out = tmp_path / "r"
    assert main(["report", str(path), "--out", str(out)]) == 0
    assert "- no drift channel (µm)" in (out / "summary.md").read_text()


def test_iso_spindle_without_the_upper_probe_reports_the_drifts(tmp_path):
    rows = _logger_rows()[:, :6]
    out = tmp_path / "r"
    path = _record(tmp_path, "no_top", rows, header="time_s,spindle_rpm,T01_degC,X_um,Y_um,Z_um")
    assert main(["report", str(path), "--iso", "spindle", "--out", str(out)]) == 0
    iso = json.loads((out / "summary.json").read_text())["iso230_3_spindle"]
    assert iso["max_abs_drift_um"]["Z"] == pytest.approx(15.0) and iso["max_abs_tilt_yz_urad"] is None
    assert "tilt in YZ: not measured (no Y_top probe)" in (out / "summary.md").read_text()


@pytest.mark.parametrize("change, message", [
    ({"iso": "etve"}, "the ISO 230-3 ETVE summary needs the room air: an ambient_<zone>_degC column"),
    ({"T01": 500.0}, "column 'T01_degC' has value 500 at t = 36000 s, outside the plausible -40 … 150 degC"),
    ({"T01": 293.15}, "it looks like kelvin (20.00 °C)"),
    ({"T01": -500.0}, "column 'T01_degC' has value -500"),
    ({"rows": 1}, "1 sample(s); a summary needs at least two"),
], ids=["etve-without-ambient", "hot", "kelvin", "below-absolute-zero", "one-row"])
def test_a_record_the_report_cannot_summarise_is_one_line(tmp_path, capsys, change, message):
    rows = _logger_rows()[:change.get("rows")]
    if "T01" in change:
        rows[0, 2] = change["T01"]
    args = ["--iso", change["iso"]] if "iso" in change else []
    out = tmp_path / "r"
    assert main(["report", str(_record(tmp_path, "bad", rows)), *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
