"""Bad input to `fea` raises `FEAInputError` with a message that names the item and the value."""
from __future__ import annotations

import math

import numpy as np
import pytest
from skfem import MeshTet

import fea
from fea import FEAInputError


def _block(nx=3):
    m = MeshTet.init_tensor(np.linspace(0, 1, nx + 1), np.linspace(0, 1, 3), np.array([0.0, 1.0]))
    mesh = fea.TetMesh.from_arrays(m.p.T, m.t.T)
    mesh.add_facet_group("left", fea.Plane.axis("x", 0.0))
    mesh.add_facet_group("skin", fea.Everything())
    return mesh


def _convective_system():
    mesh = _block()
    problem = fea.HeatProblem(mesh, {0: fea.STEEL})
    problem.add_convection("skin", 10.0, ambient="air")
    problem.add_heat_flux("left", power="heater")
    return mesh, problem.assemble()


# ------------------------------------------------------------------ materials
@pytest.mark.parametrize("attribute,value", [
    ("conductivity", 0.0), ("conductivity", -45.0), ("conductivity", math.nan),
    ("density", 0.0), ("density", -7850.0),
    ("specific_heat", 0.0), ("specific_heat", -1.0),
    ("youngs_modulus", 0.0), ("youngs_modulus", -210e9), ("youngs_modulus", math.inf),
])
def test_non_positive_material_property(attribute, value):
    props = dict(conductivity=45.0, density=7850.0, specific_heat=470.0, youngs_modulus=210e9)
    props[attribute] = value
    with pytest.raises(FEAInputError, match=rf"grey steel\.{attribute} must be positive, got {value!r}"):
        fea.Material(**props, name="grey steel")


def _two_region_mesh():
    m = MeshTet.init_tensor(np.linspace(0, 1, 3), np.array([0.0, 1.0]), np.array([0.0, 1.0]))
    return fea.TetMesh.from_arrays(m.p.T, m.t.T, regions=np.arange(len(m.t.T)) % 2, region_names={0: "base", 1: "ram"})


@pytest.mark.parametrize("missing", ["youngs_modulus", "poisson_ratio", "expansion"])
def test_elastic_problem_requires_its_material_properties(missing):
    """No silent E = 1 Pa, ν = 0 or α = 0: an elastic problem names the region and the missing property."""
    props = dict(conductivity=45.0, density=7850.0, specific_heat=470.0, youngs_modulus=210e9,
                 poisson_ratio=0.3, expansion=11.5e-6)
    del props[missing]
    with pytest.raises(FEAInputError, match=rf"material 'grey steel' of region 'ram' gives no {missing} "
                                            rf"\(.*\), which an elastic problem needs"):
        fea.ElasticProblem(_two_region_mesh(), {"base": fea.STEEL, "ram": fea.Material(**props, name="grey steel")})


def test_heat_problem_requires_conductivity_density_and_specific_heat():
    elastic_only = fea.Material(youngs_modulus=210e9, poisson_ratio=0.3, expansion=1e-5, name="spring steel")
    with pytest.raises(FEAInputError, match=r"material 'spring steel' of region 'base' gives no conductivity "
                                            r"\(W/\(m K\)\), density \(kg/m³\), specific_heat \(J/\(kg K\)\), "
                                            r"which a heat problem needs"):
        fea.HeatProblem(_two_region_mesh(), {"base": elastic_only, "ram": fea.STEEL})
    # ... while an elastic problem takes it, and a heat-only material serves a heat problem.
    fea.ElasticProblem(_two_region_mesh(), {"base": elastic_only, "ram": fea.STEEL})
    fea.HeatProblem(_two_region_mesh(), {"base": fea.Material(1.0, 1.0, 1.0), "ram": fea.STEEL})


def test_poisson_ratio_out_of_range():
    with pytest.raises(FEAInputError, match=r"poisson_ratio must lie in \(-1, 0.5\), got 0.5"):
        fea.Material(45, 7850, 470, 210e9, 0.5, 1e-5, "steel")


def test_missing_material_for_a_region():
    m = MeshTet.init_tensor(np.linspace(0, 1, 3), np.array([0.0, 1.0]), np.array([0.0, 1.0]))
    mesh = fea.TetMesh.from_arrays(m.p.T, m.t.T, regions=np.arange(len(m.t.T)) % 2, region_names={1: "ram"})
    with pytest.raises(FEAInputError, match=r"no material given for region\(s\) \['ram'\]"):
        fea.HeatProblem(mesh, {0: fea.STEEL})


