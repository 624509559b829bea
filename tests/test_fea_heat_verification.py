"""Verification of the heat solver (`fea.heat`, `fea.transient`) against analytic references.

Each case compares with a closed-form solution (Fourier series, fin and slab
profiles, lumped exponential, the radiation ODE, series resistances) or with
an exact discrete identity (energy balance), so none can pass by accident:
a wrong coefficient, area, sign or scheme moves the result by orders of
magnitude more than the tolerance.

The convergence studies are plain functions (``slab_space_study`` …) so that
``bench/verification_orders.py`` prints the same numbers that the tests
assert; ``docs/verification.md`` quotes that script.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from skfem import Basis, ElementTetP1, Functional, MeshTet

import fea
from fea.heat_forms import KELVIN, STEFAN_BOLTZMANN


# ------------------------------------------------------------------ meshes
def box_mesh(xs, ys, zs, region_of=None):
    """Structured tetrahedral mesh of a box (6 tets per hexahedron); ``region_of(centroids)`` gives region ids."""
    m = MeshTet.init_tensor(np.asarray(xs, float), np.asarray(ys, float), np.asarray(zs, float))
    points, tets = m.p.T, m.t.T
    regions = None if region_of is None else region_of(points[tets].mean(axis=1))
    return fea.TetMesh.from_arrays(points, tets, regions)


def observed_orders(sizes, errors):
    """Observed orders log(e_i/e_{i+1}) / log(h_i/h_{i+1}) between successive refinements."""
    sizes, errors = np.asarray(sizes, float), np.asarray(errors, float)
    return np.log(errors[:-1] / errors[1:]) / np.log(sizes[:-1] / sizes[1:])


# ------------------------------------------------------------------ 1. slab: Fourier series
#: Bar of length 1 m, diffusivity 1 m²/s, T = 0 at both ends, T(x, 0) = sin(πx):
#: T(x, t) = sin(πx) exp(−π² t), the single term of the Fourier series.
SLAB_LENGTH = 1.0
SLAB_END_TIME = 0.1
SLAB_WIDTH = 0.01


def slab_error(n_x, dt, theta, n_cross=1, width=SLAB_WIDTH):
    """L2 error (°C, volume-averaged) at t = 0.1 s of the sine-mode slab solved on a prism mesh.

    The prism has ``n_x`` cells along the bar and ``n_cross`` across its
    square cross-section; its sides are adiabatic, so the exact solution is
    the 1-D one.  The error is integrated with a degree-6 rule against the
    exact field, not just at the nodes.
    """
    L = SLAB_LENGTH
    cross = np.linspace(0.0, width, n_cross + 1)
    mesh = box_mesh(np.linspace(0.0, L, n_x + 1), cross, cross)
    mesh.add_facet_group("left", fea.Plane.axis("x", 0.0))
    mesh.add_facet_group("right", fea.Plane.axis("x", L))
    problem = fea.HeatProblem(mesh, {0: fea.Material(1.0, 1.0, 1.0, name="unit diffusivity")})
    problem.add_fixed_temperature("left", 0.0)
    problem.add_fixed_temperature("right", 0.0)
    system = problem.assemble()
    T0 = np.sin(np.pi * system.points[:, 0] / L)
    n_steps = int(round(SLAB_END_TIME / dt))
    result = fea.ThermalSolver(system, theta=theta).run(
        T0, np.linspace(0.0, SLAB_END_TIME, n_steps + 1), fea.InputSchedule(system, {}))
    decay = np.exp(-(np.pi / L) ** 2 * SLAB_END_TIME)

    @Functional
    def squared_error(w):
        return (w.T_h - np.sin(np.pi * w.x[0] / L) * decay) ** 2

    skmesh = MeshTet(np.ascontiguousarray(system.points.T), np.ascontiguousarray(system.tets.T))
    basis = Basis(skmesh, ElementTetP1(), intorder=6)
    volume = L * width ** 2
    return float(np.sqrt(squared_error.assemble(basis, T_h=basis.interpolate(result.final_temperature)) / volume))


#: Spatial study: Crank–Nicolson with dt = 5e-4 s, whose time error (~1e-6) is
#: 100× below the spatial error of the finest mesh (h = 1/64).
SLAB_SPACE_CELLS = (8, 16, 32, 64)
SLAB_SPACE_DT = 5e-4
#: Temporal studies: 1024 cells (spatial error ~5e-6, 250× below the smallest
#: time error measured) and the smooth sine initial condition.
SLAB_TIME_CELLS = 1024
SLAB_BE_STEPS = (0.01, 0.005, 0.0025, 0.00125)
SLAB_CN_STEPS = (0.02, 0.01, 0.005, 0.0025)


def slab_space_study(cells=SLAB_SPACE_CELLS):
    errors = [slab_error(n, SLAB_SPACE_DT, 0.5) for n in cells]
    return [SLAB_LENGTH / n for n in cells], errors


def slab_time_study(theta, steps):
    return list(steps), [slab_error(SLAB_TIME_CELLS, dt, theta) for dt in steps]


def cube_space_study(cells=(4, 8, 16)):
    """3-D check: unit cube, T = 0 on all faces, T0 = sin πx sin πy sin πz, decay exp(−3π² t), t = 0.02 s."""
    t_end, dt = 0.02, 2.5e-4
    errors = []
    for n in cells:
        g = np.linspace(0.0, 1.0, n + 1)
        mesh = box_mesh(g, g, g)
        mesh.add_facet_group("skin", fea.Everything())
        problem = fea.HeatProblem(mesh, {0: fea.Material(1.0, 1.0, 1.0)})
        problem.add_fixed_temperature("skin", 0.0)
        system = problem.assemble()
        x = system.points
        T0 = np.prod(np.sin(np.pi * x), axis=1)
        result = fea.ThermalSolver(system, theta=0.5).run(
            T0, np.linspace(0.0, t_end, int(round(t_end / dt)) + 1), fea.InputSchedule(system, {}))
        decay = np.exp(-3 * np.pi ** 2 * t_end)

        @Functional
        def squared_error(w):
            return (w.T_h - np.prod(np.sin(np.pi * w.x), axis=0) * decay) ** 2

        basis = Basis(MeshTet(np.ascontiguousarray(x.T), np.ascontiguousarray(system.tets.T)),
                      ElementTetP1(), intorder=6)
        errors.append(float(np.sqrt(squared_error.assemble(basis, T_h=basis.interpolate(result.final_temperature)))))
    return [1.0 / n for n in cells], errors


def _report(label, sizes, errors, orders):
    print(f"\n{label}")
    for i, (h, e) in enumerate(zip(sizes, errors)):
        p = f"  order {orders[i - 1]:.3f}" if i else ""
        print(f"  {h:.3e}  L2 error {e:.3e}{p}")


def test_slab_spatial_order_is_two():
    sizes, errors = slab_space_study()
    orders = observed_orders(sizes, errors)
    _report("slab, P1 in space (CN, dt = 5e-4 s)", sizes, errors, orders)
    assert np.all(np.abs(orders - 2.0) < 0.3), orders
    assert errors[-1] < 2e-4                       # 0.05 % of the initial amplitude


def test_slab_backward_euler_order_is_one():
    steps, errors = slab_time_study(1.0, SLAB_BE_STEPS)
    orders = observed_orders(steps, errors)
    _report("slab, backward Euler (1024 cells)", steps, errors, orders)
    assert np.all(np.abs(orders - 1.0) < 0.3), orders


def test_slab_crank_nicolson_order_is_two():
    steps, errors = slab_time_study(0.5, SLAB_CN_STEPS)
    orders = observed_orders(steps, errors)
    _report("slab, Crank–Nicolson (1024 cells)", steps, errors, orders)
    assert np.all(np.abs(orders - 2.0) < 0.3), orders


def test_slab_prism_solution_is_one_dimensional():
    """With adiabatic sides the cross-section is isothermal: refining it leaves the error unchanged."""
    coarse = slab_error(16, SLAB_SPACE_DT, 0.5, n_cross=1)
    fine = slab_error(16, SLAB_SPACE_DT, 0.5, n_cross=3)
    assert abs(coarse - fine) < 1e-3 * coarse


@pytest.mark.slow
def test_cube_spatial_order_is_two_in_3d():
    sizes, errors = cube_space_study((4, 8, 16, 32))
    orders = observed_orders(sizes, errors)
    _report("unit cube, P1 in space (CN, dt = 2.5e-4 s)", sizes, errors, orders)
    assert np.all(np.abs(orders[1:] - 2.0) < 0.3), orders


def test_cube_spatial_order_cheap():
    sizes, errors = cube_space_study((4, 8, 16))
    orders = observed_orders(sizes, errors)
    assert abs(orders[-1] - 2.0) < 0.3, orders


# ------------------------------------------------------------------ 2. steady convective fin and slab
def steady_slab_errors():
    """Slab −L<x<L, uniform source q, convection h on both faces: T = T∞ + qL/h + q(L² − x²)/(2k).

    Returns the maximum nodal error over the profile and at the two faces,
    both relative to the centre rise (79.2 K).
    """
    L, k, h, q, T_inf, w = 0.05, 20.0, 150.0, 2e5, 25.0, 0.002
    mesh = box_mesh(np.linspace(-L, L, 33), [0.0, w], [0.0, w])
    mesh.add_facet_group("faces", fea.Plane.axis("x", -L) | fea.Plane.axis("x", L))
    problem = fea.HeatProblem(mesh, {0: fea.Material(k, 7800.0, 500.0)})
    problem.add_convection("faces", h, ambient="air")
    problem.add_volumetric_source("generation", np.arange(mesh.n_tets), power="P")
    system = problem.assemble()
    u = fea.InputSchedule(system, {"air": T_inf, "P": q * 2 * L * w * w})(0.0)
    T = fea.ThermalSolver(system).steady_state(u)
    x = system.points[:, 0]
    exact = T_inf + q * L / h + q * (L ** 2 - x ** 2) / (2 * k)
    rise = exact.max() - T_inf
    surface = np.isclose(np.abs(x), L)                                # T(±L) − T∞ = qL/h = 66.7 K
    return np.abs(T - exact).max() / rise, np.abs(T - exact)[surface].max() / rise


def test_steady_slab_with_source_and_convection_matches_parabola():
    profile, surface = steady_slab_errors()
    assert profile < 2e-4 and surface < 2e-4


def fin_errors():
    """Square pin fin, fixed base, convective sides and tip (Incropera eq. 3.75), Bi = h a/(2k) = 6e-4.

    Returns the maximum nodal error relative to the base excess (80 K) and the
    relative error of the heat rate through the fin.
    """
    k, h, a, L, T_b, T_inf = 200.0, 25.0, 0.01, 0.15, 100.0, 20.0
    mesh = box_mesh(np.linspace(0, L, 31), np.linspace(0, a, 3), np.linspace(0, a, 3))
    mesh.add_facet_group("base", fea.Plane.axis("x", 0.0))
    mesh.add_facet_group("skin", ~fea.Plane.axis("x", 0.0))
    problem = fea.HeatProblem(mesh, {0: fea.Material(k, 2700.0, 900.0)})
    problem.add_fixed_temperature("base", T_b)
    problem.add_convection("skin", h, ambient=T_inf)
    system = problem.assemble()
    u = fea.InputSchedule(system, {})(0.0)
    T = fea.ThermalSolver(system).steady_state(u)
    m = np.sqrt(h * 4 * a / (k * a * a))                              # mL = 1.06
    r = h / (m * k)
    x = system.points[:, 0]
    exact = T_inf + (T_b - T_inf) * (np.cosh(m * (L - x)) + r * np.sinh(m * (L - x))) / (
        np.cosh(m * L) + r * np.sinh(m * L))
    q_fin = np.sqrt(h * 4 * a * k * a * a) * (T_b - T_inf) * (np.sinh(m * L) + r * np.cosh(m * L)) / (
        np.cosh(m * L) + r * np.sinh(m * L))
    convected = -system.power_in(T, u)["convection:skin"]
    return np.abs(T - exact).max() / (T_b - T_inf), abs(convected / q_fin - 1.0)


def test_steady_fin_matches_cosh_profile():
    profile, heat_rate = fin_errors()
    assert profile < 1e-3 and heat_rate < 1e-3


def test_stratified_ambient_sets_the_level_of_a_conductive_body():
    """Convection only on the top (z = 0.3 m) of a conductive column, ambient 20 °C + 2 K/m · (z − 0.1 m): T = 20.4 °C."""
    mesh = box_mesh([0, 0.1], [0, 0.1], np.linspace(0, 0.3, 4))
    mesh.add_facet_group("top", fea.Plane.axis("z", 0.3))
    problem = fea.HeatProblem(mesh, {0: fea.Material(1e4, 1000.0, 1000.0)})
    problem.add_convection("top", 10.0, ambient="air", ambient_gradient="gradient", reference_height=0.1)
    system = problem.assemble()
    T = fea.ThermalSolver(system).steady_state(fea.InputSchedule(system, {"air": 20.0, "gradient": 2.0})(0.0))
    assert np.allclose(T, 20.0 + 2.0 * (0.3 - 0.1), atol=1e-10)


# ------------------------------------------------------------------ 3. lumped cooling
def lumped_cooling_error():
    """0.1 m cube, h = 5 W/(m²K) on all faces: θ/θ0 = exp(−t/τ), τ = ρcV/(hA).

    Copper's ρc with ten times its conductivity, so that Bi = h (L/2)/k = 6e-5
    and the lumped model's own error (the centre-to-corner difference, of
    order Bi·θ) sits below the tolerance.
    """
    side, rho, c, k, h = 0.1, 8900.0, 385.0, 4000.0, 5.0
    g = np.linspace(0, side, 4)
    mesh = box_mesh(g, g, g)
    mesh.add_facet_group("skin", fea.Everything())
    problem = fea.HeatProblem(mesh, {0: fea.Material(k, rho, c)})
    problem.add_convection("skin", h, ambient="air")
    system = problem.assemble()
    tau = rho * c * side ** 3 / (h * 6 * side ** 2)                    # 11 421 s
    times = np.linspace(0.0, 3 * tau, 301)
    ops = fea.build_output_operator([fea.PointTemperature("centre", (side / 2,) * 3),
                                     fea.PointTemperature("corner", (0.0, 0.0, 0.0))], system)
    # Sub-steps of τ/1000 keep the mesh's fastest modes damped under Crank–Nicolson
    # (the sudden exposure at t = 0 excites them with an amplitude of order Bi).
    result = fea.ThermalSolver(system, theta=0.5).run(80.0, times, fea.InputSchedule(system, {"air": 20.0}),
                                                      outputs=ops, max_step_s=tau / 1000)
    theta = (result.outputs - 20.0) / 60.0
    exact = np.exp(-times / tau)[:, None]
    # The error a 1 % error in τ would cause, for scale.
    one_percent = np.abs(np.exp(-times / (1.01 * tau))[:, None] - exact).max()
    return np.abs(theta - exact).max(), one_percent


def test_lumped_cooling_of_conductive_block_is_exponential():
    error, one_percent_tau = lumped_cooling_error()
    assert error < 1e-4
    assert one_percent_tau > 30 * 1e-4            # the tolerance resolves a 1 % error in τ 30-fold


# ------------------------------------------------------------------ 3b. time-step error estimate
#: NAFEMS T3 (one-dimensional transient): a 0.1 m bar, k = 35 W/(m K), ρ = 7200 kg/m³, c = 440.5 J/(kg K),
#: at 0 °C; x = 0 held at 0 °C, x = 0.1 m at 100 sin(πt/40) °C; the benchmark asks for T(0.08 m, 32 s) = 36.60 °C.
NAFEMS_T3_REFERENCE_C = 36.60


def nafems_t3(cells=40):
    """The T3 bar (a 10 × 10 mm prism with adiabatic sides), its input schedule and the output at x = 0.08 m."""
    mesh = box_mesh(np.linspace(0.0, 0.1, cells + 1), [0.0, 0.01], [0.0, 0.01])
    mesh.add_facet_group("left", fea.Plane.axis("x", 0.0))
    mesh.add_facet_group("right", fea.Plane.axis("x", 0.1))
    problem = fea.HeatProblem(mesh, {0: fea.Material(35.0, 7200.0, 440.5, name="NAFEMS T3")})
    problem.add_fixed_temperature("left", 0.0)
    problem.add_fixed_temperature("right", "end")
    system = problem.assemble()
    schedule = fea.InputSchedule(system, {"end": lambda t: 100.0 * np.sin(np.pi * t / 40.0)})
    return system, schedule, fea.build_output_operator([fea.PointTemperature("x80", (0.08, 0.005, 0.005))], system)


def nafems_t3_step_error(theta, dt=0.5):
    """T(0.08 m, 32 s) (°C), the step-doubling estimate of its time error and the true one (K), at 32 s and the
    largest over 0–32 s; the truth is the same mesh with Crank–Nicolson steps 64 times shorter."""
    system, schedule, outputs = nafems_t3()
    times = np.arange(0.0, 32.0 + dt / 2, dt)
    solver = fea.ThermalSolver(system, theta=theta)
    run = solver.run(0.0, times, schedule, outputs)
    estimate = solver.step_error(0.0, times, schedule, outputs, run)
    truth = fea.ThermalSolver(system, theta=0.5).run(0.0, times, schedule, outputs, substeps=64)
    true = (run.outputs - truth.outputs)[np.searchsorted(times, estimate.times_s), 0]
    return dict(T_32=float(run.outputs[-1, 0]), truth_32=float(truth.outputs[-1, 0]),
                estimated_32=float(estimate.error[-1, 0]), true_32=float(true[-1]),
                estimated_max=float(np.abs(estimate.error[:, 0]).max()), true_max=float(np.abs(true).max()))


@pytest.mark.parametrize("theta", [1.0, 0.5], ids=["backward-Euler", "Crank-Nicolson"])
def test_step_doubling_estimates_the_time_error_of_nafems_t3(theta):
    r = nafems_t3_step_error(theta)
    assert r["truth_32"] == pytest.approx(NAFEMS_T3_REFERENCE_C, abs=0.1)      # the benchmark's answer, this mesh
    assert abs(r["true_32"]) > 1e-3                                             # there is a time error to estimate
    assert r["estimated_32"] == pytest.approx(r["true_32"], rel=0.1)
    assert r["estimated_max"] == pytest.approx(r["true_max"], rel=0.1)


# ------------------------------------------------------------------ 4. energy balance
def _two_block_system(radiation_full=False):
    """Two blocks joined by a contact joint, loaded by every kind of load the solver has."""
    xs = np.linspace(0.0, 0.2, 9)
    mesh = box_mesh(xs, np.linspace(0, 0.1, 4), np.linspace(0, 0.1, 4),
                    region_of=lambda c: (c[:, 0] > 0.1).astype(int))
    mesh.region_names.update({0: "steel", 1: "iron"})
    mesh.add_facet_group("left", fea.Plane.axis("x", 0.0))
    mesh.add_facet_group("right", fea.Plane.axis("x", 0.2))
    mesh.add_facet_group("top", fea.Plane.axis("z", 0.1))
    mesh.add_facet_group("bottom", fea.Plane.axis("z", 0.0))
    mesh.add_facet_group("sides", fea.Plane.axis("y", 0.0) | fea.Plane.axis("y", 0.1))
    problem = fea.HeatProblem(mesh, {"steel": fea.STEEL, "iron": fea.CAST_IRON})
    problem.add_contact("steel", "iron", 800.0)
    problem.add_convection("sides", 12.0, ambient="air", ambient_gradient="stratification", reference_height=0.05)
    problem.add_convection("bottom", 40.0, ambient="coolant")
    problem.add_heat_flux("left", power="bearing")
    problem.add_heat_flux("top", flux_density="sun")
    problem.add_volumetric_source("motor", mesh.select_tets(fea.Box((0.15, 0, 0), (0.2, 0.1, 0.1))), power="motor")
    if radiation_full:
        problem.add_radiation("right", 0.9, ambient="air")
    else:
        problem.add_radiation("right", 0.9, ambient="air", linearise_about=40.0)
    system = problem.assemble()
    schedule = fea.InputSchedule(system, {
        "air": lambda t: 20.0 + 3.0 * np.sin(t / 900.0),
        "stratification": 0.5,
        "coolant": fea.SampledSeries([0.0, 1800.0, 3600.0], [18.0, 25.0, 19.0]),
        "bearing": lambda t: 150.0 * (t < 2400.0),
        "sun": 300.0,
        "motor": fea.SampledSeries([0.0, 1000.0], [0.0, 400.0]),
    }, breakpoints_s=[2400.0])                                   # when the bearing switches off
    return system, schedule


#: Two step sizes (82 s, then 79 s): the bearing's switch-off (2400 s), the motor ramp's knee (1000 s)
#: and the coolant's (1800 s) all fall inside steps.
ENERGY_TIMES = np.concatenate([np.linspace(0.0, 1230.0, 16), np.linspace(1230.0, 3600.0, 31)[1:]])


def _energy_run(theta, radiation_full=False, schedule_of=lambda schedule: schedule):
    system, schedule = _two_block_system(radiation_full)
    result = fea.ThermalSolver(system, theta=theta).run(60.0, ENERGY_TIMES, schedule_of(schedule),
                                                        field_times_s=ENERGY_TIMES[[0, -1]], energy=True)
    return system, result


def energy_balance(theta, radiation_full=False):
    """(stored-energy change J, |change − Σ ledger loads| relative to the gross energy through the loads) over 1 h.

    The change is taken from the first and last fields (``stored_energy``),
    not from the ledger's own stored-energy row.
    """
    system, result = _energy_run(theta, radiation_full)
    fields = [result.fields[float(t)] for t in ENERGY_TIMES[[0, -1]]]
    stored = system.stored_energy(fields[1]) - system.stored_energy(fields[0])
    ledger = result.energy
    return stored, abs(stored - ledger.load_J[-1].sum()) / ledger.gross_J[-1]


@pytest.mark.parametrize("theta", [1.0, 0.5], ids=["backward-Euler", "Crank-Nicolson"])
def test_energy_balance_is_exact_for_theta_scheme(theta):
    stored, imbalance = energy_balance(theta)
    assert abs(stored) > 1e4                                 # the test moves real energy (J)
    assert imbalance < 1e-10


@pytest.mark.parametrize("theta", [1.0, 0.5], ids=["backward-Euler", "Crank-Nicolson"])
def test_energy_balance_with_full_radiation_holds_to_iteration_tolerance(theta):
    # The radiation iterations stop at a 1e-9 K change: ΣM·1e-9 K ≈ 1e-2 J against ~1e6 J.
    stored, imbalance = energy_balance(theta, radiation_full=True)
    assert imbalance < 1e-8


class _PointSamples:
    """The inputs of a schedule at points only (no step means): the scheme then takes its step ends."""

    def __init__(self, schedule):
        self.sample = schedule.sample


@pytest.mark.parametrize("theta", [1.0, 0.5], ids=["backward-Euler", "Crank-Nicolson"])
def test_loads_inject_exactly_their_integral_whatever_the_step_grid(theta):
    """Heat sources switched or bent between step times inject ∫P dt exactly (analytic energies, J)."""
    system, result = _energy_run(theta)
    names = result.energy.names
    energy = dict(zip(names, result.energy.load_J[-1]))
    assert energy["flux:left"] == pytest.approx(150.0 * 2400.0, rel=1e-12)                 # switched off at 2400 s
    assert energy["source:motor"] == pytest.approx(0.5 * 1000.0 * 400.0 + 2600.0 * 400.0, rel=1e-12)   # ramp, held
    assert energy["flux:top"] == pytest.approx(300.0 * 0.2 * 0.1 * 3600.0, rel=1e-12)
    assert result.energy.energy_of("bearing")[-1] == pytest.approx(150.0 * 2400.0, rel=1e-12)
    # Driven by its step ends instead, the bearing would run on to the end of the step holding 2400 s.
    _, ends = _energy_run(theta, schedule_of=_PointSamples)
    lost = dict(zip(names, ends.energy.load_J[-1]))["flux:left"] - 150.0 * 2400.0
    assert abs(lost) > 150.0 * 10.0


def _bar_with_fixed_ends(length=0.5, cells=20):
    """A 0.5 m steel bar (20 × 20 mm) with fixed-temperature ends and adiabatic sides."""
    mesh = box_mesh(np.linspace(0.0, length, cells + 1), [0.0, 0.02], [0.0, 0.02])
    mesh.add_facet_group("hot", fea.Plane.axis("x", 0.0))
    mesh.add_facet_group("cold", fea.Plane.axis("x", length))
    problem = fea.HeatProblem(mesh, {0: fea.STEEL})
    problem.add_fixed_temperature("hot", "T_hot")
    problem.add_fixed_temperature("cold", 20.0)
    return problem.assemble()


def test_reaction_heat_flow_of_fixed_temperatures_is_fourier_law():
    """Steady conduction between fixed ends: each end passes q = k A ΔT / L (in at the hot end, out at the cold)."""
    system = _bar_with_fixed_ends()
    u = fea.InputSchedule(system, {"T_hot": 80.0})(0.0)
    T = fea.ThermalSolver(system).steady_state(u)
    flows = system.power_in(T, u)
    fourier = fea.STEEL.conductivity * 0.02 * 0.02 * (80.0 - 20.0) / 0.5
    assert flows["fixed:hot"] == pytest.approx(fourier, rel=1e-10)
    assert flows["fixed:cold"] == pytest.approx(-fourier, rel=1e-10)


@pytest.mark.parametrize("theta", [1.0, 0.5], ids=["backward-Euler", "Crank-Nicolson"])
def test_energy_balance_includes_fixed_temperature_reactions(theta):
    """A bar at 20 °C whose hot end is raised to 80 °C: the ends supply ρcV·30 K, then Fourier's flow."""
    system = _bar_with_fixed_ends()
    tau = 0.5 ** 2 * fea.STEEL.volumetric_heat_capacity / fea.STEEL.conductivity     # L²/a ≈ 2e4 s
    times = np.linspace(0.0, 10 * tau, 401)
    result = fea.ThermalSolver(system, theta=theta).run(20.0, times, fea.InputSchedule(system, {"T_hot": 80.0}),
                                                        energy=True)
    ledger = result.energy
    reactions = dict(zip(ledger.names, ledger.load_J[-1]))
    # Linear steady profile from 80 to 20 °C: the bar gains ρc V (50 − 20) K, less what the hot end's
    # half cell (its nodes' share of the capacity, ρc V / 40) held at t = 0, fixed at 80 °C from the start.
    rho_c_V = fea.STEEL.volumetric_heat_capacity * 0.5 * 0.02 * 0.02
    gained = rho_c_V * 30.0 - rho_c_V / 40 * 60.0
    assert reactions["fixed:hot"] + reactions["fixed:cold"] == pytest.approx(gained, rel=1e-3)
    assert ledger.relative_error() < 1e-12
    # At the end the flow has settled to Fourier's law: the last step's reaction energy / Δt.
    rate = (ledger.load_J[-1] - ledger.load_J[-2]) / (times[-1] - times[-2])
    fourier = fea.STEEL.conductivity * 0.02 * 0.02 * 60.0 / 0.5
    assert rate[ledger.names.index("fixed:hot")] == pytest.approx(fourier, rel=1e-3)


