"""Verification of the thermo-elastic solver (`fea.elastic`, `fea.outputs`) against analytic references.

* free thermal expansion of a 3-2-1 mounted block: u = α ΔT (x − x₁), σ = 0;
* free thermal bending under a through-thickness linear temperature: κ = α ΔT / h;
* the bimetal strip: Timoshenko's curvature formula (J. Opt. Soc. Am. 11, 1925);
* adjoint influence outputs against direct solves.

The bending studies are plain functions so ``bench/verification_orders.py``
prints the same sequences that the tests assert.
"""
from __future__ import annotations

import numpy as np
import pytest
from skfem import MeshTet

import fea

T_REF = 20.0


def box_mesh(xs, ys, zs, region_of=None, jitter=0.0, seed=0):
    """Structured tetrahedral mesh of a box; ``jitter`` moves interior nodes randomly (fraction of the local spacing)."""
    xs, ys, zs = (np.asarray(v, float) for v in (xs, ys, zs))
    m = MeshTet.init_tensor(xs, ys, zs)
    points, tets = m.p.T.copy(), m.t.T
    if jitter:
        rng = np.random.default_rng(seed)
        spacing = np.array([np.diff(v).min() for v in (xs, ys, zs)])
        lo, hi = points.min(0), points.max(0)
        inside = np.all((points > lo + 1e-12) & (points < hi - 1e-12), axis=1)
        points[inside] += jitter * spacing * rng.uniform(-1, 1, (inside.sum(), 3))
    regions = None if region_of is None else region_of(points[tets].mean(axis=1))
    return fea.TetMesh.from_arrays(points, tets, regions)


# ------------------------------------------------------------------ 6. free thermal expansion
def free_expansion_errors(degree):
    """Jittered two-material block heated uniformly by 35 K on a 3-2-1 mount.

    Returns max |u − α ΔT (x − x₁)| relative to α ΔT L_max, and max |σ|
    relative to the fully restrained thermal stress (3λ+2μ) α ΔT of steel.
    """
    L = np.array([0.3, 0.2, 0.1])
    mesh = box_mesh([0, 0.05, 0.12, 0.2, 0.3], np.linspace(0, 0.2, 4), [0, 0.04, 0.1],
                    region_of=lambda c: (c[:, 0] > 0.15).astype(int), jitter=0.25)
    alpha, dT = 11.5e-6, 35.0
    # Two regions with different E and ν but one α: uniform heating is still stress-free.
    materials = {0: fea.Material(45, 7850, 470, 210e9, 0.30, alpha), 1: fea.Material(48, 7200, 500, 110e9, 0.26, alpha)}
    elastic = fea.ElasticProblem(mesh, materials, degree=degree, reference_temperature=T_REF)
    origin = np.zeros(3)
    elastic.add_kinematic_mount(origin, (L[0], 0, 0), (0, L[1], 0))
    T = np.full(mesh.n_nodes, T_REF + dT)
    u = elastic.displacement(T)
    exact = alpha * dT * (elastic.space.node_points - origin)
    assert u.shape == (elastic.space.n_nodes, 3)
    sigma = elastic.stress(u, T)
    restrained = fea.STEEL.thermal_stress_modulus * dT                     # 1.2e9 Pa if fully restrained
    return np.abs(u - exact).max() / (alpha * dT * L.max()), np.abs(sigma).max() / restrained


@pytest.mark.parametrize("degree", [1, 2])
def test_free_expansion_is_alpha_dt_x_and_stress_free(degree):
    displacement, stress = free_expansion_errors(degree)
    assert displacement < 1e-10 and stress < 1e-8


