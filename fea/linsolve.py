"""The single seam through which sparse direct factorisations are chosen.

``factorize(A)`` returns a callable ``solve(b)``.  The backend is picked in
this order unless one is named: scikit-sparse CHOLMOD, pypardiso, SciPy
SuperLU.  CHOLMOD and pypardiso are optional; SciPy is always there.  The
environment variable ``THERMAL_TWIN_SOLVER`` (``cholmod``, ``pardiso``,
``superlu``) overrides the automatic choice.
"""
from __future__ import annotations

import contextlib
import importlib.util
import os

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from .errors import FEAInputError

BACKENDS = ("cholmod", "pardiso", "superlu")


@contextlib.contextmanager
def blas_threads(n):
    """Limit the BLAS thread pools to ``n`` threads inside the block (a no-op without threadpoolctl).

    Many small dense operations, as in an AMG setup, run far slower with a
    multi-threaded OpenBLAS than with one thread, and much slower still when
    another process competes for the cores.
    """
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        yield
        return
    with threadpool_limits(limits=n, user_api="blas"):
        yield


def available_backends():
    """Backends importable in this environment, fastest first."""
    found = []
    if importlib.util.find_spec("sksparse") is not None:
        found.append("cholmod")
    if importlib.util.find_spec("pypardiso") is not None:
        found.append("pardiso")
    found.append("superlu")
    return found


def default_backend():
    """The backend ``factorize`` uses when none is named."""
    chosen = os.environ.get("THERMAL_TWIN_SOLVER", "").strip().lower()
    if chosen:
        if chosen not in BACKENDS:
            raise FEAInputError(f"THERMAL_TWIN_SOLVER={chosen!r} is not one of {BACKENDS}")
        return chosen
    return available_backends()[0]


def factorize(matrix, symmetric_positive_definite=True, backend=None):
    """Factorise a sparse matrix once; return ``solve(b)`` for vectors or (n, k) blocks.

    For a symmetric positive definite matrix SuperLU is run with a symmetric
    minimum-degree ordering and no pivoting, which halves the factorisation
    time and the fill of the default COLAMD ordering on heat matrices.
    """
    backend = backend or default_backend()
    if backend not in available_backends():
        raise FEAInputError(f"solver backend {backend!r} is not installed; available: {available_backends()}")
    A = sp.csc_matrix(matrix)
    if backend == "cholmod" and symmetric_positive_definite:
        from sksparse.cholmod import cholesky

        factor = cholesky(A)
        return factor
    if backend == "pardiso":
        import pypardiso

        solver = pypardiso.PyPardisoSolver(mtype=2 if symmetric_positive_definite else 11)
        A_csr = sp.csr_matrix(sp.triu(A) if symmetric_positive_definite else A)
        solver.factorize(A_csr)
        return lambda b: solver.solve(A_csr, np.asarray(b, dtype=float))
    if symmetric_positive_definite:
        lu = sla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                      options=dict(SymmetricMode=True))
    else:
        lu = sla.splu(A)
    return lu.solve