def test_power_in_reports_each_load():
    """power_in splits the heat flow per load, with the sign 'into the body'."""
    system, schedule = _two_block_system()
    u = schedule(1000.0)
    T = np.full(system.n_nodes, 25.0)
    flows = system.power_in(T, u)
    assert flows["flux:left"] == pytest.approx(150.0)
    assert flows["flux:top"] == pytest.approx(300.0 * 0.2 * 0.1)
    assert flows["source:motor"] == pytest.approx(400.0)
    air = 20.0 + 3.0 * np.sin(1000.0 / 900.0)
    # Sides: 2 faces of 0.2 x 0.1 m; stratification averages to zero about z = 0.05 m.
    assert flows["convection:sides"] == pytest.approx(12.0 * 0.04 * (air - 25.0))
    assert flows["convection:bottom"] == pytest.approx(40.0 * 0.02 * (schedule(1000.0)[system.input_index("coolant")] - 25.0))


def test_two_fluxes_on_one_group_are_both_counted():
    system_mesh = box_mesh(np.linspace(0, 1, 3), [0, 1], [0, 1])
    system_mesh.add_facet_group("face", fea.Plane.axis("x", 0.0))
    system_mesh.add_facet_group("back", fea.Plane.axis("x", 1.0))
    problem = fea.HeatProblem(system_mesh, {0: fea.STEEL})
    problem.add_heat_flux("face", power="motor")
    problem.add_heat_flux("face", power="bearing")
    problem.add_convection("back", 10.0, ambient=20.0)
    system = problem.assemble()
    u = fea.InputSchedule(system, {"motor": 30.0, "bearing": 70.0})(0.0)
    flows = system.power_in(np.full(system.n_nodes, 20.0), u)
    assert sum(flows.values()) == pytest.approx(100.0)