def test_free_expansion_output_operator_strain_and_drift():
    """Through the adjoint operator: FBG strain reads α ΔT, a point drifts by α ΔT (x − x_ref)."""
    mesh = box_mesh(np.linspace(0, 0.3, 4), np.linspace(0, 0.2, 3), [0, 0.1], jitter=0.2, seed=3)
    mesh.add_facet_group("skin", fea.Everything())
    problem = fea.HeatProblem(mesh, {0: fea.CAST_IRON})
    problem.add_convection("skin", 10.0, ambient="air")
    system = problem.assemble()
    elastic = fea.ElasticProblem(mesh, {0: fea.CAST_IRON}, degree=2, reference_temperature=T_REF)
    elastic.add_kinematic_mount((0, 0, 0), (0.3, 0, 0), (0, 0.2, 0))
    p, ref = (0.23, 0.13, 0.07), (0.04, 0.05, 0.02)
    op = fea.build_output_operator([
        fea.AxialStrain("fbg", (0.02, 0.03, 0.05), (0.27, 0.17, 0.06)),
        fea.RelativeDisplacement("drift_y", p, ref, "y"),
        fea.PointDisplacement("uz", p, "z"),
    ], system, elastic)
    dT = 12.0
    y = op.apply(np.full(system.n_nodes, T_REF + dT))
    a = fea.CAST_IRON.expansion
    assert y[0] == pytest.approx(a * dT, rel=1e-10)
    assert y[1] == pytest.approx(a * dT * (p[1] - ref[1]), rel=1e-10)
    assert y[2] == pytest.approx(a * dT * p[2], rel=1e-10)
    assert op.units == ["1", "m", "m"]


# ------------------------------------------------------------------ 7. thermal bending
BEAM_LENGTH, BEAM_WIDTH, BEAM_DEPTH = 0.1, 0.01, 0.01
#: Refinements (cells along, across, through the depth); each halves the cell size along and through the depth.
P1_BEAM_MESHES = ((20, 1, 2), (40, 1, 4), (80, 1, 8), (160, 1, 16))
P2_BEAM_MESHES = ((10, 1, 2), (20, 1, 4), (40, 1, 8))
#: For ν ≠ 0 the width is refined too; the last mesh (245 760 tetrahedra) runs in the slow suite only.
P1_GRADIENT_MESHES = ((20, 2, 2), (40, 4, 4), (80, 8, 8), (160, 16, 16))


def _beam_curvature(mesh, materials, temperature, degree):
    """Curvature −d²u_z/dx² of a free (3-2-1 mounted) beam from u_z at x = L/4, L/2, 3L/4 on the mid-line.

    The points are 2.5 depths from the ends, where the Saint-Venant end
    effects have decayed; a second difference is exact for the quadratic
    deflection of uniform bending and blind to rigid-body motion.
    """
    L, b, h = BEAM_LENGTH, BEAM_WIDTH, BEAM_DEPTH
    elastic = fea.ElasticProblem(mesh, materials, degree=degree, reference_temperature=T_REF)
    elastic.add_kinematic_mount((0, 0, 0), (L, 0, 0), (0, b, 0))
    u = elastic.displacement(temperature)
    xs = np.array([L / 4, L / 2, 3 * L / 4])
    points = np.column_stack([xs, np.full(3, b / 2), np.full(3, h / 2)])
    w = elastic.point_rows(points, "zzz") @ u.ravel()
    return -(w[0] - 2 * w[1] + w[2]) / (L / 4) ** 2


def _beam_mesh(cells, bimaterial=False):
    nx, ny, nz = cells
    region_of = (lambda c: (c[:, 2] > BEAM_DEPTH / 2).astype(int)) if bimaterial else None
    return box_mesh(np.linspace(0, BEAM_LENGTH, nx + 1), np.linspace(0, BEAM_WIDTH, ny + 1),
                    np.linspace(0, BEAM_DEPTH, nz + 1), region_of)


#: Single steel beam, 50 K hotter on top than below: κ = α ΔT / h.
GRADIENT_DT = 50.0


def gradient_beam_study(degree, meshes):
    """Relative curvature errors of a steel beam (ν = 0.3) under a linear through-depth ΔT of 50 K."""
    exact = fea.STEEL.expansion * GRADIENT_DT / BEAM_DEPTH
    errors = []
    for cells in meshes:
        mesh = _beam_mesh(cells)
        T = T_REF + GRADIENT_DT * (mesh.points[:, 2] / BEAM_DEPTH - 0.5)
        errors.append(abs(_beam_curvature(mesh, {0: fea.STEEL}, T, degree) / exact - 1.0))
    return exact, errors


#: Bimetal: steel-like bottom layer and aluminium-like top layer of equal thickness, heated
#: uniformly by 100 K.  With the same Poisson ratio in both layers the strip's interior is exactly
#: the beam of the formula, whatever its width; different ratios add a transverse coupling.
BIMETAL_DT = 100.0


