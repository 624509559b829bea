"""P1 and P2 Lagrange spaces on tetrahedra, written in barycentric coordinates λ.

P1: φ_i = λ_i.  P2: φ_i = λ_i (2λ_i − 1) at the vertices and φ_ij = 4 λ_i λ_j at
the edge midpoints.  Only what the elastic solver needs is here: node
numbering, shape values and gradients at points given by their barycentric
coordinates, and a degree-2 quadrature rule.
"""
from __future__ import annotations

import numpy as np

from .mesh import LOCAL_FACES

#: Local edges of a tetrahedron; P2 edge node k sits on EDGES[k].
EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])

#: Degree-2 rule on the tetrahedron (4 points, weights as fractions of the volume).
_A, _B = 0.5854101966249685, 0.1381966011250105
QUADRATURE_2 = (np.full((4, 4), _B) + np.eye(4) * (_A - _B), np.full(4, 0.25))
#: Degree-1 rule: the centroid.
QUADRATURE_1 = (np.full((1, 4), 0.25), np.ones(1))


def barycentric_gradients(points, tets):
    """∇λ_i of each tetrahedron (m, 4, 3) in 1/m, and volumes (m,) in m³."""
    X = points[tets]
    J = X[:, 1:, :] - X[:, :1, :]                  # rows: edge vectors from vertex 0
    inv = np.linalg.inv(J)                          # columns: ∇λ_1..∇λ_3
    grads = np.empty((len(tets), 4, 3))
    grads[:, 1:, :] = np.transpose(inv, (0, 2, 1))
    grads[:, 0, :] = -grads[:, 1:, :].sum(axis=1)
    return grads, np.linalg.det(J) / 6.0


class LagrangeSpace:
    """Scalar P1 or P2 nodes on a tetrahedral mesh (a vector field has 3 dofs per node).

    Attributes
    ----------
    element_nodes : (m, 4) for P1 or (m, 10) for P2 (4 vertices then the 6 edges of :data:`EDGES`)
    node_points : (n_nodes, 3) node coordinates, m
    """

    def __init__(self, points, tets, degree):
        if degree not in (1, 2):
            raise ValueError(f"degree must be 1 or 2, got {degree!r}")
        self.degree = degree
        self.points, self.tets = points, tets
        if degree == 1:
            self.element_nodes = tets
            self.node_points = points
        else:
            pairs = np.sort(tets[:, EDGES], axis=2).reshape(-1, 2)
            edges, inverse = np.unique(pairs, axis=0, return_inverse=True)
            self.edges = edges
            self.element_nodes = np.hstack([tets, len(points) + inverse.reshape(len(tets), 6)])
            self.node_points = np.vstack([points, points[edges].mean(axis=1)])
        self.n_nodes = len(self.node_points)

    @property
    def nodes_per_element(self):
        return self.element_nodes.shape[1]

    def shape_values(self, lam):
        """Shape functions at barycentric points ``lam`` (..., 4) → (..., nodes_per_element)."""
        if self.degree == 1:
            return lam
        i, j = EDGES.T
        return np.concatenate([lam * (2 * lam - 1), 4 * lam[..., i] * lam[..., j]], axis=-1)

    def shape_gradients(self, lam, grad_lambda):
        """Shape gradients at barycentric points.

        ``lam`` is (q, 4) (the same points in every element), ``grad_lambda``
        (m, 4, 3); the result is (m, q, nodes_per_element, 3) in 1/m.
        """
        m, q = len(grad_lambda), len(lam)
        if self.degree == 1:
            return np.broadcast_to(grad_lambda[:, None], (m, q, 4, 3))
        i, j = EDGES.T
        vertex = (4 * lam - 1)[None, :, :, None] * grad_lambda[:, None, :, :]
        edge = 4 * (lam[None, :, i, None] * grad_lambda[:, None, j, :]
                    + lam[None, :, j, None] * grad_lambda[:, None, i, :])
        return np.concatenate([vertex, edge], axis=2)

    def quadrature(self, integrand_degree):
        """Barycentric points and weights exact for polynomials of the given degree (≤ 2)."""
        return QUADRATURE_1 if integrand_degree <= 1 else QUADRATURE_2

    def facet_nodes(self, tet, local):
        """All nodes on boundary facets (vertices, and edge midpoints for P2)."""
        tet, local = np.asarray(tet), np.asarray(local)
        vertices = LOCAL_FACES[local]                           # (k, 3) local vertices
        nodes = [self.element_nodes[tet[:, None], vertices]]
        if self.degree == 2:
            # The face opposite vertex f holds the three edges not touching f.
            touches = (EDGES[None, :, 0] == local[:, None]) | (EDGES[None, :, 1] == local[:, None])
            edge_local = np.argwhere(~touches)[:, 1].reshape(len(tet), 3)
            nodes.append(self.element_nodes[tet[:, None], 4 + edge_local])
        return np.unique(np.concatenate([n.ravel() for n in nodes]))
