"""Meshing a machine: part surfaces → pytetwild → a labelled tetrahedral mesh, cached by geometry.

fTetWild (through pytetwild) tetrahedralises the union of all part surfaces
and keeps every input triangle as a mesh face (within a small envelope), so
the interfaces between parts are conforming.  Each tetrahedron is then given
the part whose shape contains its centroid most deeply, later parts winning
where parts overlap (a ram passing through its carrier belongs to the ram).

fTetWild is multithreaded and not bit-reproducible, so meshes are cached,
named ``mesh-h<size>mm-<digest>.vtu`` by the geometry digest
(:meth:`~meshes.definition.MachineGeometry.digest`: parts, shapes, STL
contents, mesh size and fTetWild settings; not the machine's name, materials,
sources or joints).  A renamed copy of a machine, or one with other heat
sources or joint conductances, therefore reuses the mesh.  Shipped meshes
live in ``meshes/cache``; new ones go to the user cache, each with a SHA-256
sidecar checked before it is read (:mod:`meshes.cachefiles`).

Meshing takes minutes: :func:`build_mesh` says what it builds and roughly
how long it will take on the ``thermal_twin`` logger, and sends fTetWild's
console output (hundreds of lines) to a log file beside the mesh.
"""
from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pyvista as pv

from fea import TetMesh

from .cachefiles import find_cached, log, user_cache_dir, write_checked
from .tomlspec import DefinitionError

if TYPE_CHECKING:   # meshes.definition imports this module (BUILDER_VERSION)
    from .definition import MachineGeometry

BUILDER_VERSION = 2

#: Tetrahedra per h³ of part volume that fTetWild makes at target edge length h (the shipped
#: meshes: 11.7 and 12.8 for vmc_ram at 35 and 45 mm, 13.2 for machine_a at 45 mm).
TETS_PER_CUBED_EDGE = 12.0
#: Meshing time ≈ fixed + per-tetrahedron seconds, measured on a 2-core VM: 46 s for the
#: 1,063-tetrahedron test machine, 698 s for a 49,535-tetrahedron vmc_ram mesh.
MESHING_FIXED_S = 45.0
MESHING_S_PER_TET = 0.014
#: Smallest target edge length accepted, m (0.1 mm: below it a machine's mesh is astronomically large).
MIN_MESH_SIZE_M = 1e-4
#: Largest target edge length accepted, m: half a metre is coarser than any part of a machine tool is thick (the
#: shipped machines' walls, spindles and slides are 0.02-0.3 m), so no useful mesh is coarser, while a size
#: typed in mm (35 for 35 mm) is above it and would start meshing a 2.5 m machine with 35 m tetrahedra.
MAX_MESH_SIZE_M = 0.5
#: Most tetrahedra a mesh may be expected to have before meshing starts: 20 million is about 400 times the
#: shipped 45 mm mesh, days of meshing and more memory than the FE's direct solver has on a workstation.
MAX_TETRAHEDRA = 2e7


@dataclass
class MeshInfo:
    """How a mesh was obtained and what it looks like."""

    path: Path
    from_cache: bool
    seconds: float
    digest: str


def cache_file_name(geometry: MachineGeometry, size_m: float) -> str:
    """File name of a geometry's mesh: the size and the geometry digest, no machine name.

    Parameters
    ----------
    geometry : MachineGeometry
        The parts and mesh settings.
    size_m : float
        Target tetrahedron edge length, m.

    Returns
    -------
    str
        ``mesh-h<size in mm>mm-<first 16 hex digits of the digest>.vtu``.
    """
    return f"mesh-h{size_m * 1e3:g}mm-{geometry.digest(size_m)[:16]}.vtu"


def meshing_estimate(geometry: MachineGeometry, size_m: float) -> tuple[float, float]:
    """Rough size and duration of meshing a geometry, from its part volumes.

    Parameters
    ----------
    geometry : MachineGeometry
        The parts.
    size_m : float
        Target tetrahedron edge length, m.

    Returns
    -------
    tetrahedra : float
        Expected number of tetrahedra.
    seconds : float
        Expected wall time on a 2-core machine, s.
    """
    volume = sum(abs(p.shape.surface(size_m).volume) for p in geometry.parts)
    tets = TETS_PER_CUBED_EDGE * volume / size_m ** 3
    return tets, MESHING_FIXED_S + MESHING_S_PER_TET * tets


