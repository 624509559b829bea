"""`--out`: the twin never deletes what it did not write, refuses its inputs, checks before the work."""
import json
import os

import pytest

from twin.cli import main
from twin.errors import TwinInputError
from twin.infra import outdir
from twin.infra.outdir import JOURNAL, MARKER, atomic_directory

REPORT_FILES = {"summary.json", "summary.md", "temperatures.png", "drift.png", "import_report.json"}


@pytest.fixture
def measured(tmp_path):
    """A small measured recording (no sidecar) in its own folder ``lab``."""
    lab = tmp_path / "lab"
    lab.mkdir()
    path = lab / "measured.csv"
    path.write_text("time_s,T01_degC,Z_um\n" + "".join(f"{60 * i},{20 + 0.1 * i},{0.5 * i}\n" for i in range(30)))
    return path


def one_error_line(capsys):
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


def tree(folder):
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def test_report_refuses_a_folder_that_holds_its_input(measured, capsys):
    before = tree(measured.parent)
    assert main(["report", str(measured), "--out", str(measured.parent)]) == 2
    assert "holds an input" in one_error_line(capsys)
    assert main(["report", str(measured), "--out", str(measured.parent), "--overwrite"]) == 2
    assert "holds an input" in one_error_line(capsys)
    assert tree(measured.parent) == before


def test_out_dot_in_a_folder_with_files_is_refused(measured, tmp_path, monkeypatch, capsys):
    work = tmp_path / "work"
    work.mkdir()
    (work / "notes.txt").write_text("mine")
    monkeypatch.chdir(work)
    assert main(["report", str(measured), "--out", "."]) == 2
    assert "not a twin output" in one_error_line(capsys)
    assert tree(work) == {"notes.txt": b"mine"}


def test_out_that_is_a_file_is_refused(measured, tmp_path, capsys):
    notes = tmp_path / "notes.txt"
    notes.write_text("mine")
    for extra in ([], ["--overwrite"]):
        assert main(["report", str(measured), "--out", str(notes), *extra]) == 2
        assert "is a file" in one_error_line(capsys)
    assert notes.read_text() == "mine"


def test_foreign_files_are_kept_and_overwrite_only_adds_beside_them(measured, tmp_path, capsys):
    out = tmp_path / "DIR"
    (out / "measurements").mkdir(parents=True)
    (out / "measurements" / "run.csv").write_text("1,2\n")
    (out / "notes.txt").write_text("mine")
    os.chmod(out, 0o555)            # read-only, as in the issue: it must not be replaced either
    try:
        assert main(["report", str(measured), "--out", str(out)]) == 2
        assert "not a twin output" in one_error_line(capsys)
        assert set(tree(out)) == {"measurements/run.csv", "notes.txt"}
    finally:
        os.chmod(out, 0o755)
    assert main(["report", str(measured), "--out", str(out), "--overwrite"]) == 0
    files = tree(out)
    assert files["notes.txt"] == b"mine" and files["measurements/run.csv"] == b"1,2\n"
    marker = json.loads(files[MARKER])
    assert set(marker["files"]) == REPORT_FILES
    assert marker["format"] == "thermal-twin-output" and "report" in marker["command"]


def test_a_rerun_replaces_only_the_twins_own_files(measured, tmp_path, capsys):
    out = tmp_path / "report"
    assert main(["report", str(measured), "--out", str(out)]) == 0
    first = json.loads((out / MARKER).read_text())
    assert set(first["files"]) == REPORT_FILES and set(tree(out)) == REPORT_FILES | {MARKER}
    (out / "my_notes.md").write_text("kept")
    (out / "summary.md").write_text("edited by hand, but written by the twin")
    assert main(["report", str(measured), "--out", str(out)]) == 0      # a twin folder: no --overwrite needed
    files = tree(out)
    assert files["my_notes.md"] == b"kept"
    assert b"edited by hand" not in files["summary.md"]
    assert set(files) == REPORT_FILES | {MARKER, "my_notes.md"}


