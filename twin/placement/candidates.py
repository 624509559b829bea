"""Candidate sensor locations of the placement study and their output rows over the thermal nodes.

Candidates are surface nodes of chosen parts (outer surfaces: the sealed
cavities and the floor contact are left out), thinned to a given count by
farthest-point sampling, plus the thermal camera's spots and optionally the
installed thermometers.  Each candidate is one row of an output operator over
the thermal nodes (an identity row for a node, the barycentric row for a spot).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..core.machine import Machine
from ..errors import TwinInputError
from ..infra.sweep import cached

DEFAULT_PARTS = ("base", "table", "column", "carrier", "ram", "z_motor", "spindle_motor")


@dataclass
class Candidates:
    """Candidate sensor locations and their output rows over the thermal nodes.

    Attributes
    ----------
    names : list of str
        ``s<node>`` for a surface node, the channel name for a camera spot or installed sensor.
    kinds : list of str
        ``surface``, ``camera`` or ``installed``.
    parts : list of str
        The part each candidate lies on (empty for an installed sensor).
    points : ndarray, shape (k, 3)
        Positions, m.
    rows : scipy.sparse.csr_matrix, shape (k, n_thermal)
        Output rows: temperature of each candidate (°C) from the thermal nodes' temperatures.
    """

    names: list
    kinds: list
    parts: list
    points: np.ndarray
    rows: sp.csr_matrix

    def __len__(self) -> int:
        return len(self.names)

    def index(self, names: list[str]) -> list[int]:
        """Positions of ``names`` among the candidates.

        Parameters
        ----------
        names : list of str
            Candidate names (a missing one raises ``KeyError``).

        Returns
        -------
        list of int
        """
        where = {n: i for i, n in enumerate(self.names)}
        return [where[n] for n in names]


@dataclass(frozen=True)
class CandidateSpec:
    """A picklable recipe of :func:`candidate_locations` (its keyword arguments)."""

    parts: tuple = DEFAULT_PARTS
    n_surface: int = 2000
    camera: bool = True
    installed: bool = False
    exclude_groups: tuple = ("cavities", "floor")

    def build(self, machine: Machine) -> Candidates:
        """The candidates on ``machine``, built once per process and machine.

        Parameters
        ----------
        machine : Machine
            A built machine.

        Returns
        -------
        Candidates
        """
        return cached(("candidates", id(machine), self), lambda: candidate_locations(machine, **vars(self)))


def farthest_point_sample(points: np.ndarray, n: int, start: int | None = None) -> np.ndarray:
    """Indices of ``n`` points spread evenly by farthest-point sampling (deterministic).

    Parameters
    ----------
    points : ndarray, shape (m, 3)
        Positions, m.
    n : int
        How many to keep; all of them if ``n >= m``.
    start : int, optional
        The first point; default the highest (largest z, then smallest x).

    Returns
    -------
    ndarray of int64, shape (min(n, m),)
        Indices into ``points`` in the order chosen (``arange(m)`` if ``n >= m``).
    """
    points = np.asarray(points, float)
    if n >= len(points):
        return np.arange(len(points))
    first = int(np.argmax(points[:, 2] - 1e-3 * points[:, 0])) if start is None else int(start)
    chosen = np.empty(n, dtype=np.int64)
    chosen[0] = first
    dist = np.linalg.norm(points - points[first], axis=1)
    for k in range(1, n):
        nxt = int(np.argmax(dist))
        chosen[k] = nxt
        np.minimum(dist, np.linalg.norm(points - points[nxt], axis=1), out=dist)
    return chosen


def _outer_facets(mesh, parts, exclude_groups):
    """Boundary facets ``(tet, local)`` of ``parts``, without those of the ``exclude_groups`` facet groups."""
    tet, local = mesh.boundary_facets()
    keep = np.isin(np.array([mesh.region_names[r] for r in mesh.regions[tet]]), parts)
    if exclude_groups:
        excluded = set()
        for g in exclude_groups:
            if g in mesh.facet_groups:
                gt, gl = mesh.facet_group(g)
                excluded.update(zip(gt.tolist(), gl.tolist()))
        keep &= np.array([(a, b) not in excluded for a, b in zip(tet.tolist(), local.tolist())])
    return tet[keep], local[keep]


def _surface_candidates(machine, parts, exclude_groups, n_surface):
    """``(names, parts, points, rows)`` of the outer surface nodes of ``parts`` thinned to ``n_surface``; or None."""
    mesh, thermal = machine.mesh, machine.thermal
    tet, local = _outer_facets(mesh, parts, exclude_groups)
    nodes = mesh.facet_nodes(tet, local, tets=thermal.tets)            # thermal numbering
    part_of = np.repeat(mesh.regions[tet], 3)
    flat, first = np.unique(nodes.ravel(), return_index=True)
    if not n_surface or not len(flat):
        return None
    node_part = [mesh.region_names[r] for r in part_of[first]]
    pick = np.sort(farthest_point_sample(thermal.points[flat], int(n_surface)))
    rows = sp.csr_matrix((np.ones(len(pick)), (np.arange(len(pick)), flat[pick])),
                         shape=(len(pick), thermal.n_nodes))
    return ([f"s{int(flat[i]):06d}" for i in pick], [node_part[i] for i in pick], thermal.points[flat][pick], rows)


def _channel_candidates(machine, camera, installed):
    """The machine's camera spots and/or installed thermometers as candidates: a list of channels."""
    extra = []
    if camera and machine.definition.camera is not None:
        extra += [c for c in machine.channels if c.kind == "camera"]
    if installed:
        extra += [c for c in machine.channels if c.kind == "temperature"]
    return extra


