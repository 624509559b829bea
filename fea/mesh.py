"""A labelled linear tetrahedral mesh with region ids and named boundary facet groups.

Coordinates are in metres.  Every tetrahedron carries a region id (a material
or a machine part).  Boundary facets are addressed as (tetrahedron, local face)
pairs, so a facet group survives any renumbering of the nodes, such as the node
splitting that the contact model does at joints.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .errors import FEAInputError

if TYPE_CHECKING:
    import meshio
    import pyvista as pv

    from .selection import Selector

#: Local faces of a positively oriented tetrahedron (a, b, c, d), each ordered
#: so that its right-hand normal points out of the tetrahedron.  Face ``f`` is
#: opposite local vertex ``f``.
LOCAL_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])

#: Volume below which a tetrahedron counts as degenerate, relative to the cube
#: of its longest edge.  A regular tetrahedron has 0.118; 1e-9 only rejects
#: slivers that make the Jacobian numerically singular.
DEGENERATE_RELATIVE_VOLUME = 1e-9


def signed_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """The signed volume of each tetrahedron.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Coordinates, m.
    tets : ndarray of int, shape (m, 4)
        Connectivity.

    Returns
    -------
    ndarray, shape (m,)
        Volume, m³ (positive for VTK ordering).
    """
    a, b, c, d = (points[tets[:, i]] for i in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


@dataclass
class TetMesh:
    """Linear tetrahedral mesh.

    Parameters
    ----------
    points : (n_nodes, 3) float array, m
    tets : (n_tets, 4) int array, positively oriented
    regions : (n_tets,) int array, region id of each tetrahedron
    region_names : optional mapping region id -> name
    """

    points: np.ndarray
    tets: np.ndarray
    regions: np.ndarray
    region_names: dict = field(default_factory=dict)
    facet_groups: dict = field(default_factory=dict)

    # ------------------------------------------------------------ construction
    @classmethod
    def from_arrays(cls, points: np.ndarray, tets: np.ndarray, regions: np.ndarray | None = None,
                    region_names: dict[int, str] | None = None) -> TetMesh:
        """Build a mesh from plain arrays, reorienting inverted tetrahedra.

        Parameters
        ----------
        points : ndarray, shape (n, 3)
            Node coordinates, m.
        tets : ndarray of int, shape (m, 4)
            Node indices of each tetrahedron.
        regions : ndarray of int, shape (m,), optional
            Region id of each tetrahedron (default 0).
        region_names : dict of int to str, optional
            Region id → name.

        Returns
        -------
        TetMesh
            With positively oriented tetrahedra.

        Raises
        ------
        FEAInputError
            A degenerate tetrahedron, an index out of range, a non-finite
            coordinate, or arrays of the wrong shape.
        """
        points = np.asarray(points, dtype=np.float64)
        tets = np.asarray(tets)
        if points.ndim != 2 or points.shape[1] != 3:
            raise FEAInputError(f"points must have shape (n, 3), got {points.shape}")
        if tets.ndim != 2 or tets.shape[1] != 4:
            raise FEAInputError(f"tets must have shape (m, 4), got {tets.shape}")
        if len(tets) == 0:
            raise FEAInputError("the mesh has no tetrahedra")
        if not np.issubdtype(tets.dtype, np.integer):
            raise FEAInputError(f"tets must hold integer node ids, got dtype {tets.dtype}")
        tets = tets.astype(np.int64, copy=True)
        if tets.min() < 0 or tets.max() >= len(points):
            raise FEAInputError(
                f"tets reference node {int(tets.max()) if tets.max() >= len(points) else int(tets.min())}"
                f" but the mesh has {len(points)} points"
            )
        if not np.isfinite(points).all():
            raise FEAInputError("points hold a NaN or an infinite coordinate")
        if regions is None:
            regions = np.zeros(len(tets), dtype=np.int32)
        regions = np.asarray(regions).astype(np.int32)
        if regions.shape != (len(tets),):
            raise FEAInputError(
                f"regions must have one id per tetrahedron ({len(tets)}), got shape {regions.shape}"
            )
        vol = signed_volumes(points, tets)
        edges = points[tets[:, [1, 2, 3, 2, 3, 3]]] - points[tets[:, [0, 0, 0, 1, 1, 2]]]
        longest = np.sqrt((edges**2).sum(-1).max(1))
        degenerate = np.abs(vol) <= DEGENERATE_RELATIVE_VOLUME * longest**3
        if degenerate.any():
            i = int(np.flatnonzero(degenerate)[0])
            raise FEAInputError(
                f"tetrahedron {i} (nodes {tets[i].tolist()}) is degenerate: volume {vol[i]:.3e} m³ "
                f"for a longest edge of {longest[i]:.3e} m ({int(degenerate.sum())} such tetrahedra)"
            )
        inverted = vol < 0
        tets[inverted] = tets[inverted][:, [0, 2, 1, 3]]
        return cls(points, tets, regions, dict(region_names or {}))

    @classmethod
    def from_pyvista(cls, grid: pv.UnstructuredGrid, region_array: str | None = None,
                     region_names: dict[int, str] | None = None) -> TetMesh:
        """Build a mesh from a pyvista ``UnstructuredGrid`` of linear tetrahedra.

        Parameters
        ----------
        grid : pyvista.UnstructuredGrid
            Only VTK_TETRA cells; coordinates in m.
        region_array : str, optional
            The cell array holding region ids; without it every tetrahedron is region 0.
        region_names : dict of int to str, optional
            Region id → name.

        Returns
        -------
        TetMesh
            As :meth:`from_arrays` builds it.
        """
        import pyvista as pv

        cells = grid.cells_dict
        if pv.CellType.TETRA not in cells:
            raise FEAInputError("the grid holds no linear tetrahedra (VTK_TETRA cells)")
        others = [pv.CellType(k).name for k in cells if k != pv.CellType.TETRA]
        if others:
            raise FEAInputError(f"the grid holds cells other than linear tetrahedra: {others}")
        regions = None
        if region_array is not None:
            if region_array not in grid.cell_data:
                raise FEAInputError(
                    f"cell array {region_array!r} not found; available: {list(grid.cell_data)}"
                )
            regions = np.asarray(grid.cell_data[region_array])
        return cls.from_arrays(grid.points, cells[pv.CellType.TETRA], regions, region_names)

    @classmethod
    def from_meshio(cls, mesh: meshio.Mesh, region_array: str | None = None,
                    region_names: dict[int, str] | None = None) -> TetMesh:
        """Build a mesh from a ``meshio.Mesh`` holding one ``tetra`` block.

        Parameters
        ----------
        mesh : meshio.Mesh
            Coordinates in m.
        region_array : str, optional
            The cell array holding region ids; without it every tetrahedron is region 0.
        region_names : dict of int to str, optional
            Region id → name.

        Returns
        -------
        TetMesh
            As :meth:`from_arrays` builds it.
        """
        blocks = [i for i, c in enumerate(mesh.cells) if c.type == "tetra"]
        if len(blocks) != 1:
            raise FEAInputError(f"expected one 'tetra' cell block, found {len(blocks)}")
        regions = None
        if region_array is not None:
            if region_array not in mesh.cell_data:
                raise FEAInputError(
                    f"cell data {region_array!r} not found; available: {list(mesh.cell_data)}"
                )
            regions = mesh.cell_data[region_array][blocks[0]]
        return cls.from_arrays(mesh.points, mesh.cells[blocks[0]].data, regions, region_names)

    def to_pyvista(self, point_data: dict[str, np.ndarray] | None = None,
                   cell_data: dict[str, np.ndarray] | None = None) -> pv.UnstructuredGrid:
        """The mesh as a pyvista ``UnstructuredGrid`` with a ``region`` cell array.

        Parameters
        ----------
        point_data, cell_data : dict of str to ndarray, optional
            Arrays to attach by name (names with units).

        Returns
        -------
        pyvista.UnstructuredGrid
            Coordinates in m.
        """
        import pyvista as pv

        cells = np.hstack([np.full((len(self.tets), 1), 4), self.tets]).ravel()
        grid = pv.UnstructuredGrid(cells, np.full(len(self.tets), pv.CellType.TETRA), self.points)
        grid.cell_data["region"] = self.regions
        for name, values in (point_data or {}).items():
            grid.point_data[name] = values
        for name, values in (cell_data or {}).items():
            grid.cell_data[name] = values
        return grid

    # ------------------------------------------------------------ geometry
    @property
    def n_nodes(self) -> int:
        """Number of nodes."""
        return len(self.points)

    @property
    def n_tets(self) -> int:
        """Number of tetrahedra."""
        return len(self.tets)

    @property
    def volumes(self) -> np.ndarray:
        """Volume of each tetrahedron, m³."""
        return signed_volumes(self.points, self.tets)

    def region_ids(self) -> np.ndarray:
        """The region ids present.

        Returns
        -------
        ndarray of int
            Sorted, unique.
        """
        return np.unique(self.regions)

    def region_id(self, region: int | str) -> int:
        """The id of a region given by name or id.

        Parameters
        ----------
        region : int or str
            Region id or name.

        Returns
        -------
        int
            Its id.

        Raises
        ------
        FEAInputError
            Unknown region.
        """
        if isinstance(region, str):
            for rid, name in self.region_names.items():
                if name == region:
                    return int(rid)
            raise FEAInputError(
                f"unknown region {region!r}; available: {sorted(self.region_names.values())}"
            )
        rid = int(region)
        if rid not in set(self.region_ids().tolist()):
            raise FEAInputError(f"unknown region id {rid}; available: {self.region_ids().tolist()}")
        return rid

    def _faces(self):
        """All 4·m local faces as (sorted node key, tet, local face)."""
        m = len(self.tets)
        tet = np.tile(np.arange(m), 4)
        local = np.repeat(np.arange(4), m)
        nodes = self.tets[tet[:, None], LOCAL_FACES[local]]
        return nodes, tet, local

    def _face_pairs(self):
        """Group identical faces: (boundary (tet, local), interior pairs (2, k) of face rows)."""
        if getattr(self, "_face_cache", None) is None:
            nodes, tet, local = self._faces()
            key = np.sort(nodes, axis=1)
            n = np.int64(len(self.points))
            if n < 2**21:   # one int64 key per face; a stable sort gives the lexicographic order faster
                order = np.argsort((key[:, 0] * n + key[:, 1]) * n + key[:, 2], kind="stable")
            else:
                order = np.lexsort(key.T[::-1])
            ks = key[order]
            same = np.all(ks[1:] == ks[:-1], axis=1)
            first = np.flatnonzero(same)
            paired = np.zeros(len(order), bool)
            paired[first] = paired[first + 1] = True
            boundary = order[~paired]
            interior = np.vstack([order[first], order[first + 1]])
            self._face_cache = (tet, local, boundary, interior)
        return self._face_cache

    def boundary_facets(self) -> tuple[np.ndarray, np.ndarray]:
        """The boundary facets (faces of exactly one tetrahedron).

        Returns
        -------
        tet, local_face : ndarray of int
            Tetrahedron and its local face (0–3) of each facet.
        """
        tet, local, boundary, _ = self._face_pairs()
        return tet[boundary], local[boundary]

    def interface_facets(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The interior faces between tetrahedra of different regions.

        Returns
        -------
        tet_a, local_a, tet_b, local_b : ndarray of int
            The two tetrahedra of each face and the face's local index in each.
        """
        tet, local, _, interior = self._face_pairs()
        a, b = interior
        differ = self.regions[tet[a]] != self.regions[tet[b]]
        a, b = a[differ], b[differ]
        return tet[a], local[a], tet[b], local[b]

    def facet_nodes(self, tet: np.ndarray, local: np.ndarray, tets: np.ndarray | None = None) -> np.ndarray:
        """The nodes of facets, ordered with outward normal.

        Parameters
        ----------
        tet, local : ndarray of int
            Tetrahedron and local face of each facet.
        tets : ndarray, optional
            Another connectivity to read the nodes from (e.g. thermal numbering).

        Returns
        -------
        ndarray of int, shape (k, 3)
            Node ids.
        """
        tets = self.tets if tets is None else tets
        return tets[np.asarray(tet)[:, None], LOCAL_FACES[np.asarray(local)]]

    def facet_geometry(self, tet: np.ndarray, local: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centroids, normals and areas of facets.

        Parameters
        ----------
        tet, local : ndarray of int
            Tetrahedron and local face of each facet.

        Returns
        -------
        centroids : ndarray, shape (k, 3)
            m.
        normals : ndarray, shape (k, 3)
            Unit outward normals.
        areas : ndarray, shape (k,)
            m².
        """
        xyz = self.points[self.facet_nodes(tet, local)]
        cross = np.cross(xyz[:, 1] - xyz[:, 0], xyz[:, 2] - xyz[:, 0])
        area2 = np.linalg.norm(cross, axis=1)
        return xyz.mean(axis=1), cross / area2[:, None], 0.5 * area2

    # ------------------------------------------------------------ facet groups
    def add_facet_group(self, name: str, selector: Selector, region: int | str | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
        """Select boundary facets geometrically and store them as a named group.

        Parameters
        ----------
        name : str
            The group's name.
        selector : Selector
            A :mod:`fea.selection` selector (a plane, a box, a predicate or a combination).
        region : int or str, optional
            Keep only facets of tetrahedra in that region.

        Returns
        -------
        tet, local_face : ndarray of int
            The group.

        Raises
        ------
        FEAInputError
            The selection matches nothing.
        """
        tet, local = self.boundary_facets()
        if region is not None:
            keep = self.regions[tet] == self.region_id(region)
            tet, local = tet[keep], local[keep]
        centroids, normals, _ = self.facet_geometry(tet, local)
        mask = np.asarray(selector.mask(centroids, normals, self.points[self.facet_nodes(tet, local)]))
        if not mask.any():
            raise FEAInputError(f"facet group {name!r} selects no boundary facet ({selector!r})")
        self.facet_groups[name] = (tet[mask], local[mask])
        return self.facet_groups[name]

    def set_facet_group(self, name: str, tet: np.ndarray, local: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Store an explicitly computed group of boundary facets.

        Parameters
        ----------
        name : str
            The group's name.
        tet, local : ndarray of int
            Tetrahedron and local face (0–3) of each facet.

        Returns
        -------
        tet, local_face : ndarray of int
            The group, as stored.
        """
        tet, local = np.asarray(tet, dtype=np.int64), np.asarray(local, dtype=np.int64)
        if tet.size == 0:
            raise FEAInputError(f"facet group {name!r} is empty")
        if tet.shape != local.shape or local.min() < 0 or local.max() > 3 or tet.max() >= self.n_tets:
            raise FEAInputError(f"facet group {name!r}: invalid (tet, local face) arrays")
        self.facet_groups[name] = (tet, local)
        return self.facet_groups[name]

    def facet_group(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """A named facet group.

        Parameters
        ----------
        name : str
            The group's name.

        Returns
        -------
        tet, local_face : ndarray of int
            Its facets.

        Raises
        ------
        FEAInputError
            Unknown group (the message lists them).
        """
        try:
            return self.facet_groups[name]
        except KeyError:
            raise FEAInputError(
                f"unknown facet group {name!r}; available: {sorted(self.facet_groups)}"
            ) from None

    def facet_group_area(self, name: str) -> float:
        """The total area of a facet group.

        Parameters
        ----------
        name : str
            The group's name.

        Returns
        -------
        float
            Area, m².
        """
        return float(self.facet_geometry(*self.facet_group(name))[2].sum())

    def select_tets(self, selector: Selector | None = None, region: int | str | None = None) -> np.ndarray:
        """The tetrahedra whose centroid a selector keeps (and in a region).

        Parameters
        ----------
        selector : Selector, optional
            A :mod:`fea.selection` selector.
        region : int or str, optional
            Keep only tetrahedra of that region.

        Returns
        -------
        ndarray of int
            Their indices.
        """
        keep = np.ones(len(self.tets), bool)
        if region is not None:
            keep &= self.regions == self.region_id(region)
        if selector is not None:
            centroids = self.points[self.tets].mean(axis=1)
            keep &= np.asarray(selector.mask(centroids, None, self.points[self.tets]))
        if not keep.any():
            raise FEAInputError(f"the selection ({selector!r}, region={region!r}) contains no tetrahedron")
        return np.flatnonzero(keep)

    # ------------------------------------------------------------ point location
    def locate(self, points: np.ndarray, tolerance: float = 1e-9, snap_distance: float = 0.0,
               names: list[str] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Containing tetrahedron and barycentric weights of each point.

        Parameters
        ----------
        points : ndarray, shape (k, 3)
            Coordinates, m.
        tolerance : float
            Relative barycentric tolerance for points on faces and edges.
        snap_distance : float
            A point outside the mesh but closer than this to it (m) is moved
            onto the nearest tetrahedron (weights clipped to it).
        names : list of str, optional
            Labels used in error messages.

        Returns
        -------
        tets : ndarray of int, shape (k,)
            Containing tetrahedra.
        weights : ndarray, shape (k, 4)
            Barycentric weights, non-negative, summing to 1.
        """
        from scipy.spatial import cKDTree

        pts = np.atleast_2d(np.asarray(points, dtype=float))
        if pts.shape[-1] != 3:
            raise FEAInputError(f"points must have shape (k, 3), got {pts.shape}")
        if getattr(self, "_centroid_tree", None) is None:
            self._centroid_tree = cKDTree(self.points[self.tets].mean(axis=1))
        found_tet = np.empty(len(pts), dtype=np.int64)
        found_w = np.empty((len(pts), 4))
        for i, x in enumerate(pts):
            for k in (16, 128, 1024):
                k = min(k, len(self.tets))
                _, cand = self._centroid_tree.query(x, k=k)
                cand = np.atleast_1d(cand)
                X = self.points[self.tets[cand]]               # only the candidates' Jacobians are inverted
                jac = np.transpose(X[:, 1:] - X[:, :1], (0, 2, 1))
                lam = np.linalg.solve(jac, (x - X[:, 0])[..., None])[..., 0]
                w = np.column_stack([1.0 - lam.sum(1), lam])
                best = int(np.argmax(w.min(1)))
                if w[best].min() >= -tolerance or k == len(self.tets):
                    break
            wb = w[best]
            if wb.min() < -tolerance:
                clipped = np.clip(wb, 0.0, None)
                clipped /= clipped.sum()
                nearest = clipped @ self.points[self.tets[cand[best]]]
                distance = float(np.linalg.norm(nearest - x))
                if distance > snap_distance:
                    label = names[i] if names is not None else f"point {i}"
                    raise FEAInputError(
                        f"{label} at {tuple(round(float(v), 6) for v in x)} m lies outside the mesh "
                        f"(nearest tetrahedron {distance * 1e3:.3f} mm away, snap distance "
                        f"{snap_distance * 1e3:.3f} mm)"
                    )
                wb = clipped
            found_tet[i] = cand[best]
            found_w[i] = np.clip(wb, 0.0, None) / np.clip(wb, 0.0, None).sum()
        return found_tet, found_w
