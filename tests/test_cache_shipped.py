"""The shipped mesh and operator cache: found under geometry keys, checked, and never used when spoiled.

Nothing here meshes or builds an operator: the shipped files are read, and a
guard turns any attempt to rebuild them into a test failure (a real rebuild of
vmc_ram would take about half an hour).
"""
import shutil

import numpy as np
import pytest
from cache_spoils import NPZ_SPOILS, VTU_SPOILS, assert_refused, spoil

from meshes import builder, cachefiles
from meshes.cachefiles import SHIPPED_CACHE, content_problem, sidecar
from twin.core import machine as twin_machine
from twin.core.machine import build_machine


@pytest.fixture
def no_rebuild(tmp_path, monkeypatch):
    """An empty user cache, and meshing or operator building made to fail loudly."""
    monkeypatch.setenv("THERMAL_TWIN_CACHE", str(tmp_path / "user"))

    def refuse(*args, **kwargs):
        raise AssertionError("a shipped artefact was rebuilt instead of read")

    monkeypatch.setattr(builder, "tetrahedralize", refuse)
    monkeypatch.setattr(twin_machine, "_compute_outputs", refuse)
    return tmp_path / "user"


def test_every_shipped_file_has_a_matching_checksum():
    files = sorted(p for p in SHIPPED_CACHE.iterdir() if p.suffix != cachefiles.SIDECAR_SUFFIX)
    assert files and all(content_problem(p) is None for p in files)
    assert sorted(SHIPPED_CACHE.glob("*.sha256")) == [sidecar(p) for p in files]


@pytest.mark.parametrize("machine, size_m", [("vmc_ram", None), ("vmc_ram", 0.035), ("vmc_ram", 0.0675), ("machine_a", None)])
def test_shipped_mesh_and_operator_are_used_with_an_empty_user_cache(no_rebuild, machine, size_m):
    model = build_machine(machine, size_m)
    assert model.mesh_path.parent == SHIPPED_CACHE and model.operator_path.parent == SHIPPED_CACHE
    assert model.mesh_path.name.startswith(f"mesh-h{(size_m or 0.045) * 1e3:g}mm-")
    assert machine not in model.mesh_path.name and machine not in model.operator_path.name
    assert [p for p in no_rebuild.rglob("*") if p.is_file()] == []


@pytest.fixture
def shipped_copy(machine, no_rebuild, tmp_path, monkeypatch):
    """A copy of the default machine's shipped mesh and operator (with checksums) as the shipped cache."""
    copy = tmp_path / "shipped"
    copy.mkdir()
    for path in (machine.mesh_path, machine.operator_path):
        for f in (path, sidecar(path)):
            shutil.copy2(f, copy / f.name)
    monkeypatch.setattr(cachefiles, "SHIPPED_CACHE", copy)
    return copy / machine.mesh_path.name, copy / machine.operator_path.name


@pytest.mark.parametrize("which, how", [(0, how) for how in VTU_SPOILS] + [(1, how) for how in NPZ_SPOILS],
                         ids=[f"mesh {h}" for h in VTU_SPOILS] + [f"operator {h}" for h in NPZ_SPOILS])
def test_spoiled_shipped_file_is_refused_with_one_line_naming_it(shipped_copy, no_rebuild, which, how):
    path = shipped_copy[which]
    spoil(path, how)
    assert_refused(path, lambda: build_machine("vmc_ram"))
    assert [p for p in no_rebuild.rglob("*") if p.is_file()] == []


def test_the_intact_copy_gives_the_shipped_operator(machine, shipped_copy):
    """The copy itself is sound: unspoiled, it is read and gives the same rows."""
    again = build_machine("vmc_ram")
    assert (again.mesh_path, again.operator_path) == shipped_copy
    assert (again.outputs.matrix != machine.outputs.matrix).nnz == 0
    np.testing.assert_array_equal(again.outputs.offset, machine.outputs.offset)