def check_mesh_size(size_m: float) -> float:
    """A target edge length given as a number (not read from a file), checked.

    Parameters
    ----------
    size_m : float
        Target tetrahedron edge length, m.

    Returns
    -------
    float
        The same length, m.

    Raises
    ------
    DefinitionError
        If it is not a finite length from :data:`MIN_MESH_SIZE_M` to :data:`MAX_MESH_SIZE_M`.
    """
    size = float(size_m)
    if not (np.isfinite(size) and MIN_MESH_SIZE_M <= size <= MAX_MESH_SIZE_M):
        raise DefinitionError(f"mesh size must be a finite length from {MIN_MESH_SIZE_M:g} m "
                              f"({MIN_MESH_SIZE_M * 1e3:g} mm) to {MAX_MESH_SIZE_M:g} m, got {size_m!r} m"
                              f"{mm_hint(size)}")
    return size


def mm_hint(size_m: float) -> str:
    """A hint that a mesh size over :data:`MAX_MESH_SIZE_M` was typed in mm, when it is a plausible size in mm
    (2 mm to :data:`MAX_MESH_SIZE_M`).

    Parameters
    ----------
    size_m : float
        The mesh size as given, read in m.

    Returns
    -------
    str
        ``"; is it in mm? …"``, or ``""``.
    """
    # under 2 mm no machine is meshed (0.6 given for 0.06?): the hint would mislead
    if size_m > MAX_MESH_SIZE_M and 2e-3 <= size_m * 1e-3 <= MAX_MESH_SIZE_M:
        return f"; is it in mm? {size_m:g} mm is a mesh size of {size_m * 1e-3:g} m"
    return ""


def _check_feasible(geometry, size_m, tets, seconds):
    """Refuse to start a meshing that would exceed :data:`MAX_TETRAHEDRA` (it would run for days)."""
    if tets > MAX_TETRAHEDRA:
        smallest = size_m * (tets / MAX_TETRAHEDRA) ** (1 / 3)
        raise DefinitionError(
            f"meshing {geometry.name} at {size_m * 1e3:g} mm would make about {tets:.2g} tetrahedra (roughly "
            f"{duration_text(seconds)}), more than the {MAX_TETRAHEDRA:.0e} this twin meshes; use a mesh size of "
            f"at least {np.ceil(smallest * 1e4) / 10:g} mm")


def duration_text(seconds: float) -> str:
    """A rough duration as text.

    Parameters
    ----------
    seconds : float
        Duration, s.

    Returns
    -------
    str
        ``"40 s"``, ``"12 min"`` or ``"1.5 h"``.
    """
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def build_mesh(geometry: MachineGeometry, size_m: float | None = None, rebuild: bool = False,
               quiet: bool = True) -> tuple[TetMesh, MeshInfo]:
    """The labelled mesh of a :class:`~meshes.definition.MachineGeometry`, from cache when possible.

    A cached mesh that fails its content check is rebuilt (user cache) or
    refused (shipped cache, :class:`~meshes.cachefiles.CacheFileError`).

    Parameters
    ----------
    geometry : MachineGeometry
        The parts and mesh settings.
    size_m : float, optional
        Target tetrahedron edge length, m (default: the definition's ``mesh.size_m``); at least
        :data:`MIN_MESH_SIZE_M`, and no finer than makes about :data:`MAX_TETRAHEDRA` tetrahedra.
    rebuild : bool
        Mesh again even if a cached mesh exists.
    quiet : bool
        Send fTetWild's console output to ``<mesh>.log`` beside the mesh (else show it).

    Returns
    -------
    mesh : TetMesh
        Coordinates in m; region ids are 1… in part order and ``mesh.region_names`` maps them to part names.
    info : MeshInfo
        The file, whether it came from the cache, the time taken (s) and the geometry digest.
    """
    size_m = geometry.mesh_size_m if size_m is None else check_mesh_size(size_m)
    name = cache_file_name(geometry, size_m)
    digest = geometry.digest(size_m)
    path = None if rebuild else find_cached(name)
    if path is not None:
        start = time.perf_counter()
        mesh = read_labelled_mesh(path)
        return mesh, MeshInfo(path, True, time.perf_counter() - start, digest)
    path = user_cache_dir() / name
    tets, seconds = meshing_estimate(geometry, size_m)
    _check_feasible(geometry, size_m, tets, seconds)
    log.info("meshing %s at %g mm (about %s tetrahedra): roughly %s on a 2-core machine",
             geometry.name, size_m * 1e3, f"{float(f'{tets:.2g}'):,.0f}", duration_text(seconds))
    start = time.perf_counter()
    mesher_log = path.with_suffix(".log")
    if quiet:
        log.info("fTetWild output goes to %s", mesher_log)
    try:
        with _console_to(mesher_log) if quiet else nullcontext():
            grid = tetrahedralize(geometry, size_m, quiet)
    except DefinitionError as exc:
        raise DefinitionError(f"{exc} (fTetWild output: {mesher_log})" if quiet else str(exc)) from None
    mesh = label_parts(geometry, grid)
    write_labelled_mesh(mesh, path, {"built_for": geometry.name, "size_m": size_m, "digest": digest,
                                     "source": Path(geometry.source).name, "mesher": _mesher_version()})
    seconds = time.perf_counter() - start
    log.info("meshed %s: %s tetrahedra in %s: %s", geometry.name, f"{mesh.n_tets:,}", duration_text(seconds), path)
    return mesh, MeshInfo(path, False, seconds, digest)


