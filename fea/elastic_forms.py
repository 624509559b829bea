"""The weak forms of linear thermo-elasticity on P1/P2 tetrahedra.

    a(u, v) = ∫ ε(v) : C : ε(u)  = ∫ λ div u div v + 2μ ε(u):ε(v)
    ℓ(v)    = ∫ (3λ + 2μ) α (T − T_ref) div v

Both are evaluated as batched tensor contractions over elements and
quadrature points rather than through scikit-fem's generic vector assembly:
for the same form that takes 1.3 s (P1) and 14 s (P2) on a 50k-tetrahedron
mesh there, against a fraction of a second here.  ``tests/test_fea_forms.py``
checks both against scikit-fem's ``BilinearForm`` to round-off.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

#: Elements per batch; bounds the memory of the (batch, 3nb, 3nb) element matrices.
BATCH = 8192


def _weighted_gradients(space, grad_lambda, volumes, rule):
    lam, weights = rule
    G = space.shape_gradients(lam, grad_lambda)                 # (m, q, nb, 3)
    W = volumes[:, None] * weights[None, :]                      # (m, q)
    return G, W


def elastic_stiffness(space, grad_lambda, volumes, lame_lambda, lame_mu):
    """Assemble the stiffness ``∫ λ div u div v + 2μ ε(u):ε(v)`` (3N × 3N, N/m).

    Dofs are interleaved: dof ``3·node + component``.

    Per element, with G_q the (nb, 3) shape gradients at quadrature point q
    and W_q the quadrature weight times volume,
        K[a i, b j] = Σ_q W_q (λ G_ai G_bj + μ G_aj G_bi + μ δ_ij G_a·G_b).
    """
    nb = space.nodes_per_element
    rule = space.quadrature(2 * (space.degree - 1))
    n_dof = 3 * space.n_nodes
    K = sp.csr_matrix((n_dof, n_dof))
    local = np.arange(3)
    for start in range(0, len(grad_lambda), BATCH):
        s = slice(start, start + BATCH)
        G, W = _weighted_gradients(space, grad_lambda[s], volumes[s], rule)
        e, q = W.shape
        flat = G.reshape(e, q, 3 * nb)                           # index a*3+i
        outer = np.matmul(np.transpose(flat * W[..., None], (0, 2, 1)), flat)   # Σ_q W g_ai g_bj
        swapped = outer.reshape(e, nb, 3, nb, 3).transpose(0, 1, 4, 3, 2).reshape(e, 3 * nb, 3 * nb)
        by_node = np.transpose(G, (0, 2, 1, 3)).reshape(e, nb, 3 * q)
        weights = np.repeat(W, 3, axis=1)[:, None, :]
        dots = np.matmul(by_node * weights, np.transpose(by_node, (0, 2, 1)))  # Σ_q W ∇φ_a·∇φ_b
        Ke = lame_lambda[s, None, None] * outer + lame_mu[s, None, None] * swapped
        Ke = Ke.reshape(e, nb, 3, nb, 3)
        # Advanced indices split by slices move to the front: the target is (3, e, nb, nb).
        Ke[:, :, local, :, local] += (lame_mu[s, None, None] * dots)[None]
        dofs = (3 * space.element_nodes[s][:, :, None] + local).reshape(e, 3 * nb)
        rows = np.repeat(dofs, 3 * nb, axis=1).ravel()
        cols = np.tile(dofs, (1, 3 * nb)).ravel()
        K = K + sp.csr_matrix((Ke.ravel(), (rows, cols)), shape=(n_dof, n_dof))
    return K


def thermal_load_operator(space, grad_lambda, volumes, thermal_stress_modulus, thermal_tets, n_thermal):
    """Assemble F with ``F @ (T − T_ref) = ℓ(v)``: ∫ (3λ+2μ) α ψ_c div v_(a i) (3N × n_thermal, N/K).

    ψ_c are the P1 temperature shape functions, on the thermal nodes of
    ``thermal_tets`` (which may differ from the mesh nodes at joints).
    """
    nb = space.nodes_per_element
    rule = space.quadrature(space.degree)
    lam, _ = rule
    rows, cols, vals = [], [], []
    local = np.arange(3)
    for start in range(0, len(grad_lambda), BATCH):
        s = slice(start, start + BATCH)
        G, W = _weighted_gradients(space, grad_lambda[s], volumes[s], rule)
        e = len(W)
        weighted = G * (W * thermal_stress_modulus[s, None])[..., None, None]  # (e, q, nb, 3)
        Fe = np.einsum("eqai,qc->eaic", weighted, lam).reshape(e, 3 * nb, 4)
        dofs = (3 * space.element_nodes[s][:, :, None] + local).reshape(e, 3 * nb)
        rows.append(np.repeat(dofs, 4, axis=1).ravel())
        cols.append(np.tile(thermal_tets[s], (1, 3 * nb)).ravel())
        vals.append(Fe.ravel())
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(3 * space.n_nodes, n_thermal))


def element_stress(space, grad_lambda, u, temperature_excess, lame_lambda, lame_mu, thermal_stress_modulus):
    """Mean stress tensor of each element (m, 3, 3) in Pa.

    σ = λ tr(ε) I + 2μ ε − (3λ+2μ) α ΔT I, averaged over the element with
    ``temperature_excess`` the per-tetrahedron mean of T − T_ref (K).
    """
    lam = space.quadrature(space.degree)[0]
    G = space.shape_gradients(lam, grad_lambda)                 # (m, q, nb, 3)
    U = u.reshape(-1, 3)[space.element_nodes]                    # (m, nb, 3)
    grad_u = np.einsum("mqai,maj->mqji", G, U).mean(axis=1)     # (m, 3, 3): ∂u_j/∂x_i
    strain = 0.5 * (grad_u + np.transpose(grad_u, (0, 2, 1)))
    trace = np.trace(strain, axis1=1, axis2=2)
    iso = lame_lambda * trace - thermal_stress_modulus * temperature_excess
    return 2 * lame_mu[:, None, None] * strain + iso[:, None, None] * np.eye(3)
