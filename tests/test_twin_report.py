"""`twin report`: plots and summary of an existing dataset, measured or synthetic."""
import json

import pytest

from twin.cli import main


def test_report_on_measured_recording(fl_thermal_csv, tmp_path, capsys):
    out = tmp_path / "report"
    assert main(["report", str(fl_thermal_csv), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["drift"]) == {"ch1", "ch2", "ch3", "ch4", "ch5"}
    assert summary["drift"]["ch3"]["peak_um"] == pytest.approx(-71.02, abs=0.01)
    assert json.loads((out / "import_report.json").read_text())["rows"] == 7711
    assert (out / "drift.png").exists() and (out / "temperatures.png").exists()
    assert "| ch3 |" in capsys.readouterr().out


def test_report_needs_a_nan_policy_for_gappy_data(tmp_path, capsys):
    path = tmp_path / "gappy.csv"
    path.write_text("time_s,T01_degC,Z_um\n0,20,0\n60,,1\n120,21,2\n")
    assert main(["report", str(path), "--out", str(tmp_path / "r")]) == 2
    assert "choose nan_policy" in capsys.readouterr().err
    assert main(["report", str(path), "--out", str(tmp_path / "r"), "--nan-policy", "interpolate"]) == 0