def _mesher_version():
    import pytetwild

    return f"pytetwild {getattr(pytetwild, '__version__', '?')}"


@contextmanager
def _console_to(path):
    """Send everything written to file descriptors 1 and 2 into ``path`` (fTetWild prints from C++, which
    Python's ``sys.stdout`` does not see), restoring them afterwards."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    try:
        with open(path, "wb") as f:
            os.dup2(f.fileno(), 1)
            os.dup2(f.fileno(), 2)
            try:
                yield
            finally:
                _flush_c_stdio()
    finally:
        for fd, saved_fd in zip((1, 2), saved):
            os.dup2(saved_fd, fd)
            os.close(saved_fd)


def _flush_c_stdio():
    """Flush C's stdio buffers, so buffered fTetWild lines land in the log and not later on the console."""
    import ctypes

    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):   # no C runtime handle (Windows): nothing to flush this way
        pass


def tetrahedralize(geometry: MachineGeometry, size_m: float, quiet: bool = True) -> pv.UnstructuredGrid:
    """Run fTetWild on the CSG union of all parts.

    A boolean tree, rather than one merged surface, keeps the winding number
    right where parts touch: two coincident faces of opposite orientation
    (a table on its base) otherwise punch holes into the touching solids.

    Parameters
    ----------
    geometry : MachineGeometry
        The parts and fTetWild settings.
    size_m : float
        Target tetrahedron edge length, m.
    quiet : bool
        fTetWild's least verbose log level.

    Returns
    -------
    pyvista.UnstructuredGrid
        Unlabelled tetrahedra, coordinates in m.

    Raises
    ------
    DefinitionError
        fTetWild failed or produced no tetrahedra.
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
        # The C++ wrapper turns std::exception into RuntimeError, invalid_argument/length_error into
        # ValueError, out_of_range into IndexError and bad_alloc into MemoryError.
        except (RuntimeError, ValueError, IndexError, MemoryError) as exc:
            raise DefinitionError(f"{geometry.source}: meshing failed in pytetwild: {exc}") from exc
        finally:
            os.chdir(cwd)
    if grid is None or grid.n_cells == 0:
        raise DefinitionError(f"{geometry.source}: meshing produced no tetrahedra (size {size_m} m)")
    return grid


def label_parts(geometry: MachineGeometry, grid: pv.UnstructuredGrid) -> TetMesh:
    """Give each tetrahedron the deepest-containing part, later parts winning overlaps.

    Parameters
    ----------
    geometry : MachineGeometry
        The parts, in priority order.
    grid : pyvista.UnstructuredGrid
        The tetrahedra of :func:`tetrahedralize`.

    Returns
    -------
    TetMesh
        With region ids 1… in part order and their part names.

    Raises
    ------
    DefinitionError
        A part received no tetrahedron (thinner than the mesh size allows).
    """
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


def write_labelled_mesh(mesh: TetMesh, path: str | Path, metadata: dict) -> None:
    """Save a mesh with its region names atomically as ``.vtu``, with its SHA-256 sidecar.

    Parameters
    ----------
    mesh : TetMesh
        A labelled mesh.
    path : str or Path
        The ``.vtu`` file.
    metadata : dict
        JSON-serialisable facts stored in the file's field data (machine, size, digest, mesher).
    """
    grid = mesh.to_pyvista()
    grid.field_data["region_names"] = [json.dumps({str(k): v for k, v in mesh.region_names.items()})]
    grid.field_data["metadata"] = [json.dumps(metadata)]
    write_checked(path, grid.save)


def read_labelled_mesh(path: str | Path) -> TetMesh:
    """Read a mesh written by :func:`write_labelled_mesh`.

    Parameters
    ----------
    path : str or Path
        The ``.vtu`` file.

    Returns
    -------
    TetMesh
        With its region ids and names.
    """
    grid = pv.read(path)
    names = {int(k): v for k, v in json.loads(str(grid.field_data["region_names"][0])).items()}
    return TetMesh.from_pyvista(grid, "region", names)


def mesh_statistics(mesh: TetMesh) -> dict:
    """Counts, volumes per part and shape quality of a mesh.

    Parameters
    ----------
    mesh : TetMesh
        A labelled mesh.

    Returns
    -------
    dict
        Nodes, tetrahedra, volume (m³) in total and per part, edge lengths
        (m) and the radius ratio (1 regular, 0 degenerate).
    """
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