# ------------------------------------------------------------------ 5. radiation
def _radiating_cube(linearise_about=None):
    side = 0.05
    g = np.linspace(0, side, 3)
    mesh = box_mesh(g, g, g)
    mesh.add_facet_group("skin", fea.Everything())
    # A fictitious, very conductive material: Bi = h_r (L/2)/k < 3e-7 (h_r ≤ 94 W/(m²K) at 500 °C),
    # so the internal temperature differences (~1e-4 K) stay below the time errors measured.
    material = fea.Material(1e7, 1000.0, 1000.0, name="isothermal")
    problem = fea.HeatProblem(mesh, {0: material})
    problem.add_radiation("skin", 0.9, ambient="wall", linearise_about=linearise_about)
    system = problem.assemble()
    capacity = material.volumetric_heat_capacity * side ** 3
    return system, capacity, 6 * side ** 2


def test_power_in_of_full_radiation_is_stefan_boltzmann():
    """A uniform 500 °C cube radiating to a 20 °C wall loses εσ(T⁴ − T_wall⁴) A (kelvin), not the linearisation."""
    system, _, area = _radiating_cube()
    u = fea.InputSchedule(system, {"wall": 20.0})(0.0)
    flows = system.power_in(np.full(system.n_nodes, 500.0), u)
    expected = -0.9 * STEFAN_BOLTZMANN * ((500.0 + KELVIN) ** 4 - (20.0 + KELVIN) ** 4) * area
    assert flows["radiation:skin"] == pytest.approx(expected, rel=1e-12)


