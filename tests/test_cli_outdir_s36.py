"""`--out`: a folder holding another of the twin's commands' result is never emptied without `--overwrite`
(`twin evaluate` had removed a `twin run`'s dataset); a re-run of the same command, with any arguments, replaces
its own result as before, and a marker that names no command (an older version's) is any command's."""
import json

import pytest

from twin.cli import main
from twin.core.scenario import SCENARIOS_DIR
from twin.infra.outdir import MARKER

SHORT = "iso230_3_spindle_short"


def tree(folder):
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def one_error_line(capsys):
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


@pytest.fixture
def simulated(tmp_path, capsys):
    """The folder ``x1`` holding a complete ``twin run`` result of the short spindle scenario."""
    out = tmp_path / "x1"
    assert main(["run", SHORT, "--out", str(out)]) == 0
    assert f"{SHORT}.csv" in tree(out)
    capsys.readouterr()
    return out


@pytest.fixture
def model(tmp_path):
    """A model trained on a small measured recording, and that recording."""
    lab = tmp_path / "lab"
    lab.mkdir()
    data = lab / "measured.csv"
    data.write_text("time_s,T01_degC,Z_um\n" + "".join(f"{60 * i},{20 + 0.1 * i},{0.5 * i}\n" for i in range(30)))
    path = lab / "z.json"
    assert main(["train", str(data), "--inputs", "T01", "--target", "Z", "--model", "mlr", "--out", str(path)]) == 0
    return path, data


def test_evaluate_into_a_run_folder_keeps_the_simulated_dataset(simulated, model, capsys):
    before = tree(simulated)
    path, data = model
    assert main(["evaluate", str(path), str(data), "--out", str(simulated)]) == 2
    err = one_error_line(capsys)
    assert str(simulated) in err and f"twin run {SHORT}" in err and "--overwrite" in err
    assert tree(simulated) == before
    assert main(["evaluate", str(path), str(data), "--out", str(simulated), "--overwrite"]) == 0
    marker = json.loads((simulated / MARKER).read_text())
    assert "evaluate" in marker["command"] and f"{SHORT}.csv" not in tree(simulated)   # replaced, as asked


def test_a_rerun_of_the_same_command_with_other_arguments_replaces_its_result(simulated, tmp_path):
    other = tmp_path / "other_short.toml"
    other.write_text((SCENARIOS_DIR / f"{SHORT}.toml").read_text(encoding="utf-8").replace(
        f'name = "{SHORT}"', 'name = "other_short"'))
    assert main(["run", str(other), "--out", str(simulated), "--no-views"]) == 0
    files = tree(simulated)
    assert "other_short.csv" in files and f"{SHORT}.csv" not in files      # the earlier run's listed files go


def test_a_marker_of_an_older_version_names_no_command_and_is_any_commands(simulated, model):
    marker = json.loads((simulated / MARKER).read_text())
    (simulated / MARKER).write_text(json.dumps({k: v for k, v in marker.items() if k != "job"}))
    path, data = model
    assert main(["evaluate", str(path), str(data), "--out", str(simulated)]) == 0


def test_a_rerun_of_the_same_job_needs_no_overwrite_even_after_one(simulated, capsys):
    assert main(["run", SHORT, "--out", str(simulated), "--overwrite"]) == 0
    assert main(["run", SHORT, "--out", str(simulated)]) == 0     # --overwrite is no part of the job
    assert f"{SHORT}.csv" in tree(simulated)