# ------------------------------------------------------------------ loads and schedules
def test_nan_in_input_schedule_names_input_and_time():
    _, system = _convective_system()
    schedule = fea.InputSchedule(system, {"air": 20.0, "heater": lambda t: np.where(t > 50, np.nan, 100.0)})
    # The step 30–60 s is integrated at its Gauss points: the first past 50 s is 56.619 s.
    with pytest.raises(FEAInputError, match=r"input 'heater' is nan at t = 56.619 s"):
        fea.ThermalSolver(system).run(20.0, [0.0, 30.0, 60.0, 90.0], schedule)


def test_inf_in_sampled_series():
    with pytest.raises(FEAInputError, match=r"ambient: samples must be finite"):
        fea.SampledSeries([0, 1, 2], [20.0, math.inf, 21.0], name="ambient")


def test_inf_constant_load():
    mesh = _block()
    problem = fea.HeatProblem(mesh, {0: fea.STEEL})
    with pytest.raises(FEAInputError, match=r"power on left: value must be finite, got inf"):
        problem.add_heat_flux("left", power=math.inf)


def test_nan_initial_temperature_names_node_and_value():
    _, system = _convective_system()
    T0 = np.full(system.n_nodes, 20.0)
    T0[5] = np.nan
    schedule = fea.InputSchedule(system, {"air": 20.0, "heater": 10.0})
    with pytest.raises(FEAInputError, match=r"initial temperature must be finite, got nan at index \(5,\)"):
        fea.ThermalSolver(system).run(T0, [0.0, 10.0], schedule)
    with pytest.raises(FEAInputError, match=r"initial temperature must be finite, got inf"):
        fea.ThermalSolver(system).run(math.inf, [0.0, 10.0], schedule)


def test_unknown_and_missing_inputs():
    _, system = _convective_system()
    with pytest.raises(FEAInputError, match=r"unknown input\(s\) \['spindle'\]"):
        fea.InputSchedule(system, {"air": 20.0, "heater": 1.0, "spindle": 3.0})
    with pytest.raises(FEAInputError, match=r"no value given for input\(s\) \['heater'\]"):
        fea.InputSchedule(system, {"air": 20.0})


@pytest.mark.parametrize("call,pattern", [
    (lambda p: p.add_convection("skin", 0.0), r"convection coefficient on 'skin' must be positive, got 0.0"),
    (lambda p: p.add_radiation("skin", 1.2), r"emissivity on 'skin' must be at most 1, got 1.2"),
    (lambda p: p.add_radiation("skin", -0.1), r"emissivity on 'skin' must be positive, got -0.1"),
    (lambda p: p.add_contact(0, 0, -5.0), r"contact conductance between 0 and 0 must be positive, got -5.0"),
    (lambda p: p.add_heat_flux("roof", power=1.0), r"unknown facet group 'roof'"),
])
def test_bad_boundary_condition(call, pattern):
    problem = fea.HeatProblem(_block(), {0: fea.STEEL})
    with pytest.raises(FEAInputError, match=pattern):
        call(problem)


# ------------------------------------------------------------------ geometry
def test_facet_group_that_selects_nothing():
    mesh = _block()
    with pytest.raises(FEAInputError, match=r"facet group 'roof' selects no boundary facet \(Plane\(normal=\(0.0, 0.0, 1.0\), offset=5.0"):
        mesh.add_facet_group("roof", fea.Plane.axis("z", 5.0))


def test_empty_tet_selection():
    with pytest.raises(FEAInputError, match=r"contains no tetrahedron"):
        _block().select_tets(fea.Box((5, 5, 5), (6, 6, 6)))


def test_output_point_outside_mesh():
    mesh, system = _convective_system()
    with pytest.raises(FEAInputError, match=r"probe at \(2.0, 0.5, 0.25\) m lies outside the mesh \(nearest tetrahedron \d+\.\d+ mm away"):
        fea.build_output_operator([fea.PointTemperature("probe", (2.0, 0.5, 0.25))], system)
    elastic = fea.ElasticProblem(mesh, {0: fea.STEEL}, degree=1)
    elastic.add_kinematic_mount((0, 0, 0), (1, 0, 0), (0, 1, 0))
    with pytest.raises(FEAInputError, match=r"tcp at \(0.5, 0.5, 1.1\) m lies outside the mesh"):
        fea.build_output_operator([fea.PointDisplacement("tcp", (0.5, 0.5, 1.1), "z")], system, elastic)


def test_degenerate_tetrahedron():
    points = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0]]
    with pytest.raises(FEAInputError, match=r"tetrahedron 1 \(nodes \[0, 1, 2, 4\]\) is degenerate: volume 0.000e\+00 m³"):
        fea.TetMesh.from_arrays(points, [[0, 1, 2, 3], [0, 1, 2, 4]])