def radiation_cooling_error(theta, dt):
    """ρcV dT/dt = −εσA (T_K⁴ − T_wall,K⁴) from 500 °C to a 20 °C wall over 1200 s, against solve_ivp (rtol 1e-12).

    Returns the maximum error (K), the final ODE temperature and the error the
    linearisation about 20 °C would make (K).
    """
    system, capacity, area = _radiating_cube()
    T0, T_wall, eps = 500.0, 20.0, 0.9
    t_end = 1200.0

    def rhs(t, T):
        return -eps * STEFAN_BOLTZMANN * area * ((T + KELVIN) ** 4 - (T_wall + KELVIN) ** 4) / capacity

    times = np.arange(0.0, t_end + dt / 2, dt)
    ode = solve_ivp(rhs, (0, t_end), [T0], t_eval=times, rtol=1e-12, atol=1e-12, method="DOP853").y[0]
    ops = fea.build_output_operator([fea.PointTemperature("centre", (0.025,) * 3)], system)
    result = fea.ThermalSolver(system, theta=theta).run(T0, times, fea.InputSchedule(system, {"wall": T_wall}),
                                                        outputs=ops)
    error = np.abs(result.outputs[:, 0] - ode).max()
    h_r = 4 * eps * STEFAN_BOLTZMANN * (20.0 + KELVIN) ** 3
    linear = np.abs(T_wall + (T0 - T_wall) * np.exp(-h_r * area * times / capacity) - ode).max()
    return error, ode[-1], linear


