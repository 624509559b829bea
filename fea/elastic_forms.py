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

from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

if TYPE_CHECKING:
    from .lagrange import LagrangeSpace

#: Elements per batch; bounds the memory of the (batch, 3nb, 3nb) element matrices.
BATCH = 8192
#: Entries of element matrices per batch in the stiffness assembly (16 MB of float64).
BATCH_ENTRIES = 2 ** 21


def _weighted_gradients(space, grad_lambda, volumes, rule):
    lam, weights = rule
    G = space.shape_gradients(lam, grad_lambda)                 # (m, q, nb, 3)
    W = volumes[:, None] * weights[None, :]                      # (m, q)
    return G, W


def _element_stiffness(space, grad_lambda, volumes, lame_lambda, lame_mu, rule):
    """Element matrices (e, nb, 3, nb, 3) of ``λ div u div v + 2μ ε(u):ε(v)`` for one batch."""
    nb = space.nodes_per_element
    G, W = _weighted_gradients(space, grad_lambda, volumes, rule)
    e, q = W.shape
    flat = G.reshape(e, q, 3 * nb)                               # index a*3+i
    outer = np.matmul(np.transpose(flat * W[..., None], (0, 2, 1)), flat)   # Σ_q W g_ai g_bj
    swapped = outer.reshape(e, nb, 3, nb, 3).transpose(0, 1, 4, 3, 2).reshape(e, 3 * nb, 3 * nb)
    by_node = np.transpose(G, (0, 2, 1, 3)).reshape(e, nb, 3 * q)
    weights = np.repeat(W, 3, axis=1)[:, None, :]
    dots = np.matmul(by_node * weights, np.transpose(by_node, (0, 2, 1)))  # Σ_q W ∇φ_a·∇φ_b
    Ke = lame_lambda[:, None, None] * outer + lame_mu[:, None, None] * swapped
    Ke = Ke.reshape(e, nb, 3, nb, 3)
    local = np.arange(3)
    # Advanced indices split by slices move to the front: the target is (3, e, nb, nb).
    Ke[:, :, local, :, local] += (lame_mu[:, None, None] * dots)[None]
    return Ke


