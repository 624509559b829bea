"""The machine builder on a small definition with an STL part: meshing, labels, groups, cache, a run."""
from pathlib import Path

import numpy as np
import pytest

from meshes.builder import build_mesh, mesh_statistics
from meshes.cachefiles import content_problem
from meshes.definition import load_geometry
from meshes.tomlspec import DefinitionError
from twin.core.machine import build_machine
from twin.core.machine_definition import load_machine

MINI = Path(__file__).parent / "data" / "mini_machine.toml"


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    path = tmp_path_factory.mktemp("cache")
    patcher = pytest.MonkeyPatch()
    patcher.setenv("THERMAL_TWIN_CACHE", str(path))
    yield path
    patcher.undo()


@pytest.fixture(scope="module")
def mini(cache):
    return build_machine(MINI)


def test_stl_part_is_meshed_and_labelled(mini):
    stats = mesh_statistics(mini.mesh)
    volumes = stats["part_volume_m3"]
    assert volumes["pedestal"] == pytest.approx(0.4 * 0.3 * 0.1, rel=1e-3)   # the STL was in mm, scaled by 0.001
    assert volumes["column"] == pytest.approx(0.2 * 0.1 * 0.4, rel=1e-3)
    assert stats["radius_ratio"]["min"] > 0.0
    assert np.all(mini.mesh.volumes > 0)                                      # every tetrahedron positively oriented


def test_second_build_reads_the_cache(mini, cache):
    geometry = load_geometry(MINI)
    mesh, info = build_mesh(geometry)
    assert info.from_cache and info.path.parent == cache
    assert np.array_equal(mesh.tets, mini.mesh.tets)
    assert sorted(p.name for p in cache.glob("*.vtu")) == [info.path.name]
    assert info.path.name.startswith("mesh-h60mm-") and content_problem(info.path) is None   # no machine name


def test_convection_group_covers_the_outside_and_joint_splits_nodes(mini):
    area = mini.mesh.facet_group_area("all")
    pedestal = 2 * (0.4 * 0.3 + 0.4 * 0.1 + 0.3 * 0.1)
    column = 2 * (0.2 * 0.4 + 0.1 * 0.4) + 0.2 * 0.1                          # sides and top
    covered = 0.2 * 0.1                                                        # the column's footprint
    assert area == pytest.approx(pedestal + column - covered, rel=1e-3)
    assert mini.thermal.n_nodes > mini.mesh.n_nodes                            # the joint duplicated its nodes


def test_heated_column_grows_the_tool_point_up(mini):
    from twin.core.simulate import simulate

    path = MINI.parent / "mini_scenario.toml"
    ds = simulate(path, mini, noise=False).dataset
    assert ds["Z"][-1] > 0.5                                                  # µm: the column grows upward
    assert ds["T1"][-1] > ds["T1"][0] + 1.0
    assert np.allclose(ds["A1"], 20.0)                                        # the air sensor reads its zone
    assert ds.metadata["energy_balance_relative_error"] < 1e-8


def test_missing_stl_file_is_a_clear_error(tmp_path):
    broken = tmp_path / "broken.toml"
    broken.write_text(MINI.read_text().replace("pedestal_mm.stl", "missing.stl"))
    with pytest.raises(DefinitionError, match=r"parts\[0\]\.file names an STL file that does not exist"):
        load_machine(broken)


def test_a_sensor_outside_the_mesh_names_the_machine_file_and_field(tmp_path, monkeypatch):
    """The solver's message names its output ("T05 at … lies outside the mesh"); the twin's names the file and
    the field that placed it (the shipped mesh is reused: sensors are not part of the geometry)."""
    monkeypatch.setenv("THERMAL_TWIN_CACHE", str(tmp_path / "cache"))
    text = (Path(__file__).parents[1] / "meshes" / "machines" / "vmc_ram.toml").read_text()
    moved = tmp_path / "vmc_ram_moved.toml"
    moved.write_text(text.replace('label = "carrier strip 1 (B5)"\nposition = [0.18, 0.2, 1]',
                                  'label = "carrier strip 1 (B5)"\nposition = [0.18, 0.2, 3]'))
    with pytest.raises(DefinitionError) as exc:
        build_machine(moved)
    assert str(exc.value).startswith(f"{moved}: sensors (name = 'T05').position: T05 at (0.18, 0.2, 3.0) m lies "
                                     "outside the mesh")


@pytest.mark.parametrize("label, field", [
    ("T05", "sensors (name = 'T05').position"), ("FBG1 end", "sensors (name = 'FBG1').end"),
    ("X", "tcp.tool_point"), ("Z reference", "tcp.workpiece_point"),
    ("Y_top", "tcp.tool_point + tcp.tilt_probe_offset (0.0, 0.0, 0.1) m (the upper Y probe)"),
    ("cam012", "camera (its spots)"),
])
def test_each_output_point_is_traced_to_its_field(label, field):
    from twin.core.machine import _point_field

    assert _point_field(load_machine("vmc_ram"), label) == field