def test_a_file_the_twin_did_not_write_is_never_replaced(measured, tmp_path, capsys):
    out = tmp_path / "report"
    out.mkdir()
    (out / "summary.md").write_text("mine")
    assert main(["report", str(measured), "--out", str(out), "--overwrite"]) == 2
    err = one_error_line(capsys)
    assert "summary.md" in err and "did not write" in err
    assert tree(out) == {"summary.md": b"mine"}


def test_stale_twin_files_of_an_older_result_are_removed(tmp_path):
    out = tmp_path / "res"
    with atomic_directory(out, command="first") as tmp:
        (tmp / "a.txt").write_text("a")
        (tmp / "fields").mkdir()
        (tmp / "fields" / "t0.vtu").write_text("old")
    with atomic_directory(out, command="second") as tmp:
        (tmp / "b.txt").write_text("b")
    assert set(tree(out)) == {"b.txt", MARKER}
    assert not (out / "fields").exists()
    assert json.loads((out / MARKER).read_text())["command"] == "second"


def test_a_failure_leaves_the_previous_result_untouched(tmp_path):
    out = tmp_path / "res"
    with atomic_directory(out) as tmp:
        (tmp / "a.txt").write_text("old")
    before = tree(out)
    with pytest.raises(KeyboardInterrupt):
        with atomic_directory(out) as tmp:
            (tmp / "a.txt").write_text("new")
            raise KeyboardInterrupt
    assert tree(out) == before
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == [MARKER]


def test_a_failure_in_a_new_folder_leaves_no_folder(tmp_path):
    out = tmp_path / "new" / "res"
    with pytest.raises(RuntimeError):
        with atomic_directory(out) as tmp:
            (tmp / "a.txt").write_text("x")
            raise RuntimeError("boom")
    assert not out.exists()


def test_an_interrupted_commit_claims_no_completeness_and_is_recognised_next_time(tmp_path, monkeypatch):
    out = tmp_path / "res"
    with atomic_directory(out) as tmp:
        for name in ("a.txt", "b.txt", "c.txt"):
            (tmp / name).write_text("old")
    (out / "user.txt").write_text("mine")
    real_replace, moved = os.replace, []

    def interrupted_after_one_move(src, dst):
        if outdir.STAGING_PREFIX in str(src):
            if moved:
                raise KeyboardInterrupt
            moved.append(dst)
        return real_replace(src, dst)

    monkeypatch.setattr(outdir.os, "replace", interrupted_after_one_move)
    with pytest.raises(KeyboardInterrupt):
        with atomic_directory(out) as tmp:
            for name in ("a.txt", "b.txt", "d.txt"):
                (tmp / name).write_text("new")
    monkeypatch.setattr(outdir.os, "replace", real_replace)
    assert not (out / MARKER).exists()                       # nothing claims to be complete
    assert (out / JOURNAL).exists()
    with atomic_directory(out) as tmp:                       # still the twin's folder: no overwrite needed
        (tmp / "e.txt").write_text("newest")
    assert set(tree(out)) == {"e.txt", "user.txt", MARKER}
    assert (out / "user.txt").read_text() == "mine"


def test_run_checks_its_output_before_simulating(tmp_path):
    from twin.run.workflows import run_scenario

    blocker = tmp_path / "file.txt"
    blocker.write_text("x")
    steps = []
    with pytest.raises(TwinInputError, match="file.txt is a file, not a folder"):
        run_scenario("iso230_3_spindle_short", out_dir=blocker / "run", progress=lambda done, total: steps.append(done))
    assert steps == []                                        # refused before a single time step


def test_unwritable_output_is_one_line_before_any_work(measured, tmp_path, capsys):
    blocker = tmp_path / "file.txt"
    blocker.write_text("x")
    assert main(["train", str(measured), "--inputs", "T01", "--target", "Z", "--model", "mlr",
                 "--out", str(blocker / "models" / "z.json")]) == 2
    assert "cannot be created" in one_error_line(capsys)
    assert main(["report", str(measured), "--out", str(blocker / "r")]) == 2
    assert "cannot be created" in one_error_line(capsys)


def test_read_only_parent_is_refused_before_the_work(measured, tmp_path, capsys):
    parent = tmp_path / "ro"
    parent.mkdir()
    os.chmod(parent, 0o555)
    try:
        if os.access(parent, os.W_OK):
            pytest.skip("this user can write in a read-only folder (root)")
        assert main(["report", str(measured), "--out", str(parent / "r")]) == 2
        assert "cannot write" in one_error_line(capsys)
    finally:
        os.chmod(parent, 0o755)


