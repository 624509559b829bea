"""Linear outputs of the temperature field, precomputed as one operator ``y = C T + c``.

Point temperatures are barycentric rows.  Displacements and strains are
linear in T through the elastic problem, so their rows are adjoint influence
vectors (see :meth:`fea.elastic.ElasticProblem.influence`).  A run then costs
one sparse/dense product per output time and never an elastic solve.
Values are SI: °C, m, and strain as a plain ratio.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from . import background
from .errors import FEAInputError

if TYPE_CHECKING:
    from .background import Background
    from .elastic import ElasticProblem
    from .heat import ThermalSystem


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


class OutputOperator:
    """``y = matrix @ T + offset`` for a list of named outputs.

    Some rows may be *deferred*: still being computed by a background worker
    (see ``build_output_operator(..., concurrent=True)``).  ``matrix``,
    ``offset``, :meth:`apply` and :meth:`subset` wait for them; a time loop
    that wants to go on meanwhile uses :meth:`poll`, :meth:`apply_available`
    and :attr:`deferred_rows` (as :meth:`fea.transient.ThermalSolver.run`
    does).

    Parameters
    ----------
    names : list of str
        Output names.
    units : list of str
        Their SI units (``°C``, ``m``, ``1``).
    matrix : sparse matrix, shape (p, n_nodes)
        Rows over the thermal nodes, output unit per °C.
    offset : ndarray, shape (p,)
        Constant terms, output unit.
    deferred : tuple, optional
        ``(rows, background job, finish)`` for rows still being computed.
    """

    def __init__(self, names: list[str], units: list[str], matrix: sp.spmatrix, offset: np.ndarray,
                 deferred: tuple | None = None) -> None:
        self.names = list(names)
        self.units = list(units)
        self._matrix = sp.csr_matrix(matrix)
        self._offset = np.asarray(offset, dtype=float)
        self._deferred = deferred       # (rows, Background job, finish(result) -> (row block, offsets))
        #: Facts about how the rows were computed (elastic timings, iterations), once available.
        self.stats = {}

    def __repr__(self):
        state = f", {len(self.deferred_rows)} rows deferred" if self._deferred else ""
        return f"OutputOperator({self.names}{state})"

    def __getstate__(self):
        self.resolve()
        return self.__dict__

    @property
    def n_outputs(self) -> int:
        """Number of outputs."""
        return len(self.names)

    # ------------------------------------------------------------------ deferred rows
    @property
    def deferred_rows(self) -> np.ndarray:
        """Indices of the rows not yet available (empty once complete)."""
        return np.array([], dtype=int) if self._deferred is None else self._deferred[0]

    def poll(self) -> bool:
        """Take in finished background rows without blocking.

        Returns
        -------
        bool
            True when every row is available.
        """
        if self._deferred is not None and self._deferred[1].done():
            self.resolve()
        return self._deferred is None

    def resolve(self) -> OutputOperator:
        """Wait for deferred rows (re-raising the background job's error, if any).

        Returns
        -------
        OutputOperator
            ``self``, complete.
        """
        if self._deferred is None:
            return self
        rows, job, finish = self._deferred
        block, offsets = finish(job.result())
        if job.forked:
            self.stats["worker_peak_rss_bytes"] = job.worker_peak_rss_bytes
        matrix = self._matrix.tolil()
        matrix[rows] = block
        self._matrix = matrix.tocsr()
        self._offset = self._offset.copy()
        self._offset[rows] = offsets
        self._deferred = None
        return self

    @property
    def background(self) -> Background | None:
        """The background job computing deferred rows, or None."""
        return None if self._deferred is None else self._deferred[1]

    # ------------------------------------------------------------------ values
    @property
    def matrix(self) -> sp.csr_matrix:
        """The rows (p, n_nodes), output unit per °C; waits for deferred rows."""
        self.resolve()
        return self._matrix

    @matrix.setter
    def matrix(self, value: sp.spmatrix) -> None:
        self.resolve()
        self._matrix = sp.csr_matrix(value)

    @property
    def offset(self) -> np.ndarray:
        """The constant terms (p,), output unit; waits for deferred rows."""
        self.resolve()
        return self._offset

    @offset.setter
    def offset(self, value: np.ndarray) -> None:
        self.resolve()
        self._offset = np.asarray(value, dtype=float)

    def apply(self, T: np.ndarray) -> np.ndarray:
        """The outputs for temperatures.

        Parameters
        ----------
        T : ndarray, shape (n,) or (n, k)
            Temperature on the thermal nodes, °C (one vector or k of them).

        Returns
        -------
        ndarray, shape (p,) or (p, k)
            Outputs in their units.
        """
        y = self.matrix @ T
        return y + (self.offset if np.ndim(T) == 1 else self.offset[:, None])

    def apply_available(self, T: np.ndarray) -> np.ndarray:
        """Like :meth:`apply`, without waiting.

        Parameters
        ----------
        T : ndarray, shape (n,) or (n, k)
            Temperature on the thermal nodes, °C.

        Returns
        -------
        ndarray, shape (p,) or (p, k)
            Outputs in their units; deferred rows are NaN.
        """
        y = self._matrix @ T
        y = y + (self._offset if np.ndim(T) == 1 else self._offset[:, None])
        y[self.deferred_rows] = np.nan
        return y

    def subset(self, names: list[str]) -> OutputOperator:
        """The operator restricted to some outputs.

        Parameters
        ----------
        names : list of str
            Output names, in the order wanted.

        Returns
        -------
        OutputOperator
            Complete (waits for deferred rows).
        """
        index = [self.index(n) for n in names]
        return OutputOperator([self.names[i] for i in index], [self.units[i] for i in index],
                              self.matrix[index], self.offset[index])

    def index(self, name: str) -> int:
        """The row of an output.

        Parameters
        ----------
        name : str
            Output name.

        Returns
        -------
        int
            Its row.
        """
        try:
            return self.names.index(name)
        except ValueError:
            raise FEAInputError(f"unknown output {name!r}; outputs: {self.names}") from None


def build_output_operator(specs: list, thermal_system: ThermalSystem, elastic: ElasticProblem | None = None,
                          snap_distance: float = 0.0, concurrent: bool = False) -> OutputOperator:
    """Precompute the operator for a list of output specifications.

    Displacement and strain outputs need ``elastic`` (an
    :class:`~fea.elastic.ElasticProblem`); their rows are found with one
    adjoint solve each, all sharing one factorisation or AMG hierarchy.
    ``snap_distance`` (m) lets points that sit just outside a curved or
    faceted surface snap onto it.

    With ``concurrent=True`` those adjoint rows are computed in a forked
    worker process (:mod:`fea.background`) and the operator is returned at
    once with them *deferred*: a :class:`~fea.transient.ThermalSolver` run
    proceeds on the other core and fills in the deferred outputs when the
    rows arrive, and anything that needs the full operator waits for them.
    Bad specifications (points outside the mesh, missing supports) still
    raise here.  Without ``fork`` (Windows) the rows are computed at once.

    Parameters
    ----------
    specs : list
        :class:`PointTemperature`, :class:`PointDisplacement`,
        :class:`RelativeDisplacement` and :class:`AxialStrain` specifications (points in m).
    thermal_system : ThermalSystem
        The thermal nodes the rows act on.
    elastic : ElasticProblem, optional
        Needed by displacement and strain outputs.
    snap_distance : float
        How far outside the mesh a point may lie and be snapped onto it, m.
    concurrent : bool
        Compute the adjoint rows in a forked worker and return at once.

    Returns
    -------
    OutputOperator
        Rows in °C, m or strain (1) per °C.
    """
    names = _checked_names(specs)
    n = thermal_system.n_nodes
    rows = [None] * len(specs)
    offset = np.zeros(len(specs))
    stats = {}
    _fill_temperature_rows(rows, specs, thermal_system, snap_distance)
    mech = [i for i, s in enumerate(specs) if not isinstance(s, PointTemperature)]
    deferred = None
    if mech:
        if elastic is None:
            raise FEAInputError(f"outputs {[specs[i].name for i in mech]} need an elastic problem")
        L = sp.vstack([_displacement_rows(specs[i], elastic, snap_distance) for i in mech]).tocsr()
        t_ref = elastic.reference_temperature

        def finish(result):
            G, elastic_stats = result
            stats.update(elastic_stats)
            return sp.csr_matrix(G), -t_ref * G.sum(axis=1)

        if concurrent:
            elastic._check_supports()       # raise bad supports here, not later from the worker
            job = background.start(_influence_with_stats, elastic, L, thermal_system)
            deferred = (np.array(mech), job, finish)
            for i in mech:
                rows[i] = sp.csr_matrix((1, n))
        else:
            block, offsets = finish(_influence_with_stats(elastic, L, thermal_system))
            for k, i in enumerate(mech):
                rows[i] = block[k]
                offset[i] = offsets[k]
    matrix = sp.vstack(rows).tocsr() if rows else sp.csr_matrix((0, n))
    operator = OutputOperator(names, [UNITS[type(s)] for s in specs], matrix, offset, deferred)
    operator.stats = stats
    operator.poll()                         # complete at once when the rows were computed serially
    return operator


def _fill_temperature_rows(rows, specs, thermal_system, snap_distance):
    """Put the barycentric row of every :class:`PointTemperature` of ``specs`` into ``rows`` (same order)."""
    temps = [i for i, s in enumerate(specs) if isinstance(s, PointTemperature)]
    if temps:
        W = thermal_system.point_weights([specs[i].point for i in temps],
                                         names=[specs[i].name for i in temps], snap_distance=snap_distance)
        for k, i in enumerate(temps):
            rows[i] = W[k]


def _checked_names(specs):
    """The names of output specifications, refusing duplicates and unknown specification types."""
    names = [s.name for s in specs]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise FEAInputError(f"duplicate output names: {dupes}")
    for s in specs:
        if type(s) not in UNITS:
            raise FEAInputError(f"unknown output specification {s!r}")
    return names


def _influence_with_stats(elastic, rows, thermal_system):
    G = elastic.influence(rows, thermal_system)
    return G, dict(elastic.stats)


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
