"""Linear outputs of the temperature field, precomputed as one operator ``y = C T + c``.

Point temperatures are barycentric rows.  Displacements and strains are
linear in T through the elastic problem, so their rows are adjoint influence
vectors (see :meth:`fea.elastic.ElasticProblem.influence`).  A run then costs
one sparse/dense product per output time and never an elastic solve.
Values are SI: °C, m, and strain as a plain ratio.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .errors import FEAInputError


@dataclass(frozen=True)
class PointTemperature:
    """Temperature (°C) at a point (m)."""

    name: str
    point: tuple


@dataclass(frozen=True)
class PointDisplacement:
    """Displacement component ('x', 'y' or 'z') at a point, m."""

    name: str
    point: tuple
    component: str


@dataclass(frozen=True)
class RelativeDisplacement:
    """Displacement component of ``point`` minus that of ``reference``, m (e.g. tool relative to table)."""

    name: str
    point: tuple
    reference: tuple
    component: str


@dataclass(frozen=True)
class AxialStrain:
    """Mean axial strain along the segment start→end (dimensionless), as a bonded fibre (FBG) reads it.

    For a continuous displacement field the mean of ε_ee along a straight
    segment is exactly ``(u(end) − u(start))·e / |end − start|``.
    """

    name: str
    start: tuple
    end: tuple


UNITS = {PointTemperature: "°C", PointDisplacement: "m", RelativeDisplacement: "m", AxialStrain: "1"}


@dataclass
class OutputOperator:
    """``y = matrix @ T + offset`` for a list of named outputs."""

    names: list
    units: list
    matrix: sp.csr_matrix
    offset: np.ndarray

    @property
    def n_outputs(self):
        return len(self.names)

    def apply(self, T):
        """Outputs for one temperature vector (n,) or a block (n, k) → (p,) or (p, k)."""
        y = self.matrix @ T
        return y + (self.offset if np.ndim(T) == 1 else self.offset[:, None])

    def subset(self, names):
        """The operator restricted to the named outputs, in the given order."""
        index = [self.index(n) for n in names]
        return OutputOperator([self.names[i] for i in index], [self.units[i] for i in index],
                              self.matrix[index], self.offset[index])

    def index(self, name):
        try:
            return self.names.index(name)
        except ValueError:
            raise FEAInputError(f"unknown output {name!r}; outputs: {self.names}") from None


def build_output_operator(specs, thermal_system, elastic=None, snap_distance=0.0):
    """Precompute the operator for a list of output specifications.

    Displacement and strain outputs need ``elastic`` (an
    :class:`~fea.elastic.ElasticProblem`); their rows are found with one
    adjoint solve each, all sharing one factorisation or AMG hierarchy.
    ``snap_distance`` (m) lets points that sit just outside a curved or
    faceted surface snap onto it.
    """
    names = [s.name for s in specs]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise FEAInputError(f"duplicate output names: {dupes}")
    n = thermal_system.n_nodes
    rows = [None] * len(specs)
    offset = np.zeros(len(specs))
    temps = [i for i, s in enumerate(specs) if isinstance(s, PointTemperature)]
    if temps:
        W = thermal_system.point_weights([specs[i].point for i in temps],
                                         names=[specs[i].name for i in temps], snap_distance=snap_distance)
        for k, i in enumerate(temps):
            rows[i] = W[k]
    mech = [i for i, s in enumerate(specs) if not isinstance(s, PointTemperature)]
    if mech:
        if elastic is None:
            raise FEAInputError(f"outputs {[specs[i].name for i in mech]} need an elastic problem")
        L = sp.vstack([_displacement_rows(specs[i], elastic, snap_distance) for i in mech]).tocsr()
        G = elastic.influence(L, thermal_system)
        for k, i in enumerate(mech):
            rows[i] = sp.csr_matrix(G[k])
            offset[i] = -elastic.reference_temperature * G[k].sum()
    for i, s in enumerate(specs):
        if type(s) not in UNITS:
            raise FEAInputError(f"unknown output specification {s!r}")
    matrix = sp.vstack(rows).tocsr() if rows else sp.csr_matrix((0, n))
    return OutputOperator(names, [UNITS[type(s)] for s in specs], matrix, offset)


def _displacement_rows(spec, elastic, snap):
    if isinstance(spec, PointDisplacement):
        return elastic.point_rows([spec.point], spec.component, [spec.name], snap)
    if isinstance(spec, RelativeDisplacement):
        both = elastic.point_rows([spec.point, spec.reference], spec.component * 2,
                                  [spec.name, f"{spec.name} reference"], snap)
        return both[0] - both[1]
    start, end = np.asarray(spec.start, float), np.asarray(spec.end, float)
    length = np.linalg.norm(end - start)
    if length == 0:
        raise FEAInputError(f"strain line {spec.name!r} has zero length")
    e = (end - start) / length
    ends = elastic.point_rows([end] * 3 + [start] * 3, "xyz" * 2,
                              [f"{spec.name} end"] * 3 + [f"{spec.name} start"] * 3, snap)
    weights = np.concatenate([e, -e]) / length
    return sp.csr_matrix(weights[None, :]) @ ends
