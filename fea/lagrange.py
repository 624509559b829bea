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


def barycentric_gradients(points: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradients of the barycentric coordinates, and volumes, of each tetrahedron.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Node coordinates, m.
    tets : ndarray of int, shape (m, 4)
        Connectivity.

    Returns
    -------
    grad_lambda : ndarray, shape (m, 4, 3)
        ∇λ_i, 1/m.
    volumes : ndarray, shape (m,)
        Signed volumes, m³.
    """
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

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Mesh vertices, m.
    tets : ndarray of int, shape (m, 4)
        Connectivity.
    degree : int
        1 or 2.
    """

    def __init__(self, points: np.ndarray, tets: np.ndarray, degree: int) -> None:
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
    def nodes_per_element(self) -> int:
        """4 for P1, 10 for P2."""
        return self.element_nodes.shape[1]

    def shape_values(self, lam: np.ndarray) -> np.ndarray:
        """Shape functions at barycentric points.

        Parameters
        ----------
        lam : ndarray, shape (..., 4)
            Barycentric coordinates.

        Returns
        -------
        ndarray, shape (..., nodes_per_element)
            Shape function values.
        """
        if self.degree == 1:
            return lam
        i, j = EDGES.T
        return np.concatenate([lam * (2 * lam - 1), 4 * lam[..., i] * lam[..., j]], axis=-1)

    def shape_gradients(self, lam: np.ndarray, grad_lambda: np.ndarray) -> np.ndarray:
        """Shape gradients at barycentric points.

        Parameters
        ----------
        lam : ndarray, shape (q, 4)
            The same points in every element.
        grad_lambda : ndarray, shape (m, 4, 3)
            From :func:`barycentric_gradients`, 1/m.

        Returns
        -------
        ndarray, shape (m, q, nodes_per_element, 3)
            Gradients, 1/m.
        """
        m, q = len(grad_lambda), len(lam)
        if self.degree == 1:
            return np.broadcast_to(grad_lambda[:, None], (m, q, 4, 3))
        i, j = EDGES.T
        vertex = (4 * lam - 1)[None, :, :, None] * grad_lambda[:, None, :, :]
        edge = 4 * (lam[None, :, i, None] * grad_lambda[:, None, j, :]
                    + lam[None, :, j, None] * grad_lambda[:, None, i, :])
        return np.concatenate([vertex, edge], axis=2)

    def quadrature(self, integrand_degree: int) -> tuple[np.ndarray, np.ndarray]:
        """A quadrature rule on the reference tetrahedron.

        Parameters
        ----------
        integrand_degree : int
            Degree of the polynomial to integrate exactly (≤ 2).

        Returns
        -------
        points : ndarray, shape (q, 4)
            Barycentric points.
        weights : ndarray, shape (q,)
            Summing to 1 (multiply by the volume).
        """
        return QUADRATURE_1 if integrand_degree <= 1 else QUADRATURE_2

    def facet_nodes(self, tet: np.ndarray, local: np.ndarray) -> np.ndarray:
        """All nodes on some facets (vertices, and edge midpoints for P2).

        Parameters
        ----------
        tet, local : ndarray of int
            Tetrahedron and local face of each facet.

        Returns
        -------
        ndarray of int
            Sorted unique node ids.
        """
        tet, local = np.asarray(tet), np.asarray(local)
        vertices = LOCAL_FACES[local]                           # (k, 3) local vertices
        nodes = [self.element_nodes[tet[:, None], vertices]]
        if self.degree == 2:
            # The face opposite vertex f holds the three edges not touching f.
            touches = (EDGES[None, :, 0] == local[:, None]) | (EDGES[None, :, 1] == local[:, None])
            edge_local = np.argwhere(~touches)[:, 1].reshape(len(tet), 3)
            nodes.append(self.element_nodes[tet[:, None], 4 + edge_local])
        return np.unique(np.concatenate([n.ravel() for n in nodes]))
