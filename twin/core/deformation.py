"""Displacement fields of a machine at given temperature fields, for the deformed-shape pictures.

A run's drift channels come from adjoint rows (no field is ever solved for);
a picture of the deformed machine needs the whole field, one forward elastic
solve ``K u = F (T − T_ref)`` per temperature field, with the machine's own
elastic problem (:func:`twin.core.machine.elastic_problem`: same element degree,
materials and 3-2-1 mount as its drift outputs).

Cost on the default machine (P2, 257,000 dofs; quiet 2-core machine): about
10 s to assemble and set up AMG (P2 and its P1 companion), then about 3 s per
field (9 AMG-CG iterations from the P1-based start, see
:func:`displacement_fields`).  :class:`DisplacementJob` does this in a forked
worker that starts setting up while the thermal run goes on.  Solves stop
at :data:`PICTURE_TOLERANCE`; on ``heat_cool_9000`` at 1, 2 and 3 h the field
then reproduces the drift channels (the adjoint route) to within 0.06 µm:
0.2 % of Y and Z.
"""
from __future__ import annotations

import multiprocessing as mp
from dataclasses import replace

import numpy as np

import fea
from fea.background import fork_available, start

from .machine import Machine, elastic_problem

#: Relative residual at which the picture solves stop (the output operator's rows use 1e-10).
PICTURE_TOLERANCE = 1e-3
#: ... and the P1 companion solves that start them (cheap: a sixth of the dofs; a rough P1 field is a poor start).
COMPANION_TOLERANCE = 1e-6


def elastic_problems(machine: Machine) -> tuple[fea.ElasticProblem, fea.ElasticProblem | None]:
    """The machine's elastic problem and, when it is P2, its P1 companion on the same mesh.

    Parameters
    ----------
    machine : Machine
        A built machine.

    Returns
    -------
    elastic : fea.ElasticProblem
        The machine's own problem.
    coarse : fea.ElasticProblem or None
        The P1 companion, or None for a P1 machine.
    """
    d = machine.definition
    elastic = elastic_problem(d, machine.mesh)
    coarse = elastic_problem(replace(d, elastic_degree=1), machine.mesh) if elastic.space.degree == 2 else None
    return elastic, coarse


def _on_p2(u1, space):
    """A P1 displacement (3N,) as P2 dofs: the vertex values, and the edge means at the midpoints."""
    v = u1.reshape(-1, 3)
    return np.vstack([v, v[space.edges].mean(axis=1)]).ravel()


def displacement_fields(machine: Machine, temperatures: dict[float, np.ndarray], tolerance: float = PICTURE_TOLERANCE,
                        problems: tuple | None = None) -> dict[float, np.ndarray]:
    """Displacement (n_nodes, 3), m, at the nodes of the machine's elastic space, for each temperature field.

    ``temperatures`` maps a key (a time in s) to a temperature vector on the
    thermal nodes (°C); the result has the same keys.  The first
    ``machine.mesh.n_nodes`` rows are the mesh vertices (P2 numbers its edge
    midpoints after them).  ``problems``: :func:`elastic_problems` of the
    machine, if already built.

    Each iterative solve starts from the best combination (Galerkin, in K's
    energy) of the fields solved before it and, for a P2 machine, the P1
    solution of the same load.  The P1 field carries the smooth bending
    shapes that AMG-CG is slowest to find: on the default machine it halves
    the iterations and brings the Y drift from 8 % to 0.2 % of the channel
    at the same tolerance.

    Parameters
    ----------
    machine : Machine
        A built machine.
    temperatures : dict of float to ndarray
        Key (a time, s) → temperature on the thermal nodes, °C.
    tolerance : float
        Relative residual of the iterative solves.
    problems : tuple, optional
        :func:`elastic_problems` of the machine, if already built.

    Returns
    -------
    dict of float to ndarray
        Key → displacement (n_nodes, 3), m.
    """
    elastic, coarse = problems or elastic_problems(machine)
    solved, out = [], {}
    for key, T in temperatures.items():
        load = elastic.thermal_load(T, machine.thermal)
        basis = list(solved)
        if coarse is not None:
            p1 = coarse.solve_load(coarse.thermal_load(T, machine.thermal), COMPANION_TOLERANCE)
            basis.append(_on_p2(p1, elastic.space))
        guess = None
        if basis:
            U = np.column_stack(basis)             # zero at the supports, so Uᵀ K U is K_ff's projection
            guess = U @ np.linalg.lstsq(U.T @ (elastic.stiffness @ U), U.T @ load, rcond=None)[0]
        u = elastic.solve_load(load, tolerance, guess)
        solved.append(u)
        out[key] = u.reshape(-1, 3)
    return out


def _prepare_then_solve(machine, pipe, tolerance):
    """Worker body: set the elastic solvers up, then solve the fields the parent sends through ``pipe``."""
    receive, send = pipe
    send.close()                       # the parent's end: closing this copy lets a dead parent end recv
    problems = [p.prepare() if p is not None else None for p in elastic_problems(machine)]
    temperatures = receive.recv()
    receive.close()
    return displacement_fields(machine, temperatures, tolerance, problems)


class DisplacementJob:
    """Displacement fields of ``machine`` computed in a forked worker that starts setting up at once.

    ``submit(temperatures)`` hands over the fields (once), ``result()`` waits
    for :func:`displacement_fields` of them; ``cancel()`` stops the worker.
    Without ``fork`` (Windows) the fields are solved in ``submit``.

    Parameters
    ----------
    machine : Machine
        A built machine.
    tolerance : float
        Relative residual of the iterative solves.
    """

    def __init__(self, machine: Machine, tolerance: float = PICTURE_TOLERANCE) -> None:
        self.machine, self.tolerance = machine, tolerance
        self._job = self._send = None
        self._result = None
        if fork_available():
            receive, self._send = mp.get_context("fork").Pipe(duplex=False)
            self._job = start(_prepare_then_solve, machine, (receive, self._send), tolerance)
            receive.close()            # the worker has its own copy

    def submit(self, temperatures: dict[float, np.ndarray]) -> None:
        """Hand over the temperature fields (once).

        Parameters
        ----------
        temperatures : dict of float to ndarray
            Key (a time, s) → temperature on the thermal nodes, °C.
        """
        temperatures = {key: np.asarray(T, float) for key, T in temperatures.items()}
        if self._send is None:
            self._result = displacement_fields(self.machine, temperatures, self.tolerance)
            return
        try:
            self._send.send(temperatures)
        except (BrokenPipeError, ConnectionResetError):
            pass                       # the worker failed while setting up: result() raises its error
        self._send.close()

    def result(self) -> dict[float, np.ndarray]:
        """Wait for the displacement fields.

        Returns
        -------
        dict of float to ndarray
            Key → displacement (n_nodes, 3), m; the worker's error is raised here.
        """
        return self._result if self._job is None else self._job.result()

    def cancel(self) -> None:
        """Stop the worker if it still runs."""
        if self._job is not None:
            self._job.cancel()
            self._send.close()
