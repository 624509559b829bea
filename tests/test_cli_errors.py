"""Missing or broken input files, and values in messages: one plain line, never a traceback."""
import numpy as np
import pytest

from twin.cli import main


def error_line(capsys):
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("args, named", [
    (["report", "nope.csv"], "nope.csv"),
    (["report", "nope.csv", "--column-map", "nomap.json"], "nomap.json"),
    (["run", "nope.toml"], "nope.toml"),
    (["run", "heat_cool_9000", "--machine", "nope.toml"], "nope.toml"),
    (["mesh", "nope.toml"], "nope.toml"),
    (["train", "nope.csv", "--inputs", "T01", "--target", "Z", "--out", "m.json"], "nope.csv"),
    (["evaluate", "nope.json", "x.csv"], "nope.json"),
    (["gap", "diagnose", "--measured", "nope.csv", "--out", "g"], "nope.csv"),
    (["fmu", "validate", "nope.fmu"], "nope.fmu"),
    (["fmu", "simulate", "nope.fmu", "heat_cool_9000"], "nope.fmu"),
])
def test_a_missing_input_file_is_one_line_naming_it(args, named, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(args) == 2
    assert named in error_line(capsys)
    assert list(tmp_path.iterdir()) == []          # and nothing was written


def test_evaluate_names_a_missing_dataset(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    csv = tmp_path / "rec.csv"
    csv.write_text("time_s,T01_degC,Z_um\n" + "".join(f"{60 * i},{20 + 0.1 * i},{0.3 * i}\n" for i in range(20)))
    assert main(["train", str(csv), "--inputs", "T01", "--target", "Z", "--model", "mlr", "--out", "m.json"]) == 0
    capsys.readouterr()
    assert main(["evaluate", "m.json", "nope.csv"]) == 2
    assert "nope.csv" in error_line(capsys)


def test_a_file_that_is_not_an_fmu_is_one_line(tmp_path, capsys):
    junk = tmp_path / "junk.fmu"
    junk.write_bytes(b"not a zip archive")
    assert main(["fmu", "validate", str(junk)]) == 2
    err = error_line(capsys)
    assert err.startswith("twin fmu validate: error:") and "junk.fmu: not an FMU" in err


def test_definition_errors_show_plain_values_not_numpy_reprs(tmp_path, capsys):
    (tmp_path / "ambient.csv").write_text("time_s,ambient_degC\n0,20\n3600,warm\n")
    scenario = tmp_path / "csv_ambient.toml"
    scenario.write_text('[scenario]\nduration_h = 2\n[ambient]\nkind = "csv"\nfile = "ambient.csv"\n')
    assert main(["run", str(scenario), "--out", str(tmp_path / "out")]) == 2
    err = error_line(capsys)
    assert "got 3600, 'warm'" in err and "np." not in err
    scenario.write_text('[scenario]\nduration_h = 2\n[ambient]\nkind = "piecewise"\n'
                        'times_h = [0.0, 1.5, 1.0]\nvalues_C = [20.0, 21.0, 22.0]\n')
    assert main(["run", str(scenario), "--out", str(tmp_path / "out")]) == 2
    err = error_line(capsys)
    assert "ambient.times_h must increase strictly, got [0.0, 1.5, 1.0]" in err and "np." not in err


def test_plain_values_in_lower_layer_messages():
    from fea.errors import FEAInputError, require_positive
    from meshes.tomlspec import DefinitionError, Table, plain_value

    assert plain_value({"a": [np.int64(3600), (np.float64(0.5), "x")], "b": np.arange(2)}) == \
        {"a": [3600, (0.5, "x")], "b": [0, 1]}
    with pytest.raises(DefinitionError, match=r"scenario.seed must be ≥ 0, got -3$"):
        Table({"seed": -3}, "s.toml", "scenario").integer("seed", minimum=0)
    with pytest.raises(DefinitionError, match=r"must be an integer, got 3600$"):
        Table({"seed": np.int64(3600)}, "s.toml", "scenario").integer("seed")
    with pytest.raises(FEAInputError, match=r"time step must be positive, got -60$"):
        require_positive("time step", np.int64(-60))
