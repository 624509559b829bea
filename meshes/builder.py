"""Meshing a machine: part surfaces → pytetwild → a labelled tetrahedral mesh, cached by content hash.

fTetWild (through pytetwild) tetrahedralises the union of all part surfaces
and keeps every input triangle as a mesh face (within a small envelope), so
the interfaces between parts are conforming.  Each tetrahedron is then given
the part whose shape contains its centroid most deeply, later parts winning
where parts overlap (a ram passing through its carrier belongs to the ram).

fTetWild is multithreaded and not bit-reproducible, so meshes are cached by
a hash of the definition, the mesh size and the mesher version.  Shipped
meshes live in ``meshes/cache``; new ones go to the user cache
(``$THERMAL_TWIN_CACHE`` or ``~/.cache/thermal-twin``).
"""
from __future__ import annotations

import json
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyvista as pv

from fea import TetMesh

from .tomlspec import DefinitionError

BUILDER_VERSION = 2
SHIPPED_CACHE = Path(__file__).resolve().parent / "cache"


def user_cache_dir():
    """Where new meshes and other derived data are cached."""
    root = os.environ.get("THERMAL_TWIN_CACHE")
    path = Path(root) if root else Path.home() / ".cache" / "thermal-twin"
    path.mkdir(parents=True, exist_ok=True)
    return path


def find_cached(name):
    """A cached file by name: shipped with the package first, then the user cache; ``None`` if absent."""
    for folder in (SHIPPED_CACHE, user_cache_dir()):
        if (folder / name).exists():
            return folder / name
    return None


@dataclass
class MeshInfo:
    """How a mesh was obtained and what it looks like."""

    path: Path
    from_cache: bool
    seconds: float
    digest: str


def cache_file_name(geometry, size_m):
    return f"{geometry.name}-h{size_m * 1e3:g}mm-{geometry.digest(size_m)[:12]}.vtu"


def build_mesh(geometry, size_m=None, rebuild=False, quiet=True):
    """The labelled mesh of a :class:`~meshes.definition.MachineGeometry`, from cache when possible.

    Parameters
    ----------
    size_m : target tetrahedron edge length in m (default: the definition's ``mesh.size_m``)
    rebuild : mesh again even if a cached mesh exists

    Returns ``(TetMesh, MeshInfo)``; region ids are 1… in part order and
    ``mesh.region_names`` maps them to part names.
    """
    size_m = float(size_m or geometry.mesh_size_m)
    if not size_m > 0:
        raise DefinitionError(f"{geometry.source}: mesh size must be positive, got {size_m!r}")
    name = cache_file_name(geometry, size_m)
    digest = geometry.digest(size_m)
    path = None if rebuild else find_cached(name)
    if path is not None:
        start = time.perf_counter()
        mesh = read_labelled_mesh(path)
        return mesh, MeshInfo(path, True, time.perf_counter() - start, digest)
    start = time.perf_counter()
    grid = tetrahedralize(geometry, size_m, quiet)
    mesh = label_parts(geometry, grid)
    path = user_cache_dir() / name
    write_labelled_mesh(mesh, path, {"machine": geometry.name, "size_m": size_m, "digest": digest,
                                      "source": geometry.source})
    return mesh, MeshInfo(path, False, time.perf_counter() - start, digest)


def tetrahedralize(geometry, size_m, quiet=True):
    """Run fTetWild on the CSG union of all parts.

    A boolean tree, rather than one merged surface, keeps the winding number
    right where parts touch: two coincident faces of opposite orientation
    (a table on its base) otherwise punch holes into the touching solids.
    """
    import pytetwild

    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        trees = [part.shape.csg(folder / part.name, size_m) for part in geometry.parts]
        tree = trees[0]
        for other in trees[1:]:
            tree = {"operation": "union", "left": tree, "right": other}
        if isinstance(tree, str):       # a single solid part: union it with itself
            tree = {"operation": "union", "left": tree, "right": tree}
        csg = folder / "machine.json"
        csg.write_text(json.dumps(tree))
        diagonal = float(np.linalg.norm(np.ptp(np.vstack([p.shape.surface(size_m).points
                                                           for p in geometry.parts]), axis=0)))
        cwd = os.getcwd()
        os.chdir(folder)        # fTetWild drops a scratch surface file in the working directory
        try:
            grid = pytetwild.tetrahedralize_csg(str(csg), epsilon=geometry.envelope_epsilon,
                                                edge_length_r=size_m / diagonal, coarsen=False,
                                                stop_energy=geometry.stop_energy,
                                                loglevel=6 if quiet else 3)
        except Exception as exc:  # fTetWild reports failures as generic exceptions
            raise DefinitionError(f"{geometry.source}: meshing failed in pytetwild: {exc}") from exc
        finally:
            os.chdir(cwd)
    if grid is None or grid.n_cells == 0:
        raise DefinitionError(f"{geometry.source}: meshing produced no tetrahedra (size {size_m} m)")
    return grid