def bimetal(poisson=(0.0, 0.0)):
    """The two layers' materials with Poisson ratios ``poisson`` (bottom, top)."""
    return {0: fea.Material(50, 7800, 500, 200e9, poisson[0], 12e-6, f"steel, ν = {poisson[0]}"),
            1: fea.Material(200, 2700, 900, 70e9, poisson[1], 23e-6, f"aluminium, ν = {poisson[1]}")}



def timoshenko_curvature(E1, E2, a1, a2, t1, t2, dT):
    """Curvature of a heated bimetal strip (Timoshenko 1925), 1/m; layer 1 below, layer 2 on top."""
    m, n, h = t1 / t2, E1 / E2, t1 + t2
    return 6 * (a2 - a1) * dT * (1 + m) ** 2 / (h * (3 * (1 + m) ** 2 + (1 + m * n) * (m ** 2 + 1 / (m * n))))


def bimetal_study(degree, meshes, poisson=(0.0, 0.0)):
    """Timoshenko's curvature (1/m) and the relative errors of the bimetal strip on each mesh."""
    materials = bimetal(poisson)
    s, a = materials[0], materials[1]
    exact = timoshenko_curvature(s.youngs_modulus, a.youngs_modulus, s.expansion, a.expansion,
                                 BEAM_DEPTH / 2, BEAM_DEPTH / 2, BIMETAL_DT)
    errors = []
    for cells in meshes:
        mesh = _beam_mesh(cells, bimaterial=True)
        T = np.full(mesh.n_nodes, T_REF + BIMETAL_DT)
        errors.append(abs(_beam_curvature(mesh, materials, T, degree) / exact - 1.0))
    return exact, errors


def test_timoshenko_formula_reduces_to_equal_layers_case():
    # Equal thickness and modulus: κ = 3 Δα ΔT / (2 h).
    assert timoshenko_curvature(1.0, 1.0, 0.0, 2e-5, 0.5e-2, 0.5e-2, 100.0) == pytest.approx(1.5 * 2e-3 / 1e-2)


def test_gradient_bending_p2_is_exact():
    """The exact field is quadratic and stress-free, so P2 reproduces it to round-off on any mesh."""
    _, errors = gradient_beam_study(2, P2_BEAM_MESHES[:2])
    print(f"\ngradient beam, P2 relative curvature errors: {errors}")
    assert max(errors) < 1e-8


def test_gradient_bending_p1_converges():
    """With ν = 0.3 the width must be refined with the depth (the free beam also bends across)."""
    _, errors = gradient_beam_study(1, P1_GRADIENT_MESHES[:3])
    print(f"\ngradient beam, P1 relative curvature errors: {errors}")
    assert np.all(np.diff(errors) < 0), errors
    assert errors[-1] < 0.04
    assert errors[0] > 0.1                # the coarse P1 mesh really is too stiff: the study is not vacuous


@pytest.mark.slow
def test_gradient_bending_p1_within_two_percent_on_finest_mesh():
    _, errors = gradient_beam_study(1, P1_GRADIENT_MESHES[2:])
    assert errors[1] < errors[0] and errors[1] < 0.02, errors