def candidate_locations(machine: Machine, parts: tuple = DEFAULT_PARTS, n_surface: int = 2000, camera: bool = True,
                        installed: bool = False, exclude_groups: tuple = ("cavities", "floor")) -> Candidates:
    """Surface nodes of ``parts`` (outer surfaces, thinned to ``n_surface``), camera spots, installed sensors.

    Parameters
    ----------
    machine : Machine
        A built machine.
    parts : tuple of str
        Parts whose outer surface nodes are candidates; empty for every part.
    n_surface : int
        Surface candidates kept by farthest-point sampling.
    camera, installed : bool
        Add the camera's spots / the installed thermometers.
    exclude_groups : tuple of str
        Facet groups whose nodes are no candidates (sealed cavities, floor contact).

    Returns
    -------
    Candidates
        Surface nodes first (in node order), then the camera spots and installed thermometers.

    Raises
    ------
    TwinInputError
        For an unknown part, or if no candidate is left.
    """
    known = [p.name for p in machine.definition.geometry.parts]
    parts = list(parts or known)
    unknown = sorted(set(parts) - set(known))
    if unknown:
        raise TwinInputError(f"unknown part(s) {unknown}; parts of {machine.name!r}: {known}")
    names, kinds, part_list, pts, rows = [], [], [], [], []
    surface = _surface_candidates(machine, parts, exclude_groups, n_surface)
    if surface is not None:
        names += surface[0]
        kinds += ["surface"] * len(surface[0])
        part_list += surface[1]
        pts.append(surface[2])
        rows.append(surface[3])
    extra = _channel_candidates(machine, camera, installed)
    if extra:
        rows.append(machine.outputs.subset([c.name for c in extra]).matrix)
        pts.append(np.array([c.position for c in extra], float))
        names += [c.name for c in extra]
        kinds += ["camera" if c.kind == "camera" else "installed" for c in extra]
        part_list += [machine.definition.camera.part if c.kind == "camera" else "" for c in extra]
    if not names:
        raise TwinInputError("no candidate location: give parts with outer surface nodes or keep the camera")
    return Candidates(names, kinds, part_list, np.vstack(pts), sp.vstack(rows).tocsr())
