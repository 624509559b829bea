"""The single seam through which sparse direct factorisations are chosen.

``factorize(A)`` returns a callable ``solve(b)``.  The backend is picked in
this order unless one is named: scikit-sparse CHOLMOD, pypardiso, SciPy
SuperLU.  CHOLMOD and pypardiso are optional; SciPy is always there.  The
environment variable ``THERMAL_TWIN_SOLVER`` (``cholmod``, ``pardiso``,
``superlu``, ``mixed``) overrides the automatic choice.

``mixed`` is never chosen automatically: SuperLU factorises a symmetric
positive definite matrix in single precision, and each solve is refined in
double precision to a relative residual of :data:`REFINEMENT_TOLERANCE`,
starting from an initial guess when the caller has one (a time stepper
passes an extrapolation of its last steps).  Single-precision factors halve
the memory traffic of the triangular solves; from a good guess one solve
usually suffices.  If the refinement stagnates (a matrix too ill-conditioned
for single precision) it falls back to a double-precision factorisation.
"""
from __future__ import annotations

import contextlib
import importlib.util
import os
from collections.abc import Callable, Iterator

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from .errors import FEAInputError

BACKENDS = ("cholmod", "pardiso", "superlu", "mixed")
#: Relative residual ‖b − A x‖ / ‖b‖ to which the ``mixed`` backend refines every solve.
REFINEMENT_TOLERANCE = 1e-12
REFINEMENT_MAX_ITERATIONS = 8


@contextlib.contextmanager
def blas_threads(n: int) -> Iterator[None]:
    """Limit the BLAS thread pools inside the block (a no-op without threadpoolctl).

    Many small dense operations, as in an AMG setup, run far slower with a
    multi-threaded OpenBLAS than with one thread, and much slower still when
    another process competes for the cores.

    Parameters
    ----------
    n : int
        Threads.

    Yields
    ------
    None
        Inside the limit.
    """
    controller = _threadpool_controller()
    if controller is None:
        yield
        return
    with controller.limit(limits=n, user_api="blas"):
        yield


_CONTROLLER = []


def _threadpool_controller():
    """A cached threadpoolctl controller (finding the libraries takes ms; limiting with it takes µs)."""
    if not _CONTROLLER:
        try:
            from threadpoolctl import ThreadpoolController
            _CONTROLLER.append(ThreadpoolController())
        except ImportError:  # optional dependency
            _CONTROLLER.append(None)
    return _CONTROLLER[0]


def available_backends() -> list[str]:
    """The solver backends importable in this environment.

    Returns
    -------
    list of str
        Fastest first, e.g. ``["cholmod", "superlu", "mixed"]``.
    """
    found = []
    if importlib.util.find_spec("sksparse") is not None:
        found.append("cholmod")
    if importlib.util.find_spec("pypardiso") is not None:
        found.append("pardiso")
    found.append("superlu")
    found.append("mixed")
    return found


def default_backend() -> str:
    """The backend :func:`factorize` uses when none is named.

    Returns
    -------
    str
        ``$THERMAL_TWIN_SOLVER`` if set, else the fastest available.
    """
    chosen = os.environ.get("THERMAL_TWIN_SOLVER", "").strip().lower()
    if chosen:
        if chosen not in BACKENDS:
            raise FEAInputError(f"THERMAL_TWIN_SOLVER={chosen!r} is not one of {BACKENDS}")
        return chosen
    return available_backends()[0]


def factorize(matrix: sp.spmatrix, symmetric_positive_definite: bool = True,
              backend: str | None = None) -> Callable[[np.ndarray], np.ndarray]:
    """Factorise a sparse matrix once.

    For a symmetric positive definite matrix SuperLU is run with a symmetric
    minimum-degree ordering and no pivoting, which halves the factorisation
    time and the fill of the default COLAMD ordering on heat matrices.

    Parameters
    ----------
    matrix : scipy.sparse matrix, shape (n, n)
        The matrix.
    symmetric_positive_definite : bool
        It is SPD (allows Cholesky and the symmetric ordering).
    backend : str, optional
        One of :func:`available_backends` (default :func:`default_backend`).

    Returns
    -------
    callable
        ``solve(b)`` for vectors (n,) or blocks (n, k).
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
    if backend == "mixed" and symmetric_positive_definite:
        return MixedPrecisionSolve(A)
    return _superlu(A, symmetric_positive_definite).solve


def _superlu(A, symmetric_positive_definite):
    if symmetric_positive_definite:
        return sla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options=dict(SymmetricMode=True))
    return sla.splu(A)


def _norm(v):
    # Not np.linalg.norm: its BLAS dot, multi-threaded, can take milliseconds under load.
    return float(np.sqrt(np.einsum("i,i->", v, v)))


class MixedPrecisionSolve:
    """``solve(b, guess=None)``: single-precision SuperLU factors, refined in double precision.

    Every solve ends with ‖b − A x‖ ≤ :data:`REFINEMENT_TOLERANCE` ‖b‖
    (checked with the double-precision matrix), so the result equals a
    double-precision direct solve to that tolerance.  ``solves`` counts the
    single-precision triangular solves, ``fallback`` tells whether the
    factorisation had to be redone in double precision.

    Parameters
    ----------
    A : scipy.sparse matrix
        The matrix (double precision).
    """

    accepts_guess = True

    def __init__(self, A: sp.spmatrix) -> None:
        self.A = sp.csr_matrix(A)
        self._lu32 = _superlu(sp.csc_matrix(A, dtype=np.float32), True)
        self._double = None
        self.solves = 0
        self.fallback = False

    def _correction(self, r, norm):
        # Scaled to unit norm so that tiny residuals do not underflow in single precision.
        self.solves += 1
        return self._lu32.solve((r / norm).astype(np.float32)).astype(np.float64) * norm

    def __call__(self, b, guess=None):
        b = np.asarray(b, dtype=float)
        if b.ndim == 2:
            return np.column_stack([self(b[:, k], None if guess is None else guess[:, k])
                                    for k in range(b.shape[1])])
        if self._double is not None:
            return self._double.solve(b)
        target = REFINEMENT_TOLERANCE * _norm(b)
        if guess is None:
            x, r = np.zeros_like(b), b.copy()
        else:
            x = np.array(guess, dtype=float)
            r = b - self.A @ x
        previous = np.inf
        for _ in range(REFINEMENT_MAX_ITERATIONS):
            norm = _norm(r)
            if norm <= target:
                return x
            if norm > 0.1 * previous:      # stagnating: too ill-conditioned for single precision
                break
            previous = norm
            x += self._correction(r, norm)
            r = b - self.A @ x
        if _norm(r) <= target:
            return x
        self._double = _superlu(sp.csc_matrix(self.A), True)
        self.fallback = True
        return self._double.solve(b)