@pytest.mark.parametrize("theta,dt,tol", [(0.5, 2.0, 0.01), (1.0, 2.0, 1.0)], ids=["Crank-Nicolson", "backward-Euler"])
def test_full_radiation_cooling_matches_ode(theta, dt, tol):
    error, final, linear = radiation_cooling_error(theta, dt)
    assert final < 100.0                                     # it cools by more than 400 K
    assert error < tol, error                                # K, against a 480 K range
    assert linear > 50.0                                     # the linearisation alone would be far off


RADIATION_CN_STEPS = (20.0, 10.0, 5.0)


def radiation_time_study(steps=RADIATION_CN_STEPS):
    """Crank–Nicolson error (K) of the radiating cube at t = 600 s for each step."""
    system, capacity, area = _radiating_cube()

    def rhs(t, T):
        return -0.9 * STEFAN_BOLTZMANN * area * ((T + KELVIN) ** 4 - (20.0 + KELVIN) ** 4) / capacity

    exact = solve_ivp(rhs, (0, 600.0), [500.0], rtol=1e-12, atol=1e-12, method="DOP853").y[0, -1]
    errors = []
    for dt in steps:
        result = fea.ThermalSolver(system, theta=0.5).run(500.0, np.arange(0.0, 600.0 + dt / 2, dt),
                                                          fea.InputSchedule(system, {"wall": 20.0}))
        errors.append(abs(result.final_temperature.mean() - exact))
    return list(steps), errors


