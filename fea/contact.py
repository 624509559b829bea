"""Zero-thickness thermal contact between regions: node splitting and interface conductance.

A bolted or guided joint conducts heat through a contact conductance
h_c (W/(m² K)): the flux across it is ``q = h_c (T_a - T_b)``.  Instead of a
thin layer of tetrahedra with ``k = h_c · t`` (which forces tiny elements), the
mesh stays conforming, the nodes on a joint interface are duplicated for the
temperature field only, and the two sides are coupled by the interface form

    ∫_Γ h_c (T_a - T_b)(v_a - v_b) dS.

Mechanically the parts stay bonded: the elastic field uses the unsplit mesh.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .errors import FEAInputError, require_positive
from .mesh import LOCAL_FACES, TetMesh


@dataclass(frozen=True)
class Joint:
    """A contact interface between two regions with conductance in W/(m² K)."""

    region_a: object
    region_b: object
    conductance: float

    def __post_init__(self):
        require_positive(f"contact conductance between {self.region_a!r} and {self.region_b!r}",
                         self.conductance)


def joint_facets(mesh: TetMesh, joints: list[Joint]) -> list[tuple]:
    """The interface facet pairs of each joint.

    Parameters
    ----------
    mesh : TetMesh
        The mesh and its regions.
    joints : list of Joint
        Region pairs and contact conductances.

    Returns
    -------
    list of tuple
        Per joint ``(tet_a, local_a, tet_b, local_b, h_c)``: facet arrays of each side and h_c in W/(m² K).
    """
    ta, la, tb, lb = mesh.interface_facets()
    out = []
    for joint in joints:
        ra, rb = mesh.region_id(joint.region_a), mesh.region_id(joint.region_b)
        fwd = (mesh.regions[ta] == ra) & (mesh.regions[tb] == rb)
        rev = (mesh.regions[ta] == rb) & (mesh.regions[tb] == ra)
        if not (fwd.any() or rev.any()):
            raise FEAInputError(
                f"joint between regions {joint.region_a!r} and {joint.region_b!r}: the regions share no facet"
            )
        out.append((np.concatenate([ta[fwd], tb[rev]]), np.concatenate([la[fwd], lb[rev]]),
                    np.concatenate([tb[fwd], ta[rev]]), np.concatenate([lb[fwd], la[rev]]),
                    joint.conductance))
    return out


def split_nodes(mesh: TetMesh, pairs: list[tuple]) -> tuple[np.ndarray, np.ndarray]:
    """Thermal connectivity with the nodes on joint facets duplicated per side.

    Each (tetrahedron, local vertex) incidence is a graph vertex; incidences of
    the same mesh node in two face-neighbouring tetrahedra are joined unless
    the shared face is a joint facet.  Each connected component becomes one
    thermal node.

    Parameters
    ----------
    mesh : TetMesh
        The mesh.
    pairs : list of tuple
        From :func:`joint_facets`.

    Returns
    -------
    thermal_tets : ndarray of int, shape (m, 4)
        Connectivity in thermal-node numbering.
    node_of : ndarray of int, shape (n_thermal,)
        The mesh node of each thermal node.
    """
    m = mesh.n_tets
    tet, local, _, interior = mesh._face_pairs()
    a, b = interior
    joint = np.zeros(len(a), bool)
    if pairs:
        jt = np.concatenate([np.concatenate([p[0], p[2]]) for p in pairs])
        jl = np.concatenate([np.concatenate([p[1], p[3]]) for p in pairs])
        joint_codes = np.unique(jt * 4 + jl)
        joint = np.isin(tet[a] * 4 + local[a], joint_codes)
    a, b = a[~joint], b[~joint]
    ta, tb = tet[a], tet[b]
    na = mesh.tets[ta[:, None], LOCAL_FACES[local[a]]]            # (k, 3) mesh nodes
    pos_a = np.argmax(mesh.tets[ta][:, None, :] == na[:, :, None], axis=2)
    pos_b = np.argmax(mesh.tets[tb][:, None, :] == na[:, :, None], axis=2)
    rows = (ta[:, None] * 4 + pos_a).ravel()
    cols = (tb[:, None] * 4 + pos_b).ravel()
    graph = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(4 * m, 4 * m))
    _, label = connected_components(graph, directed=False)
    mesh_node = mesh.tets.ravel()
    # Number thermal nodes by (mesh node, component) so an unsplit mesh keeps its numbering.
    order = np.lexsort((label, mesh_node))
    key = np.column_stack([mesh_node[order], label[order]])
    new = np.r_[True, np.any(key[1:] != key[:-1], axis=1)]
    ids = np.cumsum(new) - 1
    thermal = np.empty(4 * m, dtype=np.int64)
    thermal[order] = ids
    node_of = mesh_node[order][new]
    return thermal.reshape(m, 4), node_of


def interface_matrix(mesh: TetMesh, pairs: list[tuple], thermal_tets: np.ndarray, n_thermal: int) -> sp.csr_matrix:
    """Assemble ∫_Γ h_c (T_a − T_b)(v_a − v_b) dS over all joint facets.

    On a linear triangle of area A the facet mass matrix is A/12·(1 + δ_ij),
    so each facet contributes that block times h_c to the (a, a) and (b, b)
    couplings and its negative to (a, b) and (b, a).

    Parameters
    ----------
    mesh : TetMesh
        The mesh.
    pairs : list of tuple
        From :func:`joint_facets`.
    thermal_tets : ndarray of int, shape (m, 4)
        Connectivity in thermal-node numbering.
    n_thermal : int
        Number of thermal nodes.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (n_thermal, n_thermal)
        W/K.
    """
    rows, cols, vals = [], [], []
    local_mass = (np.ones((3, 3)) + np.eye(3)) / 12.0
    for tet_a, loc_a, tet_b, loc_b, h_c in pairs:
        _, _, area = mesh.facet_geometry(tet_a, loc_a)
        side_a = thermal_tets[tet_a[:, None], LOCAL_FACES[loc_a]]
        mesh_a = mesh.tets[tet_a[:, None], LOCAL_FACES[loc_a]]
        pos_b = np.argmax(mesh.tets[tet_b][:, None, :] == mesh_a[:, :, None], axis=2)
        side_b = np.take_along_axis(thermal_tets[tet_b], pos_b, axis=1)
        block = h_c * area[:, None, None] * local_mass
        for first, second, sign in ((side_a, side_a, 1), (side_b, side_b, 1),
                                    (side_a, side_b, -1), (side_b, side_a, -1)):
            rows.append(np.repeat(first, 3, axis=1).ravel())
            cols.append(np.tile(second, (1, 3)).ravel())
            vals.append(sign * block.ravel())
    if not rows:
        return sp.csr_matrix((n_thermal, n_thermal))
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(n_thermal, n_thermal))
