"""Geometric selectors for boundary facets and tetrahedra.

pytetwild keeps no surface tags, so boundary groups are chosen by geometry:
a plane, an axis-aligned box, or any predicate on centroids and normals.
Selectors combine with ``&``, ``|`` and ``~``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np


class Selector:
    """Base class: ``mask(centroids, normals, vertices) -> bool array``.

    ``normals`` is ``None`` when tetrahedra rather than facets are selected.
    """

    def mask(self, centroids: np.ndarray, normals: np.ndarray | None,
             vertices: np.ndarray) -> np.ndarray:  # pragma: no cover - interface
        """Which items the selector keeps.

        Parameters
        ----------
        centroids : ndarray, shape (k, 3)
            Centroids of the facets or tetrahedra, m.
        normals : ndarray, shape (k, 3), or None
            Unit outward normals of facets; None when tetrahedra are selected.
        vertices : ndarray, shape (k, 3 or 4, 3)
            Their vertices, m.

        Returns
        -------
        ndarray of bool, shape (k,)
            True where kept.
        """
        raise NotImplementedError

    def __and__(self, other):
        return _Combined(self, other, np.logical_and, "&")

    def __or__(self, other):
        return _Combined(self, other, np.logical_or, "|")

    def __invert__(self):
        return _Not(self)


@dataclass(frozen=True)
class _Combined(Selector):
    left: Selector
    right: Selector
    op: Callable
    symbol: str

    def mask(self, centroids: np.ndarray, normals: np.ndarray | None, vertices: np.ndarray) -> np.ndarray:
        return self.op(self.left.mask(centroids, normals, vertices),
                       self.right.mask(centroids, normals, vertices))

    def __repr__(self):
        return f"({self.left!r} {self.symbol} {self.right!r})"


@dataclass(frozen=True)
class _Not(Selector):
    inner: Selector

    def mask(self, centroids: np.ndarray, normals: np.ndarray | None, vertices: np.ndarray) -> np.ndarray:
        return ~np.asarray(self.inner.mask(centroids, normals, vertices))

    def __repr__(self):
        return f"~{self.inner!r}"


@dataclass(frozen=True)
class Plane(Selector):
    """Facets lying on the plane ``normal · x = offset`` (all vertices within ``tolerance`` m).

    With ``outward=True`` only facets whose outward normal points along
    ``normal`` are kept, which separates the two sides of a thin wall.
    """

    normal: tuple
    offset: float
    tolerance: float = 1e-6
    outward: bool = False

    @classmethod
    def axis(cls, axis: str, value: float, tolerance: float = 1e-6, outward: bool = False,
             sign: float = 1.0) -> Plane:
        """The plane ``x_axis = value``.

        Parameters
        ----------
        axis : str
            ``"x"``, ``"y"`` or ``"z"``.
        value : float
            Its coordinate, m.
        tolerance : float
            Distance of a facet's vertices from the plane, m.
        outward : bool
            Keep only facets whose outward normal points along ``sign`` × the axis.
        sign : float
            ±1, the direction of the normal.

        Returns
        -------
        Plane
            The selector.
        """
        n = np.zeros(3)
        n["xyz".index(axis)] = sign
        return cls(tuple(float(v) for v in n), sign * float(value), tolerance, outward)

    def mask(self, centroids: np.ndarray, normals: np.ndarray | None, vertices: np.ndarray) -> np.ndarray:
        n = np.asarray(self.normal, float)
        n = n / np.linalg.norm(n)
        off = self.offset / np.linalg.norm(np.asarray(self.normal, float))
        on = np.all(np.abs(vertices @ n - off) <= self.tolerance, axis=1)
        if self.outward and normals is not None:
            on &= normals @ n > 0.5
        return on


@dataclass(frozen=True)
class Box(Selector):
    """Centroids inside the axis-aligned box ``[lo, hi]`` (inclusive), m."""

    lo: tuple
    hi: tuple

    def mask(self, centroids: np.ndarray, normals: np.ndarray | None, vertices: np.ndarray) -> np.ndarray:
        lo, hi = np.asarray(self.lo, float), np.asarray(self.hi, float)
        return np.all((centroids >= lo) & (centroids <= hi), axis=1)


@dataclass(frozen=True)
class Facing(Selector):
    """Facets whose outward unit normal is within ``max_angle_deg`` of ``direction``."""

    direction: tuple
    max_angle_deg: float = 10.0

    def mask(self, centroids: np.ndarray, normals: np.ndarray | None, vertices: np.ndarray) -> np.ndarray:
        if normals is None:
            return np.ones(len(centroids), bool)
        d = np.asarray(self.direction, float)
        d = d / np.linalg.norm(d)
        return normals @ d >= np.cos(np.radians(self.max_angle_deg))


@dataclass(frozen=True)
class Predicate(Selector):
    """Any vectorised predicate ``fn(centroids, normals) -> bool array``."""

    fn: Callable
    label: str = "predicate"

    def mask(self, centroids: np.ndarray, normals: np.ndarray | None, vertices: np.ndarray) -> np.ndarray:
        return np.asarray(self.fn(centroids, normals), bool)

    def __repr__(self):
        return f"Predicate({self.label})"


@dataclass(frozen=True)
class Everything(Selector):
    """Selects every facet (useful combined with a region filter)."""

    def mask(self, centroids: np.ndarray, normals: np.ndarray | None, vertices: np.ndarray) -> np.ndarray:
        return np.ones(len(centroids), bool)