def test_full_radiation_time_error_shrinks_at_second_order_with_crank_nicolson():
    steps, errors = radiation_time_study()
    orders = observed_orders(steps, errors)
    assert np.all(np.abs(orders - 2.0) < 0.3), (errors, orders)


def linearised_radiation_error():
    """Radiation linearised about 150 °C: T − T_wall = (T0 − T_wall) exp(−h_r A t/(ρcV)); max error (K) at t = 3τ."""
    T_lin, eps, T0, T_wall = 150.0, 0.9, 300.0, 20.0
    system, capacity, area = _radiating_cube(linearise_about=T_lin)
    h_r = 4 * eps * STEFAN_BOLTZMANN * (T_lin + KELVIN) ** 3
    tau = capacity / (h_r * area)                                    # ≈ 1.7e3 s
    times = np.linspace(0.0, 3 * tau, 601)
    result = fea.ThermalSolver(system, theta=0.5).run(T0, times, fea.InputSchedule(system, {"wall": T_wall}))
    exact = T_wall + (T0 - T_wall) * np.exp(-3.0)
    return np.abs(result.final_temperature - exact).max()


def test_linearised_radiation_is_exponential():
    assert linearised_radiation_error() < 1e-3                # K, on a 266 K drop


# ------------------------------------------------------------------ 8. joint layer
Q_JOINT, H_CONTACT = 5000.0, 2000.0           # W/m², W/(m² K): expected drop q/h_c = 2.5 K


