"""The fast elastic kernels equal scikit-fem's generic assembly of the same weak forms, to round-off."""
import numpy as np
import pytest
import skfem
from scipy.spatial import cKDTree
from skfem.helpers import ddot, div, sym_grad, trace

import fea
from fea.elastic_forms import elastic_stiffness
from fea.lagrange import LagrangeSpace, barycentric_gradients

STEEL = fea.Material(45.0, 7850.0, 470.0, 210e9, 0.3, 11.5e-6, "steel")
IRON = fea.Material(48.0, 7200.0, 500.0, 110e9, 0.26, 10.5e-6, "iron")


def _mesh():
    m = skfem.MeshTet.init_tensor(np.linspace(0, 0.3, 4), np.linspace(0, 0.2, 3), np.linspace(0, 0.1, 3))
    # Distort the nodes so no element is a scaled copy of another.
    p = m.p.T + 0.004 * np.sin(37 * m.p.T[:, [1, 2, 0]])
    centroids = p[m.t.T].mean(axis=1)
    regions = (centroids[:, 0] > 0.15).astype(int)
    return fea.TetMesh.from_arrays(p, m.t.T, regions)


def _skfem_basis(mesh, degree):
    element = skfem.ElementTetP1() if degree == 1 else skfem.ElementTetP2()
    skmesh = skfem.MeshTet(mesh.points.T.copy(), mesh.tets.T.copy())
    vector = skfem.Basis(skmesh, skfem.ElementVector(element), intorder=2 * degree)
    scalar = skfem.Basis(skmesh, skfem.ElementTetP1(), intorder=2 * degree)
    return vector, scalar


def _our_dofs(space, vector):
    """Our interleaved dof index (3·node + component) of every scikit-fem dof."""
    tree = cKDTree(space.node_points)
    order = np.empty(vector.N, dtype=np.int64)
    for component, dofs in enumerate(vector.split_indices()):
        distance, node = tree.query(vector.doflocs[:, dofs].T)
        assert distance.max() < 1e-12
        order[dofs] = 3 * node + component
    return order


def _per_element(mesh, vector, attribute):
    values = np.where(mesh.regions == 1, getattr(IRON, attribute), getattr(STEEL, attribute))
    return np.repeat(values[:, None], vector.X.shape[-1], axis=1)


@pytest.mark.parametrize("degree", [1, 2])
def test_stiffness_equals_skfem_bilinear_form(degree):
    mesh = _mesh()
    space = LagrangeSpace(mesh.points, mesh.tets, degree)
    grads, volumes = barycentric_gradients(mesh.points, mesh.tets)
    lam = np.array([(IRON if r else STEEL).lame[0] for r in mesh.regions])
    mu = np.array([(IRON if r else STEEL).lame[1] for r in mesh.regions])
    ours = elastic_stiffness(space, grads, volumes, lam, mu).toarray()

    @skfem.BilinearForm
    def linear_elasticity(u, v, w):
        eps_u, eps_v = sym_grad(u), sym_grad(v)
        return w.lame_lambda * trace(eps_u) * trace(eps_v) + 2 * w.lame_mu * ddot(eps_u, eps_v)

    vector, _ = _skfem_basis(mesh, degree)
    lam_q = np.repeat(lam[:, None], vector.X.shape[-1], axis=1)
    mu_q = np.repeat(mu[:, None], vector.X.shape[-1], axis=1)
    reference = linear_elasticity.assemble(vector, lame_lambda=lam_q, lame_mu=mu_q).toarray()
    order = _our_dofs(space, vector)
    mapped = ours[np.ix_(order, order)]
    assert np.abs(mapped - reference).max() <= 1e-12 * np.abs(reference).max()


@pytest.mark.parametrize("degree", [1, 2])
def test_thermal_load_equals_skfem_mixed_form(degree):
    mesh = _mesh()
    problem = fea.ElasticProblem(mesh, {0: STEEL, 1: IRON}, degree=degree)
    F = problem.thermal_load_operator()
    rng = np.random.default_rng(0)
    dT = rng.normal(size=mesh.n_nodes)

    @skfem.BilinearForm
    def thermal_load(T, v, w):
        return w.modulus * T * div(v)

    vector, scalar = _skfem_basis(mesh, degree)
    modulus = _per_element(mesh, vector, "thermal_stress_modulus")
    reference = thermal_load.assemble(scalar, vector, modulus=modulus) @ dT
    order = _our_dofs(problem.space, vector)
    ours = (F @ dT)[order]
    assert np.abs(ours - reference).max() <= 1e-12 * np.abs(reference).max()