def label_parts(geometry, grid):
    """Give each tetrahedron the deepest-containing part, later parts winning overlaps."""
    mesh = TetMesh.from_pyvista(grid)
    centroids = mesh.points[mesh.tets].mean(axis=1)
    depth = np.column_stack([p.shape.depth(centroids) for p in geometry.parts])
    # A centroid inside several parts (depth > 0) goes to the last of them; one
    # inside none (a sliver in fTetWild's envelope) to the part it is nearest.
    inside = depth > 0
    last_inside = depth.shape[1] - 1 - np.argmax(inside[:, ::-1], axis=1)
    region = np.where(inside.any(axis=1), last_inside, np.argmax(depth, axis=1)) + 1
    empty = [p.name for i, p in enumerate(geometry.parts) if not np.any(region == i + 1)]
    if empty:
        raise DefinitionError(
            f"{geometry.source}: part(s) {empty} received no tetrahedron; they are thinner than the "
            "mesh size allows: use a smaller mesh size")
    names = {i + 1: p.name for i, p in enumerate(geometry.parts)}
    return TetMesh(mesh.points, mesh.tets, region.astype(np.int32), names)


def write_labelled_mesh(mesh, path, metadata):
    """Save a mesh with its region names atomically as ``.vtu``."""
    grid = mesh.to_pyvista()
    grid.field_data["region_names"] = [json.dumps({str(k): v for k, v in mesh.region_names.items()})]
    grid.field_data["metadata"] = [json.dumps(metadata)]
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.partial.vtu")
    grid.save(tmp)
    os.replace(tmp, path)


def read_labelled_mesh(path):
    grid = pv.read(path)
    names = {int(k): v for k, v in json.loads(str(grid.field_data["region_names"][0])).items()}
    return TetMesh.from_pyvista(grid, "region", names)


def mesh_statistics(mesh):
    """Counts, volumes per part and shape quality (radius ratio: 1 regular, 0 degenerate)."""
    X = mesh.points[mesh.tets]
    vol = mesh.volumes
    faces = [np.linalg.norm(np.cross(X[:, b] - X[:, a], X[:, c] - X[:, a]), axis=1) / 2
             for a, b, c in ((1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1))]
    area = np.sum(faces, axis=0)
    inradius = 3 * vol / area
    edges = X[:, [1, 2, 3, 2, 3, 3]] - X[:, [0, 0, 0, 1, 1, 2]]
    lengths = np.linalg.norm(edges, axis=2)
    # Radius ratio 3 r_in / r_circ, with the circumradius from Cayley–Menger-free bound via edge products.
    a, b, c = lengths[:, 0] * lengths[:, 5], lengths[:, 1] * lengths[:, 4], lengths[:, 2] * lengths[:, 3]
    circumradius = np.sqrt(np.clip((a + b + c) * (a + b - c) * (a - b + c) * (-a + b + c), 0, None)) / (24 * vol)
    ratio = 3 * inradius / circumradius
    per_part = {mesh.region_names.get(int(r), str(r)): float(vol[mesh.regions == r].sum())
                for r in mesh.region_ids()}
    return {
        "nodes": mesh.n_nodes,
        "tetrahedra": mesh.n_tets,
        "volume_m3": float(vol.sum()),
        "part_volume_m3": per_part,
        "edge_length_m": {"min": float(lengths.min()), "mean": float(lengths.mean()), "max": float(lengths.max())},
        "radius_ratio": {"min": float(ratio.min()), "p01": float(np.percentile(ratio, 1)),
                         "mean": float(ratio.mean())},
    }
