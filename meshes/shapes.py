"""Part shapes of a machine: closed surfaces to mesh, and signed depth to label tetrahedra.

Each shape gives
- ``surface(resolution_m)``: a closed, outward-oriented triangle surface (pyvista), and
- ``depth(points)``: signed distance-like depth, positive inside, in m, used to
  decide which part a tetrahedron belongs to.
Coordinates are in metres, z up.
"""
from __future__ import annotations

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


@dataclass(frozen=True)
class Box:
    """A solid box, ``bounds = (xmin, xmax, ymin, ymax, zmin, zmax)`` in m."""

    bounds: tuple

    def surface(self, resolution_m):
        return _box_surface(self.bounds)

    def csg(self, stem, resolution_m):
        """CSG leaf or tree (STL paths) for fTetWild, files written next to ``stem``."""
        return _save(self.surface(resolution_m), stem)

    def depth(self, points):
        return _box_depth(self.bounds, points)

    @property
    def volume(self):
        b = np.asarray(self.bounds).reshape(3, 2)
        return float(np.prod(b[:, 1] - b[:, 0]))


@dataclass(frozen=True)
class HollowBox:
    """A cast box with walls of thickness ``wall`` (m) around a sealed cavity, and optional internal ribs.

    ``ribs`` are plates across the cavity, each a box in absolute coordinates
    (they are clipped to the outer box by the mesher's union).
    """

    bounds: tuple
    wall: float
    ribs: tuple = ()

    @property
    def cavity(self):
        b = np.asarray(self.bounds, float).reshape(3, 2)
        return tuple((b + np.array([self.wall, -self.wall])).ravel())

    def surface(self, resolution_m):
        # The cavity surface is flipped inward so the winding number is 0 inside it.
        parts = [_box_surface(self.bounds), _box_surface(self.cavity).flip_faces()]
        parts += [_box_surface(r) for r in self.ribs]
        return pv.merge(parts)

    def csg(self, stem, resolution_m):
        outer = _save(_box_surface(self.bounds), f"{stem}_outer")
        tree = {"operation": "difference", "left": outer, "right": _save(_box_surface(self.cavity), f"{stem}_cavity")}
        for i, rib in enumerate(self.ribs):
            clipped = {"operation": "intersection", "left": _save(_box_surface(rib), f"{stem}_rib{i}"), "right": outer}
            tree = {"operation": "union", "left": tree, "right": clipped}
        return tree

    def depth(self, points):
        shell = np.minimum(_box_depth(self.bounds, points), -_box_depth(self.cavity, points))
        for rib in self.ribs:
            shell = np.maximum(shell, np.minimum(_box_depth(rib, points), _box_depth(self.bounds, points)))
        return shell

    @property
    def volume(self):
        cavity = np.asarray(self.cavity).reshape(3, 2)
        ribs = 0.0
        for rib in self.ribs:
            r = np.asarray(rib, float).reshape(3, 2)
            extent = np.minimum(r[:, 1], cavity[:, 1]) - np.maximum(r[:, 0], cavity[:, 0])
            ribs += float(np.prod(np.clip(extent, 0.0, None)))
        return Box(self.bounds).volume - Box(self.cavity).volume + ribs


@dataclass(frozen=True)
class Cylinder:
    """A solid cylinder along ``axis`` from ``base`` (centre of the first end, m) over ``length`` m."""

    base: tuple
    axis: str
    radius: float
    length: float

    def surface(self, resolution_m):
        n = max(24, int(np.ceil(2 * np.pi * self.radius / max(resolution_m / 2, 1e-9))))
        direction = np.eye(3)[AXES.index(self.axis)]
        centre = np.asarray(self.base, float) + direction * self.length / 2
        return pv.Cylinder(center=centre, direction=direction, radius=self.radius, height=self.length,
                           resolution=n, capping=True).triangulate().clean()

    def csg(self, stem, resolution_m):
        return _save(self.surface(resolution_m), stem)

    def depth(self, points):
        k = AXES.index(self.axis)
        rel = points - np.asarray(self.base, float)
        along = rel[:, k]
        radial = np.sqrt(np.sum(np.delete(rel, k, axis=1) ** 2, axis=1))
        return np.minimum(np.minimum(along, self.length - along), self.radius - radial)

    @property
    def volume(self):
        return float(np.pi * self.radius**2 * self.length)


@dataclass(frozen=True)
class StlPart:
    """A part read from a closed STL surface, scaled by ``scale`` (e.g. 0.001 for mm) and shifted by ``offset`` m."""

    path: str
    scale: float = 1.0
    offset: tuple = (0.0, 0.0, 0.0)

    def _surface(self):
        surf = pv.read(self.path).triangulate().clean()
        surf.points = surf.points * self.scale + np.asarray(self.offset)
        return surf

    def surface(self, resolution_m):
        return self._surface()

    def csg(self, stem, resolution_m):
        return _save(self._surface(), stem)

    def depth(self, points):
        surf = self._surface()
        cloud = pv.PolyData(np.asarray(points, float))
        # VTK's implicit distance is negative inside a closed outward-oriented surface.
        return -np.asarray(cloud.compute_implicit_distance(surf)["implicit_distance"])

    @property
    def volume(self):
        return float(self._surface().volume)

    def file_digest(self):
        import hashlib

        return hashlib.sha256(Path(self.path).read_bytes()).hexdigest()
