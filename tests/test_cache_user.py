"""The user cache on the small test machine: keys on geometry alone, spoiled files rebuilt, quiet meshing.

The mini machine is meshed once, through the ``twin mesh`` command in a
subprocess, so what a user sees on the console is checked too.  Each test then
works on its own copy of that cache.
"""
import logging
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from cache_spoils import NPZ_SPOILS, spoil

from meshes import builder
from meshes.cachefiles import content_problem
from twin.core import machine as twin_machine
from twin.core.machine import build_machine

DATA = Path(__file__).parent / "data"
MINI = DATA / "mini_machine.toml"


@pytest.fixture(scope="module")
def meshed(tmp_path_factory):
    """``twin mesh`` of the mini machine into an empty cache: (cache folder, stdout, stderr)."""
    root = tmp_path_factory.mktemp("mini")
    env = dict(os.environ, THERMAL_TWIN_CACHE=str(root / "cache"), OPENBLAS_NUM_THREADS="1")
    done = subprocess.run([sys.executable, "-m", "twin.cli", "mesh", str(MINI), "--out", str(root / "out")],
                          env=env, capture_output=True, text=True, timeout=1200)
    assert done.returncode == 0, done.stderr
    return root / "cache", done.stdout, done.stderr


@pytest.fixture
def cache(meshed, tmp_path, monkeypatch):
    """A private copy of the meshed cache as the user cache."""
    folder = tmp_path / "cache"
    shutil.copytree(meshed[0], folder)
    monkeypatch.setenv("THERMAL_TWIN_CACHE", str(folder))
    return folder