def _joint_bar(xs, region_of):
    mesh = box_mesh(xs, [0.0, 0.02], [0.0, 0.02], region_of)
    mesh.add_facet_group("heated", fea.Plane.axis("x", 0.0))
    mesh.add_facet_group("sink", fea.Plane.axis("x", xs[-1]))
    return mesh


def contact_joint_drop():
    """Interface drop (K) of the contact model and the hot-end error (K) against the series resistance."""
    a = 0.05
    mesh = _joint_bar(np.linspace(0, 2 * a, 11), lambda c: (c[:, 0] > a).astype(int))
    problem = fea.HeatProblem(mesh, {0: fea.STEEL, 1: fea.CAST_IRON})
    problem.add_contact(0, 1, H_CONTACT)
    problem.add_heat_flux("heated", flux_density="q")
    problem.add_fixed_temperature("sink", 20.0)
    system = problem.assemble()
    assert system.n_nodes == mesh.n_nodes + 4 * 1            # one 2×2 plane of nodes duplicated
    T = fea.ThermalSolver(system).steady_state(fea.InputSchedule(system, {"q": Q_JOINT})(0.0))
    on_joint = np.isclose(system.points[:, 0], a)
    side_a = np.intersect1d(np.flatnonzero(on_joint), system.tets[mesh.regions == 0])
    side_b = np.intersect1d(np.flatnonzero(on_joint), system.tets[mesh.regions == 1])
    assert len(side_a) == len(side_b) == 4
    # Pair the two thermal copies of each mesh node on the joint.
    side_a = side_a[np.argsort(system.node_of[side_a])]
    side_b = side_b[np.argsort(system.node_of[side_b])]
    assert np.array_equal(system.node_of[side_a], system.node_of[side_b])
    drops = T[side_a] - T[side_b]
    # The rest is the series resistance of the blocks: T(0) − 20 = q (a/k_s + 1/h_c + a/k_ci).
    hot = T[np.isclose(system.points[:, 0], 0.0)]
    expected = 20.0 + Q_JOINT * (a / fea.STEEL.conductivity + 1 / H_CONTACT + a / fea.CAST_IRON.conductivity)
    return drops, np.abs(hot - expected).max()