def test_bimetal_p2_converges_within_two_percent():
    _, errors = bimetal_study(2, P2_BEAM_MESHES)
    print(f"\nbimetal, P2 relative curvature errors: {errors}")
    # The interior solution is quadratic, so P2 reaches the formula up to the end effects
    # (~1e-7 at 2.5 depths from the ends); monotone decrease is asserted above that floor.
    floor = 1e-6
    assert all(b < a or b < floor for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 1e-6


def test_bimetal_p2_matches_timoshenko_with_equal_poisson_ratios():
    """ν = 0.3 in both layers: the formula (with E, not E/(1 − ν²)) still holds in the interior."""
    _, errors = bimetal_study(2, P2_BEAM_MESHES[1:], poisson=(0.3, 0.3))
    print(f"\nbimetal ν = 0.3, P2 relative curvature errors: {errors}")
    assert max(errors) < 1e-6
    # Different ratios couple the layers across the width, which the beam formula leaves out.
    _, unequal = bimetal_study(2, P2_BEAM_MESHES[1:2], poisson=(0.3, 0.33))
    assert unequal[0] > 1e-3


def test_bimetal_p1_converges_within_two_percent():
    _, errors = bimetal_study(1, P1_BEAM_MESHES)
    print(f"\nbimetal, P1 relative curvature errors: {errors}")
    assert np.all(np.diff(errors) < 0), errors
    assert errors[-1] < 0.02
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert orders[-1] > 1.7, orders       # P1 converges at second order, from far away


@pytest.mark.slow
def test_bimetal_p1_next_refinement():
    _, errors = bimetal_study(1, ((160, 1, 16), (320, 1, 32)))
    assert errors[1] < errors[0] / 3 and errors[1] < 0.005


# ------------------------------------------------------------------ 9. adjoint = direct
def _joined_blocks():
    """Two regions bonded mechanically but with a thermal contact joint (split thermal nodes)."""
    mesh = box_mesh(np.linspace(0, 0.4, 7), np.linspace(0, 0.2, 4), np.linspace(0, 0.15, 3),
                    region_of=lambda c: (c[:, 0] > 0.2).astype(int), jitter=0.2, seed=7)
    mesh.add_facet_group("skin", fea.Everything())
    materials = {0: fea.STEEL, 1: fea.CAST_IRON}
    problem = fea.HeatProblem(mesh, materials)
    problem.add_contact(0, 1, 1500.0)
    problem.add_convection("skin", 8.0, ambient="air")
    system = problem.assemble()
    assert system.n_nodes > mesh.n_nodes                # the joint really splits nodes
    return mesh, materials, system


SPECS = [
    fea.PointTemperature("T_probe", (0.13, 0.07, 0.05)),
    fea.PointDisplacement("ux", (0.31, 0.11, 0.09), "x"),
    fea.PointDisplacement("uz", (0.37, 0.17, 0.14), "z"),
    fea.RelativeDisplacement("tcp_y", (0.35, 0.15, 0.12), (0.05, 0.03, 0.02), "y"),
    fea.AxialStrain("fbg", (0.03, 0.05, 0.03), (0.38, 0.12, 0.11)),
]


def adjoint_direct_mismatch(degree):
    """Outputs of ``build_output_operator`` (adjoint) and of a direct solve for one non-trivial field.

    Returns (adjoint outputs, direct outputs, block-apply outputs) for :data:`SPECS`.
    """
    mesh, materials, system = _joined_blocks()
    elastic = fea.ElasticProblem(mesh, materials, degree=degree, reference_temperature=T_REF)
    elastic.add_kinematic_mount((0, 0, 0), (0.4, 0, 0), (0, 0.2, 0))
    op = fea.build_output_operator(SPECS, system, elastic)
    x = system.points
    rng = np.random.default_rng(1)
    # Non-trivial field: smooth gradients plus a different value on each side of the joint.
    T = 25 + 30 * np.sin(8 * x[:, 0]) * x[:, 1] / 0.2 + 40 * (x[:, 2] / 0.15) ** 2 + rng.normal(0, 2, len(x))
    y = op.apply(T)

    u = elastic.displacement(T, system).ravel()
    def at(point, comp):
        return float((elastic.point_rows([point], comp) @ u)[0])

    direct = [
        float((system.point_weights([SPECS[0].point]) @ T)[0]),
        at(SPECS[1].point, "x"),
        at(SPECS[2].point, "z"),
        at(SPECS[3].point, "y") - at(SPECS[3].reference, "y"),
    ]
    a, b = np.asarray(SPECS[4].start), np.asarray(SPECS[4].end)
    e = (b - a) / np.linalg.norm(b - a)
    du = np.array([at(b, c) - at(a, c) for c in "xyz"])
    direct.append(float(du @ e / np.linalg.norm(b - a)))
    return y, np.array(direct), op.apply(np.column_stack([T, T + 5.0]))[:, 0]


@pytest.mark.parametrize("degree", [1, 2])
def test_adjoint_outputs_equal_direct_solve(degree):
    y, direct, block = adjoint_direct_mismatch(degree)
    assert np.all(np.abs(direct[1:4]) > 1e-6)          # micrometres of real displacement
    assert np.abs(direct[4]) > 1e-5                     # tens of microstrain
    assert np.allclose(y, direct, rtol=1e-9, atol=0), (y, direct)
    assert np.allclose(block, y, rtol=1e-12)             # the block form of apply agrees