@pytest.fixture
def no_meshing(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("meshed again")

    monkeypatch.setattr(builder, "tetrahedralize", refuse)


def cached_files(folder):
    return sorted(p.name for p in folder.iterdir() if p.suffix in (".vtu", ".npz"))


def variant(tmp_path, name, **replacements):
    """A copy of the mini machine under another name, with text replacements (old → new)."""
    text = MINI.read_text().replace('name = "mini"', f'name = "{name}"')
    for old, new in replacements.items():
        assert old in text
        text = text.replace(old, new)
    shutil.copy(DATA / "pedestal_mm.stl", tmp_path / "pedestal_mm.stl")
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return path


def test_meshing_says_what_and_how_long_and_keeps_fTetWild_off_the_console(meshed):
    folder, stdout, stderr = meshed
    assert "twin: meshing mini at 60 mm (about " in stderr and " tetrahedra): roughly " in stderr
    [log] = folder.glob("mesh-*.log")
    assert f"twin: fTetWild output goes to {log}" in stderr
    assert "twin: building the output operator of mini: 4 elastic solves (P1, " in stderr
    fTetWild_lines = [line for line in log.read_text().splitlines() if line.strip()]
    assert len(fTetWild_lines) > 20 and any("CSG" in line for line in fTetWild_lines)
    console = stdout + stderr
    assert not [line for line in fTetWild_lines if line in console]


def test_renamed_copy_with_other_power_and_conductance_reuses_mesh_and_operator(cache, tmp_path, no_meshing,
                                                                                  monkeypatch):
    original = build_machine(MINI)
    before = cached_files(cache)

    def refuse(*args, **kwargs):
        raise AssertionError("output operator built again")

    monkeypatch.setattr(twin_machine, "_compute_outputs", refuse)
    copy = build_machine(variant(tmp_path, "mini_renamed", **{"coefficient_W = 50.0": "coefficient_W = 80.0",
                                                               "conductance = 1000.0": "conductance = 2500.0"}))
    assert copy.name == "mini_renamed"
    assert (copy.mesh_path, copy.operator_path) == (original.mesh_path, original.operator_path)
    assert cached_files(cache) == before
    # The changes did take effect in the thermal system (power and joint conductance).
    assert copy.definition.sources[0].coefficient_W == 80.0
    assert abs(copy.thermal.stiffness - original.thermal.stiffness).max() > 0


def test_new_expansion_coefficient_gives_a_new_operator_on_the_same_mesh(cache, tmp_path, no_meshing):
    original = build_machine(MINI)
    copy = build_machine(variant(tmp_path, "mini_alpha", **{"expansion = 10.5e-6": "expansion = 21.0e-6"}))
    assert copy.mesh_path == original.mesh_path and copy.operator_path != original.operator_path
    assert len(cached_files(cache)) == 3
    # One material, free to expand on a kinematic mount: displacements scale with α exactly.
    z_old, z_new = (m.outputs.matrix[m.outputs.index("Z")].toarray() for m in (original, copy))
    np.testing.assert_allclose(z_new, 2.0 * z_old, rtol=1e-8, atol=1e-12 * np.abs(z_old).max())


@pytest.mark.parametrize("how", NPZ_SPOILS)
def test_spoiled_user_operator_is_reported_and_rebuilt(cache, caplog, no_meshing, how):
    original = build_machine(MINI)
    spoil(original.operator_path, how)
    with caplog.at_level(logging.INFO, logger="thermal_twin"):
        again = build_machine(MINI)
    assert f"cache file {original.operator_path} is corrupt" in caplog.text
    assert "building the output operator of mini" in caplog.text
    assert again.operator_path == original.operator_path and content_problem(again.operator_path) is None
    np.testing.assert_allclose(again.outputs.matrix.toarray(), original.outputs.matrix.toarray(),
                               rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize("how", ["truncated", "values doubled"])
def test_spoiled_rom_is_reported_and_rebuilt_and_a_renamed_machine_reuses_it(cache, caplog, tmp_path, no_meshing, how):
    from twin.rom.reduction import cached_rom

    model = build_machine(MINI)
    rom = cached_rom(model, 12)
    assert cached_rom(model, 12).info["from_cache"]
    path = Path(cached_rom(model, 12).info["from_cache"])
    spoil(path, how)
    with caplog.at_level(logging.WARNING, logger="thermal_twin"):
        again = cached_rom(model, 12)
    assert f"cache file {path} is corrupt" in caplog.text and again.info["from_cache"] is None
    np.testing.assert_allclose(again.eigenvalues, rom.eigenvalues, rtol=1e-10)
    renamed = cached_rom(build_machine(variant(tmp_path, "mini_renamed")), 12)
    assert renamed.info["from_cache"] == str(path) and renamed.machine == "mini_renamed"


def test_spoiled_placement_record_is_simulated_again(cache, caplog, no_meshing):
    from twin.placement.study import CandidateSpec, MachineSpec, RecordTask, run_records

    task = RecordTask(MachineSpec(str(MINI)), CandidateSpec(parts=("column",), n_surface=8, camera=False),
                      str(DATA / "mini_scenario.toml"), axes=("Z",))
    [first] = run_records([task], scheduler="serial")
    [second] = run_records([task], scheduler="serial")
    assert not first.from_cache and second.from_cache
    [path] = (cache / "placement-records").glob("*.npz")
    spoil(path, "values doubled")
    with caplog.at_level(logging.WARNING, logger="thermal_twin"):
        [third] = run_records([task], scheduler="serial")
    assert f"cache file {path} is corrupt" in caplog.text and not third.from_cache
    np.testing.assert_array_equal(third.drift["Z"], first.drift["Z"])
    assert content_problem(path) is None


@pytest.mark.slow
def test_spoiled_user_mesh_is_reported_and_meshed_again(cache, caplog):
    original = build_machine(MINI)
    spoil(original.mesh_path, "values doubled")
    with caplog.at_level(logging.INFO, logger="thermal_twin"):
        again = build_machine(MINI)
    assert f"cache file {original.mesh_path} is corrupt" in caplog.text and "meshing mini" in caplog.text
    assert again.mesh_path == original.mesh_path and content_problem(again.mesh_path) is None
    # fTetWild keeps each mesh within its envelope (epsilon × the bounding-box diagonal) of the input surface,
    # and meshes differ from run to run inside it: two meshes of one geometry differ in volume by at most
    # twice the envelope's thickness times the surface area (a 1e-6 tolerance failed once, at 1.4e-6)
    mesh = original.mesh
    envelope = original.definition.geometry.envelope_epsilon * np.linalg.norm(np.ptp(mesh.points, axis=0))
    area = mesh.facet_geometry(*mesh.boundary_facets())[2].sum()
    assert abs(again.mesh.volumes.sum() - mesh.volumes.sum()) <= 2 * envelope * area
