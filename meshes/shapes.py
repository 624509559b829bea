"""Part shapes of a machine: closed surfaces to mesh, and signed depth to label tetrahedra.

Each shape gives
- ``surface(resolution_m)``: a closed, outward-oriented triangle surface (pyvista), and
- ``depth(points)``: signed distance-like depth, positive inside, in m, used to
  decide which part a tetrahedron belongs to.
Coordinates are in metres, z up.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyvista as pv

AXES = "xyz"


def _box_surface(bounds):
    return pv.Box(bounds=bounds, level=0, quads=False).triangulate().clean()


def _save(surface, stem):
    path = f"{stem}.stl"
    surface.save(path)
    return path


def _box_depth(bounds, points):
    b = np.asarray(bounds, float).reshape(3, 2)
    return np.minimum(points - b[:, 0], b[:, 1] - points).min(axis=1)


class Shape:
    """The interface of a part shape; the subclasses below implement it (their methods inherit these docstrings)."""

    def surface(self, resolution_m: float) -> pv.PolyData:
        """The closed, outward-oriented triangle surface of the part.

        Parameters
        ----------
        resolution_m : float
            Target edge length, m (used where the shape is curved).

        Returns
        -------
        pyvista.PolyData
            Triangles, coordinates in m.
        """
        raise NotImplementedError

    def csg(self, stem: Path | str, resolution_m: float) -> str | dict:
        """CSG leaf or tree for fTetWild: STL paths written next to ``stem``, combined by boolean operations.

        Parameters
        ----------
        stem : Path or str
            Path prefix of the STL file(s) to write.
        resolution_m : float
            Target edge length of curved surfaces, m.

        Returns
        -------
        str or dict
            An STL path (a leaf) or an fTetWild CSG tree (``operation``, ``left``, ``right``).
        """
        raise NotImplementedError

    def depth(self, points: np.ndarray) -> np.ndarray:
        """Signed depth of points in the part: positive inside, about the distance to the surface.

        Parameters
        ----------
        points : ndarray, shape (n, 3)
            Coordinates, m.

        Returns
        -------
        ndarray, shape (n,)
            Depth, m.
        """
        raise NotImplementedError

    @property
    def volume(self) -> float:
        """Volume of the solid, m³."""
        raise NotImplementedError


@dataclass(frozen=True)
class Box(Shape):
    """A solid box, ``bounds = (xmin, xmax, ymin, ymax, zmin, zmax)`` in m."""

    bounds: tuple

    def surface(self, resolution_m: float) -> pv.PolyData:
        return _box_surface(self.bounds)

    def csg(self, stem: Path | str, resolution_m: float) -> str | dict:
        return _save(self.surface(resolution_m), stem)

    def depth(self, points: np.ndarray) -> np.ndarray:
        return _box_depth(self.bounds, points)

    @property
    def volume(self) -> float:
        b = np.asarray(self.bounds).reshape(3, 2)
        return float(np.prod(b[:, 1] - b[:, 0]))


@dataclass(frozen=True)
class HollowBox(Shape):
    """A cast box with walls of thickness ``wall`` (m) around a sealed cavity, and optional internal ribs.

    ``ribs`` are plates across the cavity, each a box in absolute coordinates
    (they are clipped to the outer box by the mesher's union).
    """

    bounds: tuple
    wall: float
    ribs: tuple = ()

    @property
    def cavity(self) -> tuple:
        """Bounds of the sealed cavity, ``(xmin, xmax, ymin, ymax, zmin, zmax)`` in m."""
        b = np.asarray(self.bounds, float).reshape(3, 2)
        return tuple((b + np.array([self.wall, -self.wall])).ravel())

    def surface(self, resolution_m: float) -> pv.PolyData:
        # The cavity surface is flipped inward so the winding number is 0 inside it.
        parts = [_box_surface(self.bounds), _box_surface(self.cavity).flip_faces()]
        parts += [_box_surface(r) for r in self.ribs]
        return pv.merge(parts)

    def csg(self, stem: Path | str, resolution_m: float) -> str | dict:
        outer = _save(_box_surface(self.bounds), f"{stem}_outer")
        tree = {"operation": "difference", "left": outer, "right": _save(_box_surface(self.cavity), f"{stem}_cavity")}
        for i, rib in enumerate(self.ribs):
            clipped = {"operation": "intersection", "left": _save(_box_surface(rib), f"{stem}_rib{i}"), "right": outer}
            tree = {"operation": "union", "left": tree, "right": clipped}
        return tree

    def depth(self, points: np.ndarray) -> np.ndarray:
        shell = np.minimum(_box_depth(self.bounds, points), -_box_depth(self.cavity, points))
        for rib in self.ribs:
            shell = np.maximum(shell, np.minimum(_box_depth(rib, points), _box_depth(self.bounds, points)))
        return shell

    @property
    def volume(self) -> float:
        cavity = np.asarray(self.cavity).reshape(3, 2)
        ribs = 0.0
        for rib in self.ribs:
            r = np.asarray(rib, float).reshape(3, 2)
            extent = np.minimum(r[:, 1], cavity[:, 1]) - np.maximum(r[:, 0], cavity[:, 0])
            ribs += float(np.prod(np.clip(extent, 0.0, None)))
        return Box(self.bounds).volume - Box(self.cavity).volume + ribs


@dataclass(frozen=True)
class Cylinder(Shape):
    """A solid cylinder along ``axis`` from ``base`` (centre of the first end, m) over ``length`` m."""

    base: tuple
    axis: str
    radius: float
    length: float

    def surface(self, resolution_m: float) -> pv.PolyData:
        n = max(24, int(np.ceil(2 * np.pi * self.radius / max(resolution_m / 2, 1e-9))))
        direction = np.eye(3)[AXES.index(self.axis)]
        centre = np.asarray(self.base, float) + direction * self.length / 2
        return pv.Cylinder(center=centre, direction=direction, radius=self.radius, height=self.length,
                           resolution=n, capping=True).triangulate().clean()

    def csg(self, stem: Path | str, resolution_m: float) -> str | dict:
        return _save(self.surface(resolution_m), stem)

    def depth(self, points: np.ndarray) -> np.ndarray:
        k = AXES.index(self.axis)
        rel = points - np.asarray(self.base, float)
        along = rel[:, k]
        radial = np.sqrt(np.sum(np.delete(rel, k, axis=1) ** 2, axis=1))
        return np.minimum(np.minimum(along, self.length - along), self.radius - radial)

    @property
    def volume(self) -> float:
        return float(np.pi * self.radius**2 * self.length)


@dataclass(frozen=True)
class StlPart(Shape):
    """A part read from a closed STL surface, scaled by ``scale`` (e.g. 0.001 for mm) and shifted by ``offset`` m."""

    path: str
    scale: float = 1.0
    offset: tuple = (0.0, 0.0, 0.0)

    def _surface(self):
        surf = pv.read(self.path).triangulate().clean()
        surf.points = surf.points * self.scale + np.asarray(self.offset)
        return surf

    def surface(self, resolution_m: float) -> pv.PolyData:
        return self._surface()

    def csg(self, stem: Path | str, resolution_m: float) -> str | dict:
        return _save(self._surface(), stem)

    def depth(self, points: np.ndarray) -> np.ndarray:
        surf = self._surface()
        cloud = pv.PolyData(np.asarray(points, float))
        # VTK's implicit distance is negative inside a closed outward-oriented surface.
        return -np.asarray(cloud.compute_implicit_distance(surf)["implicit_distance"])

    @property
    def volume(self) -> float:
        return float(self._surface().volume)

    def file_digest(self) -> str:
        """The content hash of the STL file, which enters the mesh cache key.

        Returns
        -------
        str
            SHA-256 of the file's bytes, 64 hex digits.
        """
        return hashlib.sha256(Path(self.path).read_bytes()).hexdigest()