def test_file_outputs_need_overwrite_and_never_replace_an_input(measured, tmp_path, capsys):
    model = tmp_path / "z.json"
    args = ["train", str(measured), "--inputs", "T01", "--target", "Z", "--model", "mlr", "--out"]
    assert main([*args, str(model)]) == 0
    first = model.read_text()
    assert main([*args, str(model)]) == 2
    assert "--overwrite" in one_error_line(capsys)
    assert main([*args, str(model), "--overwrite"]) == 0
    assert json.loads(model.read_text())["format"] == json.loads(first)["format"]
    before = measured.read_bytes()
    assert main([*args, str(measured), "--overwrite"]) == 2
    assert "replace an input" in one_error_line(capsys)
    assert measured.read_bytes() == before


@pytest.mark.parametrize("command", [
    ["run", "x"], ["mesh"], ["report", "x.csv"], ["train", "x", "--inputs", "a", "--target", "Z", "--out", "m"],
    ["evaluate", "m", "x"], ["study", "thesis"], ["place"], ["gap", "diagnose", "--measured", "x", "--out", "o"],
    ["gap", "truth", "--effect", "none", "--out", "x.csv"], ["gap", "benchmark"], ["fmu", "export"],
    ["fmu", "simulate", "x.fmu", "s"], ["rom", "build"], ["rom", "report"]])
def test_every_writing_command_takes_overwrite(command):
    from twin.cli import build_parser

    assert build_parser().parse_args([*command, "--overwrite"]).overwrite is True


def test_studies_refuse_a_folder_holding_their_machine_file(tmp_path, monkeypatch):
    from twin.compensation.studies import thesis_protocol_study
    from twin.placement.study import placement_study

    machine = tmp_path / "my_machine.toml"
    machine.write_text("[machine]\n")
    for study in (placement_study, thesis_protocol_study):
        with pytest.raises(TwinInputError, match="holds an input"):
            study(machine=str(machine), out_dir=tmp_path, overwrite=True)
    monkeypatch.chdir(tmp_path)                      # a machine *name* is no input file, even here
    assert outdir.check_output_folder(".", overwrite=True, inputs=("vmc_ram", None)) == tmp_path.resolve()


@pytest.fixture
def disk_events(monkeypatch):
    """``[("fsync", path) | ("replace", destination)]`` in the order they happen (Linux: fd → path by /proc)."""
    if not os.path.isdir("/proc/self/fd"):
        pytest.skip("needs /proc to name a file descriptor")
    events, real_fsync, real_replace = [], os.fsync, os.replace

    def fsync(descriptor):
        events.append(("fsync", os.readlink(f"/proc/self/fd/{descriptor}")))
        return real_fsync(descriptor)

    def replace(source, destination):
        events.append(("replace", str(destination)))
        return real_replace(source, destination)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "replace", replace)
    return events


def test_the_marker_is_written_only_after_every_file_is_on_disk(tmp_path, disk_events):
    out = tmp_path / "res"
    with atomic_directory(out) as staging:
        (staging / "a.txt").write_text("a")
        (staging / "fields").mkdir()
        (staging / "fields" / "b.txt").write_text("b")
    marker_moved = disk_events.index(("replace", str(out / MARKER)))
    synced_before = {path for kind, path in disk_events[:marker_moved] if kind == "fsync"}
    assert {str(staging / "a.txt"), str(staging / "fields" / "b.txt"), str(out), str(out / "fields")} <= synced_before
    assert ("fsync", str(out)) in disk_events[marker_moved:]       # the marker's own rename is durable too


def test_an_atomic_text_file_is_on_disk_before_its_name_says_so(tmp_path, disk_events):
    from twin.core.files import write_text_atomic

    path = write_text_atomic(tmp_path / "model.json", "{}")
    assert disk_events == [("fsync", str(tmp_path / ".model.json.partial")), ("replace", str(path)),
                           ("fsync", str(tmp_path))]
    assert path.read_text() == "{}" and not (tmp_path / ".model.json.partial").exists()