def test_inverted_tetrahedron_is_reoriented_not_rejected():
    mesh = fea.TetMesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 2, 1, 3]])
    assert mesh.volumes[0] == pytest.approx(1 / 6)


def test_bad_mesh_arrays():
    with pytest.raises(FEAInputError, match=r"tets reference node 7 but the mesh has 4 points"):
        fea.TetMesh.from_arrays(np.eye(4, 3), [[0, 1, 2, 7]])
    with pytest.raises(FEAInputError, match=r"points hold a NaN"):
        fea.TetMesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, np.nan]], [[0, 1, 2, 3]])


# ------------------------------------------------------------------ elastic supports
def test_two_point_supports_leave_a_rotation_free():
    mesh = _block()
    elastic = fea.ElasticProblem(mesh, {0: fea.STEEL}, degree=1)
    elastic.add_point_support((0, 0, 0))
    elastic.add_point_support((1, 0, 0))
    with pytest.raises(FEAInputError, match=r"the elastic supports are insufficient: rotation about x is not restrained"):
        elastic.displacement(np.full(mesh.n_nodes, 30.0))


def test_no_support():
    mesh = _block()
    with pytest.raises(FEAInputError, match=r"has no support"):
        fea.ElasticProblem(mesh, {0: fea.STEEL}).displacement(np.full(mesh.n_nodes, 30.0))


def test_support_off_the_mesh_vertices():
    elastic = fea.ElasticProblem(_block(), {0: fea.STEEL}, degree=1)
    with pytest.raises(FEAInputError, match=r"no mesh vertex within 1e-06 m \(nearest 1.000e-01 m away\)"):
        elastic.add_point_support((0.0, 0.0, 0.1), name="jack")


def test_skewed_kinematic_mount():
    elastic = fea.ElasticProblem(_block(), {0: fea.STEEL}, degree=1)
    with pytest.raises(FEAInputError, match=r"is not aligned with an axis"):
        elastic.add_kinematic_mount((0, 0, 0), (1, 1, 0), (0, 1, 0))


def test_nan_temperature_in_elastic_solve():
    mesh = _block()
    elastic = fea.ElasticProblem(mesh, {0: fea.STEEL}, degree=1)
    elastic.add_kinematic_mount((0, 0, 0), (1, 0, 0), (0, 1, 0))
    T = np.full(mesh.n_nodes, 30.0)
    T[2] = np.inf
    with pytest.raises(FEAInputError, match=r"temperature must be finite, got inf at index \(2,\)"):
        elastic.displacement(T)


# ------------------------------------------------------------------ time axis and solver
def test_non_monotonic_times():
    _, system = _convective_system()
    schedule = fea.InputSchedule(system, {"air": 20.0, "heater": 1.0})
    with pytest.raises(FEAInputError, match=r"times must increase strictly: t\[2\] = 5.0 s follows t\[1\] = 10.0 s"):
        fea.ThermalSolver(system).run(20.0, [0.0, 10.0, 5.0], schedule)
    with pytest.raises(FEAInputError, match=r"spindle: time must increase strictly, but t\[2\] = 1.0 follows t\[1\] = 1.0"):
        fea.SampledSeries([0.0, 1.0, 1.0], [1.0, 2.0, 3.0], name="spindle")


def test_theta_out_of_range():
    _, system = _convective_system()
    with pytest.raises(FEAInputError, match=r"theta must lie in \[0.5, 1\].*got 0.3"):
        fea.ThermalSolver(system, theta=0.3)


def test_steady_state_without_temperature_level_is_refused():
    """Only a heat flux: the steady problem has no solution, and must not return garbage."""
    mesh = _block()
    problem = fea.HeatProblem(mesh, {0: fea.STEEL})
    problem.add_heat_flux("left", power="heater")
    system = problem.assemble()
    with pytest.raises(FEAInputError, match=r"singular at steady state: 1 of 1 bodies .* no convection, radiation or fixed temperature"):
        fea.ThermalSolver(system).steady_state(fea.InputSchedule(system, {"heater": 10.0})(0.0))
    # The transient problem is well posed: the block just heats up.
    result = fea.ThermalSolver(system).run(20.0, [0.0, 3600.0], fea.InputSchedule(system, {"heater": 10.0}))
    gained = system.stored_energy(result.final_temperature) - system.stored_energy(np.full(system.n_nodes, 20.0))
    assert gained == pytest.approx(10.0 * 3600.0, rel=1e-9)


def test_unknown_solver_backend():
    _, system = _convective_system()
    with pytest.raises(FEAInputError, match=r"solver backend 'mumps' is not installed"):
        fea.ThermalSolver(system, backend="mumps").steady_state(np.array([20.0, 0.0]))
