"""Fitting with one BLAS thread, so a seed gives the same model whatever the BLAS thread count.

A multi-threaded OpenBLAS splits long dot products (``Aᵀv``, ``Aᵀ B`` with
many rows) into per-thread partial sums, so ``OPENBLAS_NUM_THREADS=1`` and
``=2`` round differently; an iterative fit (ANFIS, FCM, PSO, Adam) can carry
that difference to the end. Every ``fit`` in :mod:`models` runs inside
:func:`single_blas_thread`. The matrices are small (tens of columns), so one
thread costs little; it is the process-wide pool, so fits must not run in
parallel threads of one process (use processes, as ``twin.infra.sweep`` does).
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable, Iterator
from typing import ParamSpec, TypeVar

P = ParamSpec("P")
R = TypeVar("R")


@functools.cache
def _controller():
    # finding the loaded BLAS libraries takes milliseconds: once per process
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


@contextlib.contextmanager
def single_blas_thread() -> Iterator[None]:
    """Limit the BLAS thread pools to one thread inside the block.

    Yields
    ------
    None
        Control, with the BLAS pools limited; the previous limits are restored on exit.
    """
    with _controller().limit(limits=1, user_api="blas"):
        yield


def one_blas_thread(fit: Callable[P, R]) -> Callable[P, R]:
    """Decorator: run ``fit`` inside :func:`single_blas_thread`.

    Parameters
    ----------
    fit : callable
        The function to wrap (an estimator's ``fit``, usually).

    Returns
    -------
    callable
        ``fit`` with the same signature, run with one BLAS thread.
    """

    @functools.wraps(fit)
    def wrapper(*args, **kwargs):
        with single_blas_thread():
            return fit(*args, **kwargs)

    return wrapper