def node_pairs(element_nodes: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The node graph of a mesh: every unordered pair of distinct nodes sharing an element.

    Parameters
    ----------
    element_nodes : ndarray of int, shape (m, nb)
        Nodes of each element.
    n_nodes : int
        Number of nodes.

    Returns
    -------
    pairs : ndarray of int, shape (E, 2)
        Sorted with ``pairs[:, 0] < pairs[:, 1]``, lexicographically ordered.
    inverse : ndarray of int, shape (m, nb(nb−1)/2)
        For the local pairs ``(a, b) = np.triu_indices(nb, 1)`` of each element, the row of ``pairs``.
    flipped : ndarray of bool, shape (m, nb(nb−1)/2)
        Whether the element's node ``a`` is the larger of the two.
    """
    nb = element_nodes.shape[1]
    la, lb = np.triu_indices(nb, 1)
    first, second = element_nodes[:, la], element_nodes[:, lb]
    flipped = first > second
    lo = np.where(flipped, second, first).astype(np.int64)
    hi = np.where(flipped, first, second).astype(np.int64)
    keys, inverse = np.unique((lo * n_nodes + hi).ravel(), return_inverse=True)
    pairs = np.column_stack([keys // n_nodes, keys % n_nodes])
    return pairs, inverse.reshape(lo.shape), flipped


def block_symmetric_matrix(n_nodes: int, pairs: np.ndarray, diagonal_blocks: np.ndarray, upper_blocks: np.ndarray,
                           block: int = 3) -> sp.csr_matrix:
    """Assemble a symmetric node-block matrix as CSR from its diagonal and upper blocks.

    ``diagonal_blocks`` (N, b, b) sit at (i, i); ``upper_blocks`` (E, b, b)
    at ``(pairs[k, 0], pairs[k, 1])`` with their transposes mirrored below.
    ``pairs`` must be sorted as :func:`node_pairs` returns them, so the block
    layout is found by counting, without a sort of the entries.

    Parameters
    ----------
    n_nodes : int
        Number of nodes N.
    pairs : ndarray of int, shape (E, 2)
        From :func:`node_pairs`.
    diagonal_blocks : ndarray, shape (N, b, b)
        The blocks at (i, i).
    upper_blocks : ndarray, shape (E, b, b)
        The blocks at ``(pairs[k, 0], pairs[k, 1])``.
    block : int
        Block size b.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (bN, bN)
        The symmetric matrix.
    """
    rows, cols = pairs[:, 0], pairs[:, 1]
    n_upper = np.bincount(rows, minlength=n_nodes)
    n_lower = np.bincount(cols, minlength=n_nodes)
    indptr = np.zeros(n_nodes + 1, dtype=np.int64)
    np.cumsum(n_lower + 1 + n_upper, out=indptr[1:])
    E = len(pairs)
    # Upper blocks: already ordered by (row, col).
    start_u = np.cumsum(n_upper) - n_upper
    pos_u = indptr[rows] + n_lower[rows] + 1 + (np.arange(E) - start_u[rows])
    # Lower blocks (col, row): a stable sort by their row keeps the columns ascending.
    order = np.argsort(cols, kind="stable")
    start_l = np.cumsum(n_lower) - n_lower
    lower_rows = cols[order]
    pos_l = np.empty(E, dtype=np.int64)
    pos_l[order] = indptr[lower_rows] + (np.arange(E) - start_l[lower_rows])
    pos_d = indptr[:-1] + n_lower
    nnzb = int(indptr[-1])
    indices = np.empty(nnzb, dtype=np.int64)
    indices[pos_u], indices[pos_l], indices[pos_d] = cols, rows, np.arange(n_nodes)
    data = np.empty((nnzb, block, block))
    data[pos_u] = upper_blocks
    data[pos_l] = np.transpose(upper_blocks, (0, 2, 1))
    data[pos_d] = diagonal_blocks
    size = block * n_nodes
    return sp.bsr_matrix((data, indices, indptr), shape=(size, size)).tocsr()


def elastic_stiffness(space: LagrangeSpace, grad_lambda: np.ndarray, volumes: np.ndarray, lame_lambda: np.ndarray,
                      lame_mu: np.ndarray) -> sp.csr_matrix:
    """Assemble the stiffness ``∫ λ div u div v + 2μ ε(u):ε(v)`` (3N × 3N CSR, N/m).

    Dofs are interleaved: dof ``3·node + component``.

    Per element, with G_q the (nb, 3) shape gradients at quadrature point q
    and W_q the quadrature weight times volume,
        K[a i, b j] = Σ_q W_q (λ G_ai G_bj + μ G_aj G_bi + μ δ_ij G_a·G_b).

    The 3×3 node blocks are summed per node pair with ``bincount`` on a
    precomputed node graph (:func:`node_pairs`), which avoids sorting the
    9·nb² entries per element that a COO → CSR conversion would.

    Parameters
    ----------
    space : LagrangeSpace
        The displacement space (P1 or P2).
    grad_lambda : ndarray, shape (m, 4, 3)
        Barycentric gradients, 1/m.
    volumes : ndarray, shape (m,)
        Tetrahedron volumes, m³.
    lame_lambda, lame_mu : ndarray, shape (m,)
        Lamé parameters of each tetrahedron, Pa.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (3N, 3N)
        K, N/m.
    """
    # About 60 lines: the P1 fast path and the batched general path fill the same block arrays
    # (upper, diagonal), which the shared tail symmetrises; the hot path of every elastic solve.
    nb = space.nodes_per_element
    n = space.n_nodes
    rule = space.quadrature(2 * (space.degree - 1))
    pairs, inverse, flipped = node_pairs(space.element_nodes, n)
    la, lb = np.triu_indices(nb, 1)
    E = len(pairs)
    upper = np.zeros((3, 3, E))
    diagonal = np.zeros((3, 3, n))
    if space.degree == 1:
        # Constant gradients: the blocks are V (λ g_a g_bᵀ + μ g_b g_aᵀ + μ g_a·g_b I), formed per
        # node pair directly; a flipped pair is the transposed block, i.e. a and b swapped.
        ga, gb = grad_lambda[:, la], grad_lambda[:, lb]                          # (m, 6, 3)
        first = np.where(flipped[..., None], gb, ga)
        second = np.where(flipped[..., None], ga, gb)
        vl, vm = (volumes * lame_lambda)[:, None], (volumes * lame_mu)[:, None]
        dot = vm * np.einsum("mpi,mpi->mp", ga, gb)
        idx = inverse.ravel()
        g = grad_lambda
        gdot = (volumes * lame_mu)[:, None] * np.einsum("mai,mai->ma", g, g)
        nodes = space.element_nodes.ravel()
        for i in range(3):
            for j in range(3):
                w = vl * first[..., i] * second[..., j] + vm * second[..., i] * first[..., j]
                if i == j:
                    w += dot
                upper[i, j] = np.bincount(idx, weights=w.ravel(), minlength=E)
                if j >= i:
                    d = (vl + vm) * g[..., i] * g[..., j] + (gdot if i == j else 0.0)
                    diagonal[i, j] = np.bincount(nodes, weights=d.ravel(), minlength=n)
        for i in range(3):
            for j in range(i):
                diagonal[i, j] = diagonal[j, i]
        return block_symmetric_matrix(n, pairs, np.moveaxis(diagonal, -1, 0), np.moveaxis(upper, -1, 0))
    batch = max(256, BATCH_ENTRIES // (9 * nb * nb))
    for start in range(0, len(grad_lambda), batch):
        s = slice(start, start + batch)
        Ke = _element_stiffness(space, grad_lambda[s], volumes[s], lame_lambda[s], lame_mu[s], rule)
        off = Ke[:, la, :, lb, :]                                # (pairs, e, 3, 3): advanced dims first
        flip = flipped[s].T[..., None, None]
        off = np.where(flip, np.swapaxes(off, -1, -2), off)
        idx = inverse[s].T.ravel()
        a = np.arange(nb)
        diag = Ke[:, a, :, a, :]                                 # (nb, e, 3, 3)
        nodes = space.element_nodes[s].T.ravel()
        for i in range(3):
            for j in range(3):
                upper[i, j] += np.bincount(idx, weights=off[..., i, j].ravel(), minlength=E)
                if j >= i:
                    diagonal[i, j] += np.bincount(nodes, weights=diag[..., i, j].ravel(), minlength=n)
    for i in range(3):
        for j in range(i):
            diagonal[i, j] = diagonal[j, i]
    return block_symmetric_matrix(n, pairs, np.moveaxis(diagonal, -1, 0), np.moveaxis(upper, -1, 0))


def thermal_load_operator(space: LagrangeSpace, grad_lambda: np.ndarray, volumes: np.ndarray,
                          thermal_stress_modulus: np.ndarray, thermal_tets: np.ndarray,
                          n_thermal: int) -> sp.csr_matrix:
    """Assemble F with ``F @ (T − T_ref) = ℓ(v)``: ∫ (3λ+2μ) α ψ_c div v_(a i) (3N × n_thermal, N/K).

    ψ_c are the P1 temperature shape functions, on the thermal nodes of
    ``thermal_tets`` (which may differ from the mesh nodes at joints).

    Parameters
    ----------
    space : LagrangeSpace
        The displacement space (P1 or P2).
    grad_lambda : ndarray, shape (m, 4, 3)
        Barycentric gradients, 1/m.
    volumes : ndarray, shape (m,)
        Tetrahedron volumes, m³.
    thermal_stress_modulus : ndarray, shape (m,)
        (3λ+2μ) α of each tetrahedron, Pa/K.
    thermal_tets : ndarray of int, shape (m, 4)
        Connectivity in thermal-node numbering.
    n_thermal : int
        Number of thermal nodes.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (3N, n_thermal)
        F, N/K.
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


class ThermalLoadOperator:
    """Matrix-free F (3N × n_thermal, N/K) with ``F @ (T − T_ref)`` the thermal load vector.

    Behaves like the assembled :func:`thermal_load_operator` for products:
    ``F @ x`` and ``F.T @ z`` for vectors or (·, k) blocks, ``Z.T @ F`` and
    ``tocsr()`` when the matrix itself is wanted.  Each product is one
    gather and one ``bincount`` scatter over the elements, cheaper than
    assembling F when only a few products are needed (the adjoint
    influence needs one transposed block product).

    Parameters
    ----------
    space, grad_lambda, volumes, thermal_stress_modulus, thermal_tets, n_thermal
        As :func:`thermal_load_operator`.
    """

    __array_ufunc__ = None        # let ``ndarray @ F`` defer to __rmatmul__

    def __init__(self, space: LagrangeSpace, grad_lambda: np.ndarray, volumes: np.ndarray,
                 thermal_stress_modulus: np.ndarray, thermal_tets: np.ndarray, n_thermal: int) -> None:
        self.space = space
        self.grad_lambda, self.volumes = grad_lambda, volumes
        self.modulus = thermal_stress_modulus
        self.thermal_tets = np.asarray(thermal_tets)
        self.n_thermal = int(n_thermal)
        self.shape = (3 * space.n_nodes, self.n_thermal)
        self.dtype = np.dtype(float)
        self._rule = space.quadrature(space.degree)

    # ------------------------------------------------------------------ kernels
    def _batches(self):
        """Per batch: element slice and Wκ-weighted shape gradients (e, q, nb, 3)."""
        if self.space.degree == 1:
            # Constant gradients, and Σ_q W λ_c = V/4 exactly: one "quadrature point" at the centroid.
            yield slice(None), ((self.volumes * self.modulus)[:, None, None] * self.grad_lambda)[:, None]
            return
        for start in range(0, len(self.grad_lambda), BATCH):
            s = slice(start, start + BATCH)
            G, W = _weighted_gradients(self.space, self.grad_lambda[s], self.volumes[s], self._rule)
            yield s, G * (W * self.modulus[s, None])[..., None, None]

    def _lam(self):
        return np.full((1, 4), 0.25) if self.space.degree == 1 else self._rule[0]

    def _forward(self, X):
        """F @ X for X (n_thermal, k) → (3N, k)."""
        lam = self._lam()
        out = np.zeros((self.shape[0], X.shape[1]))
        for s, WG in self._batches():
            tets = self.thermal_tets[s]
            dofs = (3 * self.space.element_nodes[s][:, :, None] + np.arange(3)).ravel()
            for k in range(X.shape[1]):
                xq = X[tets, k] @ lam.T                                 # (e, q)
                load = np.einsum("eqai,eq->eai", WG, xq)
                out[:, k] += np.bincount(dofs, weights=load.ravel(), minlength=self.shape[0])
        return out

    def _transposed(self, Z):
        """Fᵀ @ Z for Z (3N, k) → (n_thermal, k)."""
        lam = self._lam()
        out = np.zeros((self.n_thermal, Z.shape[1]))
        nodes = self.space.element_nodes
        for s, WG in self._batches():
            tets = self.thermal_tets[s].ravel()
            for k in range(Z.shape[1]):
                ze = Z[:, k].reshape(-1, 3)[nodes[s]]                   # (e, nb, 3)
                div = np.einsum("eqai,eai->eq", WG, ze)                  # W κ div z at each point
                out[:, k] += np.bincount(tets, weights=(div @ lam).ravel(), minlength=self.n_thermal)
        return out

    # ------------------------------------------------------------------ operator protocol
    def _apply(self, other, transpose):
        dense = np.asarray(other.toarray() if sp.issparse(other) else other, dtype=float)
        expect = self.shape[0] if transpose else self.shape[1]
        if dense.shape[0] != expect:
            raise ValueError(f"dimension mismatch: operator {self.shape}{'ᵀ' if transpose else ''} "
                             f"and operand {dense.shape}")
        block = dense.reshape(expect, -1)
        out = self._transposed(block) if transpose else self._forward(block)
        return out.reshape((out.shape[0],) + dense.shape[1:])

    def __matmul__(self, other):
        return self._apply(other, transpose=False)

    def __rmatmul__(self, other):
        """``Y @ F`` = (Fᵀ Yᵀ)ᵀ for Y (k, 3N) or (3N,)."""
        other = other.toarray() if sp.issparse(other) else np.asarray(other, dtype=float)
        return self._apply(other.T, transpose=True).T

    def dot(self, other: np.ndarray) -> np.ndarray:
        """``F @ other``, as scipy's ``dot``.

        Parameters
        ----------
        other : ndarray, shape (n_thermal,) or (n_thermal, k)
            Temperature excess over T_ref, K.

        Returns
        -------
        ndarray
            Load, N.
        """
        return self @ other

    @property
    def T(self) -> _Transposed:
        """Fᵀ, matrix-free."""
        return _Transposed(self)

    def tocsr(self) -> sp.csr_matrix:
        """The assembled sparse matrix.

        Returns
        -------
        scipy.sparse.csr_matrix
            F, N/K.
        """
        return thermal_load_operator(self.space, self.grad_lambda, self.volumes, self.modulus,
                                     self.thermal_tets, self.n_thermal)

    def toarray(self) -> np.ndarray:
        """The assembled matrix, dense.

        Returns
        -------
        ndarray
            F, N/K.
        """
        return self.tocsr().toarray()


class _Transposed:
    """Fᵀ of a :class:`ThermalLoadOperator`."""

    __array_ufunc__ = None

    def __init__(self, op):
        self._op = op
        self.shape = op.shape[::-1]
        self.dtype = op.dtype

    def __matmul__(self, other):
        return self._op._apply(other, transpose=True)

    def __rmatmul__(self, other):
        other = other.toarray() if sp.issparse(other) else np.asarray(other, dtype=float)
        return self._op._apply(other.T, transpose=False).T

    def dot(self, other):
        return self @ other

    @property
    def T(self):
        return self._op

    def tocsr(self):
        return self._op.tocsr().T.tocsr()

    def toarray(self):
        return self.tocsr().toarray()


def element_stress(space: LagrangeSpace, grad_lambda: np.ndarray, u: np.ndarray, temperature_excess: np.ndarray,
                   lame_lambda: np.ndarray, lame_mu: np.ndarray, thermal_stress_modulus: np.ndarray) -> np.ndarray:
    """Mean stress tensor of each element: σ = λ tr(ε) I + 2μ ε − (3λ+2μ) α ΔT I, averaged over the element.

    Parameters
    ----------
    space : LagrangeSpace
        The displacement space.
    grad_lambda : ndarray, shape (m, 4, 3)
        Barycentric gradients, 1/m.
    u : ndarray, shape (3N,)
        Displacement, m.
    temperature_excess : ndarray, shape (m,)
        Per-tetrahedron mean of T − T_ref, K.
    lame_lambda, lame_mu : ndarray, shape (m,)
        Lamé parameters, Pa.
    thermal_stress_modulus : ndarray, shape (m,)
        (3λ+2μ) α, Pa/K.

    Returns
    -------
    ndarray, shape (m, 3, 3)
        Stress, Pa.
    """
    lam = space.quadrature(space.degree)[0]
    G = space.shape_gradients(lam, grad_lambda)                 # (m, q, nb, 3)
    U = u.reshape(-1, 3)[space.element_nodes]                    # (m, nb, 3)
    grad_u = np.einsum("mqai,maj->mqji", G, U).mean(axis=1)     # (m, 3, 3): ∂u_j/∂x_i
    strain = 0.5 * (grad_u + np.transpose(grad_u, (0, 2, 1)))
    trace = np.trace(strain, axis1=1, axis2=2)
    iso = lame_lambda * trace - thermal_stress_modulus * temperature_excess
    return 2 * lame_mu[:, None, None] * strain + iso[:, None, None] * np.eye(3)
