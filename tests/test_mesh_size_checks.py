"""A mesh size given on the command line or as an argument is checked as one read from a machine file."""
from pathlib import Path

import pytest

import meshes.builder
from meshes.builder import MAX_TETRAHEDRA, MIN_MESH_SIZE_M, build_mesh, meshing_estimate
from meshes.definition import load_geometry
from meshes.tomlspec import DefinitionError
from twin.cli import main

MINI = Path(__file__).parent / "data" / "mini_machine.toml"


@pytest.mark.parametrize("value", ["0", "-1", "nan", "inf", "1e-5", "abc"])
@pytest.mark.parametrize("command", [["run", "heat_cool_9000"], ["mesh"], ["rom", "build"], ["place"]])
def test_a_bad_mesh_size_option_is_refused_by_the_parser(command, value, capsys):
    with pytest.raises(SystemExit) as exc:
        main([*command, f"--mesh-size={value}"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert f"argument --mesh-size: {value!r} is not a mesh size" in err and "0.0001 m" in err


@pytest.mark.parametrize("size", [0.0, -0.02, float("nan"), float("inf"), MIN_MESH_SIZE_M / 2])
def test_build_mesh_refuses_a_bad_size_instead_of_using_the_default(size):
    with pytest.raises(DefinitionError, match="mesh size must be a finite length"):
        build_mesh(load_geometry(MINI), size)


def test_a_mesh_too_fine_to_build_is_refused_before_meshing(monkeypatch, tmp_path):
    monkeypatch.setenv("THERMAL_TWIN_CACHE", str(tmp_path))

    def mesher_must_not_run(*args):
        raise AssertionError("fTetWild was started")

    monkeypatch.setattr(meshes.builder, "tetrahedralize", mesher_must_not_run)
    geometry = load_geometry("vmc_ram")
    size = 0.002
    assert meshing_estimate(geometry, size)[0] > MAX_TETRAHEDRA
    with pytest.raises(DefinitionError, match=r"would make about .* tetrahedra .* use a mesh size of at least") as exc:
        build_mesh(geometry, size)
    smallest = float(str(exc.value).rsplit("at least ", 1)[1].split()[0]) * 1e-3
    assert meshing_estimate(geometry, smallest)[0] <= MAX_TETRAHEDRA < meshing_estimate(geometry, 0.99 * smallest)[0]


def test_a_machine_file_mesh_size_in_mm_is_refused_naming_the_field(tmp_path):
    """``size_m = 35`` (35 mm typed as a number of mm) had started meshing the machine with 35 m tetrahedra."""
    text = MINI.read_text().replace("size_m = 0.06", "size_m = 35")
    for stl in MINI.parent.glob("*.stl"):          # the machine's parts are read relative to its file
        (tmp_path / stl.name).write_bytes(stl.read_bytes())
    path = tmp_path / "mini_machine.toml"
    path.write_text(text)
    with pytest.raises(DefinitionError, match=r"mesh\.size_m must be ≤ 0\.5, got 35; is it in mm\? 35 mm is a "
                                              r"mesh size of 0\.035 m$"):
        load_geometry(path)
