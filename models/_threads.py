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


@functools.cache
def _controller():
    # finding the loaded BLAS libraries takes milliseconds: once per process
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


@contextlib.contextmanager
def single_blas_thread():
    """Limit the BLAS thread pools to one thread inside the block."""
    with _controller().limit(limits=1, user_api="blas"):
        yield


def one_blas_thread(fit):
    """Decorator: run ``fit`` inside :func:`single_blas_thread`."""

    @functools.wraps(fit)
    def wrapper(*args, **kwargs):
        with single_blas_thread():
            return fit(*args, **kwargs)

    return wrapper