def test_contact_interface_drop_equals_flux_over_conductance():
    drops, hot_end_error = contact_joint_drop()
    assert np.allclose(drops, Q_JOINT / H_CONTACT, rtol=1e-9)          # 2.5 K at every node pair
    assert hot_end_error < 1e-9


def thin_layer_drop():
    """Temperature drop (K) across a 0.5 mm layer region with k = h_c·t."""
    a, t = 0.05, 0.5e-3
    xs = np.concatenate([np.linspace(0, a, 6), np.linspace(a + t, 2 * a + t, 6)])
    mesh = _joint_bar(xs, lambda c: np.where(c[:, 0] < a, 0, np.where(c[:, 0] < a + t, 2, 1)))
    layer = fea.Material(H_CONTACT * t, 1000.0, 1000.0, name="joint layer")
    problem = fea.HeatProblem(mesh, {0: fea.STEEL, 1: fea.CAST_IRON, 2: layer})
    problem.add_heat_flux("heated", flux_density="q")
    problem.add_fixed_temperature("sink", 20.0)
    system = problem.assemble()
    T = fea.ThermalSolver(system).steady_state(fea.InputSchedule(system, {"q": Q_JOINT})(0.0))
    x = system.points[:, 0]
    return T[np.isclose(x, a)].mean() - T[np.isclose(x, a + t)].mean()


def test_thin_layer_drop_equals_flux_over_conductance():
    assert thin_layer_drop() == pytest.approx(Q_JOINT / H_CONTACT, rel=1e-9)


# ------------------------------------------------------------------ 11. factorisation cache
def _small_system():
    mesh = box_mesh(np.linspace(0, 1, 4), [0, 1], [0, 1])
    mesh.add_facet_group("skin", fea.Everything())
    problem = fea.HeatProblem(mesh, {0: fea.STEEL})
    problem.add_convection("skin", 10.0, ambient="air")
    system = problem.assemble()
    return system, fea.InputSchedule(system, {"air": 20.0})


def test_constant_step_factorises_once():
    system, schedule = _small_system()
    solver = fea.ThermalSolver(system)
    result = solver.run(30.0, np.linspace(0, 3600, 61), schedule)       # 60 s steps with round-off
    assert solver.factorisations == 1 and result.factorisations == 1


def test_two_step_sizes_factorise_twice_and_are_reused():
    system, schedule = _small_system()
    solver = fea.ThermalSolver(system, theta=0.5)
    times = [0, 10, 20, 40, 60, 70, 90, 100, 110]                     # 10 s and 20 s steps, interleaved
    solver.run(30.0, times, schedule)
    assert solver.factorisations == 2
    solver.run(30.0, np.arange(0, 200, 20.0), schedule)              # a new run reuses the cached factor
    assert solver.factorisations == 2
    solver.run(30.0, [0, 600], schedule, max_step_s=10.0)             # sub-steps of 10 s: cached too
    assert solver.factorisations == 2


@pytest.mark.parametrize("conductivity, level", [(50.0, 30.0), (1e4, 80.0)], ids=["cast-iron-30C", "stiff-80C"])
@pytest.mark.parametrize("theta", [1.0, 0.5], ids=["backward-Euler", "Crank-Nicolson"])
def test_a_day_at_rest_passes_the_energy_balance(theta, conductivity, level):
    """A box held at its ambient for a day moves no heat: the solver's round-off (1e-12 to 1e-9 K) is not
    judged as heat lost or created (against a 1 µK floor it read 5e-6 to 5e-3)."""
    mesh = box_mesh(np.linspace(0, 0.4, 9), np.linspace(0, 0.3, 7), np.linspace(0, 0.5, 11))
    mesh.add_facet_group("skin", fea.Everything())
    problem = fea.HeatProblem(mesh, {0: fea.Material(conductivity, 7200.0, 500.0)})
    problem.add_convection("skin", 10.0, ambient="air")
    system = problem.assemble()
    times = np.arange(0.0, 86400.0 + 1.0, 600.0)
    result = fea.ThermalSolver(system, theta=theta).run(level, times, fea.InputSchedule(system, {"air": level}),
                                                        max_step_s=60.0, energy=True)
    assert np.abs(result.final_temperature - level).max() < 1e-8          # K: nothing happened
    assert result.energy.relative_error() < 1e-6
