"""VTK output: `fea.write_vtu` and `fea.write_time_series` files read back in pyvista with their arrays."""
from __future__ import annotations

import numpy as np
import pytest
import pyvista as pv
from skfem import MeshTet

import fea


@pytest.fixture
def solved(tmp_path):
    m = MeshTet.init_tensor(np.linspace(0, 0.3, 4), np.linspace(0, 0.2, 3), np.array([0.0, 0.1]))
    mesh = fea.TetMesh.from_arrays(m.p.T, m.t.T, regions=(m.p.T[m.t.T].mean(1)[:, 0] > 0.15).astype(int))
    mesh.add_facet_group("skin", fea.Everything())
    mesh.add_facet_group("left", fea.Plane.axis("x", 0.0))
    problem = fea.HeatProblem(mesh, {0: fea.STEEL, 1: fea.CAST_IRON})
    problem.add_convection("skin", 10.0, ambient="air")
    problem.add_heat_flux("left", power="heater")
    system = problem.assemble()
    times = np.linspace(0, 600, 4)
    result = fea.ThermalSolver(system).run(20.0, times, fea.InputSchedule(system, {"air": 20.0, "heater": 200.0}),
                                           field_times_s=times)
    return mesh, system, result


def test_write_vtu_round_trip(solved, tmp_path):
    mesh, system, result = solved
    T = system.nodal_field(result.final_temperature)
    elastic = fea.ElasticProblem(mesh, {0: fea.STEEL, 1: fea.CAST_IRON}, degree=1)
    elastic.add_kinematic_mount((0, 0, 0), (0.3, 0, 0), (0, 0.2, 0))
    u = elastic.displacement(T)
    von_mises = np.linalg.norm(elastic.stress(u, T), axis=(1, 2))
    path = fea.write_vtu(tmp_path / "state.vtu", mesh, {"temperature_degC": T, "displacement_m": u},
                         {"stress_norm_Pa": von_mises})
    assert path.exists() and not list(tmp_path.glob(".*partial*"))
    grid = pv.read(path)
    assert grid.n_points == mesh.n_nodes and grid.n_cells == mesh.n_tets
    assert np.allclose(grid.points, mesh.points)
    assert np.array_equal(np.asarray(grid.cells_dict[pv.CellType.TETRA]), mesh.tets)
    assert np.allclose(grid.point_data["temperature_degC"], T)
    assert np.allclose(grid.point_data["displacement_m"], u)
    assert np.allclose(grid.cell_data["stress_norm_Pa"], von_mises)
    assert np.array_equal(grid.cell_data["region"], mesh.regions)
    # And the file is a mesh again.
    again = fea.TetMesh.from_pyvista(grid, "region")
    assert np.array_equal(again.regions, mesh.regions) and np.allclose(again.volumes, mesh.volumes)


def test_write_time_series_round_trip(solved, tmp_path):
    mesh, system, result = solved
    frames = {t: {"temperature_degC": system.nodal_field(T)} for t, T in result.fields.items()}
    pvd = fea.write_time_series(tmp_path / "heating.pvd", mesh, frames)
    reader = pv.get_reader(str(pvd))
    assert np.allclose(reader.time_values, sorted(frames))
    for t in sorted(frames):
        reader.set_active_time_value(t)
        block = reader.read()
        grid = block[0] if isinstance(block, pv.MultiBlock) else block
        assert np.allclose(grid.point_data["temperature_degC"], frames[t]["temperature_degC"])
    # The heater really changed the field between frames.
    first, last = (frames[t]["temperature_degC"] for t in (min(frames), max(frames)))
    assert np.ptp(last - first) > 0.01
